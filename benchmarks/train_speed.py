"""Training speed: PPO on the native vector env, env steps per CPU second, split by stage.

Trains stable-baselines3 PPO exactly as ``quadfault train --vector-env`` does
(:func:`agents.train.make_vec_env`: the array-stepped vector env through the SB3 adapter,
``VecMonitor``, ``VecNormalize``; torch on ``--torch-threads`` threads) and reports the CPU
seconds of this process spent in

* **env**: the vector env's ``step`` (physics, estimator, observation, reward, resets) and the
  SB3 adapter around it (``QuadFaultSB3VecEnv.step_wait``);
* **wrappers**: ``VecMonitor`` and ``VecNormalize`` around the env;
* **policy**: the rest of the rollout (the policy's forward pass, SB3's buffer);
* **update**: PPO's gradient epochs (``PPO.train``);

and env steps per CPU second over the whole run (the figure a training budget is made of)
and per stage. CPU seconds are the process's (``time.process_time``), so the numbers hold on
a loaded machine; every report names the load average. The first compile of numba's kernels
is excluded by a short warm-up in the same process (``--warmup`` steps).

    python benchmarks/train_speed.py                        # RotorLoss, IRLS, 64 envs
    python benchmarks/train_speed.py --timesteps 262144 --estimator none
    python benchmarks/train_speed.py --estimator-rate control   # IRLS at the control rate
    python benchmarks/train_speed.py --torch-threads 2           # torch's own default on 2 cores
    python benchmarks/train_speed.py --keep-threads              # numba's switch resets torch
    python benchmarks/train_speed.py --profile 30                # top 30 functions (cProfile)
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time


class _Clock:
    """Accumulated process CPU seconds of the wrapped calls."""

    def __init__(self):
        self.cpu = 0.0

    def wrap(self, fn):
        def timed(*args, **kwargs):
            c = time.process_time()
            try:
                return fn(*args, **kwargs)
            finally:
                self.cpu += time.process_time() - c

        return timed


def build(args):
    """The PPO model on the training env of ``quadfault train --vector-env``, with clocks
    around the env's step, the whole wrapped env's step and PPO's update."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from agents.train import TrainConfig, make_vec_env, set_threads

    env_kwargs = {
        "estimator": args.estimator,
        "estimator_rate": args.estimator_rate,
        "action_mode": "residual",
        "residual_scale": 2.45,
    }
    config = TrainConfig(
        env_id=args.env,
        env_kwargs=env_kwargs,
        n_envs=args.n_envs,
        vector_env=True,
        torch_threads=args.torch_threads,
    )
    if args.keep_threads:  # torch as set, the env's numba switch left to reset it
        import torch

        torch.set_num_threads(args.torch_threads)
    else:
        set_threads(config)
    vec = make_vec_env(config, 0, args.n_envs)
    env = VecNormalize(vec, norm_obs=True, norm_reward=True)
    sb3 = vec.venv  # QuadFaultSB3VecEnv under VecMonitor
    clocks = {"env": _Clock(), "wrapped": _Clock(), "update": _Clock()}
    sb3.step_wait = clocks["env"].wrap(sb3.step_wait)
    env.step_wait = clocks["wrapped"].wrap(env.step_wait)
    model = PPO(
        "MlpPolicy",
        env,
        seed=0,
        device="cpu",
        verbose=0,
        n_steps=args.n_steps,
        batch_size=args.batch_size,
        policy_kwargs={"net_arch": [64, 64]},
    )
    model.train = clocks["update"].wrap(model.train)
    return model, clocks


def _torch_threads() -> int:
    import torch

    return torch.get_num_threads()


