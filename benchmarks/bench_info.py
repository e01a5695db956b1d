"""What the single env's ``info`` costs: ``info="light"`` against ``info="full"``, side by side.

Part 1, the env alone: ``gym.make("QuadFault-v1", estimator=E, info=L)`` stepped with the zero
residual action (episodes reset when they end), env steps per CPU second, for E = none and
irls and L = light and full.

Part 2, a new user's training loop: stable-baselines3 PPO (``MlpPolicy``, torch on one thread)
on SB3's ``make_vec_env`` of ``--n-envs`` single envs of ``QuadFault-v1`` (``DummyVecEnv``,
``Monitor``), ``--rollouts`` rollouts of ``--n-steps`` steps per env through ``learn``. It
reports the env steps per CPU second of the rollouts (``learn`` minus PPO's update,
``PPO.train``) and the shares of the rollouts' CPU spent in ``DummyVecEnv``'s deep copy of the
infos (its ``deepcopy`` in ``step_wait``) and in building them (``QuadFaultEnv._info``).

CPU seconds are the process's (``time.process_time``), so the numbers hold on a loaded
machine; the configurations run in interleaved rounds and the best round of each is kept;
the report names the load average. The first compile of numba's kernels is excluded by a
warm-up.

    python benchmarks/bench_info.py
    python benchmarks/bench_info.py --rounds 5 --steps 2000 --n-steps 512
"""

from __future__ import annotations

import argparse
import os
import time

ENV_ID = "QuadFault-v1"
LEVELS = ("light", "full")


class _Clock:
    """Accumulated process CPU seconds of the wrapped calls (nested calls counted once)."""

    def __init__(self):
        self.cpu, self._depth = 0.0, 0

    def wrap(self, fn):
        def timed(*args, **kwargs):
            self._depth += 1
            c = time.process_time()
            try:
                return fn(*args, **kwargs)
            finally:
                self._depth -= 1
                if self._depth == 0:
                    self.cpu += time.process_time() - c

        return timed


def env_alone(estimator: str, level: str, steps: int) -> float:
    """Env steps per CPU second of the single env."""
    import gymnasium as gym
    import numpy as np

    env = gym.make(ENV_ID, estimator=estimator, info=level)
    a = np.zeros(4, dtype=np.float32)
    env.reset(seed=0)
    for _ in range(5):  # compile / load the cache, first-step allocations
        env.step(a)
    c = time.process_time()
    for _ in range(steps):
        *_, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    rate = steps / (time.process_time() - c)
    env.close()
    return rate


def ppo_rollouts(estimator: str, level: str, args) -> dict:
    """PPO on a DummyVecEnv of single envs: rollout steps per CPU second and the shares of
    the rollout in copying and building the infos."""
    import copy

    import gymnasium as gym
    import stable_baselines3.common.vec_env.dummy_vec_env as dummy
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv

    from quad_fault_env.envs.quad_fault import QuadFaultEnv

    venv = make_vec_env(
        lambda: gym.make(ENV_ID, estimator=estimator, info=level),
        n_envs=args.n_envs,
        seed=0,
        vec_env_cls=DummyVecEnv,
    )
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=args.n_steps,
        batch_size=args.n_steps,
        n_epochs=1,
        seed=0,
        device="cpu",
        verbose=0,
    )
    model.learn(args.n_steps * args.n_envs)  # warm-up: compile, first allocations
    clocks = {k: _Clock() for k in ("update", "copy", "build")}
    info_of = QuadFaultEnv._info
    model.train = clocks["update"].wrap(model.train)
    dummy.deepcopy = clocks["copy"].wrap(copy.deepcopy)
    QuadFaultEnv._info = clocks["build"].wrap(info_of)
    try:
        steps = args.rollouts * args.n_steps * args.n_envs
        c = time.process_time()
        model.learn(steps, reset_num_timesteps=False)
        rollout = time.process_time() - c - clocks["update"].cpu
    finally:
        dummy.deepcopy, QuadFaultEnv._info = copy.deepcopy, info_of
        venv.close()
    return {
        "rate": steps / rollout,
        "copy": clocks["copy"].cpu / rollout,
        "build": clocks["build"].cpu / rollout,
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--estimators", nargs="+", default=["none", "irls"])
    parser.add_argument("--steps", type=int, default=1000, help="env steps per round (part 1)")
    parser.add_argument("--n-envs", type=int, default=4, help="single envs of the DummyVecEnv")
    parser.add_argument("--n-steps", type=int, default=256, help="PPO's steps per env and rollout")
    parser.add_argument("--rollouts", type=int, default=2, help="rollouts per round (part 2)")
    parser.add_argument("--rounds", type=int, default=3, help="rounds; the best is kept")
    parser.add_argument("--skip-ppo", action="store_true", help="part 1 only")
    args = parser.parse_args(argv)

    import torch

    import quad_fault_env  # noqa: F401  (registers the ids)

    torch.set_num_threads(1)
    load0 = os.getloadavg()[0]
    alone, ppo = {}, {}
    for _ in range(args.rounds):
        for est in args.estimators:
            for level in LEVELS:
                key = (est, level)
                alone[key] = max(alone.get(key, 0.0), env_alone(est, level, args.steps))
                if not args.skip_ppo:
                    r = ppo_rollouts(est, level, args)
                    if r["rate"] > ppo.get(key, {"rate": 0.0})["rate"]:
                        ppo[key] = r
    load1 = os.getloadavg()[0]

    print(f"{ENV_ID}, zero residual action: env steps per CPU second (best of {args.rounds})")
    print(f"{'estimator':<10} {'light':>8} {'full':>8} {'light/full':>11}")
    for est in args.estimators:
        lo, hi = alone[(est, "light")], alone[(est, "full")]
        print(f"{est:<10} {lo:>8,.0f} {hi:>8,.0f} {lo / hi:>10.2f}x")
    if ppo:
        print(
            f"\nPPO on a DummyVecEnv of {args.n_envs} single envs, {args.rollouts} rollouts "
            f"of {args.n_steps} steps per env (torch 1 thread): rollout env steps per CPU "
            f"second, and the rollout's CPU share in copying / building the infos"
        )
        print(
            f"{'estimator':<10} {'info':<6} {'steps/CPU-s':>12} {'info copy':>10} "
            f"{'info build':>11}"
        )
        for est in args.estimators:
            for level in LEVELS:
                r = ppo[(est, level)]
                print(
                    f"{est:<10} {level:<6} {r['rate']:>12,.0f} {r['copy']:>10.1%} "
                    f"{r['build']:>11.1%}"
                )
            ratio = ppo[(est, "light")]["rate"] / ppo[(est, "full")]["rate"]
            print(f"{est:<10} light/full rollout speed: {ratio:.2f}x")
    print(f"\nload average {load0:.1f} before, {load1:.1f} after ({os.cpu_count()} cores)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
