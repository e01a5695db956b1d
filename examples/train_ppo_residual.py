"""Train a PPO residual policy on top of the geometric controller and plot its learning curve.

The policy adds up to 2.45 N per rotor (the hover thrust of one rotor) to the geometric
controller's commands, sees the IRLS efficiency estimate in its observation and learns on
the hover task with one random motor fault of efficiency 0.5-0.85 (``QuadFaultHover-v1``,
``random_faults`` as in ``benchmarks/studies/ppo_residual_study.py``, episodes shortened to 5 s).
``--n-envs`` quadrotors are stepped as arrays in one process (``TrainConfig(vector_env=True)``,
:class:`quad_fault_env.vector.QuadFaultVectorEnv`). With the defaults it finishes in a few
minutes on a 2-core CPU without GPU::

    python examples/train_ppo_residual.py --out runs/ppo_residual

Writes ``OUT/seed_0/`` (model, VecNormalize statistics, best model, evaluations) and
``OUT/learning_curve.png`` (the same figure as ``quadfault train``: evaluation return on 10
fixed seeded episodes against environment steps, with the geometric controller on the same
episodes). Needs the ``rl`` extra (stable-baselines3, torch).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="runs/ppo_residual", help="output folder")
    parser.add_argument("--timesteps", type=int, default=20_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--n-envs", type=int, default=8, help="quadrotors stepped as arrays in one vector env"
    )
    parser.add_argument("--estimator", default="irls", choices=("irls", "ekf", "truth", "none"))
    parser.add_argument("--duration", type=float, default=5.0, help="episode length [s]")
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)

    from agents.learning_curve import CURVE_FILE, write_learning_curve
    from agents.train import TrainConfig, train_one
    from quadfault.errors import QuadfaultError

    config = TrainConfig(
        algo="ppo",
        env_id="QuadFaultHover-v1",
        env_kwargs={
            "estimator": args.estimator,
            "estimator_rate": "control",
            "action_mode": "residual",
            "residual_scale": 2.45,
            "random_faults": {"n_faults": [1, 1], "severity": [0.5, 0.85]},
            "duration": args.duration,
        },
        timesteps=args.timesteps,
        seeds=(args.seed,),
        n_envs=args.n_envs,
        vector_env=True,
        eval_freq=max(args.timesteps // 8, 500),
        # small initial exploration noise (exp(-2.3) x 2.45 N ~ 0.25 N per rotor, as in the
        # study): the residual starts from a controller that already flies, and large noise
        # early only costs return
        algo_kwargs={
            "n_steps": 256,
            "batch_size": 256,
            "learning_rate": 1e-4,
            "policy_kwargs": {"net_arch": [64, 64], "log_std_init": -2.3},
        },
    )
    out = Path(args.out)
    run_dir = out / f"seed_{args.seed}"
    try:
        train_one(config, args.seed, run_dir, force=args.force)
        data = write_learning_curve(
            [run_dir], out / CURVE_FILE, label=f"PPO residual, eta_hat from {args.estimator}"
        )
    except QuadfaultError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    curve = data["returns"][0]
    print(
        f"evaluation return ({len(data['episode_seeds'])} fixed episodes, max possible "
        f"{args.duration * 100:.0f}): geometric controller {data['baseline']:.1f}; PPO first "
        f"{curve[0]:.1f}, last {curve[-1]:.1f}, best {curve.max():.1f}; curve -> "
        f"{out / CURVE_FILE}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
