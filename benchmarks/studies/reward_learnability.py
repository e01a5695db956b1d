"""Does the reward teach? A short PPO run against random and zero residual actions, and a late
crash against a survived episode, under the ``-v1`` and the ``-v0`` rewards.

Part 1 (crash): on ``QuadFaultHover-v1`` (hover, one random fault) in motor mode, the
geometric controller flies the whole episode; the same episode with the rotors off for its
last 0.6 s falls and crashes just before the end (the same flight, so the same tracking, up
to then). Printed: both returns under each reward (the ``-v1`` reward scores the late crash
below the survived episode by its termination penalty and more).

Part 2 (learning): ``quadfault train`` trains PPO for ``--timesteps`` steps (one seed, the
array-stepped vector env) on the residual hover task with one fault of eta 0.5-0.85 and a
residual authority of 2.45 N per unit action (the PPO study's task,
``benchmarks/studies/ppo_residual_study.py``), on ``QuadFaultHover-v1``; then the final policy
(deterministic), random uniform actions and the zero action (the geometric controller alone)
fly the same ``--episodes`` seeded evaluation episodes. Printed: mean and standard deviation of
the return, crashes, and the same random-vs-zero gap under the ``-v0`` reward.

    python benchmarks/studies/reward_learnability.py                     # 30,000 steps, 10 episodes
    python benchmarks/studies/reward_learnability.py --timesteps 4096 --episodes 3   # quick look
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

#: the task of both parts: the PPO study's residual hover task (one fault, 2.45 N per unit)
ENV_KWARGS = {
    "action_mode": "residual",
    "residual_scale": 2.45,
    "estimator": "irls",
    "estimator_rate": "control",
    "random_faults": {"n_faults": [1, 1], "severity": [0.5, 0.85]},
}
#: PPO settings (the study's, with 8 sub-envs: rollouts of 8 x 256 steps)
PPO_KWARGS = {
    "n_steps": 256,
    "batch_size": 512,
    "n_epochs": 10,
    "learning_rate": 3e-4,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "policy_kwargs": {"log_std_init": -1.0, "net_arch": [64, 64]},
}
EVAL_SEED = 20_000
ROLL = np.array(
    [-1.0, 1.0, 1.0, -1.0]
)  # residual: right rotors down, left rotors up  # the evaluation episodes' reset seeds: EVAL_SEED, EVAL_SEED + 1, ...


class RandomPolicy:
    """Uniform random actions in [-1, 1]^4 from a seeded generator (SB3's ``predict``)."""

    def __init__(self, seed: int):
        self.rng = np.random.default_rng(seed)

    def predict(self, obs, deterministic=True):
        return self.rng.uniform(-1.0, 1.0, 4).astype(np.float32), None


class ZeroPolicy:
    """The zero residual: the geometric controller alone."""

    def predict(self, obs, deterministic=True):
        return np.zeros(4, np.float32), None


def _episode(env, seed: int, policy, cut: int | None = None) -> tuple[float, int, str | None]:
    """Return, length and termination reason of one episode of ``policy``; from step ``cut``
    on, all rotors off instead (motor mode: action -1)."""
    obs, _ = env.reset(seed=seed)
    total, n = 0.0, 0
    while True:
        action = policy.predict(obs)[0] if cut is None or n < cut else -np.ones(4, np.float32)
        obs, r, term, trunc, info = env.step(action)
        total, n = total + float(r), n + 1
        if term or trunc:
            return total, n, info["termination_reason"]


def crash_part(seeds) -> None:
    import gymnasium as gym

    from agents.policies import GeometricPolicy

    print(
        "Part 1: the geometric controller's flight (motor mode) vs the same flight with the "
        "rotors off from 0.6 s before its end"
    )
    print(f"{'reward':>7} {'seed':>6} {'survived':>9} {'late crash':>11} {'crash step':>10}")
    for env_id in ("QuadFaultHover-v1", "QuadFaultHover-v0"):
        env = gym.make(env_id, **dict(ENV_KWARGS, action_mode="motor"))
        policy = GeometricPolicy.from_env(env)
        for seed in seeds:
            survived, n_s, reason_s = _episode(env, seed, policy)
            crashed, n_c, reason_c = _episode(env, seed, policy, cut=n_s - 60)
            note = "" if reason_s is None else f" (the controller alone: {reason_s})"
            print(
                f"{env_id[-2:]:>7} {seed:>6} {survived:9.1f} {crashed:11.1f} "
                f"{f'{n_c}/{n_s}' if reason_c else '-':>10}{note}"
            )
        env.close()


def evaluate(env_id: str, policy, seeds) -> tuple[np.ndarray, int]:
    import gymnasium as gym

    from agents.train_eval import evaluate_episodes

    env = gym.make(env_id, **ENV_KWARGS)
    returns, crashes = [], 0
    for seed in seeds:
        ret, n = evaluate_episodes(policy, env, [seed])
        returns.append(ret[0])
        crashes += int(n[0] < env.unwrapped.max_steps)
    env.close()
    return np.asarray(returns), crashes


def learning_part(args) -> None:
    from ppo_residual_study import t_interval  # benchmarks/studies/ (this script's folder)

    from agents.train import load_agent
    from agents.train import main as train_main

    out = Path(args.out or tempfile.mkdtemp(prefix="reward_learnability_"))
    t0 = time.perf_counter()
    code = (
        0
        if args.trained
        else train_main(
            [
                "--env",
                "QuadFaultHover-v1",
                "--env-kwargs",
                json.dumps(ENV_KWARGS),
                "--vector-env",
                "--n-envs",
                "8",
                "--timesteps",
                str(args.timesteps),
                "--eval-freq",
                str(args.timesteps),
                "--eval-episodes",
                "3",
                "--algo-kwargs",
                json.dumps(PPO_KWARGS),
                "--seeds",
                str(args.seed),
                "--out",
                str(out),
                "--force",
            ]
        )
    )
    if code != 0:
        raise SystemExit(code)
    train_s = time.perf_counter() - t0
    model, venv = load_agent(out / f"seed_{args.seed}")

    class Trained:
        def predict(self, obs, deterministic=True):
            o = venv.normalize_obs(obs) if hasattr(venv, "normalize_obs") else obs
            return model.predict(o, deterministic=True)

    seeds = [EVAL_SEED + i for i in range(args.episodes)]
    print(
        f"\nPart 2: PPO {args.timesteps} steps (seed {args.seed}, {train_s:.0f} s of training, "
        f"load {os.getloadavg()[0]:.1f}) vs random and zero actions, {args.episodes} "
        f"evaluation episodes (seeds {seeds[0]}..{seeds[-1]})"
    )
    print(f"{'reward':>7} {'policy':>8} {'mean':>9} {'sd':>8} {'crashes':>8}")
    rows = {}
    for env_id, arms in (
        ("QuadFaultHover-v1", ("ppo", "random", "zero")),
        ("QuadFaultHover-v0", ("random", "zero")),
    ):
        for arm in arms:
            policy = {"ppo": Trained(), "random": RandomPolicy(args.seed), "zero": ZeroPolicy()}[
                arm
            ]
            ret, crashes = evaluate(env_id, policy, seeds)
            rows[env_id[-2:], arm] = ret
            print(
                f"{env_id[-2:]:>7} {arm:>8} {ret.mean():9.1f} {ret.std(ddof=1):8.1f} "
                f"{crashes:>4}/{len(seeds)}"
            )
    for v in ("v1", "v0"):
        zero, rand = rows[v, "zero"].mean(), rows[v, "random"].mean()
        print(
            f"{v}: random actions score {100 * (zero - rand) / abs(zero):.1f} % below the "
            f"zero action"
        )
    for other in ("random", "zero"):  # paired over the same episodes
        mean, half = t_interval(rows["v1", "ppo"] - rows["v1", other])
        print(
            f"v1: PPO - {other} = {mean:.1f} +- {half:.1f} (95 % CI, paired), PPO ahead in "
            f"{int(np.sum(rows['v1', 'ppo'] > rows['v1', other]))}/{len(seeds)} episodes"
        )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--timesteps", type=int, default=30_000, help="PPO steps (default 30000)")
    p.add_argument("--episodes", type=int, default=10, help="evaluation episodes (default 10)")
    p.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    p.add_argument("--crash-seeds", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--out", help="training folder (default: a temporary one)")
    p.add_argument("--skip-training", action="store_true", help="part 1 only")
    p.add_argument(
        "--trained", action="store_true", help="evaluate the run already in --out (no training)"
    )
    args = p.parse_args(argv)
    import quad_fault_env  # noqa: F401

    print(f"load {os.getloadavg()[0]:.1f}")
    crash_part(args.crash_seeds)
    if not args.skip_training:
        learning_part(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
