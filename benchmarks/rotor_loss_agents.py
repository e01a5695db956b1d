"""Does the efficiency estimate help a learned policy survive the complete loss of a rotor?

PPO residual policies on ``QuadFaultRotorLossComplete-v0`` (hover, one rotor -- any of the
four -- stops at an onset drawn from 30-60 % of the episode (3-6 s of 10 s), the
complete-loss vehicle; actions are residuals
on the relaxed-hover base: the estimate-aware allocation until the IRLS estimate isolates the
lost rotor, then the relaxed-hover controller on the other three). The arms differ ONLY in
what the policy observes in the ``eta_hat`` / ``eta_sd`` slots
(:class:`agents.observed_estimate.ObservedEstimateVectorEnv`); the base, the physics, the
reward, the PPO settings (``ppo_residual_study.PPO_KWARGS``), the budget and the training
episodes are the same:

* ``irls``: the sliding-window IRLS estimate (what the base itself flies on);
* ``ekf``: the EKF estimate, run on the same measurement records;
* ``none``: no estimate (the nominal belief: efficiency 1, a constant sd);
* ``truth``: the true efficiency (the labelled oracle: the upper bound of what an estimate
  can give);
* ``memory``: no estimate, but the last ``--frames`` observations stacked (SB3's
  ``VecFrameStack``): a policy that may infer the loss from the motion.

Each arm trains ``--seeds`` runs of ``--timesteps`` steps on ``--n-envs`` rows of the vector
env. Every ``--eval-every`` steps (and before training) the policy flies the same
``--curve-episodes`` episodes (reset seeds from 20000: the same scenario -- rotor, onset,
initial state -- for every arm and run): the learning curves. After training it flies the
``--episodes`` paired test episodes (reset seeds from 10000), as does the reference
controller alone (zero residual). Per episode:

* **survived**: ran to the end of the 10 s without a termination (5 m, 80 degrees, ground);
* **success** (the task's, docs/environment.md): survived and within 1 m of the hover point
  from 2 s after the loss to the end (:func:`agents.metrics.held_after_loss`);
* **error after the loss**: RMS position error from 2 s after the loss to the end [m], a
  crashed episode scored 5 m (the termination's position limit).

Rates and errors are reported with 95 % Student-t intervals over the training seeds, and
each arm's success against the ``irls`` arm's as a paired difference per seed. **Steps to
50 %**: the first evaluation of the learning curve at which the rate reaches 0.5 (per seed;
"-" when a seed never does within the budget).

    python benchmarks/rotor_loss_agents.py --quick --plot rotor_loss_agents.png
    python benchmarks/rotor_loss_agents.py --plot rotor_loss_agents.png   # full study

``--quick`` (<= 45 CPU-minutes; 5 arms x 3 seeds of 81,920 steps): a smoke-sized study whose
numbers are what that budget gives, not what PPO can learn here. The full study (5 arms x
3 seeds x 1,003,520 steps; about 3 CPU-hours, estimated from the quick run's cost per step
and per evaluated episode) is the one to conclude from. Each run's results go to ``OUT/runs/<arm>_seed<k>.json`` and are reused by a
later call with the same settings (``--retrain`` trains again); the table is printed and
written to ``OUT/study.md`` with ``OUT/study.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent / "studies"))
from ppo_residual_study import PPO_KWARGS, t_interval  # noqa: E402  (benchmarks/studies/)

ENV_ID = "QuadFaultRotorLossComplete-v0"
#: arm -> (what the policy observes, stacked frames)
ARMS = {
    "irls": ("irls", 1),
    "ekf": ("ekf", 1),
    "none": ("none", 1),
    "truth": ("truth", 1),
    "memory": ("none", 4),
}
CRASH_ERROR = 5.0  # [m] error after the loss of a crashed episode (the position limit)
TEST_SEED, CURVE_SEED = 10_000, 20_000


@dataclass(frozen=True)
class Budget:
    """What one run trains and how it is evaluated (the same for every arm)."""

    timesteps: int
    n_envs: int
    n_steps: int
    eval_every: int
    curve_episodes: int
    episodes: int
    duration: float = 10.0
    frames: int = 4


QUICK = Budget(81_920, 16, 256, 16_384, 12, 40)
FULL = Budget(1_003_520, 32, 256, 100_352, 24, 100)


def make_env(arm: str, n: int, budget: Budget, seed: int | None = None, info: str = "light"):
    """The SB3 VecEnv an arm's policy sees: ``n`` rows of the task observing the arm's
    estimate, stacked over ``budget.frames`` steps for ``memory``."""
    from stable_baselines3.common.vec_env import VecFrameStack

    from agents.observed_estimate import observed_sb3_vec_env

    observe, frames = ARMS[arm]
    frames = budget.frames if frames > 1 else 1
    env = observed_sb3_vec_env(
        n, ENV_ID, observe, seed=seed, duration=budget.duration, info=info, numba_threads=1
    )
    return VecFrameStack(env, frames) if frames > 1 else env


def fly(arm: str, model, budget: Budget, first_seed: int, n: int) -> dict:
    """``n`` deterministic episodes (reset seeds ``first_seed ..``) of ``model`` (None: the
    zero residual, the reference controller alone) in ``arm``'s observation; per episode
    ``survived``, ``success``, ``error`` (see the module docstring), ``rotor`` and ``onset``."""
    from agents.metrics import held_after_loss
    from agents.observed_estimate import ObservedEstimateVectorEnv

    env = make_env(arm, n, budget, seed=first_seed, info="full")
    base = env.venv
    while not isinstance(base, ObservedEstimateVectorEnv):  # under the frame stack
        base = base.venv
    norm = None if model is None else model.get_vec_normalize_env()
    try:
        obs = env.reset()
        faults = [min(sc.efficiency.faults, key=lambda f: f.onset) for sc in base.scenarios]
        onset = np.array([f.onset for f in faults])
        errs, times = [[] for _ in range(n)], [[] for _ in range(n)]
        live = np.ones(n, dtype=bool)
        crashed = np.zeros(n, dtype=bool)
        while live.any():
            if model is None:
                act = np.zeros((n, 4))
            else:
                o = obs if norm is None else norm.normalize_obs(obs)
                act = model.predict(o, deterministic=True)[0]
            obs, _, done, infos = env.step(act)
            for i in np.flatnonzero(live):
                errs[i].append(float(infos[i]["tracking_error"]))
                times[i].append(float(infos[i]["t"]))
                if done[i]:
                    live[i] = False
                    crashed[i] = not infos[i].get("TimeLimit.truncated", False)
    finally:
        env.close()
    out = {"survived": [], "success": [], "error": [], "rotor": [], "onset": onset.tolist()}
    for i in range(n):
        t, e = np.asarray(times[i]), np.asarray(errs[i])
        late = e[t >= onset[i] + 2.0]
        err = CRASH_ERROR if crashed[i] else float(np.sqrt(np.mean(late**2)))
        out["survived"].append(bool(not crashed[i]))
        out["success"].append(
            bool(not crashed[i] and held_after_loss(t, e, onset[i], budget.duration))
        )
        out["error"].append(err)
        out["rotor"].append(int(faults[i].motor))
    return out


def _rates(flown: dict) -> dict:
    return {
        "survival": float(np.mean(flown["survived"])),
        "success": float(np.mean(flown["success"])),
        "error": float(np.mean(flown["error"])),
    }


def train_run(arm: str, seed: int, budget: Budget, path: Path) -> dict:
    """Train one run with its learning curve; its results (also written to ``path``)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecNormalize

    from agents.train import set_numba_threads
    from quadfault.fileio import atomic_write_text

    set_numba_threads(1)
    torch.set_num_threads(1)
    cpu0, wall0 = time.process_time(), time.time()
    env = VecNormalize(make_env(arm, budget.n_envs, budget, seed=seed), gamma=PPO_KWARGS["gamma"])
    kwargs = dict(PPO_KWARGS, n_steps=budget.n_steps)
    kwargs["batch_size"] = min(kwargs["batch_size"], budget.n_steps * budget.n_envs)
    model = PPO("MlpPolicy", env, seed=seed, device="cpu", verbose=0, **kwargs)
    curve = []

    def evaluate(steps: int) -> None:
        rates = _rates(fly(arm, model, budget, CURVE_SEED, budget.curve_episodes))
        curve.append(dict(rates, steps=int(steps)))
        print(
            f"  {arm} seed {seed}: {steps:>9,} steps  survived {rates['survival']:.2f}  "
            f"success {rates['success']:.2f}  error after loss {rates['error']:.3f} m  "
            f"({time.process_time() - cpu0:.0f} CPU-s)",
            flush=True,
        )

    class Curve(BaseCallback):
        def _on_training_start(self) -> None:
            self.next_at = 0

        def _on_rollout_start(self) -> None:
            if self.num_timesteps >= self.next_at:
                evaluate(self.num_timesteps)
                self.next_at = self.num_timesteps + budget.eval_every

        def _on_step(self) -> bool:
            return True

    try:
        model.learn(total_timesteps=budget.timesteps, callback=Curve())
    finally:
        env.close()
    evaluate(model.num_timesteps)
    test = fly(arm, model, budget, TEST_SEED, budget.episodes)
    result = {
        "arm": arm,
        "seed": seed,
        "budget": asdict(budget),
        "curve": curve,
        "test": test,
        "cpu_seconds": time.process_time() - cpu0,
        "wall_seconds": time.time() - wall0,
    }
    atomic_write_text(path, json.dumps(result), force=True)
    return result


