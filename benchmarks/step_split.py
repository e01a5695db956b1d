"""Where a vector-env step's time goes at one physics step per env step: the compiled step
against the Python (and numpy) around it.

``QuadFaultVectorEnv(N, "none", "combined", control_rate=1000, action_mode="motor",
duration=600)`` (one physics substep per env step, as in the env-against-env comparison of
``env_vs_crazyflow.py``; the env's default numba threads) is stepped with the zero action; the
compiled step (``quad_fault_env.vector_step.step``: action mapping, the closed loop, termination,
reward, observation; in a checkout without it, the closed loop's calls) is timed apart. Printed per N: nanoseconds per vehicle-step of the whole step and of the kernel,
per wall second and per CPU second of the process (all its threads), and the kernel's share.

Episodes that end often (the autoreset of the finished rows, the refills of their time
tables) are measured with ``--episode-steps K`` (``max_episode_steps``), ``--action noise``
(uniform random motor actions: the vehicles crash at scattered steps), ``--scenario
random`` (a scenario drawn per episode) and ``--action-mode residual`` (the geometric
controller in the step); the last column is the share of rows reset per step.

With ``--baseline PATH`` (another checkout: ``git worktree add ../qf-base <commit>``) each N
runs in both checkouts in fresh processes, rounds alternated, best of each kept, so a busy
machine slows both alike.

    python benchmarks/step_split.py                       # N = 1, 1024, 16384
    python benchmarks/step_split.py --baseline ../qf-base --rounds 2
    python benchmarks/step_split.py --sizes 1024 4096 --episode-steps 50 --action noise
"""

from __future__ import annotations

import argparse
import os
import sys
import time

if "--omp-spin" not in sys.argv:  # as throughput.py: idle OpenMP threads sleep
    os.environ.setdefault("OMP_WAIT_POLICY", "passive")

SIZES = (1, 1024, 16384)


ACTIONS = ("zero", "noise")


def split(
    N: int,
    seconds: float = 1.0,
    repeat: int = 3,
    scenario: str = "combined",
    episode_steps: int | None = None,
    action: str = "zero",
    action_mode: str = "motor",
) -> dict:
    """ns per vehicle-step of the env step and of the loop kernel inside it, wall and CPU
    (best of ``repeat`` timings of at least ``seconds``), and the fraction of the rows that
    ended per step; ``episode_steps`` the env's ``max_episode_steps``, ``action`` the zero
    action or uniform random ones (8 seeded arrays in turn)."""
    import numpy as np

    from quad_fault_env.vector import QuadFaultVectorEnv

    spent = {"wall": 0.0, "cpu": 0.0}

    def timed(fn):
        def call(*args, **kwargs):
            w, c = time.perf_counter(), time.process_time()
            out = fn(*args, **kwargs)
            spent["wall"] += time.perf_counter() - w
            spent["cpu"] += time.process_time() - c
            return out

        return call

    try:
        from quad_fault_env import vector_step
    except ImportError:  # a checkout whose env calls the loop alone (a --baseline)
        from quadfault.model import closed_loop

        closed_loop.fly_batch = timed(closed_loop.fly_batch)
        closed_loop.fly = timed(closed_loop.fly)
    else:
        vector_step.step = timed(vector_step.step)
    env = QuadFaultVectorEnv(
        N,
        "none",
        scenario=scenario,
        duration=600.0,
        control_rate=1000.0,
        action_mode=action_mode,
        max_episode_steps=episode_steps,
    )
    env.reset(seed=0)
    if action == "zero":
        actions = [np.zeros((N, 4), dtype=np.float32)]
    else:
        rng = np.random.default_rng(0)
        actions = [rng.uniform(-1, 1, (N, 4)).astype(np.float32) for _ in range(8)]
    warm = 3 if episode_steps is None else 2 * episode_steps  # the ends spread over the steps
    for k in range(max(warm, 3)):  # compile / load the cache, first-step allocations
        env.step(actions[k % len(actions)])
    best = None
    for _ in range(repeat):
        spent.update(wall=0.0, cpu=0.0)
        steps, ended, w, c = 0, 0, time.perf_counter(), time.process_time()
        while time.perf_counter() - w < seconds:
            _, _, term, trunc, _ = env.step(actions[steps % len(actions)])
            ended += int(np.count_nonzero(term)) + int(np.count_nonzero(trunc))
            steps += 1
        per = 1e9 / (steps * N)
        got = {
            "ended": ended / (steps * N),
            "step_wall": (time.perf_counter() - w) * per,
            "step_cpu": (time.process_time() - c) * per,
            "kernel_wall": spent["wall"] * per,
            "kernel_cpu": spent["cpu"] * per,
        }
        if best is None or got["step_cpu"] < best["step_cpu"]:
            best = got
    return best


