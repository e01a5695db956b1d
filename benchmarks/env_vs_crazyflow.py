"""Our vector env against crazyflow's first-principles gym env, side by side, env steps/s.

Each side runs in its own child process of this script (one process tree), built and warmed
up once (compiles, caches); then the rounds alternate the order (round 1: ours first, round 2:
crazyflow first, ...), one side timing while the other waits idle, and each side's best of
``--rounds`` (3) is kept. Printed per N: env steps per wall second and per CPU second (all the
child's threads), physics steps per wall second, the cores each side used (CPU s / wall s)
and the ratios ours / crazyflow. The settings of both sides are pinned and printed:

* ours: ``gym.make_vec("QuadFault-v1", num_envs=N, vectorization_mode="vector_entry_point",
  estimator="none", action_mode="motor", control_rate=1000)``: RKMK4, float64, 1 kHz physics,
  one physics step per env step, motor commands, the combined scenario (thrust noise,
  degradation), numba threads as the env chooses for N (``numba_threads="auto"``);
* crazyflow: ``gym.make_vec("DroneReachPos-v0", num_envs=N, dynamics="first_principles",
  device="cpu")`` with its defaults (printed: physics rate, integrator, precision, control
  mode, physics steps per env step), JAX on the CPU with XLA's default threads;

both fed a constant hover action. ``--threads 1`` pins both to one thread
(``NUMBA_NUM_THREADS=1``; XLA's ``intra_op_parallelism_threads=1``); ``--taskset CPUS`` runs
both children on the same CPUs (``taskset -c CPUS``) and says so.

A figure is for publication only when the 1-minute load average stays at or below
:data:`QUIET_LOAD` from the first round to the last; otherwise the table is printed headed
NOT FOR PUBLICATION with the load (the ratios of the two sides, measured in turn, are still
the best the machine allowed). crazyflow is an optional peer, never a dependency: without it
the script says so and exits 0.

    python benchmarks/env_vs_crazyflow.py                       # N = 1 64 1024 4096 16384
    python benchmarks/env_vs_crazyflow.py --sizes 1024 --seconds 2 --rounds 3
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

SIZES = (1, 64, 1024, 4096, 16384)
#: the highest 1-minute load average at which a figure is printed for publication
QUIET_LOAD = 1.5
ROOT = Path(__file__).resolve().parents[1]


# -- the children ----------------------------------------------------------------------------
def _ours(N: int):
    """(step function, settings) of our vector env at one physics step per env step."""
    import gymnasium as gym
    import numpy as np

    import quad_fault_env  # noqa: F401  (registers the ids)
    from quadfault import jit

    env = gym.make_vec(
        "QuadFault-v1",
        num_envs=N,
        vectorization_mode="vector_entry_point",
        estimator="none",
        action_mode="motor",
        control_rate=1000.0,
    )
    u = env.unwrapped
    env.reset(seed=0)
    veh = u.vehicle
    hover = 2.0 * (veh.weight / veh.n_rotors) / veh.rotor_max_thrust - 1.0
    a = np.full((N, 4), hover, dtype=np.float32)
    with jit.threads(u.numba_threads):
        threads = jit.set_threads(None)
    settings = {
        "physics rate [Hz]": round(1.0 / u.dt),
        "integrator": "RKMK4",
        "precision": "float64",
        "control": "motor thrusts",
        "physics steps per env step": int(u.substeps),
        "threads": f"numba {threads}",
    }
    return (lambda: env.step(a)), int(u.substeps), settings


def _crazyflow(N: int):
    """(step function, settings) of crazyflow's DroneReachPos-v0, first-principles dynamics."""
    import jax
    import numpy as np

    jax.config.update("jax_platform_name", "cpu")
    import crazyflow  # noqa: F401  (registers its ids)
    import gymnasium as gym

    env = gym.make_vec("DroneReachPos-v0", num_envs=N, dynamics="first_principles", device="cpu")
    env.reset(seed=0)
    u = env.unwrapped
    lo, hi = env.single_action_space.low, env.single_action_space.high
    hover = float(np.ravel(u.sim.data.params.mass)[0]) * 9.81  # collective thrust [N], last
    a = np.tile(
        np.where(np.arange(lo.size) == lo.size - 1, np.clip(hover, lo[-1], hi[-1]), 0.0), (N, 1)
    ).astype(np.float32)  # level attitude, hover thrust

    def step():
        jax.block_until_ready(env.step(a)[0])

    xla = os.environ.get("XLA_FLAGS", "")
    settings = {
        "physics rate [Hz]": int(u.sim.freq),
        "integrator": str(u.sim.integrator),
        "precision": str(u.sim.data.states.pos.dtype),
        "control": str(u.sim.control),
        "physics steps per env step": int(u.n_substeps),
        "threads": "XLA " + ("1 (intra_op_parallelism_threads=1)" if "=1" in xla else "default"),
        "version": f"crazyflow {_version('crazyflow')}, jax {jax.__version__}",
    }
    return step, int(u.n_substeps), settings


