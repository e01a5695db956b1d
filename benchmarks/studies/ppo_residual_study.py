"""PPO residual policy vs the plain geometric controller, with and without the estimate.

Two training arms on ``QuadFaultHover-v0`` (hover, random motor faults, residual actions
``f = f_geometric + residual_scale * a``):

* ``with_estimate``: the observation carries the IRLS estimate (``--estimator``, run at the
  control rate);
* ``without_estimate``: ``estimator="none"`` (eta_hat slot constant 1, sd constant).

The arms differ only in the estimator: same environment and fault distribution
(``--random-faults``, default :data:`RANDOM_FAULTS`: one motor at efficiency 0.5-0.85),
reward (the ``-v0`` reward of ``QuadFaultHover-v0``), residual scale, VecNormalize, PPO
hyperparameters (:data:`PPO_KWARGS`), timesteps and seeds. Each arm trains ``--seeds`` PPO
runs of ``--timesteps`` steps on ``--n-envs`` quadrotors stepped as arrays
(:class:`quad_fault_env.vector.QuadFaultVectorEnv`, the same episodes as the single env).
``--timesteps`` is rounded *up* to whole rollouts of ``n_envs x n_steps`` (10^6 -> 1,007,616
with the defaults), the steps the documented runs trained.

Evaluation (paired): every trained model and the baseline (the same environment with a zero
residual, i.e. the geometric controller) fly the *same* ``--episodes`` episodes: the
environment's random scenario of a reset seed (the training distribution; seeds from 10000
on, skipping any whose scenario has no fault), hence the same scenario, initial state and
noise for every agent. Each agent flies the episodes as the rows of its own vector env.
Scores per episode: the tracking RMSE [m] of the true position error after each control
step over the flown part (primary; crashes are counted separately as the crash rate) and,
as a secondary column, the same score with a crash counted as 5 m. Reported with 95 %
confidence intervals (Student t over the seeds of the per-seed mean paired differences;
with one seed, over the episodes instead):

* each arm vs the baseline: ``RMSE_baseline - RMSE_arm`` (> 0: the policy is better);
* ``with`` vs ``without``: ``RMSE_without - RMSE_with`` paired by seed and episode.

The estimate-aware allocation (:class:`agents.policies.GeometricPolicy` with
``estimate_aware=True``, IRLS) flies the same episodes through the same bounded residual:
the headroom, what a policy could gain from the estimate at this residual scale.
``--check-distribution`` flies only the baseline and this reference (no training): the
first check of a fault distribution (the baseline must not crash, the reference must gain).

The documented study (>= 3 seeds per arm, each run within 30 min of CPU; docs/agents.md,
"PPO residual studies")::

    python benchmarks/studies/ppo_residual_study.py --check-distribution --episodes 40 --out runs/ppo_s3
    python benchmarks/studies/ppo_residual_study.py --timesteps 1000000 --seeds 0 1 2 \\
        --episodes 40 --out runs/ppo_s4m

Variants (both arms alike) and options: ``--help``. Runs can train in separate processes
(``--arms <arm> --seeds <k> --train-only``); a run without ``--train-only`` reuses the trained
models and evaluates. Writes ``OUT/study.json`` and ``OUT/study.md``; per run
``OUT/<arm>/seed_<k>/`` (see ``agents.train``) and ``train_time.json`` (wall and CPU seconds).
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
#: the study's fault distribution (``random_faults`` of the environment, both arms): one
#: motor, efficiency 0.5-0.85 -- faults the geometric controller survives but tracks worse
#: and the estimate-aware allocation counters (checked with ``--check-distribution``)
RANDOM_FAULTS = {"n_faults": [1, 1], "severity": [0.5, 0.85]}
#: PPO settings of both arms. The residual starts at zero (SB3 initialises the action head
#: with gain 0.01) with exploration noise exp(-2.3) ~ 0.1 per unit action (0.25 N); rollouts
#: of n_envs x n_steps = 32 x 256 steps (2.56 s of flight per quadrotor).
PPO_KWARGS = {
    "n_steps": 256,
    "batch_size": 1024,
    "n_epochs": 10,
    "learning_rate": 3e-4,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "policy_kwargs": {"log_std_init": -2.3, "net_arch": [128, 128]},
}


def ppo_kwargs(args) -> dict:
    """:data:`PPO_KWARGS` updated with ``--ppo-kwargs`` (``policy_kwargs`` merged key by key)."""
    extra = dict(getattr(args, "ppo_kwargs", None) or {})
    policy_extra = extra.pop("policy_kwargs", {})
    if not isinstance(policy_extra, dict):
        raise SystemExit(f"--ppo-kwargs: policy_kwargs must be a JSON object, got {policy_extra!r}")
    policy = dict(PPO_KWARGS["policy_kwargs"], **policy_extra)
    return dict(PPO_KWARGS, **extra, policy_kwargs=policy)


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
    kwargs = {
        "action_mode": "residual",
        "residual_scale": args.residual_scale,
        "estimator_rate": "control",
        "duration": args.duration,
        "estimator": estimator,
        "random_trajectory": getattr(args, "trajectory", "hover"),
    }
    if getattr(args, "compensate", False):
        kwargs["compensate"] = True
    if args.random_faults is not None:
        kwargs["random_faults"] = args.random_faults
    return kwargs


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
    """RMSE [m] of the flown part (up to the end or a crash) and crash flags, arrays
    (n_policies, n_episodes).

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
        venv = QuadFaultVectorEnv(n, info="full", **dict(spec.kwargs, **kwargs))
        try:
            obs, _ = venv.reset(seed=[int(s) for s in seeds])
            done = np.zeros(n, dtype=bool)
            sq, steps = np.zeros(n), np.zeros(n)
            while not done.all():
                act = np.asarray(policy.predict(obs, deterministic=True)[0], dtype=float).reshape(
                    n, -1
                )
                obs, _, term, trunc, info = venv.step(np.clip(act, -1.0, 1.0))
                live = ~done
                sq[live] += info["tracking_error"][live] ** 2
                steps[live] += 1
                crashed[j, live] |= term[live]
                done |= term | trunc
        finally:
            venv.close()
        rmse[j] = np.sqrt(sq / np.maximum(steps, 1))
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
    rollout = args.n_envs * ppo_kwargs(args)["n_steps"]
    steps = math.ceil(args.timesteps / rollout) * rollout
    for seed in args.seeds:
        run_dir = out / arm / f"seed_{seed}"
        if not args.retrain and (run_dir / "model.zip").exists():
            continue
        cfg = TrainConfig(
            algo="ppo",
            env_id=ENV_ID,
            env_kwargs=env_kwargs(args, estimator),
            timesteps=steps,
            seeds=(seed,),
            n_envs=args.n_envs,
            vector_env=True,
            eval_freq=max(args.timesteps // 2, 1000),
            eval_episodes=4,
            algo_kwargs=ppo_kwargs(args),
            numba_threads=args.numba_threads,
        )
        wall, cpu = time.time(), time.process_time()
        train_one(cfg, seed, run_dir, force=True, quiet=True)
        times = {
            "wall_seconds": time.time() - wall,
            "cpu_seconds": time.process_time() - cpu,
            "timesteps": steps,
        }
        atomic_write_text(run_dir / "train_time.json", json.dumps(times, indent=2), force=True)
        print(
            f"{arm} seed {seed}: trained {steps} steps in {times['wall_seconds']:.0f} s"
            f" wall, {times['cpu_seconds']:.0f} s CPU",
            flush=True,
        )


def model_path(out: Path, arm: str, seed: int, snapshot: str) -> Path:
    """The model evaluated: the run's final ``model.zip`` or (``snapshot="mid"``) the one the
    mid-training evaluation saved (``best/best_model.zip``, written at the first
    evaluation, after ``timesteps // 2`` steps; later only when an evaluation improves)."""
    run = out / arm / f"seed_{seed}"
    return run / "model.zip" if snapshot == "final" else run / "best" / "best_model.zip"


def evaluate(args, out: Path, seeds_by_arm: dict) -> dict:
    """Paired flown RMSE and crash flags of the baseline, the reference and the trained runs.

    Each agent's episodes are kept in ``OUT/eval/<agent>.json`` together with what they
    depend on (episode seeds, environment keywords, model file and its modification time);
    a later evaluation reuses a file only when all of that matches (flights are deterministic
    under the seeds), so agents can be evaluated as their runs finish.
    """
    import gymnasium as gym

    from agents.policies import GeometricPolicy
    from agents.train import load_agent
    from quadfault.fileio import atomic_write_text
    from quadfault.model.vehicle import Vehicle

    seeds = episode_seeds(args.episodes, env_kwargs(args, "none"))
    results = {"episode_seeds": seeds}
    for arm, estimator in (("with_estimate", args.estimator), ("without_estimate", "none")):
        kwargs = env_kwargs(args, estimator)
        agents = []  # (name, model file or None, make policy, environment keywords)
        if arm == "with_estimate":
            # the baseline and the reference always fly the plain geometric controller's
            # environment; with --compensate the zero residual of the arm's own environment
            # (the geometric commands divided by eta_hat) is one more row
            plain = {k: v for k, v in kwargs.items() if k != "compensate"}
            rows = [("baseline", False, plain), ("estimate_aware_reference", True, plain)]
            if "compensate" in kwargs:
                rows.append(("compensated_zero_residual", False, kwargs))
            for name, aware, kw in rows:
                agents.append(
                    (
                        name,
                        None,
                        lambda aware=aware: GeometricPolicy(
                            Vehicle(),
                            "residual",
                            estimate_aware=aware,
                            residual_scale=args.residual_scale,
                        ),
                        kw,
                    )
                )
        for seed in seeds_by_arm.get(arm, ()):
            path = model_path(out, arm, seed, args.snapshot)
            agents.append(
                (
                    f"{arm}/{seed}",
                    path,
                    lambda path=path, kw=kwargs: _Normalised(
                        *load_agent(path, gym.make(ENV_ID, **kw))
                    ),
                    kwargs,
                )
            )
        for name, path, make, kw in agents:
            key = {
                "episode_seeds": seeds,
                "env_kwargs": kw,
                "model": None if path is None else [str(path), path.stat().st_mtime],
            }
            cache = out / "eval" / f"{name.replace('/', '_seed_')}.json"
            if cache.exists() and json.loads(cache.read_text())["key"] == key:
                results[name] = json.loads(cache.read_text())["episodes"]
                continue
            rmse, crashed = paired_scores([make()], kw, seeds)
            results[name] = {"rmse": rmse[0].tolist(), "crashed": crashed[0].tolist()}
            cache.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(
                cache, json.dumps({"key": key, "episodes": results[name]}), force=True
            )
            print(f"evaluated {name}: {len(seeds)} episodes", flush=True)
    return results


def _json_object(text: str) -> dict:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise argparse.ArgumentTypeError(f"not JSON: {exc}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError("must be a JSON object")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}")
    return value


def _random_faults(text: str):
    return None if text == "default" else _json_object(text)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--timesteps", type=int, default=1_000_000)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--episodes", type=int, default=40, help="paired evaluation episodes")
    p.add_argument("--duration", type=float, default=10.0, help="episode length [s]")
    p.add_argument(
        "--trajectory",
        default="hover",
        choices=("hover", "circle", "lissajous", "random"),
        help="reference of the random scenarios (both arms; default hover)",
    )
    p.add_argument(
        "--compensate",
        action="store_true",
        help="both arms: the residual is added to the geometric commands divided by "
        "eta_hat (the environment's compensate=True; a no-op without the estimate)",
    )
    p.add_argument("--estimator", default="irls", choices=("irls", "ekf", "truth"))
    p.add_argument(
        "--residual-scale",
        type=float,
        default=RESIDUAL_SCALE,
        help="thrust per unit residual action [N] (both arms; default m g / 4)",
    )
    p.add_argument("--n-envs", type=int, default=32, help="quadrotors per training env")
    p.add_argument(
        "--random-faults",
        type=_random_faults,
        default=RANDOM_FAULTS,
        help="fault distribution: JSON random_faults keywords of the environment, "
        "or 'default' for the environment's own (0-2 faults, severity 0.3-0.9); "
        f"default {json.dumps(RANDOM_FAULTS)}",
    )
    p.add_argument(
        "--ppo-kwargs",
        type=_json_object,
        default=None,
        help="JSON overriding PPO_KWARGS in both arms (policy_kwargs merged), "
        "e.g. '{\"use_sde\": true}'",
    )
    p.add_argument(
        "--numba-threads",
        type=_positive_int,
        default=1,
        help="threads of numba's parallel kernels per training run (default 1: "
        "see agents.train.TrainConfig.numba_threads)",
    )
    p.add_argument(
        "--arms",
        nargs="+",
        choices=ARMS,
        default=list(ARMS),
        help="arms to train (evaluation always needs both)",
    )
    p.add_argument("--train-only", action="store_true", help="train, do not evaluate")
    p.add_argument("--out", default="runs/ppo_study")
    p.add_argument("--retrain", action="store_true")
    p.add_argument(
        "--available",
        action="store_true",
        help="train nothing; evaluate the runs that exist (at least one per arm) "
        "and list the missing ones",
    )
    p.add_argument(
        "--snapshot",
        choices=("final", "mid"),
        default="final",
        help="evaluate each run's final model or its mid-training snapshot "
        "(best/best_model.zip: for runs stopped after their first evaluation)",
    )
    p.add_argument(
        "--check-distribution",
        action="store_true",
        help="train nothing; fly only the baseline and the estimate-aware reference "
        "(does the fault distribution leave headroom without crashing the baseline?)",
    )
    args = p.parse_args(argv)

    from agents.train import set_numba_threads
    from quadfault.fileio import atomic_write_text

    set_numba_threads(args.numba_threads)  # evaluation too: see TrainConfig.numba_threads
    out = Path(args.out)
    t0 = time.time()
    if args.check_distribution:
        done, missing = {a: [] for a in ARMS}, []
    else:
        for arm in () if args.available else args.arms:
            train_arm(args, arm, out)
        if args.train_only:
            return 0
        done = {
            a: [s for s in args.seeds if model_path(out, a, s, args.snapshot).exists()]
            for a in ARMS
        }
        missing = [f"{a}/seed_{s}" for a in ARMS for s in args.seeds if s not in done[a]]
        if missing and not (args.available and all(done.values())):
            raise SystemExit(
                f"{out}: runs missing for the evaluation: {', '.join(missing)} "
                "(train them with --arms, or evaluate what exists with --available)"
            )
    results = evaluate(args, out, done)
    summary = _summary(results, done)
    train_times = {}
    for a in ARMS:
        for s in done[a]:
            # a run stopped at its snapshot has snapshot_time.json (CPU and wall seconds
            # of the process when it was stopped) instead of train_time.json
            names = (
                ("snapshot_time.json", "train_time.json")
                if args.snapshot == "mid"
                else ("train_time.json",)
            )
            for path in (out / a / f"seed_{s}" / n for n in names):
                if path.exists():
                    train_times[f"{a}/seed_{s}"] = dict(
                        json.loads(path.read_text()), file=path.name
                    )
                    break
    meta = {
        "timesteps": args.timesteps,
        "seeds": args.seeds,
        "episodes": args.episodes,
        "duration": args.duration,
        "estimator": args.estimator,
        "env_id": ENV_ID,
        "residual_scale": args.residual_scale,
        "random_faults": args.random_faults,
        "trajectory": args.trajectory,
        "compensate": args.compensate,
        "n_envs": args.n_envs,
        "ppo_kwargs": ppo_kwargs(args),
        "train_times": train_times,
        "snapshot": args.snapshot,
        "evaluated_seeds": done,
        "missing_runs": missing,
        "evaluation_seconds": time.time() - t0,
    }
    name = "distribution" if args.check_distribution else "study"
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(
        out / f"{name}.json",
        json.dumps({"meta": meta, "summary": summary, "episodes": results}, indent=2),
        force=True,
    )
    md = _markdown(summary, meta)
    atomic_write_text(out / f"{name}.md", md, force=True)
    print(md)
    return 0


