"""Vector-env step cost with one numba thread vs numba's default, by batch size.

Two tasks (``--task``):

* ``study`` (default): ``QuadFaultVectorEnv(N, estimator=E, estimator_rate="control")`` on the
  PPO study's environment (``QuadFaultHover-v1``, one fault of eta 0.5-0.85, residual actions,
  zero action), for each estimator of ``--estimators``;
* ``physics``: the env-against-env comparison's env (``QuadFault-v1``, no estimator, motor
  actions at the hover thrust, 1 kHz control: one physics step per env step,
  ``benchmarks/env_vs_crazyflow.py``).

Each is stepped with ``numba_threads=1`` and with numba's default thread count, rounds
interleaved, and the script prints wall and CPU microseconds per vehicle-step and the ratios
(default / one thread: above 1 means the extra threads cost more than they save). The vector
env's default (``numba_threads="auto"``: one thread below
``quad_fault_env.vector.THREADS_MIN_BATCH``) comes from these numbers on an idle machine.

CPU time counts every thread of this process, so idle OpenMP workers that spin between
parallel regions show up there even when the wall time looks fine. On a shared machine read
the CPU ratio; every line carries the 1-minute load average.

    python benchmarks/numba_threads.py                    # N = 8 ... 4096, IRLS and none
    python benchmarks/numba_threads.py --sizes 32 --steps 200
    python benchmarks/numba_threads.py --task physics --sizes 1024 2048 4096 8192 16384
    python benchmarks/numba_threads.py --task physics --sizes 4096 16384 --chunks 64 256 1024

With ``--chunks`` the default thread count is timed once per task size of the parallel step
(``quad_fault_env.vector_step.CHUNK``: vehicles per task the threads claim), rounds
interleaved, beside one thread.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

_DEFAULTS: dict = {}  # vector_step.CHUNK as the module sets it (restored between timings)


def _env(n: int, estimator: str, task: str = "study"):
    """``(vector env, action)`` of ``task`` at ``n`` sub-envs, reset."""
    import gymnasium as gym

    import quad_fault_env  # noqa: F401
    from quad_fault_env.vector import QuadFaultVectorEnv

    if task == "physics":
        kwargs = dict(
            gym.spec("QuadFault-v1").kwargs,
            estimator="none",
            action_mode="motor",
            control_rate=1000.0,
        )
        venv = QuadFaultVectorEnv(n, **kwargs)
        veh = venv.vehicle
        hover = 2.0 * (veh.weight / veh.n_rotors) / veh.rotor_max_thrust - 1.0
        venv.reset(seed=0)
        return venv, np.full((n, 4), hover, dtype=np.float32)
    kwargs = dict(
        gym.spec("QuadFaultHover-v1").kwargs,
        action_mode="residual",
        residual_scale=2.45,
        estimator_rate="control",
        duration=10.0,
        estimator=estimator,
        random_faults={"n_faults": [1, 1], "severity": [0.5, 0.85]},
    )
    venv = QuadFaultVectorEnv(n, **kwargs)
    venv.reset(seed=0)
    return venv, np.zeros((n, 4))


def _time(venv, action, steps: int, threads: int, chunk: int | None = None):
    """Wall and CPU seconds of ``steps`` vector steps with ``threads`` numba threads (and
    ``chunk`` vehicles per task of the parallel step)."""
    from quad_fault_env import vector_step

    _DEFAULTS.setdefault("chunk", vector_step.CHUNK)
    vector_step.CHUNK = chunk or _DEFAULTS["chunk"]
    venv.numba_threads = threads  # the env sets it on this thread for its own calls
    for _ in range(5):
        venv.step(action)
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        venv.step(action)
    return time.perf_counter() - wall, time.process_time() - cpu


def _chunks_table(args, default: int) -> None:
    """One thread against ``default`` threads with each task size of ``--chunks``."""
    print(f"{'N':>5} {'threads':>7} {'chunk':>6} {'wall':>8} {'cpu':>8} {'wall/1':>7}  load")
    for n in args.sizes:
        venv, action = _env(n, "none", args.task)
        steps = max(5, args.steps * 32 // max(n, 32), 400_000 // n)
        cases = [(1, None)] + [(default, c) for c in args.chunks]
        best = {case: [np.inf, np.inf] for case in cases}
        try:
            for _ in range(args.rounds):
                for case in cases:
                    wall, cpu = _time(venv, action, steps, *case)
                    best[case] = [min(best[case][0], wall), min(best[case][1], cpu)]
        finally:
            venv.close()
        per = 1e6 / (steps * n)
        w1 = best[(1, None)][0] * per
        for (threads, chunk), (wall, cpu) in best.items():
            print(
                f"{n:>5} {threads:>7} {chunk or '-':>6} {wall * per:8.3f} {cpu * per:8.3f} "
                f"{wall * per / w1:7.2f}  {os.getloadavg()[0]:.1f}",
                flush=True,
            )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[8, 32, 128, 512, 4096])
    p.add_argument(
        "--estimators", nargs="+", default=["irls", "none"], choices=("irls", "ekf", "none")
    )
    p.add_argument("--task", choices=("study", "physics"), default="study")
    p.add_argument("--steps", type=int, default=100, help="vector steps per round")
    p.add_argument("--rounds", type=int, default=3, help="interleaved rounds (best kept)")
    p.add_argument(
        "--chunks", type=int, nargs="+", default=None, help="vehicles per task to compare"
    )
    args = p.parse_args(argv)

    import numba

    default = numba.config.NUMBA_NUM_THREADS
    if default == 1:
        print("numba has one thread on this machine: nothing to compare")
        return 0
    print(
        f"task {args.task}; numba threads: 1 vs {default} (default) on {os.cpu_count()} cpus; "
        f"us per vehicle-step, best of {args.rounds} rounds"
    )
    if args.chunks:
        _chunks_table(args, default)
        return 0
    print(
        f"{'estimator':>9} {'N':>5} {'wall 1':>8} {'wall d':>8} {'cpu 1':>8} {'cpu d':>8} "
        f"{'wall d/1':>8} {'cpu d/1':>8}  load"
    )
    for est in ["none"] if args.task == "physics" else args.estimators:
        for n in args.sizes:
            venv, action = _env(n, est, args.task)
            steps = max(5, args.steps * 32 // max(n, 32), 400_000 // n)  # >= 0.4 M vehicle-steps
            best = {1: [np.inf, np.inf], default: [np.inf, np.inf]}
            try:
                for _ in range(args.rounds):
                    for threads in (1, default):
                        wall, cpu = _time(venv, action, steps, threads)
                        best[threads] = [min(best[threads][0], wall), min(best[threads][1], cpu)]
            finally:
                venv.close()
            per = 1e6 / (steps * n)
            w1, c1 = (x * per for x in best[1])
            wd, cd = (x * per for x in best[default])
            print(
                f"{est:>9} {n:>5} {w1:8.2f} {wd:8.2f} {c1:8.2f} {cd:8.2f} {wd / w1:8.2f} "
                f"{cd / c1:8.2f}  {os.getloadavg()[0]:.1f}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