def _row(N: int, r: dict) -> str:
    return (
        f"| {N} | {r['step_wall']:,.0f} / {r['step_cpu']:,.0f} | "
        f"{r['kernel_wall']:,.0f} / {r['kernel_cpu']:,.0f} | "
        f"{r['step_wall'] - r['kernel_wall']:,.0f} / {r['step_cpu'] - r['kernel_cpu']:,.0f} | "
        f"{r['kernel_cpu'] / r['step_cpu']:.0%} | {r.get('ended', 0.0):.2%} |"
    )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    p.add_argument("--seconds", type=float, default=1.0, help="length of each timing")
    p.add_argument("--baseline", default=None, help="another checkout, measured side by side")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--scenario", default="combined", help="the env's scenario (default combined)")
    p.add_argument(
        "--episode-steps", type=int, default=None, help="max_episode_steps (default: none)"
    )
    p.add_argument("--action", choices=ACTIONS, default="zero")
    p.add_argument("--action-mode", default="motor", help="the env's action_mode (default motor)")
    p.add_argument(
        "--omp-spin",
        action="store_true",
        help="keep OpenMP's spin-waiting (default: OMP_WAIT_POLICY=passive)",
    )
    args = p.parse_args(argv)
    if (
        min(args.sizes) < 1
        or args.seconds <= 0
        or args.rounds < 1
        or (args.episode_steps is not None and args.episode_steps < 1)
    ):
        print(
            "step_split: --sizes >= 1, --seconds > 0, --rounds >= 1, --episode-steps >= 1",
            file=sys.stderr,
        )
        return 2
    case = dict(
        scenario=args.scenario,
        episode_steps=args.episode_steps,
        action=args.action,
        action_mode=args.action_mode,
    )
    sys.path.insert(1, os.path.dirname(os.path.abspath(__file__)))
    import side_by_side as sbs

    print(
        f"# ns per vehicle-step, wall / CPU (all threads); scenario {args.scenario}, "
        f"max_episode_steps {args.episode_steps}, {args.action} actions "
        f"({args.action_mode} mode); "
        f"{sbs.load()} on {os.cpu_count()} cpus"
    )
    head = (
        "| N | step | compiled step | Python around it | compiled share (CPU) "
        "| rows ended per step |"
    )
    rule = "|---|---|---|---|---|---|"
    rows = {}
    for N in args.sizes:
        if args.baseline:
            rows[N] = sbs.compare(
                args.baseline,
                "step_split",
                "split",
                args.rounds,
                N=N,
                seconds=args.seconds,
                **case,
            )
        else:
            rows[N] = (
                sbs.measure(sbs.ROOT, "step_split", "split", N=N, seconds=args.seconds, **case),
                None,
            )
    for k, label in enumerate(("this checkout", "baseline") if args.baseline else ("",)):
        if label:
            print(f"\n{label}:")
        print(head + "\n" + rule)
        for N, pair in rows.items():
            print(_row(N, pair[k]))
    print(f"# {sbs.load()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
