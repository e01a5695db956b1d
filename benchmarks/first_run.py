"""A new user's first run: CPU seconds of whole processes on an empty numba cache, then cached.

Each case runs as its own process, exactly as a user starts it, first with an empty numba
cache (a fresh ``NUMBA_CACHE_DIR``: every kernel it needs is compiled) and then again on the
cache the first run filled (the kernels load). The CPU time is the child's user + system time.

* ``simulate``: ``quadfault simulate --scenario combined --duration 10``;
* ``effects``: the same flight with drag, motor lag and a gusty wind (the compiled effect
  chain);
* ``env``: ``gym.make("QuadFault-v1")`` (IRLS in the observation), ``reset`` and one step;
* ``estimate``: ``quadfault estimate`` (IRLS) of a 10 s recording (made beforehand).

With ``--baseline PATH`` (another checkout, e.g. ``git worktree add ../qf-base <commit>``) each
case runs in both, alternated, and the table gives the ratio baseline / this.

    python benchmarks/first_run.py [--only simulate,env] [--rounds 1] [--baseline ../qf-base]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ENV_CODE = (
    "import gymnasium as gym, numpy as np, quad_fault_env; env = gym.make('QuadFault-v1'); "
    "env.reset(seed=0); env.step(np.zeros(4, dtype=np.float32))"
)
CASES = ("simulate", "effects", "env", "estimate")
#: the effects of the ``effects`` case
EFFECTS = ("drag=0.3", "motor_lag=0.05", "wind=1,0,0,gust=0.5")


def command(case: str, work: Path) -> list[str]:
    cli = [sys.executable, "-m", "quadfault.cli"]
    if case in ("simulate", "effects"):
        effects = [a for spec in EFFECTS for a in ("--effect", spec)] if case == "effects" else []
        return cli + [
            "simulate",
            *effects,
            "--scenario",
            "combined",
            "--duration",
            "10",
            "--seed",
            "0",
            "--out",
            str(work / "flight.csv"),
            "--force",
            "--quiet",
        ]
    if case == "env":
        return [sys.executable, "-c", ENV_CODE]
    return cli + [
        "estimate",
        str(work / "input.csv"),
        "--estimator",
        "irls",
        "--out",
        str(work / "est.csv"),
        "--force",
        "--quiet",
    ]


def run(cmd: list[str], checkout: Path, cache: str) -> tuple[float, float]:
    """CPU seconds (user + system) and wall seconds of ``cmd`` run with ``checkout``'s code."""
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("NUMBA_CACHE_DIR", "QUADFAULT_NUMBA_CACHE", "QUADFAULT_NUMBA_CACHE_USER")
    }
    env.update(NUMBA_CACHE_DIR=cache, PYTHONPATH=str(checkout))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, cwd=checkout, env=env, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime), wall


def measure(case: str, checkout: Path, work: Path) -> dict:
    cache = tempfile.mkdtemp(prefix="qf-first-run-")
    cold = run(command(case, work), checkout, cache)
    warm = run(command(case, work), checkout, cache)
    return {"cold_cpu": cold[0], "cold_wall": cold[1], "warm_cpu": warm[0], "warm_wall": warm[1]}


def load() -> str:
    return "load average " + ", ".join(f"{x:.1f}" for x in os.getloadavg())


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--only", default=",".join(CASES), help="comma-separated cases")
    p.add_argument("--rounds", type=int, default=1, help="alternated rounds (best kept)")
    p.add_argument("--baseline", type=Path, default=None, help="another checkout")
    args = p.parse_args(argv)
    cases = [c for c in args.only.split(",") if c]
    unknown = set(cases) - set(CASES)
    if unknown:
        p.error(f"unknown case(s) {sorted(unknown)}; choose from {', '.join(CASES)}")
    checkouts = {"this": ROOT} | ({"baseline": args.baseline.resolve()} if args.baseline else {})
    work = Path(tempfile.mkdtemp(prefix="qf-first-run-work-"))
    if "estimate" in cases:
        subprocess.run(
            [
                sys.executable,
                "-m",
                "quadfault.cli",
                "simulate",
                "--scenario",
                "combined",
                "--duration",
                "10",
                "--seed",
                "0",
                "--out",
                str(work / "input.csv"),
                "--quiet",
            ],
            cwd=ROOT,
            check=True,
            env=dict(os.environ, PYTHONPATH=str(ROOT)),
        )
    print(
        f"# first run on an empty numba cache, then cached; CPU s (wall s); {load()} on "
        f"{os.cpu_count()} cpus"
    )
    best: dict = {}
    for _ in range(args.rounds):
        for case in cases:
            for name, checkout in checkouts.items():
                got = measure(case, checkout, work)
                key = (case, name)
                best[key] = {k: min(v, best.get(key, got)[k]) for k, v in got.items()}
    header = f"{'case':<9} {'checkout':<9} {'empty cache':>18} {'cached':>16}"
    print(header + ("   baseline / this (empty cache CPU)" if args.baseline else ""))
    for case in cases:
        for name in checkouts:
            b = best[(case, name)]
            line = (
                f"{case:<9} {name:<9} {b['cold_cpu']:>8.1f} ({b['cold_wall']:>6.1f}) "
                f"{b['warm_cpu']:>7.1f} ({b['warm_wall']:>5.1f})"
            )
            if name == "this" and args.baseline:
                ratio = best[(case, "baseline")]["cold_cpu"] / b["cold_cpu"]
                line += f"   {ratio:.2f}x"
            print(line)
    print(f"# {load()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
