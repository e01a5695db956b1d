"""Environment speed: single-env steps, vector-env steps and resets against N, cold start.

* single env: ``gym.make("QuadFault-v1", estimator=E)`` stepped with the zero residual action
  (episodes reset when they end), env steps per CPU second of the process and per wall second,
  for E = none and irls;
* vector env: ``QuadFaultVectorEnv(N, "none", "combined", duration=600)`` stepped with the
  zero action, physics vehicle-steps per CPU second and per wall second, and the batched
  ``reset(seed=0)`` of ``QuadFaultVectorEnv(N, "none", "random")``, for N = ``--sizes``;
* cold start: CPU seconds of the first env step and of the first vector-env step (N = 128) in
  a fresh process with an empty numba cache (what compiling the kernels costs).

Every timing is the best of repeated runs. Numba's thread count is its default (one per
core) -- what users get. With ``--baseline PATH`` (another checkout, e.g. ``git worktree add
../qf-base <commit>``) each measure runs in both, rounds alternated, and the table gives the
ratio this / baseline for rates (above 1 = this checkout is faster) and baseline / this for
times. On a shared machine read the per-CPU-second columns; every table carries the load.

    python benchmarks/bench_env_step.py
    python benchmarks/bench_env_step.py --baseline ../qf-base --rounds 3
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time


def _clock(fn, repeat: int) -> tuple[float, float]:
    """Best (wall, CPU) seconds of ``fn()`` over ``repeat`` calls."""
    wall = cpu = float("inf")
    for _ in range(repeat):
        w, c = time.perf_counter(), time.process_time()
        fn()
        wall, cpu = min(wall, time.perf_counter() - w), min(cpu, time.process_time() - c)
    return wall, cpu


def single(estimators=("none", "irls"), steps: int = 400, repeat: int = 3) -> dict:
    """Env steps per wall / CPU second of the single env, per estimator."""
    import gymnasium as gym
    import numpy as np

    import quad_fault_env  # noqa: F401  (registers the ids)

    out = {}
    a = np.zeros(4, dtype=np.float32)
    for est in estimators:
        env = gym.make("QuadFault-v1", estimator=est)
        env.reset(seed=0)
        for _ in range(5):  # compile / load the cache, first-step allocations
            env.step(a)

        def run(env=env):
            for _ in range(steps):
                *_, term, trunc, _ = env.step(a)
                if term or trunc:
                    env.reset()

        wall, cpu = _clock(run, repeat)
        out[f"single_{est}_wall"], out[f"single_{est}_cpu"] = steps / wall, steps / cpu
    return out


def vector(sizes=(1024, 4096), steps: int = 20, repeat: int = 3, estimator: str = "none") -> dict:
    """Vehicle-steps per wall / CPU second of the vector env's step (with ``estimator``)."""
    import numpy as np

    from quad_fault_env.vector import QuadFaultVectorEnv

    out = {}
    for n in sizes:
        env = QuadFaultVectorEnv(n, estimator, scenario="combined", duration=600.0)
        env.reset(seed=0)
        a = np.zeros((n, 4), dtype=np.float32)
        for _ in range(3):
            env.step(a)

        def run(env=env, a=a):
            for _ in range(steps):
                env.step(a)

        wall, cpu = _clock(run, repeat)
        work = n * steps * env.substeps
        out[f"vector_{n}_wall"], out[f"vector_{n}_cpu"] = work / wall, work / cpu
    return out


def resets(sizes=(1024, 4096)) -> dict:
    """Seconds of the batched ``reset(seed=0)`` of a vector env of random scenarios."""
    from quad_fault_env.vector import QuadFaultVectorEnv

    out = {}
    for n in sizes:
        rand = QuadFaultVectorEnv(n, "none", scenario="random")
        rand.reset(seed=1)
        out[f"reset_{n}_wall"], out[f"reset_{n}_cpu"] = _clock(lambda r=rand: r.reset(seed=0), 2)
    return out


