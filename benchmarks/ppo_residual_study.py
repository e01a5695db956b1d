"""PPO residual policy vs the plain geometric controller, with and without the estimate.

Two training arms on ``QuadFaultHover-v0`` (hover, random motor faults, residual actions
``f = f_geometric + residual_scale * a``):

* ``with_estimate``: the observation carries the IRLS estimate (``--estimator``);
* ``without_estimate``: ``estimator="none"`` (eta_hat slot constant 1, sd constant).

The arms differ only in the estimator: same environment, reward, residual scale, PPO
hyperparameters (:data:`PPO_KWARGS`), timesteps and seeds. Each arm trains ``--seeds`` PPO
runs of ``--timesteps`` steps on ``--n-envs`` quadrotors stepped as arrays
(:class:`quad_fault_env.vector.QuadFaultVectorEnv`, the same episodes as the single env).

Evaluation (paired): every trained model and the baseline (the same environment with a zero
residual, i.e. the geometric controller) fly the *same* ``--episodes`` episodes: the
environment's random scenario of a reset seed (the training distribution: hover, 0-2 faults
of severity 0.3-0.9, optional battery degradation, thrust noise, perturbed initial state;
seeds from 10000 on, skipping those whose scenario has no fault), hence the same scenario,
initial state and noise for every agent. Each agent flies the episodes as the rows of its
own vector env. Score per episode: tracking RMSE [m] of the true position error after each
control step, up to the end; a crashed (terminated) episode scores the crash limit (5 m).
Reported with 95 % confidence intervals (Student t over the seeds of the per-seed mean
paired differences; with one seed, over the episodes instead):

* each arm vs the baseline: ``RMSE_baseline - RMSE_arm`` (> 0: the policy is better);
* ``with`` vs ``without``: ``RMSE_without - RMSE_with`` paired by seed and episode.

For context (not a target) the estimate-aware allocation (:class:`agents.policies.
GeometricPolicy` with ``estimate_aware=True``, IRLS) flies the same episodes through the
same bounded residual: what a policy could gain from the estimate at this residual scale.

The study of issue 5 (>= 3 seeds per arm, each run within 30 min of CPU)::

    python benchmarks/ppo_residual_study.py --timesteps 150000 --seeds 0 1 2 \\
        --episodes 20 --out runs/ppo_study

The arms can train in two processes (``--arms with_estimate --train-only`` and
``--arms without_estimate --train-only``); the run without ``--train-only`` then reuses the
trained models (``--retrain`` trains again) and evaluates. Writes ``OUT/study.json`` and
``OUT/study.md``; per run ``OUT/<arm>/seed_<k>/`` (see ``agents.train``) and
``train_time.json`` (wall and CPU seconds of the run).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

CRASH_RMSE = 5.0  # [m] score of a crashed episode (the environment's out-of-bounds limit)
ENV_ID = "QuadFaultHover-v0"
ARMS = ("with_estimate", "without_estimate")
#: residual authority [N] per unit action: the hover thrust of one rotor (m g / 4 = 2.45 N
#: for the F450), so the residual can carry a motor at eta = 0.5 to f_max from hover
#: (the env's default of 1 N cannot: the estimate-aware allocation needs +2.45 N there)
RESIDUAL_SCALE = 2.45
#: PPO settings of both arms. The residual starts at zero (SB3 initialises the action head
#: with gain 0.01) with exploration noise exp(-2.3) ~ 0.1 per unit action (0.25 N); rollouts
#: of n_envs x n_steps = 32 x 256 steps (2.56 s of flight per quadrotor).
PPO_KWARGS = {"n_steps": 256, "batch_size": 1024, "n_epochs": 10, "learning_rate": 3e-4,
              "gamma": 0.99, "gae_lambda": 0.95, "clip_range": 0.2,
              "policy_kwargs": {"log_std_init": -2.3, "net_arch": [128, 128]}}


def t_interval(x, confidence: float = 0.95):
    """Mean and the half-width of its Student-t confidence interval (nan for n < 2)."""
    from scipy import stats

    x = np.asarray(x, float)
    n = x.size
    if n < 2:
        return float(x.mean()) if n else math.nan, math.nan
    half = stats.t.ppf(0.5 + confidence / 2, n - 1) * x.std(ddof=1) / math.sqrt(n)
    return float(x.mean()), float(half)


def env_kwargs(args, estimator: str) -> dict:
    """Keywords of the study's environment (on top of the registration's) for ``estimator``."""
    return {"action_mode": "residual", "residual_scale": args.residual_scale,
            "estimator_rate": "control", "duration": args.duration, "estimator": estimator}


def episode_seeds(n: int, kwargs: dict, first: int = 10_000) -> list[int]:
    """The first ``n`` reset seeds from ``first`` on whose random scenario has a fault.

    An episode is the environment's own random scenario of its reset seed (the training
    distribution); seeds whose scenario has no motor fault are skipped. The choice depends
    only on the seed, never on an agent.
    """
    import gymnasium as gym

    import quad_fault_env  # noqa: F401

    env = gym.make(ENV_ID, **dict(kwargs, estimator="none"))
    seeds, seed = [], first
    try:
        while len(seeds) < n:
            env.reset(seed=seed)
            if env.unwrapped.scenario.efficiency.faults:
                seeds.append(seed)
            seed += 1
    finally:
        env.close()
    return seeds


def paired_scores(policies, kwargs: dict, seeds: list[int]):
    """RMSE [m] (crash = CRASH_RMSE) and crash flags, arrays (n_policies, n_episodes).

    Policy j flies its own :class:`QuadFaultVectorEnv` whose row i is reset with
    ``seeds[i]``, so every policy meets the same scenarios, initial states and noise. (One
    env per policy: rows that repeat a seed inside one vector env were measured to couple,
    giving results that differ from the single env.)
    """
    import gymnasium as gym

    import quad_fault_env  # noqa: F401
    from quad_fault_env.vector import QuadFaultVectorEnv

    spec = gym.spec(ENV_ID)
    n = len(seeds)
    rmse = np.zeros((len(policies), n))
    crashed = np.zeros((len(policies), n), dtype=bool)
    for j, policy in enumerate(policies):
        venv = QuadFaultVectorEnv(n, **dict(spec.kwargs, **kwargs))
        try:
            obs, _ = venv.reset(seed=[int(s) for s in seeds])
            done = np.zeros(n, dtype=bool)
            sq, steps = np.zeros(n), np.zeros(n)
            while not done.all():
                act = np.asarray(policy.predict(obs, deterministic=True)[0],
                                 dtype=float).reshape(n, -1)
                obs, _, term, trunc, info = venv.step(np.clip(act, -1.0, 1.0))
                live = ~done
                sq[live] += info["tracking_error"][live] ** 2
                steps[live] += 1
                crashed[j, live] |= term[live]
                done |= term | trunc
        finally:
            venv.close()
        rmse[j] = np.where(crashed[j], CRASH_RMSE, np.sqrt(sq / np.maximum(steps, 1)))
    return rmse, crashed


class _Normalised:
    """A model that normalises raw observations with its frozen VecNormalize statistics."""

    def __init__(self, model, venv):
        self.model = model
        self.norm = venv if hasattr(venv, "normalize_obs") and hasattr(venv, "obs_rms") else None

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        o = obs if self.norm is None else self.norm.normalize_obs(obs)
        return self.model.predict(o, state, episode_start, deterministic)


def train_arm(args, arm: str, out: Path) -> None:
    """Train the missing runs of ``arm`` (all of them with ``--retrain``)."""
    from agents.train import TrainConfig, train_one
    from quadfault.fileio import atomic_write_text

    estimator = args.estimator if arm == "with_estimate" else "none"
    for seed in args.seeds:
        run_dir = out / arm / f"seed_{seed}"
        if not args.retrain and (run_dir / "model.zip").exists():
            continue
        cfg = TrainConfig(algo="ppo", env_id=ENV_ID, env_kwargs=env_kwargs(args, estimator),
                          timesteps=args.timesteps, seeds=(seed,), n_envs=args.n_envs,
                          vector_env=True, eval_freq=max(args.timesteps // 2, 1000),
                          eval_episodes=4, algo_kwargs=PPO_KWARGS)
        wall, cpu = time.time(), time.process_time()
        train_one(cfg, seed, run_dir, force=True, quiet=True)
        times = {"wall_seconds": time.time() - wall, "cpu_seconds": time.process_time() - cpu}
        atomic_write_text(run_dir / "train_time.json", json.dumps(times, indent=2), force=True)
        print(f"{arm} seed {seed}: trained {args.timesteps} steps in {times['wall_seconds']:.0f} s"
              f" wall, {times['cpu_seconds']:.0f} s CPU", flush=True)


def evaluate(args, out: Path, seeds_by_arm: dict) -> dict:
    """Paired scores of the baseline, the reference and the trained runs of every arm."""
    from agents.policies import GeometricPolicy
    from agents.train import load_agent
    from quadfault.vehicle import Vehicle

    seeds = episode_seeds(args.episodes, env_kwargs(args, "none"))
    results = {"episode_seeds": seeds}
    for arm, estimator in (("with_estimate", args.estimator), ("without_estimate", "none")):
        kwargs = env_kwargs(args, estimator)
        names, policies = [], []
        if arm == "with_estimate":
            names += ["baseline", "estimate_aware_reference"]
            policies += [GeometricPolicy(Vehicle(), "residual", residual_scale=args.residual_scale),
                         GeometricPolicy(Vehicle(), "residual", estimate_aware=True,
                                         residual_scale=args.residual_scale)]
        for seed in seeds_by_arm[arm]:
            import gymnasium as gym

            env = gym.make(ENV_ID, **kwargs)
            model, venv = load_agent(out / arm / f"seed_{seed}", env)
            names.append(f"{arm}/{seed}")
            policies.append(_Normalised(model, venv))
        rmse, crashed = paired_scores(policies, kwargs, seeds)
        for name, r, c in zip(names, rmse, crashed):
            results[name] = {"rmse": r.tolist(), "crashed": c.tolist()}
        print(f"evaluated {arm}: {len(names)} agents x {len(seeds)} episodes", flush=True)
    return results


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--timesteps", type=int, default=150_000)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--episodes", type=int, default=20, help="paired evaluation episodes")
    p.add_argument("--duration", type=float, default=10.0, help="episode length [s]")
    p.add_argument("--estimator", default="irls", choices=("irls", "ekf", "truth"))
    p.add_argument("--residual-scale", type=float, default=RESIDUAL_SCALE,
                   help="thrust per unit residual action [N] (both arms; default m g / 4)")
    p.add_argument("--n-envs", type=int, default=32, help="quadrotors per training env")
    p.add_argument("--arms", nargs="+", choices=ARMS, default=list(ARMS),
                   help="arms to train (evaluation always needs both)")
    p.add_argument("--train-only", action="store_true", help="train, do not evaluate")
    p.add_argument("--out", default="runs/ppo_study")
    p.add_argument("--retrain", action="store_true")
    p.add_argument("--available", action="store_true",
                   help="train nothing; evaluate the runs that exist (at least one per arm) "
                   "and list the missing ones")
    args = p.parse_args(argv)

    from quadfault.fileio import atomic_write_text

    out = Path(args.out)
    t0 = time.time()
    for arm in () if args.available else args.arms:
        train_arm(args, arm, out)
    if args.train_only:
        return 0
    done = {a: [s for s in args.seeds if (out / a / f"seed_{s}" / "model.zip").exists()]
            for a in ARMS}
    missing = [f"{a}/seed_{s}" for a in ARMS for s in args.seeds if s not in done[a]]
    if missing and not (args.available and all(done.values())):
        raise SystemExit(f"{out}: runs missing for the evaluation: {', '.join(missing)} "
                         "(train them with --arms, or evaluate what exists with --available)")
    results = evaluate(args, out, done)
    summary = _summary(results, done)
    train_times = {}
    for a in ARMS:
        for s in args.seeds:
            path = out / a / f"seed_{s}" / "train_time.json"
            if path.exists():
                train_times[f"{a}/seed_{s}"] = json.loads(path.read_text())
    meta = {"timesteps": args.timesteps, "seeds": args.seeds, "episodes": args.episodes,
            "duration": args.duration, "estimator": args.estimator, "env_id": ENV_ID,
            "residual_scale": args.residual_scale, "n_envs": args.n_envs,
            "ppo_kwargs": PPO_KWARGS, "train_times": train_times,
            "evaluated_seeds": done, "missing_runs": missing,
            "evaluation_seconds": time.time() - t0}
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "study.json", json.dumps({"meta": meta, "summary": summary,
                                                      "episodes": results}, indent=2),
                      force=True)
    md = _markdown(summary, meta)
    atomic_write_text(out / "study.md", md, force=True)
    print(md)
    return 0


def _paired(a_minus_b_by_seed: list[np.ndarray]):
    if len(a_minus_b_by_seed) >= 2:
        return t_interval([d.mean() for d in a_minus_b_by_seed]) + ("seeds",)
    return t_interval(a_minus_b_by_seed[0]) + ("episodes",)


def _summary(results, seeds_by_arm: dict) -> dict:
    base = np.array(results["baseline"]["rmse"])
    out = {}
    for name in ("baseline", "estimate_aware_reference"):
        r = np.array(results[name]["rmse"])
        mean, half = t_interval(base - r)
        out[name] = {"rmse_mean": float(r.mean()),
                     "crash_rate": float(np.mean(results[name]["crashed"])),
                     "improvement_vs_baseline": mean, "ci95": half, "ci_over": "episodes"}
    for arm in ARMS:
        seeds = seeds_by_arm[arm]
        rm = [np.array(results[f"{arm}/{s}"]["rmse"]) for s in seeds]
        cr = [np.mean(results[f"{arm}/{s}"]["crashed"]) for s in seeds]
        mean, half, over = _paired([base - r for r in rm])
        out[arm] = {"rmse_mean": float(np.mean([r.mean() for r in rm])),
                    "crash_rate": float(np.mean(cr)),
                    "per_seed_improvement": [float((base - r).mean()) for r in rm],
                    "improvement_vs_baseline": mean, "ci95": half, "ci_over": over}
    common = [s for s in seeds_by_arm["with_estimate"] if s in seeds_by_arm["without_estimate"]]
    mean, half, over = _paired([np.array(results[f"without_estimate/{s}"]["rmse"])
                                - np.array(results[f"with_estimate/{s}"]["rmse"])
                                for s in common])
    out["with_minus_without"] = {"improvement": mean, "ci95": half, "ci_over": over,
                                 "seeds": common}
    return out


def _markdown(s, meta) -> str:
    def ci(m, h):
        return f"{m:+.4f} ± {h:.4f}" if math.isfinite(h) else f"{m:+.4f} (no CI)"

    lines = [f"# PPO residual study ({meta['env_id']}, {meta['timesteps']} steps/run, seeds "
             f"{meta['evaluated_seeds']}, {meta['episodes']} paired episodes of "
             f"{meta['duration']} s, residual scale {meta['residual_scale']} N)", "",
             *([f"Missing runs (not trained yet): {', '.join(meta['missing_runs'])}", ""]
               if meta["missing_runs"] else []),
             "| agent | mean RMSE [m] (crash = 5 m) | crash rate | RMSE gain vs baseline "
             "[m], 95% CI |", "|---|---|---|---|",
             f"| geometric (zero residual) | {s['baseline']['rmse_mean']:.4f} | "
             f"{s['baseline']['crash_rate']:.2f} | - |"]
    for arm in ARMS:
        a = s[arm]
        lines.append(f"| PPO {arm.replace('_', ' ')} | {a['rmse_mean']:.4f} | "
                     f"{a['crash_rate']:.2f} | {ci(a['improvement_vs_baseline'], a['ci95'])} "
                     f"(over {a['ci_over']}) |")
    r = s["estimate_aware_reference"]
    lines.append(f"| (reference) estimate-aware allocation, same residual bound | "
                 f"{r['rmse_mean']:.4f} | {r['crash_rate']:.2f} | "
                 f"{ci(r['improvement_vs_baseline'], r['ci95'])} (over episodes) |")
    w = s["with_minus_without"]
    lines += ["", f"With vs without the estimate (RMSE_without - RMSE_with, paired, seeds "
              f"{w['seeds']}): {ci(w['improvement'], w['ci95'])} m (over {w['ci_over']}).", "",
              "Per-seed gains vs baseline [m]: " + "; ".join(
                  f"{arm}: " + ", ".join(f"{g:+.4f}" for g in s[arm]["per_seed_improvement"])
                  for arm in ARMS), "", "Training time per run (wall / CPU s): " + ", ".join(
                  f"{k} {v['wall_seconds']:.0f}/{v['cpu_seconds']:.0f}"
                  for k, v in meta["train_times"].items()), ""]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
