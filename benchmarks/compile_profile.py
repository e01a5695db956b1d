"""Where a first run's compile time goes: each kernel numba compiles, with its CPU seconds.

Runs one case of :mod:`first_run` (``simulate`` or ``env``) in this process on an empty numba
cache and listens to numba's ``numba:compile`` events (they fire on a cache miss only). A
kernel's time includes the kernels it calls that were not compiled yet; the table lists the
outermost compiles (they add up to the compile time of the case) and then every
specialisation of the closed loop's kernels.

    python benchmarks/compile_profile.py simulate
    python benchmarks/compile_profile.py env
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from collections import defaultdict

if __name__ == "__main__" and "NUMBA_CACHE_DIR" not in os.environ:
    # an empty cache, set before quadfault (and numba) are imported
    os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="qf-compile-profile-")

LOOP_KERNELS = ("fly_vehicle", "_fly_rows", "_fly_parallel")


def profile(case: str) -> tuple[float, list]:
    """CPU seconds of ``case`` and its compiles ``(depth, kernel, CPU s, argument types)``."""
    from numba.core import event

    stack, rows = [], []

    class Compiles(event.Listener):
        def on_start(self, ev):
            stack.append((ev.data["dispatcher"], time.process_time()))

        def on_end(self, ev):
            dispatcher, t0 = stack.pop()
            fn = dispatcher.py_func
            rows.append(
                (
                    len(stack),
                    f"{fn.__module__}.{fn.__name__}",
                    time.process_time() - t0,
                    str(ev.data.get("args")),
                )
            )

    listener = Compiles()
    event.register("numba:compile", listener)
    c0 = time.process_time()
    try:
        if case == "simulate":
            from quadfault.cli import main

            out = os.path.join(tempfile.mkdtemp(prefix="qf-compile-profile-"), "flight.csv")
            main(
                [
                    "simulate",
                    "--scenario",
                    "combined",
                    "--duration",
                    "10",
                    "--seed",
                    "0",
                    "--out",
                    out,
                    "--quiet",
                ]
            )
        else:
            import gymnasium as gym
            import numpy as np

            import quad_fault_env  # noqa: F401

            env = gym.make("QuadFault-v1")
            env.reset(seed=0)
            env.step(np.zeros(4, dtype=np.float32))
    finally:
        event.unregister("numba:compile", listener)
    return time.process_time() - c0, rows


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    case = argv[0] if argv else "simulate"
    if case not in ("simulate", "env"):
        print("usage: compile_profile.py simulate|env", file=sys.stderr)
        return 2
    total, rows = profile(case)
    outer = defaultdict(float)
    for depth, name, seconds, _ in rows:
        if depth == 0:
            outer[name] += seconds
    print(
        f"# {case}: {total:.1f} CPU-s in all, {sum(outer.values()):.1f} compiling "
        f"(cache {os.environ['NUMBA_CACHE_DIR']})"
    )
    for name, seconds in sorted(outer.items(), key=lambda x: -x[1]):
        if seconds >= 0.05:
            print(f"{seconds:8.2f}  {name}")
    print("# the closed loop's specialisations (depth, CPU s incl. callees, kernel)")
    for depth, name, seconds, args in rows:
        if name.rsplit(".", 1)[-1] in LOOP_KERNELS:
            print(f"{depth:>3} {seconds:8.2f}  {name}{args[:120]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
