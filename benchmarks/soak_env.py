"""Environment soak: many random-action steps over randomised fault scenarios.

    python benchmarks/soak_env.py [--steps 1000000] [--seed 0] [--repeat-steps 2000]

Cycles through every action mode (motor, residual, wrench), estimator (none, irls, ekf, truth)
and observation kind of ``QuadFaultEnv`` on randomised scenarios (random faults, onsets,
severities, trajectories, thrust noise, initial states), with uniformly random actions in
[-1, 1]^4 and a fresh seed per episode from one ``numpy.random.Generator``. Checks on every
step:

* the observation is finite and inside ``observation_space``; the reward is finite;
* an episode that terminates carries a reason from ``TERMINATION_REASONS`` (and one that does
  not terminate carries none); the truth in ``info`` is finite unless the reason is
  ``non_finite``;

and reports the resident memory (RSS) after the warm-up and at the end, and whether two runs
of ``--repeat-steps`` steps with the same seed are bit-for-bit identical (observations,
rewards, flags, reasons). Exit status 1 if any check fails.
"""

from __future__ import annotations

import argparse
import hashlib
import math
import sys
import time

import gymnasium as gym
import numpy as np

import quad_fault_env  # noqa: F401  (registers the ids)
from quad_fault_env.envs.config import TERMINATION_REASONS
from quadfault.progress import progress_bar

ACTION_MODES = ("motor", "residual", "wrench")
#: estimator -> share of episodes (the estimators cost most of the step time)
ESTIMATORS = {"none": 0.55, "irls": 0.2, "ekf": 0.1, "truth": 0.15}
OBSERVATIONS = ("flat", "dict")
#: counters of failed checks
CHECKS = (
    "nonfinite_obs",
    "nonfinite_reward",
    "outside_space",
    "missing_reason",
    "spurious_reason",
    "nonfinite_truth",
)


