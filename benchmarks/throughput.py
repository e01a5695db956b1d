"""Throughput: batched physics, the vector env, batched IRLS, peers and PPO, side by side.

Prints, measured in one run (ratios are what to compare; the machine may be shared):

1. physics vehicle-steps/s against N: the closed loop alone (``closed_loop.fly_batch``: motors,
   thrust noise, RKMK4; with the geometric controller at every step, as crazyflow runs it) and
   the full ``QuadFaultVectorEnv`` step, without an estimator and with the batched IRLS; memory
   per vehicle (tracemalloc peak / N) and the time to build and reset the env;
2. batched IRLS window updates/s (``estimators.batched.BatchedIRLS``);
3. peers at the same physics rate (1 kHz) and horizon: RotorPy's ``BatchedMultirotor``
   (torch, CPU, rk4) and crazyflow's ``Sim`` (JAX, CPU) against the compiled loop, and
   crazyflow's gym env ``DroneReachPos-v0`` (its fitted default model and
   ``dynamics="first_principles"``) against the vector env at one physics step per env step;
   each peer runs in a subprocess of ``--peer-python`` and is skipped with the reason when it
   cannot be imported or run;
4. where the time goes: the kernels' stages (CPU ns per vehicle-step, each alone;
   ``benchmarks/kernel_stages.py``) and a profile of the env step (the loop, sensors,
   controller, the rest);
5. SB3 PPO training steps/s with the native vector env vs ``SubprocVecEnv``.

This script installs nothing. Peers, in a separate virtual environment so they cannot touch
the project's environment::

    python -m venv --system-site-packages ../peers
    ../peers/bin/pip install rotorpy crazyflow torchdiffeq roma
    python benchmarks/throughput.py --peer-python ../peers/bin/python

Options: ``--help`` (by default the script sets ``OMP_WAIT_POLICY=passive``, much faster on a
shared machine). Every rate is the best of repeated timings of at least ``MIN_TIME`` seconds,
per wall second and (peers table) per CPU second of the measuring process.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import textwrap
import time
import tracemalloc
from pathlib import Path

import numpy as np

if "--omp-spin" not in sys.argv:
    # idle OpenMP threads sleep, not spin: on a shared machine a spinning barrier waits for
    # descheduled threads (4-5x at N = 256); set before numba / torch start (peers inherit it)
    os.environ.setdefault("OMP_WAIT_POLICY", "passive")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from quadfault.model.vehicle import Vehicle  # noqa: E402

RATE = 1000.0  # physics rate of every measurement [Hz]
MIN_TIME = 0.3  # each timing repeats its call for at least this long [s]


def _rates(fn, work: int, repeats: int = 3) -> tuple[float, float]:
    """Best of ``repeats`` of: units of ``work`` per second of ``fn()`` called for MIN_TIME,
    per wall-clock second and per CPU second of this process (all its threads: the rate one
    core gives, which a shared machine's load does not change much)."""
    best, best_cpu = 0.0, 0.0
    for _ in range(repeats):
        calls, t0, c0 = 0, time.perf_counter(), time.process_time()
        while True:
            fn()
            calls += 1
            elapsed = time.perf_counter() - t0
            if elapsed >= MIN_TIME:
                break
        cpu = time.process_time() - c0
        best = max(best, work * calls / elapsed)
        best_cpu = max(best_cpu, work * calls / max(cpu, 1e-9))
    return best, best_cpu


def compiled_batch(N: int, horizon: int, rng, control_every: int = 0, thrust_noise=0.07):
    """``fn`` advancing N hovering vehicles by ``horizon`` steps with one call of the loop
    (``closed_loop.fly_batch``: motors with thrust noise + RKMK4; the geometric controller
    every ``control_every`` steps when > 0), compiled before it is returned."""
    from quadfault.model import closed_loop
    from quadfault.model.controller import GeometricController
    from quadfault.model.motors import MotorModel
    from quadfault.model.plant import Plant
    from quadfault.model.sensors import SensorNoise
    from quadfault.model.trajectory import Hover

    veh = Vehicle()
    plant = Plant(veh, MotorModel(thrust_noise), dt=1.0 / RATE, n_vehicles=N)
    V = plant.vehicles
    V.p[:, 2] = -1.0
    V.f_cmd[:] = veh.weight / 4 + 0.01 * rng.standard_normal((N, 4))
    ctrl = GeometricController(veh, Hover(position=(0.0, 0.0, -1.0)))
    refs = np.zeros((N, horizon, 6, 3))
    refs[:, :, 0, 2], refs[:, :, 3, 0] = -1.0, 1.0  # hover at 1 m, heading north
    tables = closed_loop.Tables(np.zeros(N, np.int64), np.ones((N, horizon, 4)), refs)
    consts = closed_loop.constants(plant, SensorNoise(), max(control_every, 0))
    K = ctrl.constants if control_every > 0 else None
    gens = closed_loop.generators([np.random.default_rng(i) for i in range(N)])
    active, k0 = np.ones(N, dtype=bool), np.zeros(N, dtype=np.int64)
    none = closed_loop.Records.none(N, 4)

    def fn():
        closed_loop.fly_batch(gens, active, k0, horizon, True, consts, V, tables, none, K)

    fn()  # compile (or load numba's cache)
    return fn


def core_compiled(N: int, horizon: int, rng, control_every: int = 0, cpu: bool = False):
    """Vehicle-steps/s of the compiled loop (see :func:`compiled_batch`); with ``cpu`` the
    pair (per wall second, per CPU second)."""
    rates = _rates(compiled_batch(N, horizon, rng, control_every), N * horizon)
    return rates if cpu else rates[0]


def make_env(N: int, estimator: str = "none", **kw):
    """A reset ``QuadFaultVectorEnv`` (combined scenario) and the seconds building + reset took;
    numba's thread count is the process's (``numba_threads=None``: this table measures the
    kernels at numba's threads, not the env's default by batch size)."""
    from quad_fault_env.vector import QuadFaultVectorEnv

    kw.setdefault("numba_threads", None)
    t0 = time.perf_counter()
    env = QuadFaultVectorEnv(N, estimator, scenario="combined", duration=600.0, **kw)
    env.reset(seed=0)
    return env, time.perf_counter() - t0


def env_rate(
    N: int, control_steps: int, estimator: str = "none", env=None, cpu: bool = False, **kw
):
    """Physics vehicle-steps/s of QuadFaultVectorEnv (after one warm-up step); with ``cpu``
    the pair (per wall second, per CPU second)."""
    env = env if env is not None else make_env(N, estimator, **kw)[0]
    a = np.zeros((N, 4), dtype=np.float32)
    env.step(a)

    def fn():
        for _ in range(control_steps):
            env.step(a)

    rates = _rates(fn, N * control_steps * env.substeps, repeats=2)
    return rates if cpu else rates[0]


def env_memory_per_vehicle(N: int) -> float:
    """Bytes per vehicle: tracemalloc peak of building, resetting and stepping the env / N."""
    from quad_fault_env.vector import QuadFaultVectorEnv

    tracemalloc.start()
    env = QuadFaultVectorEnv(N, "irls", scenario="combined", duration=60.0)
    env.reset(seed=0)
    env.step(np.zeros((N, 4), dtype=np.float32))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    del env
    return peak / N


def irls_window_rate(N: int, updates: int) -> tuple[float, str]:
    """Solved IRLS windows/s of BatchedIRLS on N copies of a simulated flight's samples."""
    from estimators.base import samples
    from estimators.batched import BatchedIRLS
    from quadfault.model.scenarios import named_scenario
    from quadfault.sim.simulator import simulate

    rec = simulate(named_scenario("combined", 0.2, 1e-3), seed=0).without_truth()
    rows = list(samples(rec))
    est = BatchedIRLS(rec.vehicle, N)
    rng = np.random.default_rng(0)
    tile = lambda x: np.broadcast_to(np.asarray(x, float), (N,) + np.shape(x))  # noqa: E731
    batches = []
    for s in rows[: updates + 12]:
        batches.append(
            (
                np.full(N, s.t),
                tile(s.p) + 1e-4 * rng.standard_normal((N, 3)),
                tile(s.v),
                tile(s.R),
                tile(s.w),
                tile(s.f),
            )
        )
    for b in batches[:12]:  # fill the windows (and compile on a first run)
        est.update(*b)
    solved = 0
    t0 = time.perf_counter()
    for b in batches[12:]:
        out = est.update(*b)
        solved += int(np.sum(out.status_names == "ok") + np.sum(out.status_names == "max_iter"))
    return N * len(batches[12:]) / (
        time.perf_counter() - t0
    ), f"{solved / (N * len(batches[12:])):.0%} ok"


_CRAZYFLOW_SIM = textwrap.dedent("""
    import json, sys, time
    import jax
    jax.config.update("jax_platform_name", "cpu")
    from crazyflow.sim import Sim
    N, H, rate = int(sys.argv[1]), int(sys.argv[2]), int(float(sys.argv[3]))
    sim = Sim(n_worlds=N, n_drones=1, freq=rate, device="cpu", **KW)
    sim.reset()
    sim.step(H)  # compile
    jax.block_until_ready(sim.data.states.pos)
    best, best_cpu = 0.0, 0.0
    for _ in range(3):  # best of 3 timings of >= 0.3 s, as the quadfault rates
        calls, t0, c0 = 0, time.perf_counter(), time.process_time()
        while time.perf_counter() - t0 < 0.3:
            sim.step(H)
            jax.block_until_ready(sim.data.states.pos)
            calls += 1
        best = max(best, N * H * calls / (time.perf_counter() - t0))
        best_cpu = max(best_cpu, N * H * calls / (time.process_time() - c0))
    print(json.dumps({"rate": best, "cpu_rate": best_cpu}))
""")

_CRAZYFLOW_ENV = textwrap.dedent("""
    import json, sys, time
    import numpy as np
    import jax
    jax.config.update("jax_platform_name", "cpu")
    import gymnasium as gym
    import crazyflow  # noqa: F401  (registers its ids)
    N, H = int(sys.argv[1]), max(1, int(sys.argv[2]) // 10)
    env = gym.make_vec("DroneReachPos-v0", num_envs=N, device="cpu", **KW)  # 500 Hz
    env.reset(seed=0)
    u = env.unwrapped
    lo, hi = env.single_action_space.low, env.single_action_space.high
    hover = float(np.ravel(u.sim.data.params.mass)[0]) * 9.81  # collective thrust [N], last
    a = np.tile(np.where(np.arange(lo.size) == lo.size - 1, np.clip(hover, lo[-1], hi[-1]),
                         0.0), (N, 1)).astype(np.float32)  # hover thrust, level attitude
    for _ in range(2):
        jax.block_until_ready(env.step(a)[0])  # compile
    best, best_cpu = 0.0, 0.0
    work = N * H * u.n_substeps  # physics vehicle-steps per timing call
    for _ in range(3):
        calls, t0, c0 = 0, time.perf_counter(), time.process_time()
        while time.perf_counter() - t0 < 0.3:
            for _ in range(H):
                out = env.step(a)
            jax.block_until_ready(out[0])
            calls += 1
        best = max(best, work * calls / (time.perf_counter() - t0))
        best_cpu = max(best_cpu, work * calls / (time.process_time() - c0))
    print(json.dumps({"rate": best, "cpu_rate": best_cpu}))
""")

#: what one step of each peer (and of the quadfault row it is compared with) includes
PEER_STEPS = {
    "rotorpy": "RotorPy BatchedMultirotor (torch CPU): rk4, aero, motor-speed commands, no "
    "controller",
    "crazyflow": "crazyflow Sim defaults (JAX CPU): Euler, first-principles model, attitude "
    "controller (computed every step, applied at 500 Hz), motor mixing",
    "crazyflow-rk4": "crazyflow Sim like-for-like: rk4, first-principles model, Mellinger "
    "position + attitude controller at 1 kHz, motor mixing",
    "crazyflow-env": "crazyflow DroneReachPos-v0 (gymnasium VectorEnv, JAX CPU) defaults: "
    "fitted so_rpy model, Euler, attitude commands, 1 physics step at 500 Hz "
    "per env step",
    "crazyflow-env-fp": "crazyflow DroneReachPos-v0 with dynamics='first_principles': rotor "
    "model, Euler, attitude controller + mixing, 1 physics step per env "
    "step",
}
#: the quadfault row each peer is compared with: the compiled closed loop or the env
PEER_VERSUS = {
    "rotorpy": "compiled",
    "crazyflow": "compiled",
    "crazyflow-rk4": "compiled",
    "crazyflow-env": "env1",
    "crazyflow-env-fp": "env1",
}


PEERS = {
    "rotorpy": textwrap.dedent("""
        import json, sys, time, copy
        import torch
        from rotorpy.vehicles.multirotor import BatchedMultirotor, BatchedMultirotorParams
        from rotorpy.vehicles.crazyflie_params import quad_params
        N, H, rate = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
        dev = torch.device("cpu")
        params = BatchedMultirotorParams([quad_params] * N, N, dev)
        d = lambda *s: torch.zeros(*s, dtype=torch.double)
        q = d(N, 4); q[:, 3] = 1.0
        hover = (quad_params["mass"] * 9.81 / 4 / quad_params["k_eta"]) ** 0.5
        init = {"x": d(N, 3), "v": d(N, 3), "q": q, "w": d(N, 3), "wind": d(N, 3),
                "rotor_speeds": torch.full((N, 4), hover, dtype=torch.double)}
        sim = BatchedMultirotor(params, N, copy.deepcopy(init), dev,
                                control_abstraction="cmd_motor_speeds", aero=True,
                                integrator="rk4")
        ctrl = {"cmd_motor_speeds": torch.full((N, 4), hover, dtype=torch.double)}
        state = sim.step(copy.deepcopy(init), ctrl, 1.0 / rate)
        calls, t0, c0 = 0, time.perf_counter(), time.process_time()
        while time.perf_counter() - t0 < 0.3:
            for _ in range(H):
                state = sim.step(state, ctrl, 1.0 / rate)
            calls += 1
        print(json.dumps({"rate": N * H * calls / (time.perf_counter() - t0),
                          "cpu_rate": N * H * calls / (time.process_time() - c0)}))
    """),
    "crazyflow": _CRAZYFLOW_SIM.replace("KW", "{}"),
    "crazyflow-rk4": _CRAZYFLOW_SIM.replace(
        "KW", "dict(control='state', integrator='rk4', state_freq=rate, attitude_freq=rate)"
    ),
    "crazyflow-env": _CRAZYFLOW_ENV.replace("KW", "{}"),
    "crazyflow-env-fp": _CRAZYFLOW_ENV.replace("KW", "dict(dynamics='first_principles')"),
}


def peer_rate(python: str, name: str, N: int, horizon: int, timeout: float):
    """((vehicle-steps per wall s, per CPU s), None) of a peer, or (None, why it could not
    run)."""
    try:
        out = subprocess.run(
            [python, "-c", PEERS[name], str(N), str(horizon), str(RATE)],
            capture_output=True,
            text=True,
            timeout=timeout,
        )
    except subprocess.TimeoutExpired:
        return None, f"timed out after {timeout:.0f} s"
    except OSError as exc:
        return None, str(exc)
    if out.returncode != 0:
        lines = [ln for ln in out.stderr.strip().splitlines() if ln.strip()]
        return None, lines[-1] if lines else f"exit {out.returncode}"
    try:
        got = json.loads(out.stdout.strip().splitlines()[-1])
        return (got["rate"], got["cpu_rate"]), None
    except (ValueError, IndexError, KeyError):
        return None, f"unreadable output {out.stdout[-200:]!r}"


def ppo_rates(n_envs: int, total: int):
    """PPO env-steps/s: native vector env (SB3 adapter) vs SubprocVecEnv of single envs."""
    try:
        from stable_baselines3 import PPO
        from stable_baselines3.common.env_util import make_vec_env
        from stable_baselines3.common.vec_env import SubprocVecEnv
    except ImportError as exc:
        return None, f"stable-baselines3 / torch missing ({exc})"
    import gymnasium as gym

    import quad_fault_env  # noqa: F401
    from quad_fault_env.sb3_vec import make_sb3_vec_env

    kw = dict(estimator="none", scenario="combined", duration=20.0)
    out = {}
    for name in ("native", "subproc"):
        if name == "native":
            env = make_sb3_vec_env(n_envs, seed=0, **kw)
        else:
            env = make_vec_env(
                lambda: gym.make("quad_fault_env:QuadFault-v1", **kw),
                n_envs=n_envs,
                seed=0,
                vec_env_cls=SubprocVecEnv,
            )
        model = PPO("MlpPolicy", env, n_steps=128, batch_size=256, n_epochs=1, device="cpu", seed=0)
        t0 = time.perf_counter()
        model.learn(total)
        out[name] = model.num_timesteps / (time.perf_counter() - t0)
        env.close()
    return out, None


def _fmt(x) -> str:
    return "n/a" if x is None else f"{x:,.0f}"


def profile_env(N: int, steps: int = 5) -> list[tuple[str, float]]:
    """Share of the env step's time (cProfile) by part."""
    import cProfile
    import pstats

    env, _ = make_env(N)
    a = np.zeros((N, 4), dtype=np.float32)
    env.step(a)
    prof = cProfile.Profile()
    prof.enable()
    for _ in range(steps):
        env.step(a)
    prof.disable()
    stats = pstats.Stats(prof).stats
    total = sum(v[2] for v in stats.values())  # own time of every function
    parts = {
        "the closed loop (fly_batch: sensors, motors, RKMK4)": ("fly_batch",),
        "end-of-step measurement (sense_rows)": ("sense_rows",),
        "controller + action mapping (_motor_commands)": ("_motor_commands",),
        "reference / efficiency tables": ("_ensure_tables", "references"),
        "observation + info": ("_observations", "_infos"),
        "termination + reward": ("reasons", "__call__"),
    }
    out = []
    for label, names in parts.items():
        cum = sum(v[3] for (_, _, fn), v in stats.items() if fn in names)
        out.append((label, cum / total))
    out.append(("everything else", 1.0 - sum(s for _, s in out)))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--full", action="store_true", help="N up to 16384 (default up to 4096)")
    ap.add_argument("--max-n", type=int, default=None, help="largest N")
    ap.add_argument("--horizon", type=int, default=50, help="physics steps per timing (50)")
    ap.add_argument(
        "--peer-python",
        default=sys.executable,
        help="python that has the peers installed (default: this one)",
    )
    ap.add_argument("--peer-timeout", type=float, default=600.0)
    ap.add_argument("--skip-peers", action="store_true")
    ap.add_argument(
        "--peers",
        nargs="+",
        choices=sorted(PEERS),
        default=None,
        help="the peers to run (default all)",
    )
    ap.add_argument(
        "--peer-sizes",
        type=int,
        nargs="+",
        default=None,
        help="N of the peer table (default 1 256 4096 16384 up to --max-n)",
    )
    ap.add_argument("--skip-ppo", action="store_true")
    ap.add_argument("--skip-profile", action="store_true")
    ap.add_argument(
        "--skip-table",
        action="store_true",
        help="skip the N table and the batched IRLS (peers / profile / PPO only)",
    )
    ap.add_argument(
        "--omp-spin",
        action="store_true",
        help="keep OpenMP's default spin-waiting (default here: OMP_WAIT_POLICY="
        "passive, better on a shared machine)",
    )
    ap.add_argument("--ppo-envs", type=int, default=8)
    ap.add_argument("--ppo-steps", type=int, default=4096)
    args = ap.parse_args(argv)
    max_n = (16384 if args.full else 4096) if args.max_n is None else args.max_n
    if max_n < 1 or args.horizon < 10 or min(args.peer_sizes or [1]) < 1:
        print(
            "throughput: --max-n >= 1, --peer-sizes >= 1 and --horizon >= 10 required",
            file=sys.stderr,
        )
        return 2
    import numba

    from quadfault.model import closed_loop

    Ns = [n for n in (1, 16, 256, 1024, 4096, 16384) if n <= max_n]
    rng = np.random.default_rng(0)
    compiled_batch(closed_loop.PARALLEL_MIN_VEHICLES, 10, rng)  # compile; start the threads
    steps = max(1, args.horizon // 10)
    print(
        f"# physics vehicle-steps/s at {RATE:.0f} Hz, horizon {args.horizon} steps; numba "
        f"{numba.__version__}, {numba.get_num_threads()} threads "
        f"({numba.threading_layer() if _threading_started() else 'layer not started'}, "
        f"OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY', 'unset')}); load average "
        f"{', '.join(f'{x:.1f}' for x in os.getloadavg())} on {os.cpu_count()} cpus"
    )
    if not args.skip_table:
        print(
            "| N | loop (motors + RKMK4) | loop + controller | env | env + IRLS | "
            "memory/vehicle (env + IRLS) | build + reset [s] |"
        )
        print("|---|---|---|---|---|---|---|")
    results = {}
    for N in [] if args.skip_table else Ns:
        comp = core_compiled(N, args.horizon, rng)
        closed = core_compiled(N, args.horizon, rng, control_every=1)
        env, setup = make_env(N)
        nb = env_rate(N, steps, env=env)
        del env
        irls = env_rate(N, max(1, steps // 2), "irls") if N <= 1024 else None
        mem = env_memory_per_vehicle(N) if N <= 4096 else None
        results[N] = (comp, closed, nb, irls)
        print(
            f"| {N} | {_fmt(comp)} | {_fmt(closed)} | {_fmt(nb)} | {_fmt(irls)} | "
            f"{'n/a' if mem is None else f'{mem / 1024:.1f} KiB'} | {setup:.1f} |",
            flush=True,
        )
    n_ref = 4096 if 4096 in results else max(results, default=0)
    r = results.get(n_ref)
    if r is not None:
        print(
            f"\nat N = {n_ref}: loop {r[0] / 1e6:.2f}, loop + controller {r[1] / 1e6:.2f}, "
            f"env {r[2] / 1e6:.2f} of the 1,000,000 vehicle-steps/s target"
        )
    if not args.skip_table:
        n_irls = min(4096, max_n)
        rate, note = irls_window_rate(n_irls, 20)
        print(
            f"\nbatched IRLS at N = {n_irls}: {rate:,.0f} window updates/s ({note}; target "
            f"100,000: ratio {rate / 1e5:.2f})"
        )
    if not args.skip_profile:
        n_prof = min(4096, max_n)
        print(f"\n# where the time goes at N = {n_prof}")
        print(
            "kernels, CPU ns per vehicle-step, each stage alone on one core "
            "(benchmarks/kernel_stages.py):"
        )
        from benchmarks.kernel_stages import STAGES, stage_ns

        ns = stage_ns(n_prof, args.horizon, repeats=3)
        for key, label in STAGES:
            print(f"  {label:<64} {ns[key]:8.0f}")
        print("env step (cProfile, cumulative share):")
        for label, share in profile_env(n_prof, steps):
            print(f"  {label:<56} {share:6.1%}")
    if not args.skip_peers:
        peers = list(PEERS) if args.peers is None else args.peers
        print(
            f"\n# peers at {RATE:.0f} Hz, horizon {args.horizon} (python {args.peer_python}); "
            f"vehicle-steps per wall second / per CPU second of each process (all threads); "
            f"load average {', '.join(f'{x:.1f}' for x in os.getloadavg())}"
        )
        for name in peers:
            print(f"  {name}: {PEER_STEPS[name]}")
        wanted = {PEER_VERSUS[name] for name in peers}
        if "compiled" in wanted:
            print(
                "  quadfault compiled + controller: closed_loop.fly_batch, geometric "
                "controller every step, motor model with thrust noise, RKMK4 (4 derivatives, "
                "5 SO(3) exponentials)"
            )
        if "env1" in wanted:
            print(
                "  quadfault env1: QuadFaultVectorEnv.step at control = physics = 1 kHz (1 "
                "substep per env step), motor commands, no estimator, combined scenario "
                "(thrust noise, degradation), the env's default numba threads; RKMK4"
            )
        print("| N | system | vehicle-steps/s wall / CPU | quadfault / system, wall / CPU |")
        print("|---|---|---|---|")
        pair = lambda r: "n/a" if r is None else f"{r[0]:,.0f} / {r[1]:,.0f}"  # noqa: E731

        def ratio(a, b):
            return (
                "n/a"
                if b is None  # noqa: E731
                else f"**{a[0] / b[0]:.2f}x / {a[1] / b[1]:.2f}x**"
            )

        best = lambda a, b: (max(a[0], b[0]), max(a[1], b[1]))  # noqa: E731
        measures = {
            "compiled": lambda N: core_compiled(N, args.horizon, rng, control_every=1, cpu=True),
            "env1": lambda N: env_rate(
                N,
                args.horizon,
                cpu=True,
                control_rate=RATE,
                action_mode="motor",
                numba_threads="auto",
            ),
        }
        labels = {"compiled": "quadfault compiled + controller", "env1": "quadfault env1"}
        sizes = args.peer_sizes or [n for n in Ns if n in (1, 256, 4096, 16384)]
        for N in sizes:
            # measured right before and after the peers (the machine's load drifts)
            ours = {key: measures[key](N) for key in sorted(wanted)}
            got = {}
            for name in peers:
                if name == "rotorpy" and N > 4096:  # ~1,700 steps/s: minutes per timing
                    got[name] = (None, "not run above N = 4096 (too slow)")
                    continue
                got[name] = peer_rate(args.peer_python, name, N, args.horizon, args.peer_timeout)
            ours = {key: best(x, measures[key](N)) for key, x in ours.items()}
            for key in sorted(wanted):
                print(f"| {N} | {labels[key]} | {pair(ours[key])} | |")
            for name in peers:
                rate, why = got[name]
                if rate is None:
                    print(f"| {N} | {name} | did not run: {why} | |", flush=True)
                    continue
                print(
                    f"| {N} | {name} | {pair(rate)} | {PEER_VERSUS[name]}: "
                    f"{ratio(ours[PEER_VERSUS[name]], rate)} |",
                    flush=True,
                )
    if not args.skip_ppo:
        rates, why = ppo_rates(args.ppo_envs, args.ppo_steps)
        if rates is None:
            print(f"\nPPO: skipped ({why})")
        else:
            print(
                f"\nPPO training with {args.ppo_envs} envs, {args.ppo_steps} steps: native "
                f"vector env {rates['native']:,.0f} steps/s, SubprocVecEnv "
                f"{rates['subproc']:,.0f} steps/s, "
                f"ratio {rates['native'] / rates['subproc']:.2f}"
            )
    return 0


def _threading_started() -> bool:
    try:
        import numba

        numba.threading_layer()
        return True
    except ValueError:  # no parallel region has run yet
        return False


if __name__ == "__main__":
    raise SystemExit(main())
