"""Throughput: batched physics, the vector env, batched IRLS, peers and PPO, side by side.

Prints, measured in one run (ratios are what to compare; the machine may be shared):

1. physics vehicle-steps/s against N: the core physics alone (motors + ``step_rk4`` over the
   batch axis, 1 kHz) and the full ``QuadFaultVectorEnv`` step (controller, noise, physics,
   termination, observation) without an estimator, plus with the batched IRLS estimator;
   memory per vehicle (tracemalloc peak of building, resetting and stepping the env / N);
2. batched IRLS window updates/s (``estimators.batched.BatchedIRLS``);
3. peers at the same physics rate (1 kHz) and horizon: RotorPy's ``BatchedMultirotor``
   (torch, CPU, rk4) and crazyflow's ``Sim`` (JAX, CPU); each runs in a subprocess of
   ``--peer-python`` and is skipped with the reason when it cannot be imported or run;
4. SB3 PPO training steps/s with the native vector env vs ``SubprocVecEnv``.

This script installs nothing. Peers, in a separate virtual environment so they cannot touch
the project's environment::

    python -m venv --system-site-packages /tmp/peers
    /tmp/peers/bin/pip install rotorpy crazyflow torchdiffeq roma
    python benchmarks/throughput.py --peer-python /tmp/peers/bin/python

Flags: ``--full`` (N up to 16384), ``--max-n``, ``--horizon`` (physics steps per timing),
``--skip-peers``, ``--skip-ppo``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import textwrap
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from quadfault.dynamics import RigidBodyState, step_rk4  # noqa: E402
from quadfault.motors import MotorModel  # noqa: E402
from quadfault.vehicle import Vehicle  # noqa: E402

RATE = 1000.0  # physics rate of every measurement [Hz]


def core_physics(N: int, horizon: int, rng) -> float:
    """Vehicle-steps/s of motors (eqs. 11, 13) + RKMK4 (eqs. 1-4) over a batch of N."""
    veh = Vehicle()
    motor = MotorModel(0.07)
    state = RigidBodyState.at_rest((0.0, 0.0, -1.0), (N,))
    f_cmd = np.full((N, 4), veh.weight / 4) + 0.01 * rng.standard_normal((N, 4))
    eta = np.ones((N, 4))
    t0 = time.perf_counter()
    for _ in range(horizon):
        f = motor.apply(f_cmd, eta, veh.rotor_max_thrust, rng)
        wrench = veh.wrench(f)
        state = step_rk4(state, wrench[:, 0], wrench[:, 1:], veh, 1.0 / RATE)
    return N * horizon / (time.perf_counter() - t0)


def env_rate(N: int, control_steps: int, estimator: str = "none", **kw) -> float:
    """Physics vehicle-steps/s of QuadFaultVectorEnv (after one warm-up step)."""
    from quad_fault_env.vector import QuadFaultVectorEnv

    env = QuadFaultVectorEnv(N, estimator, scenario="combined", duration=60.0, **kw)
    env.reset(seed=0)
    a = np.zeros((N, 4), dtype=np.float32)
    env.step(a)
    t0 = time.perf_counter()
    for _ in range(control_steps):
        env.step(a)
    return N * control_steps * env.substeps / (time.perf_counter() - t0)


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
    from quadfault.scenarios import named_scenario
    from quadfault.simulator import simulate

    rec = simulate(named_scenario("combined", 0.2, 1e-3), seed=0).without_truth()
    rows = list(samples(rec))
    est = BatchedIRLS(rec.vehicle, N)
    rng = np.random.default_rng(0)
    tile = lambda x: np.broadcast_to(np.asarray(x, float), (N,) + np.shape(x))  # noqa: E731
    batches = []
    for s in rows[:updates + 12]:
        batches.append((np.full(N, s.t), tile(s.p) + 1e-4 * rng.standard_normal((N, 3)),
                        tile(s.v), tile(s.R), tile(s.w), tile(s.f)))
    for b in batches[:12]:  # fill the windows (and compile on a first run)
        est.update(*b)
    solved = 0
    t0 = time.perf_counter()
    for b in batches[12:]:
        out = est.update(*b)
        solved += int(np.sum(out.status_names == "ok") + np.sum(out.status_names == "max_iter"))
    return N * len(batches[12:]) / (time.perf_counter() - t0), \
        f"{solved / (N * len(batches[12:])):.0%} ok, backend {est.backend}"


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
        t0 = time.perf_counter()
        for _ in range(H):
            state = sim.step(state, ctrl, 1.0 / rate)
        print(json.dumps({"rate": N * H / (time.perf_counter() - t0)}))
    """),
    "crazyflow": textwrap.dedent("""
        import json, sys, time
        import jax
        jax.config.update("jax_platform_name", "cpu")
        from crazyflow.sim import Sim
        N, H, rate = int(sys.argv[1]), int(sys.argv[2]), int(float(sys.argv[3]))
        sim = Sim(n_worlds=N, n_drones=1, freq=rate, attitude_freq=500, device="cpu")
        sim.reset()
        sim.step(H)  # compile
        jax.block_until_ready(sim.data.states.pos)
        t0 = time.perf_counter()
        sim.step(H)
        jax.block_until_ready(sim.data.states.pos)
        print(json.dumps({"rate": N * H / (time.perf_counter() - t0)}))
    """),
}