def _paired(a_minus_b_by_seed: list[np.ndarray]):
    """Mean paired difference, CI half-width and what the CI is over (seeds or episodes)."""
    if len(a_minus_b_by_seed) >= 2:
        return t_interval([d.mean() for d in a_minus_b_by_seed]) + ("seeds",)
    return t_interval(a_minus_b_by_seed[0]) + ("episodes",)


#: the scores of an episode [m]: ``rmse`` the flown part's RMSE (primary; crashes are
#: reported separately as the crash rate), ``rmse_crash5`` the same with a crashed episode
#: scored CRASH_RMSE
SCORES = ("rmse", "rmse_crash5")


def _scores(entry: dict) -> dict:
    r, c = np.array(entry["rmse"]), np.array(entry["crashed"], dtype=bool)
    return {"rmse": r, "rmse_crash5": np.where(c, CRASH_RMSE, r)}


def _summary(results, seeds_by_arm: dict) -> dict:
    base = _scores(results["baseline"])
    out = {}
    for name in ("baseline", "estimate_aware_reference", "compensated_zero_residual"):
        if name not in results:
            continue
        sc = _scores(results[name])
        out[name] = {"crash_rate": float(np.mean(results[name]["crashed"])), "ci_over": "episodes"}
        for k in SCORES:
            mean, half = t_interval(base[k] - sc[k])
            out[name][k] = {"mean": float(sc[k].mean()), "gain": mean, "ci95": half}
    for arm in ARMS:
        runs = [_scores(results[f"{arm}/{s}"]) for s in seeds_by_arm[arm]]
        if not runs:
            continue
        out[arm] = {
            "crash_rate": float(
                np.mean([results[f"{arm}/{s}"]["crashed"] for s in seeds_by_arm[arm]])
            )
        }
        for k in SCORES:
            mean, half, over = _paired([base[k] - r[k] for r in runs])
            out[arm][k] = {
                "mean": float(np.mean([r[k].mean() for r in runs])),
                "gain": mean,
                "ci95": half,
                "per_seed_gain": [float((base[k] - r[k]).mean()) for r in runs],
            }
            out[arm]["ci_over"] = over
    common = [s for s in seeds_by_arm["with_estimate"] if s in seeds_by_arm["without_estimate"]]
    if common:
        out["with_minus_without"] = {"seeds": common}
        for k in SCORES:
            mean, half, over = _paired(
                [
                    _scores(results[f"without_estimate/{s}"])[k]
                    - _scores(results[f"with_estimate/{s}"])[k]
                    for s in common
                ]
            )
            out["with_minus_without"][k] = {"gain": mean, "ci95": half, "ci_over": over}
    return out


