"""Train a policy in a simulator calibrated on a real flight, evaluate it nominal and calibrated.

The workflow: real log -> ``quadfault import`` -> ``quadfault diagnose`` -> an environment
that flies what the diagnosis learnt (``gym.make(id, model="diag.json")``: the log's nominal
vehicle plus its accepted effects, e.g. motor lag and rotor drag on a Crazyflie) -> train ->
evaluate. The task is ``QuadFaultTrack-v0`` (random smooth trajectories, scaled to the
vehicle's size; the geometric controller's gains follow its mass and inertia). The PPO policy
adds a bounded residual to the geometric controller. It is then flown on the same fixed
episodes in the nominal env (the log's vehicle, no effects) and in the calibrated env, beside
the geometric controller alone (zero residual)::

    python examples/train_calibrated_env.py \\
        --log ../shared/data/real/nanodrone-cf21bl/square_20251017_run3.csv.gz \\
        --dataset nanodrone --out runs/calibrated

Writes ``OUT/flight.csv`` (the imported log), ``OUT/diag.json`` (the diagnosis),
``OUT/seed_0/`` (the trained policy) and prints the mean return and tracking RMSE of each
agent in each env. Needs the ``rl`` extra (stable-baselines3, torch).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ENV_ID = "QuadFaultTrack-v0"


def fly(env, policy, seeds, normalizer=None) -> tuple[float, float]:
    """Mean return and mean tracking RMSE [m] over one episode per reset seed."""
    from agents.train_eval import fly_episodes

    flown = fly_episodes(policy, env, seeds, normalizer)
    return float(np.mean(flown["returns"])), float(np.mean(flown["rmse"]))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--log", required=True, help="a real flight log")
    parser.add_argument(
        "--dataset", default="nanodrone", help="its importer (quadfault import DATASET)"
    )
    parser.add_argument("--out", default="runs/calibrated", help="output folder")
    parser.add_argument("--timesteps", type=int, default=16_384)
    parser.add_argument("--episodes", type=int, default=5, help="evaluation episodes")
    parser.add_argument("--duration", type=float, default=10.0, help="episode length [s]")
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)

    import gymnasium as gym

    import quad_fault_env  # noqa: F401  (registers the ids)
    from agents.train import TrainConfig, load_agent, train_one
    from quadfault.cli import main as cli
    from quadfault.errors import QuadfaultError
    from quadfault.model.effects import from_diagnosis

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    flight, diag = out / "flight.csv", out / "diag.json"
    force = ["--force"] if args.force else []
    if cli(["import", args.dataset, args.log, "--out", str(flight), *force]) != 0:
        return 2
    if cli(["diagnose", str(flight), "--json", str(diag), *force]) != 0:
        return 2
    model = from_diagnosis(diag)
    print("calibrated model: " + (", ".join(e.name for e in model.effects) or "no effects"))
    common = {
        "estimator": "none",
        "action_mode": "residual",
        "duration": args.duration,
        "residual_scale": 0.25 * model.vehicle.mass * model.vehicle.gravity,
    }
    config = TrainConfig(
        algo="ppo",
        env_id=ENV_ID,
        env_kwargs=dict(common, model=str(diag)),
        timesteps=args.timesteps,
        seeds=(0,),
        n_envs=4,
        eval_freq=max(args.timesteps // 4, 1000),
        eval_episodes=3,
        algo_kwargs={
            "n_steps": 512,
            "batch_size": 256,
            "policy_kwargs": {"net_arch": [64, 64], "log_std_init": -2.3},
        },
    )
    try:
        train_one(config, 0, out / "seed_0", force=args.force)
    except QuadfaultError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    seeds = [30_000 + i for i in range(args.episodes)]
    scored = dict(common, info="full")  # fly() scores info["tracking_error"]
    envs = {
        "nominal": gym.make(ENV_ID, vehicle=model.vehicle, **scored),
        "calibrated": gym.make(ENV_ID, model=str(diag), **scored),
    }
    print(f"{'env':<11} {'agent':<22} {'mean return':>12} {'RMSE [m]':>9}")
    for name, env in envs.items():
        policy, venv = load_agent(out / "seed_0", env=env)
        norm = venv if hasattr(venv, "normalize_obs") else None
        for label, (ret, rmse) in (
            ("geometric (zero)", fly(env, None, seeds)),
            ("PPO residual", fly(env, policy, seeds, norm)),
        ):
            print(f"{name:<11} {label:<22} {ret:>12.1f} {rmse:>9.4f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