def steps_to(curve: list, key: str, level: float = 0.5):
    """The steps of the first evaluation at which ``key`` reached ``level`` (None: never)."""
    return next((c["steps"] for c in curve if c[key] >= level), None)


def _ci(values) -> str:
    m, h = t_interval(values)
    return f"{m:.2f} ± {h:.2f}" if math.isfinite(h) else f"{m:.2f}"


def _steps(runs: list, key: str) -> str:
    got = [steps_to(r["curve"], key) for r in runs]
    reached = [g for g in got if g is not None]
    if len(reached) < len(got):
        return f"{len(reached)}/{len(got)} seeds reached"
    m, h = t_interval(reached)
    return f"{m:,.0f} ± {h:,.0f}" if math.isfinite(h) else f"{m:,.0f}"


def summarise(results: dict, reference: dict, budget: Budget, seeds) -> str:
    """The study's table (markdown)."""
    ref = _rates(reference)
    lines = [
        f"{ENV_ID}, PPO residual on the relaxed-hover base; {budget.timesteps:,} steps per "
        f"run ({budget.n_envs} envs x {budget.n_steps} steps per rollout), seeds "
        f"{list(seeds)}; {budget.episodes} paired test episodes (the same rotor, onset and "
        f"initial state for every arm); 95 % intervals over the seeds.",
        "",
        "| arm (what the policy observes) | survived | success (within 1 m from 2 s after "
        "the loss) | error after the loss [m] | success - irls arm (paired) | steps to 50 % "
        "survival | steps to 50 % success |",
        "|---|---|---|---|---|---|---|",
        f"| reference controller alone (zero residual) | {ref['survival']:.2f} | "
        f"{ref['success']:.2f} | {ref['error']:.2f} | - | - | - |",
    ]
    irls = {r["seed"]: r for r in results.get("irls", [])}
    for arm, runs in results.items():
        if not runs:
            continue
        rates = [_rates(r["test"]) for r in runs]
        paired = [
            np.mean(r["test"]["success"]) - np.mean(irls[r["seed"]]["test"]["success"])
            for r in runs
            if r["seed"] in irls
        ]
        diff = "-" if arm == "irls" or not paired else _ci(paired)
        label = {
            "irls": "irls (IRLS estimate)",
            "ekf": "ekf (EKF estimate)",
            "none": "none (no estimate)",
            "truth": "truth (true efficiency)",
            "memory": f"memory (no estimate, {budget.frames} frames)",
        }[arm]
        lines.append(
            f"| {label} | {_ci([x['survival'] for x in rates])} | "
            f"{_ci([x['success'] for x in rates])} | {_ci([x['error'] for x in rates])} | "
            f"{diff} | {_steps(runs, 'survival')} | {_steps(runs, 'success')} |"
        )
    cpu = sum(r["cpu_seconds"] for runs in results.values() for r in runs)
    lines += ["", f"Training and evaluation: {cpu / 60:.1f} CPU-minutes over the runs."]
    return "\n".join(lines) + "\n"