def _markdown(s, meta) -> str:
    def ci(d):
        m, h = d["gain"], d["ci95"]
        return f"{m:+.4f} ± {h:.4f}" if math.isfinite(h) else f"{m:+.4f} (no CI)"

    def row(label, a):
        gains = (
            ("-", "-")
            if label.startswith("geometric")
            else (f"{ci(a['rmse'])} (over {a['ci_over']})", ci(a["rmse_crash5"]))
        )
        return (
            f"| {label} | {a['rmse']['mean']:.4f} | {a['crash_rate']:.3f} | {gains[0]} | "
            f"{a['rmse_crash5']['mean']:.4f} | {gains[1]} |"
        )

    lines = [
        (
            f"# PPO residual study ({meta['env_id']}, random_faults "
            f"{json.dumps(meta['random_faults'])}, {meta['timesteps']}-step runs"
            f"{' (their mid-training snapshots)' if meta.get('snapshot') == 'mid' else ''}, seeds "
            f"{meta['evaluated_seeds']}, {meta['episodes']} paired episodes of "
            f"{meta['duration']} s, residual scale {meta['residual_scale']} N)"
        ),
        "",
        *(
            [f"Missing runs (not trained yet): {', '.join(meta['missing_runs'])}", ""]
            if meta["missing_runs"]
            else []
        ),
        (
            "| agent | mean RMSE [m] | crash rate | RMSE gain vs baseline [m], 95% CI | "
            "mean RMSE, crash = 5 m [m] | its gain, 95% CI |"
        ),
        "|---|---|---|---|---|---|",
        row("geometric (zero residual)", s["baseline"]),
    ]
    for arm in ARMS:
        if arm in s:
            lines.append(row(f"PPO {arm.replace('_', ' ')}", s[arm]))
    lines.append(
        row(
            "(reference) estimate-aware allocation, same residual bound",
            s["estimate_aware_reference"],
        )
    )
    if "compensated_zero_residual" in s:
        lines.append(
            row(
                "(--compensate) zero residual on geometric / eta_hat",
                s["compensated_zero_residual"],
            )
        )
    if "with_minus_without" in s:
        w = s["with_minus_without"]
        lines += [
            "",
            (
                f"With vs without the estimate (RMSE_without - RMSE_with, paired, seeds "
                f"{w['seeds']}): {ci(w['rmse'])} m (over {w['rmse']['ci_over']}); crash = "
                f"5 m score: {ci(w['rmse_crash5'])} m."
            ),
        ]
    arms = [a for a in ARMS if a in s]
    if arms:
        lines += [
            "",
            "Per-seed RMSE gains vs baseline [m]: "
            + "; ".join(
                f"{a}: " + ", ".join(f"{g:+.4f}" for g in s[a]["rmse"]["per_seed_gain"])
                for a in arms
            ),
        ]
    if meta["train_times"]:
        lines += [
            "",
            "Training per run (steps, wall / CPU s): "
            + ", ".join(
                f"{k} {v.get('timesteps', meta['timesteps'])}"
                f"{' (stopped at the snapshot)' if v.get('file') == 'snapshot_time.json' else ''}, "
                f"{v['wall_seconds']:.0f}/{v['cpu_seconds']:.0f}"
                for k, v in meta["train_times"].items()
            ),
        ]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
