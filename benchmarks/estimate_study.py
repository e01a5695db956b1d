"""Does the efficiency estimate in the observation help a PPO policy survive a rotor loss?

Two arms that differ only in the estimator of the observation: ``with_estimate`` (the online
IRLS estimate and its sd) and ``without_estimate`` (``estimator="none"``: the eta_hat slot is
constant 1). Everything else is the same: ``QuadFaultRotorLoss-v0`` (hover; one rotor drops
abruptly to eta 0-0.5 at 3-6 s and stays there), sensor noise on the measured state, residual
actions on top of the geometric controller, the task's -v1 reward, PPO settings, steps and
seeds. Optional domain randomisation (``--effects``, the environment's ``effects`` keyword:
the ``quadfault simulate --effect`` syntax with ``a:b`` ranges drawn at every reset).

Each run is one command a user can rerun (printed before it starts)::

    quadfault train --env QuadFaultRotorLoss-v0 --env-kwargs '<arm's JSON>' --timesteps T \\
        --seeds K --n-envs 16 --vector-env --out OUT/<arm>

Evaluation (paired): every trained policy, the geometric controller (zero residual) and the
estimate-aware allocation (``compensate=True`` with the IRLS estimate, zero residual) fly the
same ``--episodes`` episodes (reset seeds 20000 on: the same rotor, level, onset, initial
state and noise for every agent). Per episode: crashed (terminated), the RMS of the true
tracking error over the flown steps [m], the return. Reported: crash rate and mean RMSE per
agent; with vs without the estimate paired by seed and episode, the per-seed mean difference
with a 95 % interval (Student t over the seeds).

    python benchmarks/estimate_study.py --timesteps 50000 --seeds 0 1 2 --episodes 20 \\
        --out runs/estimate_study [--effects 'drag=0:0.3' 'motor_lag=0.01:0.04']

Trained runs are reused when their ``model.zip`` exists (``--retrain`` trains again).
Writes ``OUT/study.json`` and ``OUT/study.md``.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ENV_ID = "QuadFaultRotorLoss-v0"
ARMS = {"with_estimate": "irls", "without_estimate": "none"}
#: the measured state's noise (position, velocity [m, m/s], attitude [rad], gyro [rad/s])
SENSOR_NOISE = {"position": 0.01, "velocity": 0.02, "attitude": 0.005, "gyro": 0.01}
#: both arms: residual authority of one rotor's hover thrust (m g / 4 for the F450), the
#: estimate at the control rate (every 10th physics sample)
BASE_KWARGS = {"action_mode": "residual", "residual_scale": 2.45, "estimator_rate": "control",
               "sensor_noise": SENSOR_NOISE}
EVAL_SEED = 20_000


def arm_kwargs(arm: str, effects: list[str] | None) -> dict:
    kw = dict(BASE_KWARGS, estimator=ARMS[arm])
    if effects:
        kw["effects"] = list(effects)
    return kw


def train_command(arm: str, seed: int, args) -> list[str]:
    return ["quadfault", "train", "--env", ENV_ID,
            "--env-kwargs", json.dumps(arm_kwargs(arm, args.effects)),
            "--timesteps", str(args.timesteps), "--seeds", str(seed), "--n-envs",
            str(args.n_envs), "--vector-env", "--eval-freq", str(max(args.timesteps // 4, 1)),
            "--quiet", "--force", "--out",
            str(Path(args.out) / arm)]


def fly(policy, env, seeds, normalizer=None) -> dict:
    """Per episode: crashed, RMS tracking error over the flown steps [m], return."""
    from agents.train_eval import fly_episodes

    flown = fly_episodes(policy, env, seeds, normalizer)
    return {"crashed": flown["crashed"].tolist(), "rmse": flown["rmse"].tolist(),
            "return": flown["returns"].tolist()}


def t_interval(x) -> tuple[float, float]:
    """Mean and 95 % half-width (Student t) of ``x``."""
    from scipy import stats

    x = np.asarray(x, dtype=float)
    if x.size < 2:
        return float(x.mean()), math.nan
    half = stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size)
    return float(x.mean()), float(half)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timesteps", type=int, default=50_000)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--n-envs", type=int, default=16)
    ap.add_argument("--effects", nargs="*", default=None,
                    help="domain randomisation: effect specs with a:b ranges")
    ap.add_argument("--out", default="runs/estimate_study")
    ap.add_argument("--retrain", action="store_true")
    ap.add_argument("--evaluate-only", action="store_true")
    args = ap.parse_args(argv)
    out = Path(args.out)
    costs = {}
    for arm in ARMS:
        for seed in args.seeds:
            run = out / arm / f"seed_{seed}"
            if (run / "model.zip").exists() and not args.retrain:
                continue
            if args.evaluate_only:
                raise SystemExit(f"{run}: not trained")
            cmd = train_command(arm, seed, args)
            print("+", shlex.join(cmd), flush=True)
            t0 = time.time()
            res = subprocess.run(cmd, check=False)
            if res.returncode != 0:
                raise SystemExit(f"training {arm} seed {seed} failed ({res.returncode})")
            costs[f"{arm}/seed_{seed}"] = time.time() - t0

    import gymnasium as gym

    import quad_fault_env  # noqa: F401
    from agents.train import load_agent
    from quadfault.fileio import atomic_write_text

    seeds = [EVAL_SEED + i for i in range(args.episodes)]
    results = {}
    base = arm_kwargs("without_estimate", args.effects)
    results["geometric"] = fly(None, gym.make(ENV_ID, **base), seeds)
    ref_kw = dict(arm_kwargs("with_estimate", args.effects), compensate=True)
    results["estimate-aware allocation (IRLS)"] = fly(None, gym.make(ENV_ID, **ref_kw), seeds)
    for arm in ARMS:
        for seed in args.seeds:
            env = gym.make(ENV_ID, **arm_kwargs(arm, args.effects))
            model, venv = load_agent(out / arm / f"seed_{seed}", env=env)
            norm = venv if hasattr(venv, "normalize_obs") else None
            results[f"{arm}/seed_{seed}"] = fly(model, env, seeds, norm)
    rows = ["| agent | crash rate | mean RMSE [m] | mean return |", "|---|---|---|---|"]

    def row(name, keys):
        c = np.mean([np.mean(results[k]["crashed"]) for k in keys])
        r = np.mean([np.nanmean(results[k]["rmse"]) for k in keys])
        g = np.mean([np.mean(results[k]["return"]) for k in keys])
        rows.append(f"| {name} | {c:.2f} | {r:.4f} | {g:.1f} |")

    row("geometric (zero residual)", ["geometric"])
    row("estimate-aware allocation, IRLS (zero residual)", ["estimate-aware allocation (IRLS)"])
    for arm in ARMS:
        row(f"PPO {arm.replace('_', ' ')} (seeds {', '.join(map(str, args.seeds))})",
            [f"{arm}/seed_{s}" for s in args.seeds])
    d_rmse = [np.nanmean(np.subtract(results[f"without_estimate/seed_{s}"]["rmse"],
                                     results[f"with_estimate/seed_{s}"]["rmse"]))
              for s in args.seeds]
    d_crash = [np.mean(np.subtract(np.asarray(results[f"without_estimate/seed_{s}"]["crashed"],
                                              float),
                                   np.asarray(results[f"with_estimate/seed_{s}"]["crashed"],
                                              float))) for s in args.seeds]
    m, h = t_interval(d_rmse)
    mc, hc = t_interval(d_crash)
    summary = (f"\nwith vs without the estimate, paired by seed and episode (> 0: the estimate "
               f"helps): RMSE {m:+.4f} +/- {h:.4f} m, crash rate {mc:+.3f} +/- {hc:.3f} "
               f"(95 % intervals over {len(args.seeds)} seeds)")
    text = "\n".join(rows) + summary + "\n"
    print(text)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "study.md", text, force=True)
    atomic_write_text(out / "study.json", json.dumps(
        {"env_id": ENV_ID, "arms": {a: arm_kwargs(a, args.effects) for a in ARMS},
         "timesteps": args.timesteps, "seeds": args.seeds, "episodes": seeds,
         "results": results, "train_wall_s": costs,
         "paired_rmse": [m, h], "paired_crash": [mc, hc]}, indent=1), force=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