def cold_start() -> dict:
    """CPU seconds of the first env step and the first vector-env step (N = 128) with an empty
    numba cache (``NUMBA_CACHE_DIR`` set by the caller)."""
    import gymnasium as gym
    import numpy as np

    import quad_fault_env  # noqa: F401
    from quad_fault_env.vector import QuadFaultVectorEnv

    c0 = time.process_time()
    env = gym.make("QuadFault-v1", estimator="none")
    env.reset(seed=0)
    env.step(np.zeros(4, dtype=np.float32))
    c1 = time.process_time()
    vec = QuadFaultVectorEnv(128, "none", scenario="combined")
    vec.reset(seed=0)
    vec.step(np.zeros((128, 4), dtype=np.float32))
    return {"cold_env_cpu_s": c1 - c0, "cold_vector_cpu_s": time.process_time() - c1}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--sizes",
        type=int,
        nargs="+",
        default=[1024, 4096],
        help="vector env sizes N (default 1024 4096)",
    )
    p.add_argument("--steps", type=int, default=400, help="single-env steps per timing (400)")
    p.add_argument("--baseline", default=None, help="another checkout, measured side by side")
    p.add_argument("--rounds", type=int, default=3, help="alternated rounds (3)")
    p.add_argument("--vector-estimator", default="none", help="the vector env's estimator (none)")
    p.add_argument("--skip-cold", action="store_true", help="skip the empty-cache first steps")
    args = p.parse_args(argv)
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import side_by_side as sbs

    jobs = (
        ("single", max, {"steps": args.steps}),
        ("vector", max, {"sizes": list(args.sizes), "estimator": args.vector_estimator}),
        ("resets", min, {"sizes": list(args.sizes)}),
    )
    now, base = {}, {}
    for fn, better, kw in jobs:
        if args.baseline:
            a, b = sbs.compare(
                args.baseline, "bench_env_step", fn, args.rounds, better=better, **kw
            )
            now.update(a)
            base.update(b)
        else:
            now.update(sbs.measure(sbs.ROOT, "bench_env_step", fn, **kw))
    for _ in range(0 if args.skip_cold else args.rounds if args.baseline else 1):
        cold_env = {"NUMBA_CACHE_DIR": tempfile.mkdtemp(prefix="qf-cold-")}
        got = sbs.measure(sbs.ROOT, "bench_env_step", "cold_start", env=cold_env)
        now.update({k: min(now.get(k, x), x) for k, x in got.items()})
        if args.baseline:
            cold_env = {"NUMBA_CACHE_DIR": tempfile.mkdtemp(prefix="qf-cold-")}
            got = sbs.measure(args.baseline, "bench_env_step", "cold_start", env=cold_env)
            base.update({k: min(base.get(k, x), x) for k, x in got.items()})
    rows = []
    for est in ("none", "irls"):
        rows.append((f"single env ({est}) steps / CPU s", f"single_{est}_cpu", "rate"))
        rows.append((f"single env ({est}) steps / wall s", f"single_{est}_wall", "rate"))
    for n in args.sizes:
        est = args.vector_estimator
        rows.append((f"vector N = {n} ({est}): vehicle-steps / CPU s", f"vector_{n}_cpu", "rate"))
        rows.append((f"vector N = {n} ({est}): vehicle-steps / wall s", f"vector_{n}_wall", "rate"))
        rows.append((f"vector N = {n}: reset (random) [CPU s]", f"reset_{n}_cpu", "time"))
    if not args.skip_cold:
        rows.append(("first env step, empty cache [CPU s]", "cold_env_cpu_s", "time"))
        rows.append(
            ("first vector step (N = 128), empty cache [CPU s]", "cold_vector_cpu_s", "time")
        )
    print(f"# environments; {sbs.load()} on {os.cpu_count()} cpus")
    if args.baseline:
        print("| measure | baseline | this checkout | speed-up |\n|---|---|---|---|")
        for label, key, kind in rows:
            x, y = now[key], base[key]
            ratio = x / y if kind == "rate" else y / x
            print(f"| {label} | {y:.4g} | {x:.4g} | {ratio:.2f}x |")
    else:
        print("| measure | value |\n|---|---|")
        for label, key, _ in rows:
            print(f"| {label} | {now[key]:.4g} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