def peer_rate(python: str, name: str, N: int, horizon: int, timeout: float):
    """(vehicle-steps/s, None) of a peer, or (None, why it could not run)."""
    try:
        out = subprocess.run([python, "-c", PEERS[name], str(N), str(horizon), str(RATE)],
                             capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, f"timed out after {timeout:.0f} s"
    except OSError as exc:
        return None, str(exc)
    if out.returncode != 0:
        lines = [ln for ln in out.stderr.strip().splitlines() if ln.strip()]
        return None, lines[-1] if lines else f"exit {out.returncode}"
    try:
        return json.loads(out.stdout.strip().splitlines()[-1])["rate"], None
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
            env = make_vec_env(lambda: gym.make("quad_fault_env:QuadFault-v0", **kw),
                               n_envs=n_envs, seed=0, vec_env_cls=SubprocVecEnv)
        model = PPO("MlpPolicy", env, n_steps=128, batch_size=256, n_epochs=1, device="cpu",
                    seed=0)
        t0 = time.perf_counter()
        model.learn(total)
        out[name] = model.num_timesteps / (time.perf_counter() - t0)
        env.close()
    return out, None


def _fmt(x) -> str:
    return "n/a" if x is None else f"{x:,.0f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--full", action="store_true", help="N up to 16384 (default up to 4096)")
    ap.add_argument("--max-n", type=int, default=None, help="largest N")
    ap.add_argument("--horizon", type=int, default=50, help="physics steps per timing (50)")
    ap.add_argument("--peer-python", default=sys.executable,
                    help="python that has the peers installed (default: this one)")
    ap.add_argument("--peer-timeout", type=float, default=600.0)
    ap.add_argument("--skip-peers", action="store_true")
    ap.add_argument("--skip-ppo", action="store_true")
    ap.add_argument("--ppo-envs", type=int, default=8)
    ap.add_argument("--ppo-steps", type=int, default=4096)
    args = ap.parse_args(argv)
    max_n = (16384 if args.full else 4096) if args.max_n is None else args.max_n
    if max_n < 1 or args.horizon < 10:
        print("throughput: --max-n >= 1 and --horizon >= 10 required", file=sys.stderr)
        return 2
    Ns = [n for n in (1, 16, 256, 1024, 4096, 16384) if n <= max_n]
    rng = np.random.default_rng(0)
    steps = max(1, args.horizon // 10)
    print(f"# physics vehicle-steps/s at {RATE:.0f} Hz, horizon {args.horizon} steps")
    print("| N | core physics | env, no estimator | env, shared noise | env + IRLS (physics "
          "rate) | memory/vehicle (env + IRLS) |")
    print("|---|---|---|---|---|---|")
    results = {}
    for N in Ns:
        core = core_physics(N, args.horizon, rng)
        env = env_rate(N, steps)
        shared = env_rate(N, steps, noise_streams="shared")
        irls = env_rate(N, max(1, steps // 2), "irls") if N <= 1024 else None
        mem = env_memory_per_vehicle(N) if N <= 4096 else None
        results[N] = (core, env, shared, irls)
        print(f"| {N} | {_fmt(core)} | {_fmt(env)} | {_fmt(shared)} | {_fmt(irls)} | "
              f"{'n/a' if mem is None else f'{mem / 1024:.1f} KiB'} |", flush=True)
    n_irls = min(4096, max_n)
    rate, note = irls_window_rate(n_irls, 20)
    print(f"\nbatched IRLS at N = {n_irls}: {rate:,.0f} window updates/s ({note}; target 100,000: "
          f"ratio {rate / 1e5:.2f})")
    n_ref = max(Ns)
    print(f"env, shared noise at N = {n_ref}: {results[n_ref][2] / 1e6:.2f} of the 1,000,000 "
          f"vehicle-steps/s target")
    if not args.skip_peers:
        print(f"\n# peers at {RATE:.0f} Hz, horizon {args.horizon} (python {args.peer_python})")
        print("| N | quadfault core | quadfault env | rotorpy | crazyflow | core/rotorpy | "
              "env/rotorpy | core/crazyflow | env/crazyflow |")
        print("|---|---|---|---|---|---|---|---|---|")
        for N in [n for n in Ns if n in (1, 256, 4096, 16384)]:
            # measured again right next to the peers (the machine's load drifts)
            core, env = core_physics(N, args.horizon, rng), env_rate(N, steps,
                                                                     noise_streams="shared")
            peers, why = {}, {}
            for name in PEERS:
                peers[name], why[name] = peer_rate(args.peer_python, name, N, args.horizon,
                                                   args.peer_timeout)
            ratio = lambda a, b: "n/a" if b is None else f"{a / b:.1f}x"  # noqa: E731
            print(f"| {N} | {_fmt(core)} | {_fmt(env)} | {_fmt(peers['rotorpy'])} | "
                  f"{_fmt(peers['crazyflow'])} | {ratio(core, peers['rotorpy'])} | "
                  f"{ratio(env, peers['rotorpy'])} | {ratio(core, peers['crazyflow'])} | "
                  f"{ratio(env, peers['crazyflow'])} |", flush=True)
            for name, reason in why.items():
                if reason:
                    print(f"  {name} at N = {N} did not run: {reason}")
    if not args.skip_ppo:
        rates, why = ppo_rates(args.ppo_envs, args.ppo_steps)
        if rates is None:
            print(f"\nPPO: skipped ({why})")
        else:
            print(f"\nPPO training with {args.ppo_envs} envs, {args.ppo_steps} steps: native "
                  f"vector env {rates['native']:,.0f} steps/s, SubprocVecEnv "
                  f"{rates['subproc']:,.0f} steps/s, "
                  f"ratio {rates['native'] / rates['subproc']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