def _version(name: str) -> str:
    from importlib.metadata import version

    return version(name)


#: what starts a line of the child's answers (a peer may print to stdout when imported)
MARK = "@@"


def _say(message: dict) -> None:
    print(MARK + json.dumps(message), flush=True)


def child(side: str, N: int) -> int:
    """Build and warm up one side, then time it whenever the parent says ``run SECONDS``."""
    try:
        step, substeps, settings = (_ours if side == "ours" else _crazyflow)(N)
        for _ in range(20):  # compile / load caches, first-step allocations
            step()
    except Exception as exc:  # report why the side cannot run, in one line
        _say({"error": f"{type(exc).__name__}: {exc}".splitlines()[0]})
        return 0
    _say({"ready": settings})
    for line in sys.stdin:
        cmd = line.split()
        if not cmd or cmd[0] != "run":
            break
        seconds = float(cmd[1])
        steps, w0, c0 = 0, time.perf_counter(), time.process_time()
        while time.perf_counter() - w0 < seconds:
            step()
            steps += 1
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        _say(
            {
                "wall": N * steps / wall,
                "cpu": N * steps / max(cpu, 1e-9),
                "physics": N * steps * substeps / wall,
                "cores": cpu / wall,
            }
        )
    return 0


# -- the parent ------------------------------------------------------------------------------
def _spawn(side: str, N: int, args) -> subprocess.Popen:
    env = dict(os.environ)  # (numba's OpenMP wait policy as a user gets it)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    env["JAX_PLATFORMS"] = "cpu"
    if args.threads == 1:
        env["NUMBA_NUM_THREADS"] = "1"
        env["XLA_FLAGS"] = (
            env.get("XLA_FLAGS", "")
            + " --xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
        ).strip()
    cmd = [sys.executable, os.path.abspath(__file__), "--child", side, str(N)]
    if args.taskset:
        cmd = ["taskset", "-c", args.taskset] + cmd
    return subprocess.Popen(
        cmd,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env=env,
    )


def _read(proc: subprocess.Popen) -> dict:
    """The child's next answer (other lines it prints are skipped)."""
    while True:
        line = proc.stdout.readline()
        if not line:
            return {"error": f"exited with {proc.wait()}"}
        if line.startswith(MARK):
            try:
                return json.loads(line[len(MARK) :])
            except ValueError:
                return {"error": f"unreadable output {line[-200:]!r}"}


def compare(N: int, args) -> dict:
    """Both sides at N: their settings and best rates (or why a side did not run)."""
    procs = {side: _spawn(side, N, args) for side in ("ours", "crazyflow")}
    ready = {side: _read(p) for side, p in procs.items()}
    best: dict = {}
    loads = []
    try:
        if all("ready" in r for r in ready.values()):
            for r in range(args.rounds):
                order = ("ours", "crazyflow") if r % 2 == 0 else ("crazyflow", "ours")
                loads.append(os.getloadavg()[0])
                for side in order:
                    procs[side].stdin.write(f"run {args.seconds}\n")
                    procs[side].stdin.flush()
                    got = _read(procs[side])
                    if "error" in got:
                        ready[side] = got
                        break
                    if side not in best or got["wall"] > best[side]["wall"]:
                        best[side] = dict(got, cpu=max(got["cpu"], best.get(side, got)["cpu"]))
                    else:
                        best[side]["cpu"] = max(best[side]["cpu"], got["cpu"])
            loads.append(os.getloadavg()[0])
    finally:
        for p in procs.values():
            try:
                p.stdin.write("quit\n")
                p.stdin.close()
            except (BrokenPipeError, OSError):
                pass
            p.wait(timeout=60)
    return {"ready": ready, "best": best, "load": max(loads) if loads else os.getloadavg()[0]}