def rss_mib() -> float:
    """Current resident set size [MiB] (Linux /proc; NaN elsewhere)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return math.nan


class EnvPool:
    """One environment per (action mode, estimator, observation kind), made on first use."""

    def __init__(self, max_episode_steps: int | None, env_kwargs: dict | None = None):
        self.envs = {}
        self.max_episode_steps = max_episode_steps
        self.env_kwargs = env_kwargs or {}

    def get(self, mode, estimator, observation):
        key = (mode, estimator, observation)
        if key not in self.envs:
            self.envs[key] = gym.make(
                "QuadFaultHover-v0" if mode == "motor" else "QuadFault-v0",
                action_mode=mode,
                estimator=estimator,
                observation=observation,
                scenario="random",
                max_episode_steps=self.max_episode_steps,
                info="full",
                **self.env_kwargs,
            )
        return self.envs[key]

    def close(self):
        for env in self.envs.values():
            env.close()


def _flat(obs) -> np.ndarray:
    if isinstance(obs, dict):
        return np.concatenate([np.ravel(obs[k]) for k in sorted(obs)])
    return np.asarray(obs)


def soak(
    steps: int,
    seed: int,
    *,
    max_episode_steps: int | None = 300,
    progress: bool = True,
    digest: bool = False,
    on_warm=None,
    env_kwargs: dict | None = None,
    corner_actions: float = 0.0,
    report_every: int = 0,
) -> dict:
    """Run ``steps`` random-action steps; returns counts (and a SHA-256 of the run if
    ``digest``). ``env_kwargs`` go to every environment (e.g. a lower ``physics_rate`` for a
    quick run); a fraction ``corner_actions`` of the actions are corners of [-1, 1]^4; every
    ``report_every`` steps one checkpoint line is printed (counts so far and RSS)."""
    rng = np.random.default_rng(seed)
    pool = EnvPool(max_episode_steps, env_kwargs)
    est_names, est_p = list(ESTIMATORS), np.array(list(ESTIMATORS.values()))
    h = hashlib.sha256() if digest else None
    stats = {
        "steps": 0,
        "episodes": 0,
        "nonfinite_obs": 0,
        "nonfinite_reward": 0,
        "outside_space": 0,
        "missing_reason": 0,
        "spurious_reason": 0,
        "nonfinite_truth": 0,
        "terminations": {},
        "truncations": 0,
        "combos": set(),
        "interrupted": False,
    }
    bar = progress_bar(total=steps, desc="soak", unit="step", disable=None if progress else True)
    env, done = None, True
    started = time.perf_counter()
    try:
        while stats["steps"] < steps:
            if done:
                combo = (
                    ACTION_MODES[int(rng.integers(len(ACTION_MODES)))],
                    est_names[int(rng.choice(len(est_names), p=est_p))],
                    OBSERVATIONS[int(rng.integers(len(OBSERVATIONS)))],
                )
                stats["combos"].add(combo)
                env = pool.get(*combo)
                env.action_space.seed(int(rng.integers(2**31)))
                obs, info = env.reset(seed=int(rng.integers(2**31)))
                stats["episodes"] += 1
                done = False
            action = rng.uniform(-1.0, 1.0, 4).astype(np.float32)
            if corner_actions and rng.uniform() < corner_actions:
                action = np.sign(action).astype(np.float32)
            obs, reward, terminated, truncated, info = env.step(action)
            stats["steps"] += 1
            flat = _flat(obs)
            if not np.all(np.isfinite(flat)):
                stats["nonfinite_obs"] += 1
            if not env.observation_space.contains(obs):
                stats["outside_space"] += 1
            if not math.isfinite(reward):
                stats["nonfinite_reward"] += 1
            reason = info.get("termination_reason")
            if terminated:
                if reason not in TERMINATION_REASONS:
                    stats["missing_reason"] += 1
                stats["terminations"][reason] = stats["terminations"].get(reason, 0) + 1
            elif reason is not None:
                stats["spurious_reason"] += 1
            if truncated and not terminated:
                stats["truncations"] += 1
            if reason != "non_finite" and not (
                np.all(np.isfinite(info["position_error"])) and np.all(np.isfinite(info["eta_hat"]))
            ):
                stats["nonfinite_truth"] += 1
            if h is not None:
                h.update(flat.tobytes())
                h.update(np.float64(reward).tobytes())
                h.update(bytes([terminated, truncated]))
                h.update(str(reason).encode())
            done = terminated or truncated
            if on_warm is not None and stats["steps"] == min(1000, steps):
                on_warm()
            if stats["steps"] % 100 == 0:
                bar.update(100)
            if report_every and stats["steps"] % report_every == 0:
                bad = sum(stats[k] for k in CHECKS)
                print(
                    f"  checkpoint: {stats['steps']} steps, {stats['episodes']} episodes, "
                    f"{len(stats['combos'])} configurations, {bad} failed checks, "
                    f"RSS {rss_mib():.1f} MiB, {time.perf_counter() - started:.0f} s",
                    flush=True,
                )
    except KeyboardInterrupt:  # Ctrl-C ends the soak early; the summary says so
        stats["interrupted"] = True
    bar.close()
    pool.close()
    stats["combos"] = len(stats["combos"])
    if h is not None:
        stats["sha256"] = h.hexdigest()
    return stats


#: vector soak: (registered id, action mode, estimator) cycled in blocks
VECTOR_CONFIGS = (
    ("QuadFaultHover-v0", "motor", "none"),
    ("QuadFault-v0", "residual", "none"),
    ("QuadFault-v0", "wrench", "truth"),
    ("QuadFaultHover-v0", "residual", "none"),
    ("QuadFault-v0", "motor", "none"),
    ("QuadFaultHover-v0", "wrench", "ekf"),
    ("QuadFault-v0", "residual", "irls"),
)


def vector_soak(
    steps: int,
    seed: int,
    num_envs: int = 64,
    block: int = 100,
    max_episode_steps: int = 300,
    report_every: int = 0,
) -> dict:
    """``steps`` sub-env steps of ``QuadFaultVectorEnv`` (``num_envs`` per array step, next-step
    autoreset), cycling :data:`VECTOR_CONFIGS` every ``block`` array steps with a fresh seed."""
    rng = np.random.default_rng(seed)
    envs = {}
    stats = {
        "steps": 0,
        "episodes": 0,
        "nonfinite_obs": 0,
        "nonfinite_reward": 0,
        "outside_space": 0,
        "missing_reason": 0,
        "spurious_reason": 0,
        "terminations": {},
        "truncations": 0,
        "interrupted": False,
    }
    started, k = time.perf_counter(), 0
    try:
        while stats["steps"] < steps:
            key = VECTOR_CONFIGS[k % len(VECTOR_CONFIGS)]
            k += 1
            if key not in envs:
                envs[key] = gym.make_vec(
                    key[0],
                    num_envs=num_envs,
                    vectorization_mode="vector_entry_point",
                    action_mode=key[1],
                    estimator=key[2],
                    scenario="random",
                    max_episode_steps=max_episode_steps,
                )
            if k == len(VECTOR_CONFIGS) + 1:  # every configuration built and run once
                stats["rss_warm"] = rss_mib()
            env = envs[key]
            space = env.single_observation_space
            env.reset(seed=int(rng.integers(2**31)))
            for _ in range(block):
                action = rng.uniform(-1.0, 1.0, (num_envs, 4)).astype(np.float32)
                obs, reward, terminated, truncated, info = env.step(action)
                stats["steps"] += num_envs
                stats["nonfinite_obs"] += int(np.sum(~np.all(np.isfinite(obs), axis=1)))
                stats["outside_space"] += int(sum(not space.contains(o) for o in obs))
                stats["nonfinite_reward"] += int(np.sum(~np.isfinite(reward)))
                reasons = info.get("termination_reason", np.full(num_envs, None))
                for i in np.flatnonzero(terminated):
                    if reasons[i] not in TERMINATION_REASONS:
                        stats["missing_reason"] += 1
                    stats["terminations"][reasons[i]] = stats["terminations"].get(reasons[i], 0) + 1
                stats["spurious_reason"] += int(
                    sum(r is not None for r in np.asarray(reasons)[~terminated])
                )
                stats["truncations"] += int(np.sum(truncated & ~terminated))
                stats["episodes"] += int(np.sum(terminated | truncated))
                if (
                    report_every
                    and stats["steps"] // report_every
                    != (stats["steps"] - num_envs) // report_every
                ):
                    bad = sum(
                        stats[x]
                        for x in (
                            "nonfinite_obs",
                            "nonfinite_reward",
                            "outside_space",
                            "missing_reason",
                            "spurious_reason",
                        )
                    )
                    print(
                        f"  checkpoint: {stats['steps']} sub-env steps, {stats['episodes']} "
                        f"episode ends, {bad} failed checks, RSS {rss_mib():.1f} MiB, "
                        f"{time.perf_counter() - started:.0f} s",
                        flush=True,
                    )
                if stats["steps"] >= steps:
                    break
    except KeyboardInterrupt:
        stats["interrupted"] = True
    for env in envs.values():
        env.close()
    stats["configurations"] = len(envs)
    return stats


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=1_000_000, help="soak steps (default 10^6)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--repeat-steps",
        type=int,
        default=2000,
        help="steps of each of the two determinism runs (0: skip)",
    )
    p.add_argument(
        "--episode-steps",
        type=int,
        default=300,
        help="truncate episodes after this many steps (more resets, more scenarios)",
    )
    p.add_argument(
        "--vector",
        type=int,
        default=0,
        metavar="N",
        help="soak QuadFaultVectorEnv with N sub-envs instead of single envs",
    )
    p.add_argument(
        "--report-every",
        type=int,
        default=0,
        help="print a checkpoint line every this many steps (0: none)",
    )
    p.add_argument("--quiet", action="store_true")
    args = p.parse_args(argv)
    if args.steps < 1:
        p.error("--steps must be >= 1")
    ok = True
    if args.repeat_steps:
        t0 = time.perf_counter()
        a = soak(
            args.repeat_steps,
            args.seed + 1,
            max_episode_steps=args.episode_steps,
            progress=False,
            digest=True,
            corner_actions=0.1,
        )
        b = soak(
            args.repeat_steps,
            args.seed + 1,
            max_episode_steps=args.episode_steps,
            progress=False,
            digest=True,
            corner_actions=0.1,
        )
        same = a["sha256"] == b["sha256"]
        ok &= same
        print(
            f"determinism: two runs of {args.repeat_steps} steps (seed {args.seed + 1}, "
            f"{a['episodes']} episodes, {a['combos']} configurations): "
            f"{'bit-for-bit identical' if same else 'DIFFERENT'} "
            f"(sha256 {a['sha256'][:16]}..., {time.perf_counter() - t0:.0f} s)"
        )
    if args.vector:
        rss_start = rss_mib()
        t0 = time.perf_counter()
        stats = vector_soak(
            args.steps,
            args.seed,
            args.vector,
            max_episode_steps=args.episode_steps,
            report_every=args.report_every,
        )
        seconds = time.perf_counter() - t0
        bad = {
            k: stats[k]
            for k in (
                "nonfinite_obs",
                "nonfinite_reward",
                "outside_space",
                "missing_reason",
                "spurious_reason",
            )
        }
        ok &= not any(bad.values())
        print(
            f"vector soak: {stats['steps']} sub-env steps ({args.vector} per array step), "
            f"{stats['episodes']} episode ends, {stats['configurations']} configurations in "
            f"{seconds:.0f} s ({stats['steps'] / seconds:.0f} steps/s), seed {args.seed}"
            + (" [stopped early by Ctrl-C]" if stats["interrupted"] else "")
        )
        print("  " + ", ".join(f"{k} {v}" for k, v in bad.items()))
        print(f"  terminations {stats['terminations']}, truncations {stats['truncations']}")
        print(
            f"  RSS at the start {rss_start:.1f} MiB, after the first cycle of configurations "
            f"{stats.get('rss_warm', math.nan):.1f} MiB, at the end {rss_mib():.1f} MiB"
        )
        print("PASS" if ok else "FAIL")
        return 0 if ok else 1
    rss = {}
    t0 = time.perf_counter()
    stats = soak(
        args.steps,
        args.seed,
        max_episode_steps=args.episode_steps,
        progress=not args.quiet,
        on_warm=lambda: rss.setdefault("start", rss_mib()),
        corner_actions=0.1,
        report_every=args.report_every,
    )
    seconds = time.perf_counter() - t0
    rss_end = rss_mib()
    bad = {
        k: stats[k]
        for k in (
            "nonfinite_obs",
            "nonfinite_reward",
            "outside_space",
            "missing_reason",
            "spurious_reason",
            "nonfinite_truth",
        )
    }
    ok &= not any(bad.values())
    print(
        f"soak: {stats['steps']} steps, {stats['episodes']} episodes, {stats['combos']} "
        f"configurations (mode x estimator x observation) in {seconds:.0f} s "
        f"({stats['steps'] / seconds:.0f} steps/s), seed {args.seed}"
        + (" [stopped early by Ctrl-C]" if stats["interrupted"] else "")
    )
    print("  " + ", ".join(f"{k} {v}" for k, v in bad.items()))
    print(f"  terminations {stats['terminations']}, truncations {stats['truncations']}")
    print(f"  RSS after warm-up {rss.get('start', math.nan):.1f} MiB, at the end {rss_end:.1f} MiB")
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