def measure(args) -> dict:
    model, clocks = build(args)
    model.learn(args.warmup)  # compile / load numba's cache, first allocations
    for c in clocks.values():
        c.cpu = 0.0
    load0 = os.getloadavg()[0]
    w, c = time.perf_counter(), time.process_time()
    steps0 = model.num_timesteps
    model.learn(args.timesteps, reset_num_timesteps=False)
    wall, cpu = time.perf_counter() - w, time.process_time() - c
    steps = model.num_timesteps - steps0
    env, wrapped, update = (clocks[k].cpu for k in ("env", "wrapped", "update"))
    parts = {
        "env": env,
        "wrappers": wrapped - env,
        "policy": cpu - wrapped - update,
        "update": update,
    }
    return {
        "env_id": args.env,
        "estimator": args.estimator,
        "estimator_rate": args.estimator_rate,
        "n_envs": args.n_envs,
        "n_steps": args.n_steps,
        "torch_threads": args.torch_threads,
        "steps": steps,
        "cpu_s": cpu,
        "wall_s": wall,
        "steps_per_cpu_s": steps / cpu,
        "steps_per_wall_s": steps / wall,
        "cpu_s_by_stage": parts,
        "steps_per_cpu_s_by_stage": {k: steps / v for k, v in parts.items() if v > 0},
        "cpu_min_per_1e6_steps": 1e6 / (steps / cpu) / 60,
        "torch_threads_after": _torch_threads(),
        "load_average": [load0, os.getloadavg()[0]],
        "cpus": os.cpu_count(),
    }


def report(r: dict) -> str:
    lines = [
        f"{r['env_id']}, estimator {r['estimator']} ({r['estimator_rate']} rate), "
        f"{r['n_envs']} envs x {r['n_steps']} steps per rollout, torch threads "
        f"{r['torch_threads']} asked, {r['torch_threads_after']} in use; load average {r['load_average'][0]:.1f} -> "
        f"{r['load_average'][1]:.1f} on {r['cpus']} CPUs",
        f"{r['steps']:,} env steps in {r['cpu_s']:.1f} CPU-s ({r['wall_s']:.1f} s wall): "
        f"{r['steps_per_cpu_s']:,.0f} steps per CPU-s, "
        f"{r['cpu_min_per_1e6_steps']:.1f} CPU-min per 10^6 steps",
        "| stage | CPU-s | share | env steps per CPU-s of the stage |",
        "|---|---|---|---|",
    ]
    for k, v in r["cpu_s_by_stage"].items():
        rate = r["steps_per_cpu_s_by_stage"].get(k, float("nan"))
        lines.append(f"| {k} | {v:.1f} | {v / r['cpu_s']:.0%} | {rate:,.0f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="QuadFaultRotorLoss-v0")
    ap.add_argument("--estimator", default="irls", choices=("irls", "ekf", "truth", "none"))
    ap.add_argument("--estimator-rate", default="physics", choices=("physics", "control"))
    ap.add_argument("--n-envs", type=int, default=64)
    ap.add_argument("--n-steps", type=int, default=256, help="PPO steps per env per rollout")
    ap.add_argument("--batch-size", type=int, default=1024)
    ap.add_argument("--timesteps", type=int, default=131_072)
    ap.add_argument("--warmup", type=int, default=64)
    ap.add_argument("--torch-threads", type=int, default=1)
    ap.add_argument(
        "--keep-threads",
        action="store_true",
        help="set torch's threads only, not numba's first (shows what the "
        "shared OpenMP runtime costs when the env's step resets torch's count)",
    )
    ap.add_argument(
        "--profile",
        type=int,
        default=0,
        metavar="K",
        help="also print the K functions of most own time (cProfile)",
    )
    ap.add_argument("--json", help="write the result as JSON here")
    args = ap.parse_args(argv)
    if args.profile:
        import cProfile
        import pstats

        prof = cProfile.Profile()
        prof.enable()
        result = measure(args)
        prof.disable()
        print(report(result))
        pstats.Stats(prof).sort_stats("tottime").print_stats(args.profile)
    else:
        result = measure(args)
        print(report(result))
    if args.json:
        from quadfault.fileio import atomic_write_text

        atomic_write_text(args.json, json.dumps(result, indent=1), force=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