def _k(x: float) -> str:
    return f"{x / 1e6:.2f} M" if x >= 1e6 else f"{x / 1e3:.1f} k"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    p.add_argument("--seconds", type=float, default=3.0, help="length of each timing [s]")
    p.add_argument("--rounds", type=int, default=3, help="alternated rounds; best kept")
    p.add_argument("--threads", type=int, choices=(1,), default=None, help="pin both to 1")
    p.add_argument("--taskset", default=None, help="run both sides on these CPUs (taskset -c)")
    p.add_argument("--child", nargs=2, metavar=("SIDE", "N"), help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        return child(args.child[0], int(args.child[1]))
    if min(args.sizes) < 1 or args.seconds <= 0 or args.rounds < 1:
        print("env_vs_crazyflow: --sizes >= 1, --seconds > 0, --rounds >= 1", file=sys.stderr)
        return 2
    try:
        import crazyflow  # noqa: F401
    except Exception as exc:  # an optional peer
        print(f"env_vs_crazyflow: crazyflow is not importable here ({exc}); nothing measured")
        return 0
    load0 = os.getloadavg()
    print(
        f"# our vector env vs crazyflow's first-principles gym env; {os.cpu_count()} cpus, "
        f"load average {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}; best of {args.rounds} "
        f"alternated rounds of {args.seconds:g} s"
        + (f"; both pinned to CPUs {args.taskset} (taskset)" if args.taskset else "")
        + ("; both on 1 thread" if args.threads == 1 else "")
    )
    rows, settings, worst = [], {}, 0.0
    for N in args.sizes:
        got = compare(N, args)
        worst = max(worst, got["load"])
        for side, r in got["ready"].items():
            if "ready" in r:
                settings.setdefault(side, r["ready"])
        if len(got["best"]) < 2:
            why = "; ".join(f"{s}: {r['error']}" for s, r in got["ready"].items() if "error" in r)
            rows.append(f"| {N:,} | did not run: {why} |")
            continue
        o, c = got["best"]["ours"], got["best"]["crazyflow"]
        threads = " / ".join(
            got["ready"][side]["ready"]["threads"] for side in ("ours", "crazyflow")
        )
        rows.append(
            f"| {N:,} | {_k(o['wall'])} ({_k(o['cpu'])}) | {_k(c['wall'])} ({_k(c['cpu'])}) | "
            f"**{o['wall'] / c['wall']:.2f}x** ({o['cpu'] / c['cpu']:.2f}x) | "
            f"{_k(o['physics'])} / {_k(c['physics'])} | {o['cores']:.1f} / {c['cores']:.1f} | "
            f"{threads} | {got['load']:.1f} |"
        )
        print(rows[-1], file=sys.stderr, flush=True)  # progress
    for side, s in settings.items():  # (threads per N in the table)
        print(f"# {side}: " + ", ".join(f"{k} {v}" for k, v in s.items() if k != "threads"))
    if worst > QUIET_LOAD:
        print(
            f"# NOT FOR PUBLICATION: the 1-minute load reached {worst:.2f} (> {QUIET_LOAD}); "
            "rerun on a quiet machine"
        )
    print(
        "| N | ours, env steps/s wall (per CPU-s) | crazyflow, wall (per CPU-s) | ratio wall "
        "(per CPU) | physics steps/s wall, ours / crazyflow | cores used, ours / crazyflow "
        "| threads, ours / crazyflow | load |"
    )
    print("|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
