"""Environment speed: single-env steps/s (numpy vs compiled physics) and vector-env reset vs N.

Part 1 steps ``gym.make("QuadFault-v0", estimator=E, physics=P)`` with the zero residual
action for P = numpy and numba side by side in one run (rounds interleaved, best round kept,
numba compiled / loaded from its cache before timing) and prints env steps per wall second,
per CPU second of this process and the numba / numpy ratio, for E = none and irls.

Part 2 times ``QuadFaultVectorEnv(N, "none", "random").reset(seed=0)`` (the batched reset,
best of 2 by CPU time) against the per-row path it replaced -- one
``QuadFaultEnv.reset(seed=i)`` per sub-env, the same episodes -- and the part of a row's
reset that stays per row in Python (seeding the row's generator and drawing its random
scenario), measured side by side for each N, in wall and CPU seconds of this process.

Part 3 steps ``QuadFaultVectorEnv(N, "none", scenario, duration=0.1)`` (compiled physics,
zero action) for ``scenario="combined"`` (one trajectory shared by every row) and
``"random"`` (a trajectory and a schedule per row) side by side: CPU seconds per ordinary
step, and of the step that autoresets every row (the episodes end together).

Every timing line carries the 1-minute load average: on a shared machine read the ratios and
the per-CPU-second rates, not the absolute numbers.

    nice -n 10 python benchmarks/bench_env_step.py                  # N up to 4096
    nice -n 10 python benchmarks/bench_env_step.py --quick          # small, for a smoke run
"""

from __future__ import annotations

import argparse
import os
import sys
import time


def _parse(argv):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=400,
                   help="compiled-physics steps per round (numpy: a tenth; default 400)")
    p.add_argument("--rounds", type=int, default=3, help="interleaved rounds, best kept")
    p.add_argument("--sizes", type=int, nargs="+", default=[256, 1024, 4096],
                   help="vector env sizes N for the reset timing (default 256 1024 4096)")
    p.add_argument("--estimators", nargs="+", default=["none", "irls"],
                   choices=["none", "irls", "ekf", "truth"])
    p.add_argument("--quick", action="store_true", help="few steps, N = 64 and 256 only")
    return p.parse_args(argv)


def _load() -> str:
    return f"load {os.getloadavg()[0]:.2f}"


def _clock(fn):
    """(wall seconds, CPU seconds of this process) of ``fn()``."""
    w, c = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w, time.process_time() - c


def single_env(estimators, steps: int, rounds: int) -> None:
    import gymnasium as gym
    import numpy as np

    import quad_fault_env  # noqa: F401  (registers the ids)

    print(f"# single env QuadFault-v0, zero residual action ({_load()}, {os.cpu_count()} CPUs)")
    print(f"{'estimator':<10} {'physics':<7} {'steps/s':>9} {'steps/CPU-s':>12} {'ms/step':>8}")
    a = np.zeros(4, dtype=np.float32)
    for est in estimators:
        envs = {p: gym.make("QuadFault-v0", estimator=est, physics=p)
                for p in ("numpy", "numba")}
        n_steps = {"numpy": max(steps // 10, 5), "numba": steps}
        best = {p: (0.0, 0.0) for p in envs}
        for env in envs.values():
            env.reset(seed=0)
            for _ in range(3):  # numba compile / cache load, first-step allocations
                env.step(a)

        def run(env, n):
            for _ in range(n):
                *_, term, trunc, _ = env.step(a)
                if term or trunc:
                    env.reset()

        for _ in range(rounds):
            for p, env in envs.items():
                wall, cpu = _clock(lambda: run(env, n_steps[p]))  # noqa: B023
                rate = (n_steps[p] / wall, n_steps[p] / max(cpu, 1e-9))
                best[p] = max(best[p], rate)
        for p in envs:
            print(f"{est:<10} {p:<7} {best[p][0]:>9.0f} {best[p][1]:>12.0f} "
                  f"{1e3 / best[p][0]:>8.2f}")
        print(f"{est:<10} ratio numba/numpy: {best['numba'][0] / best['numpy'][0]:.1f}x wall, "
              f"{best['numba'][1] / best['numpy'][1]:.1f}x per CPU-s ({_load()})")


def vector_reset(sizes) -> None:
    import gymnasium as gym

    from quad_fault_env.envs.quad_fault import QuadFaultEnv
    from quad_fault_env.vector import QuadFaultVectorEnv

    print(f"\n# vector env reset, scenario='random', estimator='none' ({_load()})")
    print(f"{'N':>6} {'batched s':>10} {'per-row s':>10} {'ratio':>6} {'batched CPU-s':>14} "
          f"{'per-row CPU-s':>14} {'CPU ratio':>9} {'scenario+seed CPU-s':>20}  load")
    QuadFaultVectorEnv(4, "none", "random").reset(seed=0)  # imports, numba cache
    for n in sizes:
        vec = QuadFaultVectorEnv(n, "none", "random")
        vec.reset(seed=1)
        batched = min((_clock(lambda: vec.reset(seed=0)) for _ in range(2)),  # noqa: B023
                      key=lambda x: x[1])
        single = QuadFaultEnv("none", "random")

        def per_row(n=n, single=single):
            for i in range(n):
                single.reset(seed=i)

        def floor(n=n, single=single):
            for i in range(n):
                gym.Env.reset(single, seed=i)
                single._make_scenario("random")

        row = _clock(per_row)
        rest = _clock(floor)
        print(f"{n:>6} {batched[0]:>10.3f} {row[0]:>10.3f} {row[0] / batched[0]:>6.1f} "
              f"{batched[1]:>14.3f} {row[1]:>14.3f} {row[1] / batched[1]:>9.1f} "
              f"{rest[1]:>20.3f}  {os.getloadavg()[0]:.2f}")


def vector_step(sizes) -> None:
    import numpy as np

    from quad_fault_env.vector import QuadFaultVectorEnv

    print(f"\n# vector env step, physics='numba', estimator='none', 0.1 s episodes ({_load()})")
    print(f"{'N':>6} {'scenario':<9} {'step CPU-s':>10} {'vehicle-steps/CPU-s':>20} "
          f"{'autoreset step CPU-s':>21}  load")
    for n in sizes:
        for scenario in ("combined", "random"):
            vec = QuadFaultVectorEnv(n, "none", scenario, duration=0.1, physics="numba")
            a = np.zeros((n, 4), dtype=np.float32)
            vec.reset(seed=0)
            cpu = {"plain": [], "autoreset": []}
            for _ in range(33):  # three episodes of 10 steps plus their autoreset steps
                resetting = bool(vec._needs_reset.any())
                _, c = _clock(lambda: vec.step(a))  # noqa: B023
                cpu["autoreset" if resetting else "plain"].append(c)
            plain = float(np.median(cpu["plain"][12:]))  # after the first window and reset
            print(f"{n:>6} {scenario:<9} {plain:>10.4f} {n * vec.substeps / plain:>20.0f} "
                  f"{float(np.median(cpu['autoreset'])):>21.3f}  {os.getloadavg()[0]:.2f}")


def main(argv=None) -> int:
    args = _parse(argv)
    from quadfault import _sim_numba

    if not _sim_numba.AVAILABLE:
        print("numba is not installed: pip install 'quadfault[fast]'", file=sys.stderr)
        return 1
    steps, sizes = (60, [64, 256]) if args.quick else (args.steps, args.sizes)
    single_env(args.estimators, steps, args.rounds)
    vector_reset(sizes)
    vector_step(sizes)
    return 0


if __name__ == "__main__":
    sys.exit(main())