def plot(results: dict, reference: dict, path, *, force: bool = False) -> None:
    """Learning curves per arm: survival, success and error after the loss on the curve
    episodes (mean over seeds, the seeds' range shaded), the reference controller alone on
    the same episodes (``reference``) as a dashed line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from quadfault.fileio import atomic_savefig

    ref = _rates(reference)
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    for ax, key, label in zip(
        axes,
        ("survival", "success", "error"),
        ("survived [-]", "success: within 1 m from 2 s after the loss [-]", "error after loss [m]"),
    ):
        for arm, runs in results.items():
            if not runs:
                continue
            n = min(len(r["curve"]) for r in runs)
            steps = np.array([c["steps"] for c in runs[0]["curve"][:n]])
            y = np.array([[c[key] for c in r["curve"][:n]] for r in runs])
            (line,) = ax.plot(steps, y.mean(axis=0), label=arm)
            ax.fill_between(steps, y.min(axis=0), y.max(axis=0), color=line.get_color(), alpha=0.15)
        ax.axhline(ref[key], color="k", ls="--", lw=1, label="reference controller alone")
        ax.set_xlabel("training steps")
        ax.set_ylabel(label, fontsize=8)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{ENV_ID}: PPO residual learning curves (curve episodes)", fontsize=9)
    fig.tight_layout()
    atomic_savefig(fig, path, force=force, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the <= 45 CPU-minute budget")
    ap.add_argument("--arms", nargs="+", choices=list(ARMS), default=list(ARMS))
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--timesteps", type=int, default=None, help="steps per run")
    ap.add_argument("--n-envs", type=int, default=None)
    ap.add_argument("--n-steps", type=int, default=None, help="PPO steps per env per rollout")
    ap.add_argument("--eval-every", type=int, default=None, help="learning-curve period")
    ap.add_argument("--curve-episodes", type=int, default=None)
    ap.add_argument("--episodes", type=int, default=None, help="paired test episodes")
    ap.add_argument("--duration", type=float, default=None, help="episode length [s]")
    ap.add_argument("--frames", type=int, default=None, help="frames of the memory arm")
    ap.add_argument("--out", default="runs/rotor_loss_agents")
    ap.add_argument("--retrain", action="store_true")
    ap.add_argument("--plot", default=None, metavar="PATH", help="learning curves (png)")
    ap.add_argument("--force", action="store_true", help="overwrite --plot's file")
    args = ap.parse_args(argv)
    base = QUICK if args.quick else FULL
    changes = {
        k: getattr(args, k)
        for k in (
            "timesteps",
            "n_envs",
            "n_steps",
            "eval_every",
            "curve_episodes",
            "episodes",
            "duration",
            "frames",
        )
        if getattr(args, k) is not None
    }
    bad = [f"--{k.replace('_', '-')}" for k, v in changes.items() if not v > 0]
    if bad or any(s < 0 for s in args.seeds):
        raise SystemExit(f"rotor_loss_agents: {', '.join(bad) or '--seeds'} must be positive")
    if "duration" in changes and changes["duration"] < 5.0:
        # the onset is drawn from 30-60 % of the episode; success needs 2 s after it
        raise SystemExit("rotor_loss_agents: --duration must be at least 5 s")
    budget = Budget(**dict(asdict(base), **changes))
    if args.plot and Path(args.plot).exists() and not args.force:
        raise SystemExit(f"rotor_loss_agents: {args.plot} exists (pass --force to overwrite)")
    from quadfault.fileio import atomic_write_text

    out = Path(args.out)
    (out / "runs").mkdir(parents=True, exist_ok=True)
    c0 = time.process_time()
    print(f"{ENV_ID}: arms {args.arms}, seeds {args.seeds}, {budget}", flush=True)
    reference = fly("irls", None, budget, TEST_SEED, budget.episodes)
    reference_curve = fly("irls", None, budget, CURVE_SEED, budget.curve_episodes)
    print(
        f"reference controller alone: test episodes {_rates(reference)}, curve episodes "
        f"{_rates(reference_curve)}",
        flush=True,
    )
    results = {}
    for arm in args.arms:
        results[arm] = []
        for seed in args.seeds:
            path = out / "runs" / f"{arm}_seed{seed}.json"
            if path.exists() and not args.retrain:
                saved = json.loads(path.read_text())
                if saved["budget"] == asdict(budget):
                    results[arm].append(saved)
                    print(f"{arm} seed {seed}: reused {path}", flush=True)
                    continue
            print(f"{arm} seed {seed}: training {budget.timesteps:,} steps", flush=True)
            results[arm].append(train_run(arm, seed, budget, path))
    table = summarise(results, reference, budget, args.seeds)
    table += f"Whole command: {(time.process_time() - c0) / 60:.1f} CPU-minutes in this process.\n"
    atomic_write_text(out / "study.md", table, force=True)
    atomic_write_text(
        out / "study.json",
        json.dumps(
            {
                "budget": asdict(budget),
                "reference": reference,
                "reference_curve": reference_curve,
                "runs": results,
            }
        ),
        force=True,
    )
    print(table)
    if args.plot:
        plot(results, reference_curve, args.plot, force=args.force)
        print(f"figure: {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
