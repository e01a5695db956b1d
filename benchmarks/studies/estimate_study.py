"""Does the efficiency estimate in the observation help a PPO policy adapt to a fault?

Five arms, trained and evaluated alike, differing only in what the policy observes:

* ``mlp_none``    -- MLP, no estimate (``estimator="none"``: the eta_hat slot is constant 1);
* ``mlp_irls``    -- MLP with the online IRLS estimate and its sd;
* ``mlp_ekf``     -- MLP with the EKF estimate and its sd;
* ``mlp_truth``   -- MLP with the true efficiency (the oracle: the upper bound);
* ``memory_none`` -- no estimate, the observations of the last ``FRAME_STACK`` steps stacked
  (a policy with a short memory, which may infer the fault from how the vehicle responds).

With ``--allocation estimate-aware`` (the default) the residual policy adds to a base that
allocates the geometric controller's wrench by the arm's own estimate (the environment's
``allocation`` keyword), so each arm's estimate feeds base and policy alike; ``mlp_none``
and ``memory_none`` then fly the nominal-belief base.

Tasks (``--tasks``): ``rotor_loss`` -- ``QuadFaultRotorLoss-v0`` (hover; one rotor drops
abruptly to eta 0.1-0.5 at 3-6 s); ``tracking`` -- ``QuadFaultTrack-v0`` with every motor
degrading gradually to eta 0.8-0.95 over the flight and one rotor dropping abruptly to
0.3-0.6 at 30-60 % of it (``track_scenario``'s ``degradation`` and ``level`` options).

Design. Every arm: the same PPO settings (:data:`PPO_KWARGS`), residual scale, reward (the
task's ``-v1`` reward), steps, training seeds, number of vector-env quadrotors. During
training each run is evaluated at about ``--curve-points`` points on the tuning episodes
(reset seeds 10000+; they pick nothing but are the learning curve and the steps-to-crash-rate
measure); the final model then flies the paired test episodes (reset seeds 20000+, the same
rotor, level, onset, trajectory, initial state and noise for every arm, recorded per arm in
the results so the pairing can be checked). Reported per arm: crash rate, tracking RMSE over
the flown steps [m] and return, mean over the training seeds with a 95 % Student-t interval
over the seeds; the same paired against ``mlp_none`` (per seed, same episodes); steps to
reach a tuning-episode crash rate of ``--crash-target`` or lower (sample efficiency). The
zero-residual bases of the arms' estimators fly the same test episodes as references.

    python benchmarks/studies/estimate_study.py --out runs/estimate_study          # full: about 2 CPU-h
    python benchmarks/studies/estimate_study.py --quick --out runs/estimate_quick  # 1 task, 3 seeds
    python benchmarks/studies/estimate_study.py --tasks rotor_loss --seeds 0 --timesteps 16384 \\
        --episodes 10 --out runs/estimate_tiny

Writes ``OUT/study.json`` (design, every episode of every run, curves, summaries) and
``OUT/study.png`` (learning curves and the test scores with their intervals). A run folder
(``OUT/<task>/<arm>/seed_<k>/``, a ``quadfault train`` run) with a ``model.zip`` is reused
unless ``--retrain``; its training CPU time is kept beside it (``train_cpu.json``), so the
study's CPU total counts it however many processes trained the runs. ``--train-only`` trains
the missing runs and stops, so several processes can train one study in parallel (a run being
trained by another live process is waited for, not trained twice); the same command without
``--train-only`` then evaluates everything. ``--markdown`` prints the summaries as tables.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

#: the tasks: registered id, environment keywords, training seeds of the full study
TASKS = {
    "rotor_loss": {
        "env_id": "QuadFaultRotorLoss-v0",
        "seeds": 5,
        "env_kwargs": {"scenario_options": {"level": [0.1, 0.5]}},
    },
    "tracking": {
        "env_id": "QuadFaultTrack-v0",
        "seeds": 3,
        "env_kwargs": {
            "scenario_options": {
                "degradation": [0.8, 0.95],
                "level": [0.3, 0.6],
                "onset": [0.3, 0.6],
            }
        },
    },
}
FRAME_STACK = 8
#: the arms: the estimator in the observation (and the base) and the memory
ARMS = {
    "mlp_none": ("none", 1),
    "mlp_irls": ("irls", 1),
    "mlp_ekf": ("ekf", 1),
    "mlp_truth": ("truth", 1),
    "memory_none": ("none", FRAME_STACK),
}
REFERENCE_ARM = "mlp_none"
#: every arm: residual authority of one rotor's hover thrust (m g / 4 for the F450)
BASE_KWARGS = {"action_mode": "residual", "residual_scale": 2.45}
#: PPO settings of every arm (chosen on the tuning episodes, never on the test episodes)
PPO_KWARGS = {
    "n_steps": 256,
    "batch_size": 1024,
    "learning_rate": 3e-4,
    "n_epochs": 10,
    "policy_kwargs": {"net_arch": [64, 64], "log_std_init": -2.3},
}
TUNING_SEED, TEST_SEED = 10_000, 20_000
FULL = {"timesteps": 300_000, "episodes": 50}
QUICK = {"tasks": ["rotor_loss"], "seeds": [0, 1, 2], "timesteps": 200_000, "episodes": 20}


def env_kwargs(task: str, arm: str, args) -> dict:
    kw = dict(
        BASE_KWARGS,
        **TASKS[task]["env_kwargs"],
        estimator=ARMS[arm][0],
        estimator_rate=args.estimator_rate,
    )
    if args.duration is not None:
        kw["duration"] = args.duration
    if args.allocation != "nominal":
        kw["allocation"] = args.allocation
    if getattr(args, "sensor_noise", None) is not None:
        kw["sensor_noise"] = args.sensor_noise
    return kw


def train_config(task: str, arm: str, args):
    from agents.train import TrainConfig

    ppo = dict(
        PPO_KWARGS,
        n_steps=args.n_steps,
        batch_size=min(PPO_KWARGS["batch_size"], args.n_steps * args.n_envs),
    )
    return TrainConfig(
        algo="ppo",
        env_id=TASKS[task]["env_id"],
        env_kwargs=env_kwargs(task, arm, args),
        timesteps=args.timesteps,
        n_envs=args.n_envs,
        vector_env=True,
        frame_stack=ARMS[arm][1],
        eval_freq=max(args.timesteps // args.curve_points, 1),
        eval_episodes=args.tuning_episodes,
        eval_seed=TUNING_SEED,
        algo_kwargs=ppo,
    )


def t_interval(x) -> list[float]:
    """[mean, 95 % half-width (Student t; NaN below two values)] of ``x``."""
    from scipy import stats

    x = np.asarray(x, dtype=float)
    if x.size < 2:
        return [float(x.mean()), math.nan]
    half = stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size)
    return [float(x.mean()), float(half)]


def episode_faults(env, seeds) -> list:
    """Per test episode, what the scenario drew (faults and trajectory), to check pairing."""
    out = []
    for s in seeds:
        env.reset(seed=int(s))
        sc = env.unwrapped.scenario
        out.append(repr((sc.efficiency, sc.trajectory)))
    return out


def fly(policy, env, seeds, normalizer=None) -> dict:
    from agents.train_eval import fly_episodes

    flown = fly_episodes(policy, env, seeds, normalizer)
    return {
        "crashed": flown["crashed"].astype(float).tolist(),
        "rmse": flown["rmse"].tolist(),
        "return": flown["returns"].tolist(),
    }


def curve(run_dir: Path, full_length: int) -> dict:
    """The tuning-episode learning curve: steps, mean return, crash rate (an episode shorter
    than the task's steps was terminated)."""
    with np.load(run_dir / "evaluations.npz") as data:
        return {
            "timesteps": data["timesteps"].tolist(),
            "return": data["results"].mean(axis=1).tolist(),
            "crash_rate": (data["ep_lengths"] < full_length).mean(axis=1).tolist(),
            "base_return": base_return(data),
        }


def base_return(data) -> float | None:
    """The zero-residual base's mean return on the tuning episodes (None: not evaluated)."""
    return float(data["baseline_results"].mean()) if "baseline_results" in data.files else None


def steps_to(c: dict, target: float) -> float:
    """The first evaluated step count with a crash rate <= ``target`` (None: never)."""
    hit = [t for t, r in zip(c["timesteps"], c["crash_rate"]) if r <= target]
    return int(hit[0]) if hit else None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def train_run(config, seed: int, run_dir: Path, retrain: bool) -> None:
    """Train one run unless it exists; ``train_cpu.json`` records its training CPU seconds.
    A run that another live process is training (``.seed_<k>.training`` holds its pid) is
    waited for."""
    from agents.train import train_one
    from quadfault.fileio import atomic_write_text

    lock = run_dir.parent / f".{run_dir.name}.training"
    while True:
        if (run_dir / "model.zip").exists() and not retrain:
            return
        run_dir.parent.mkdir(parents=True, exist_ok=True)
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            try:
                owner = int(lock.read_text() or 0)
            except (OSError, ValueError):
                owner = 0
            if owner and _alive(owner):
                time.sleep(5)
                continue
            lock.unlink(missing_ok=True)  # left by a process that died
            continue
        break
    try:
        os.write(fd, str(os.getpid()).encode())
        os.close(fd)
        c0 = time.process_time()
        train_one(config, seed, run_dir, force=True, quiet=True)
        cpu = time.process_time() - c0
        atomic_write_text(run_dir / "train_cpu.json", json.dumps({"train_cpu_s": cpu}), force=True)
    finally:
        lock.unlink(missing_ok=True)


def train_cpu(run_dir: Path):
    """The recorded training CPU seconds of a run (None when it was not recorded)."""
    path = run_dir / "train_cpu.json"
    return json.loads(path.read_text())["train_cpu_s"] if path.is_file() else None


def run_arm(task: str, arm: str, args, test_seeds) -> dict:
    """Train (or reuse) every seed of one arm and fly the test episodes (with
    ``--train-only`` only train, and return None)."""
    from agents.train import load_agent, make_eval_env

    config = train_config(task, arm, args)
    if args.train_only:
        for seed in args.seeds:
            train_run(config, seed, Path(args.out) / task / arm / f"seed_{seed}", args.retrain)
        return None
    # the test episodes score info["tracking_error"]: the full info (training keeps it light)
    env = make_eval_env(replace(config, env_kwargs=dict(config.env_kwargs, info="full")))
    env.reset(seed=TEST_SEED)
    full_length = env.unwrapped.max_steps  # steps of a flight that is not terminated
    runs = {}
    for seed in args.seeds:
        run_dir = Path(args.out) / task / arm / f"seed_{seed}"
        train_run(config, seed, run_dir, args.retrain)
        cpu = train_cpu(run_dir)
        saved = json.loads((run_dir / "train_config.json").read_text())
        model, venv = load_agent(run_dir, env=env)
        r = fly(model, env, test_seeds, venv if hasattr(venv, "normalize_obs") else None)
        r["curve"] = curve(run_dir, full_length)
        r["steps_to_crash_target"] = steps_to(r["curve"], args.crash_target)
        r.update(
            timesteps_run=saved["timesteps_run"],
            train_cpu_s=cpu,
            episode_seeds=list(test_seeds),
            episode_scenarios=episode_faults(env, test_seeds),
        )
        runs[str(seed)] = r
    env.close()
    return runs


def summarise(arms: dict, references: dict) -> tuple[dict, dict, dict]:
    """Per arm: mean and 95 % interval over seeds of the per-seed mean scores. Per arm vs
    :data:`REFERENCE_ARM`: the same of the per-seed paired differences (arm minus reference,
    episode by episode). Per arm vs its own base (the zero-residual controller with the same
    estimator, on the same test episodes): what the learned residual adds."""
    keys = ("crashed", "rmse", "return")
    summary, paired, vs_base = {}, {}, {}
    for arm, runs in arms.items():
        summary[arm] = {k: t_interval([np.nanmean(r[k]) for r in runs.values()]) for k in keys}
        steps = [r["steps_to_crash_target"] for r in runs.values()]
        summary[arm]["steps_to_crash_target"] = {
            "per_seed": steps,
            "reached": sum(s is not None for s in steps),
        }
        base = references.get(f"base_{ARMS[arm][0]}")
        if base is not None:
            vs_base[arm] = paired_interval([(r, base) for r in runs.values()], keys)
    ref = arms.get(REFERENCE_ARM)
    for arm, runs in arms.items():
        if ref is None or arm == REFERENCE_ARM:
            continue
        paired[arm] = paired_interval([(runs[s], ref[s]) for s in runs if s in ref], keys)
    return summary, paired, vs_base


def paired_interval(pairs, keys) -> dict:
    """Per key: mean and 95 % interval over the pairs of each pair's mean episode-by-episode
    difference (first minus second)."""
    return {k: t_interval([np.nanmean(np.subtract(a[k], b[k])) for a, b in pairs]) for k in keys}


def plot(results: dict, path: Path) -> None:
    from agents.plots import _figure
    from quadfault.fileio import atomic_savefig

    tasks = list(results["tasks"])
    plt, fig, axes = _figure(len(tasks), 3.6)
    fig.set_figwidth(11)
    for row, task in enumerate(tasks):
        ax = axes[row]
        fig.delaxes(ax)
        a1 = fig.add_subplot(len(tasks), 2, 2 * row + 1)
        a2 = fig.add_subplot(len(tasks), 2, 2 * row + 2)
        res = results["tasks"][task]
        for j, (arm, runs) in enumerate(res["arms"].items()):
            curves = [r["curve"] for r in runs.values()]
            n = min(len(c["timesteps"]) for c in curves)
            ts = curves[0]["timesteps"][:n]
            colour = f"C{j}"
            a1.plot(
                ts,
                np.mean([c["return"][:n] for c in curves], axis=0),
                marker=".",
                color=colour,
                label=arm,
            )
            base = [c.get("base_return") for c in curves]
            if all(b is not None for b in base):
                a1.axhline(float(np.mean(base)), color=colour, ls="--", lw=0.8)
        a1.set_xlabel("environment steps")
        a1.set_ylabel("mean return, tuning episodes")
        a1.set_title(
            f"{task}: learning curves (mean of {len(args_seeds(res))} seeds; "
            "dashed: the arm's zero-residual base)",
            fontsize=9,
        )
        a1.grid(alpha=0.3)
        a1.legend(fontsize=7)
        names = list(res["summary"])
        for j, key in enumerate(("crashed", "rmse")):
            m = [res["summary"][a][key][0] for a in names]
            h = [res["summary"][a][key][1] for a in names]
            a2.errorbar(
                np.arange(len(names)) + 0.15 * j,
                m,
                yerr=np.nan_to_num(np.asarray(h, float)),
                fmt="o",
                capsize=3,
                label={"crashed": "crash rate", "rmse": "RMSE [m]"}[key],
            )
        a2.set_xticks(np.arange(len(names)), names, rotation=20, fontsize=7)
        a2.set_title(f"{task}: test episodes, mean and 95 % interval over seeds")
        a2.grid(alpha=0.3)
        a2.legend(fontsize=7)
    fig.tight_layout()
    atomic_savefig(fig, path, force=True, dpi=110)
    plt.close(fig)


def _json(x):
    """``x`` with NaN as None (strict JSON)."""
    if isinstance(x, dict):
        return {k: _json(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def args_seeds(res: dict) -> list:
    return sorted({s for runs in res["arms"].values() for s in runs})


def bases_only(tasks, args, test_seeds) -> int:
    """The zero-residual base of each arm's estimator on the test episodes of each task."""
    import gymnasium as gym

    print(f"sensor noise: {args.sensor_noise or 'none'}; {len(test_seeds)} test episodes")
    print("| task | base (estimator) | crashed | tracking RMSE [m] mean (max) |")
    print("|---|---|---|---|")
    for task in tasks:
        for est in sorted({ARMS[a][0] for a in args.arms}):
            arm = next(a for a in args.arms if ARMS[a][0] == est)
            env = gym.make(TASKS[task]["env_id"], **env_kwargs(task, arm, args), info="full")
            got = fly(None, env, test_seeds)
            env.close()
            rmse = np.array(got["rmse"])
            print(
                f"| {task} | {est} | {int(sum(got['crashed']))}/{len(test_seeds)} | "
                f"{np.nanmean(rmse):.4f} ({np.nanmax(rmse):.4f}) |",
                flush=True,
            )
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--quick",
        action="store_true",
        help="one task (rotor_loss), 3 seeds, 2x10^5 steps, 20 test episodes",
    )
    ap.add_argument("--tasks", nargs="+", choices=list(TASKS))
    ap.add_argument("--arms", nargs="+", choices=list(ARMS), default=list(ARMS))
    ap.add_argument(
        "--seeds",
        type=int,
        nargs="+",
        help="training seeds (default: the task's count in the full study, from 0)",
    )
    ap.add_argument("--timesteps", type=int, help="env steps per run (full study 3x10^5)")
    ap.add_argument("--episodes", type=int, help="paired test episodes (full study 50)")
    ap.add_argument("--tuning-episodes", type=int, default=10)
    ap.add_argument(
        "--curve-points", type=int, default=20, help="evaluations on the tuning episodes per run"
    )
    ap.add_argument("--crash-target", type=float, default=0.2)
    ap.add_argument("--n-envs", type=int, default=64)
    ap.add_argument("--n-steps", type=int, default=PPO_KWARGS["n_steps"])
    ap.add_argument("--allocation", default="estimate-aware", choices=("nominal", "estimate-aware"))
    ap.add_argument("--estimator-rate", default="physics", choices=("physics", "control"))
    ap.add_argument(
        "--duration",
        type=float,
        help="episode length [s] (default: the task's; shorter only for tests)",
    )
    ap.add_argument(
        "--sensor-noise",
        default=None,
        metavar="PRESET",
        help="the envs' sensors: a preset measured on real logs (crazyflie, indiflight, px4: "
        "docs/sensors.md), numbers 'P,V,A,G[,ACC]' or a JSON object of SensorNoise fields "
        '(\'{"preset": "crazyflie", "rate": 0}\'); default none, ideal sensors; give '
        "it its own --out",
    )
    ap.add_argument("--out", default="runs/estimate_study")
    ap.add_argument("--retrain", action="store_true")
    ap.add_argument(
        "--train-only",
        action="store_true",
        help="train the missing runs and stop (for training in parallel)",
    )
    ap.add_argument(
        "--bases-only",
        action="store_true",
        help="fly only the zero-residual bases of the arms' estimators on the test episodes "
        "(no training) and print their crash rate and tracking RMSE",
    )
    ap.add_argument(
        "--markdown", action="store_true", help="print the summaries as markdown tables"
    )
    ap.add_argument(
        "--replot",
        action="store_true",
        help="only recompute the summaries and the plot of OUT/study.json",
    )
    args = ap.parse_args(argv)
    if args.sensor_noise is not None:
        from quadfault.errors import ConfigError
        from quadfault.model.sensor_presets import as_sensor_noise

        try:
            if args.sensor_noise.lstrip().startswith("{"):
                args.sensor_noise = json.loads(args.sensor_noise)
            as_sensor_noise(args.sensor_noise, "--sensor-noise")
        except (ConfigError, json.JSONDecodeError) as e:
            ap.error(f"--sensor-noise: {e}")
    if args.replot:
        return replot(Path(args.out), args.markdown)
    cpu0 = time.process_time()
    preset = QUICK if args.quick else FULL
    tasks = args.tasks or preset.get("tasks", list(TASKS))
    args.timesteps = args.timesteps or preset["timesteps"]
    episodes = args.episodes or preset["episodes"]
    test_seeds = [TEST_SEED + i for i in range(episodes)]

    import gymnasium as gym

    import quad_fault_env  # noqa: F401  (registers the ids)

    if args.bases_only:
        return bases_only(tasks, args, test_seeds)
    out = Path(args.out)
    seed_arg = args.seeds
    results = {
        "design": {
            "arms": {
                a: {"estimator": e, "frame_stack": k}
                for a, (e, k) in ARMS.items()
                if a in args.arms
            },
            "reference_arm": REFERENCE_ARM,
            "ppo": PPO_KWARGS,
            "n_envs": args.n_envs,
            "n_steps": args.n_steps,
            "timesteps": args.timesteps,
            "allocation": args.allocation,
            "duration": args.duration,
            "estimator_rate": args.estimator_rate,
            "sensor_noise": args.sensor_noise or "none",
            "tuning_seeds": [TUNING_SEED, TUNING_SEED + args.tuning_episodes - 1],
            "test_seeds": test_seeds,
            "crash_target": args.crash_target,
        },
        "tasks": {},
    }
    for task in tasks:
        args.seeds = seed_arg or list(
            range(TASKS[task]["seeds"] if not args.quick else len(QUICK["seeds"]))
        )
        arms = {}
        for arm in args.arms:
            print(f"{task} / {arm}: seeds {args.seeds}, {args.timesteps:,} steps each", flush=True)
            arms[arm] = run_arm(task, arm, args, test_seeds)
        if args.train_only:
            continue
        references = {}
        for est in sorted({ARMS[a][0] for a in args.arms}):
            arm = next((a for a in args.arms if ARMS[a][0] == est and ARMS[a][1] == 1), None)
            if arm is None:
                continue
            env = gym.make(
                TASKS[task]["env_id"], **env_kwargs(task, arm, args), info="full"
            )  # fly() scores info["tracking_error"]
            references[f"base_{est}"] = fly(None, env, test_seeds)
            env.close()
        results["tasks"][task] = {
            "env_id": TASKS[task]["env_id"],
            "env_kwargs": TASKS[task]["env_kwargs"],
            "seeds": args.seeds,
            "episode_seeds": test_seeds,
            "arms": arms,
            "references": references,
        }
    if args.train_only:
        print(f"trained; CPU of this process {(time.process_time() - cpu0) / 60:.1f} min")
        return 0
    results["cpu_s"] = time.process_time() - cpu0
    finish(results, out, args.crash_target, args.markdown)
    return 0


def finish(results: dict, out: Path, crash_target: float, markdown: bool = False) -> None:
    """Summarise every task of ``results``, print the summaries, write ``study.json`` and
    ``study.png`` into ``out``."""
    from quadfault.fileio import atomic_write_text

    for task, res in results["tasks"].items():
        summary, paired, vs_base = summarise(res["arms"], res["references"])
        res.update(
            {"summary": summary, f"paired_vs_{REFERENCE_ARM}": paired, "paired_vs_base": vs_base}
        )
        print(
            f"{task} (mean and 95 % interval over seeds; 'vs base': the arm minus its "
            "zero-residual base, paired by episode)"
        )
        for arm, s in summary.items():
            line = ", ".join(
                f"{k} {m:.3f} +/- {h:.3f}"
                for k, (m, h) in ((k, s[k]) for k in ("crashed", "rmse", "return"))
            )
            b = vs_base.get(arm)
            extra = (
                f"; vs base: rmse {b['rmse'][0]:+.4f} +/- {b['rmse'][1]:.4f}, return "
                f"{b['return'][0]:+.1f} +/- {b['return'][1]:.1f}"
                if b
                else ""
            )
            print(
                f"  {arm}: {line}{extra}; steps to crash rate <= {crash_target}: "
                f"{s['steps_to_crash_target']['per_seed']}"
            )
        if markdown:
            print(markdown_table(res))
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(
        out / "study.json", json.dumps(_json(results), indent=1, allow_nan=False), force=True
    )
    plot(results, out / "study.png")
    train = [
        r.get("train_cpu_s")
        for res in results["tasks"].values()
        for runs in res["arms"].values()
        for r in runs.values()
    ]
    known = [c for c in train if c is not None]
    if known:
        print(
            f"training CPU, sum over the {len(known)} of {len(train)} runs that recorded it: "
            f"{sum(known) / 60:.1f} min"
        )
    if results.get("cpu_s") is not None:
        print(
            f"CPU time of this process (evaluations, and the training it did): "
            f"{results['cpu_s'] / 60:.1f} min"
        )
    print(f"-> {out / 'study.json'}, {out / 'study.png'}")


def markdown_table(res: dict) -> str:
    """One task's summary as a markdown table: mean +/- 95 % interval over seeds."""

    def pm(v, digits):
        m, h = v
        return (
            f"{m:.{digits}f} ± {h:.{digits}f}"
            if h is not None and math.isfinite(h)
            else f"{m:.{digits}f}"
        )

    rows = [
        "| arm | crash rate | tracking RMSE [m] | return | RMSE vs `mlp_none` [m] "
        "| return vs `mlp_none` | RMSE vs base [m] | return vs base |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for arm, s in res["summary"].items():
        p = res.get(f"paired_vs_{REFERENCE_ARM}", {}).get(arm)
        b = res.get("paired_vs_base", {}).get(arm)
        rows.append(
            f"| `{arm}` | {pm(s['crashed'], 2)} | {pm(s['rmse'], 3)} | "
            f"{pm(s['return'], 0)} | {pm(p['rmse'], 4) if p else '-'} | "
            f"{pm(p['return'], 1) if p else '-'} | {pm(b['rmse'], 4) if b else '-'} | "
            f"{pm(b['return'], 1) if b else '-'} |"
        )
    return "\n".join(rows)


def replot(out: Path, markdown: bool = False) -> int:
    """Recompute the summaries and the plot of ``OUT/study.json`` without flying anything (the
    learning curves' base returns are read from the run folders where they are present)."""
    path = out / "study.json"
    if not path.is_file():
        print(f"estimate_study: no {path} to replot", file=sys.stderr)
        return 2
    results = json.loads(path.read_text())
    for task, res in results["tasks"].items():
        for arm, runs in res["arms"].items():
            for seed, r in runs.items():
                run_dir = out / task / arm / f"seed_{seed}"
                if r.get("train_cpu_s") is None:
                    r["train_cpu_s"] = train_cpu(run_dir)
                npz = run_dir / "evaluations.npz"
                if npz.is_file():
                    with np.load(npz) as data:
                        base = base_return(data)
                    if base is not None:
                        r["curve"]["base_return"] = base
    finish(results, out, results["design"]["crash_target"], markdown)
    return 0


if __name__ == "__main__":
    sys.exit(main())
