"""PPO residual policy vs the plain geometric controller, with and without the estimate.

Two training arms on ``QuadFaultHover-v0`` (hover, random motor faults, residual actions):

* ``with_estimate``: the observation carries the IRLS estimate (``--estimator``);
* ``without_estimate``: ``estimator="none"`` (eta_hat slot constant 1, sd constant).

Each arm trains ``--seeds`` PPO runs of ``--timesteps`` steps. Every trained model and the
baseline (the same environment with a zero residual, i.e. the geometric controller) then fly
the *same* ``--episodes`` random fault scenarios with the same reset seeds, so the comparisons
are paired. Score per episode: tracking RMSE [m], a crashed episode counting as the crash
limit (5 m). Reported with 95 % confidence intervals (Student t over the seeds of the
per-seed mean paired differences; with one seed, over the episodes instead):

* each arm vs the baseline: ``RMSE_baseline - RMSE_arm`` (> 0: the policy is better);
* ``with`` vs ``without``: ``RMSE_without - RMSE_with`` paired by seed and episode.

The full study (issue 5: >= 3 seeds per arm, ~30 min per run) is e.g.::

    python benchmarks/ppo_residual_study.py --timesteps 150000 --seeds 0 1 2 --episodes 20 \\
        --out runs/ppo_study

A small run finishes in minutes (``--timesteps 3000 --seeds 0 1 --episodes 4``). Writes
``OUT/study.json`` and ``OUT/study.md``; trained runs are reused when present (``--retrain``).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

CRASH_RMSE = 5.0  # [m] score of a crashed episode (the environment's out-of-bounds limit)


def t_interval(x, confidence: float = 0.95):
    """Mean and the half-width of its Student-t confidence interval (nan for n < 2)."""
    from scipy import stats

    x = np.asarray(x, float)
    n = x.size
    if n < 2:
        return float(x.mean()) if n else math.nan, math.nan
    half = stats.t.ppf(0.5 + confidence / 2, n - 1) * x.std(ddof=1) / math.sqrt(n)
    return float(x.mean()), float(half)


def scenarios(n: int, duration: float):
    from quadfault.scenarios import random_scenario

    return [random_scenario(np.random.default_rng([2024, i]), duration, n_faults=(1, 2),
                            trajectory="hover").replace(name=f"random_hover_{i}")
            for i in range(n)]


def episode_scores(policy, env_id, env_kwargs, scs, normalizer_path=None):
    """Tracking RMSE (crash = CRASH_RMSE) and crash flags of ``policy`` over ``scs``."""
    from agents.env_rollout import fly_env, make_scenario_env

    rmse, crashed = [], []
    for i, sc in enumerate(scs):
        env = make_scenario_env(env_id, env_kwargs, sc)
        try:
            pol, norm = policy(env) if callable(policy) else (policy, None)
            f = fly_env(pol, env, sc, seed=10_000 + i, label="", estimator="")
        finally:
            env.close()
        crashed.append(bool(f.metrics.crashed))
        rmse.append(CRASH_RMSE if f.metrics.crashed else f.metrics.rmse)
    return np.array(rmse), np.array(crashed)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--timesteps", type=int, default=150_000)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--duration", type=float, default=10.0, help="episode length [s]")
    p.add_argument("--estimator", default="irls", choices=("irls", "ekf", "truth"))
    p.add_argument("--n-envs", type=int, default=2)
    p.add_argument("--out", default="runs/ppo_study")
    p.add_argument("--retrain", action="store_true")
    args = p.parse_args(argv)

    from agents.policies import GeometricPolicy
    from agents.train import TrainConfig, load_agent, train_one
    from quadfault.fileio import atomic_write_text

    out = Path(args.out)
    base_kwargs = {"action_mode": "residual", "estimator_rate": "control",
                   "duration": args.duration}
    arms = {"with_estimate": dict(base_kwargs, estimator=args.estimator),
            "without_estimate": dict(base_kwargs, estimator="none")}
    env_id = "QuadFaultHover-v0"
    scs = scenarios(args.episodes, args.duration)
    t0 = time.time()
    base, base_crash = episode_scores(lambda env: (GeometricPolicy.from_env(env), None), env_id,
                                      dict(base_kwargs, estimator="none"), scs)
    results = {"baseline": {"rmse": base.tolist(), "crashed": base_crash.tolist()}}
    train_seconds = {}
    for arm, kwargs in arms.items():
        results[arm] = {}
        for seed in args.seeds:
            run_dir = out / arm / f"seed_{seed}"
            if args.retrain or not (run_dir / "model.zip").exists():
                cfg = TrainConfig(algo="ppo", env_id=env_id, env_kwargs=kwargs,
                                  timesteps=args.timesteps, seeds=(seed,), n_envs=args.n_envs,
                                  eval_freq=max(args.timesteps // 5, 1000), eval_episodes=2,
                                  algo_kwargs={"n_steps": 512, "batch_size": 128,
                                               "learning_rate": 1e-4,
                                               "policy_kwargs": {"log_std_init": -1.5}})
                ts = time.time()
                train_one(cfg, seed, run_dir, force=True, quiet=True)
                train_seconds[f"{arm}/seed_{seed}"] = time.time() - ts

            def loaded(env, run_dir=run_dir):
                model, venv = load_agent(run_dir, env)
                return _Normalised(model, venv), None

            rmse, crash = episode_scores(loaded, env_id, kwargs, scs)
            results[arm][str(seed)] = {"rmse": rmse.tolist(), "crashed": crash.tolist()}
    summary = _summary(results, args.seeds)
    meta = {"timesteps": args.timesteps, "seeds": args.seeds, "episodes": args.episodes,
            "duration": args.duration, "estimator": args.estimator, "env_id": env_id,
            "train_seconds": train_seconds, "total_seconds": time.time() - t0}
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "study.json", json.dumps({"meta": meta, "summary": summary,
                                                      "episodes": results}, indent=2),
                      force=True)
    md = _markdown(summary, meta)
    atomic_write_text(out / "study.md", md, force=True)
    print(md)
    return 0


class _Normalised:
    """A model that normalises raw observations with its frozen VecNormalize statistics."""

    def __init__(self, model, venv):
        self.model = model
        self.norm = venv if hasattr(venv, "normalize_obs") and hasattr(venv, "obs_rms") else None

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        o = obs if self.norm is None else self.norm.normalize_obs(obs)
        return self.model.predict(o, state, episode_start, deterministic)


def _paired(a_minus_b_by_seed: list[np.ndarray]):
    if len(a_minus_b_by_seed) >= 2:
        return t_interval([d.mean() for d in a_minus_b_by_seed]) + ("seeds",)
    return t_interval(a_minus_b_by_seed[0]) + ("episodes",)


def _summary(results, seeds) -> dict:
    base = np.array(results["baseline"]["rmse"])
    out = {"baseline": {"rmse_mean": float(base.mean()),
                        "crash_rate": float(np.mean(results["baseline"]["crashed"]))}}
    for arm in ("with_estimate", "without_estimate"):
        rm = [np.array(results[arm][str(s)]["rmse"]) for s in seeds]
        cr = [np.mean(results[arm][str(s)]["crashed"]) for s in seeds]
        mean, half, over = _paired([base - r for r in rm])
        out[arm] = {"rmse_mean": float(np.mean([r.mean() for r in rm])),
                    "crash_rate": float(np.mean(cr)),
                    "improvement_vs_baseline": mean, "ci95": half, "ci_over": over}
    mean, half, over = _paired([np.array(results["without_estimate"][str(s)]["rmse"])
                                - np.array(results["with_estimate"][str(s)]["rmse"])
                                for s in seeds])
    out["with_minus_without"] = {"improvement": mean, "ci95": half, "ci_over": over}
    return out


def _markdown(s, meta) -> str:
    def ci(m, h):
        return f"{m:+.4f} ± {h:.4f}" if math.isfinite(h) else f"{m:+.4f} (no CI)"

    lines = [f"# PPO residual study ({meta['env_id']}, {meta['timesteps']} steps/run, seeds "
             f"{meta['seeds']}, {meta['episodes']} paired episodes of {meta['duration']} s)", "",
             "| agent | mean RMSE [m] (crash = 5 m) | crash rate | RMSE gain vs baseline "
             "[m], 95% CI |", "|---|---|---|---|",
             f"| geometric (zero residual) | {s['baseline']['rmse_mean']:.4f} | "
             f"{s['baseline']['crash_rate']:.2f} | - |"]
    for arm in ("with_estimate", "without_estimate"):
        a = s[arm]
        lines.append(f"| PPO {arm.replace('_', ' ')} | {a['rmse_mean']:.4f} | "
                     f"{a['crash_rate']:.2f} | {ci(a['improvement_vs_baseline'], a['ci95'])} "
                     f"(over {a['ci_over']}) |")
    w = s["with_minus_without"]
    lines += ["", f"With vs without the estimate (RMSE_without - RMSE_with, paired): "
              f"{ci(w['improvement'], w['ci95'])} m (over {w['ci_over']}).", ""]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
