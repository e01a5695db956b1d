"""What ``quadfault train`` does around ``model.learn``: the policy for the observation
space, the step budget in whole rollouts,
evaluation on fixed seeded episodes (best model, learning curve, geometric baseline),
checkpoints and the progress bar.

**Step budget.** SB3 collects experience in whole rollouts (PPO: ``n_steps`` per environment,
``n_envs`` environments; SAC: ``train_freq`` steps per environment) and checks the budget only
between them, so ``learn(50_000)`` with 8 environments and ``n_steps=2048`` runs 65,536
steps. :func:`planned_timesteps` rounds the request to the *nearest* whole number of
rollouts (at least one); training runs exactly that many steps, says so in one line before
it starts when it differs from the request, and records it in ``train_config.json``
(``timesteps_run``, ``steps_per_rollout``).

**Evaluation.** Every evaluation flies the same episodes: one deterministic episode per
reset seed ``eval_seed, eval_seed + 1, ..., eval_seed + eval_episodes - 1`` (default seeds
10000-10009) in a single environment of the run's id and keywords, the observation
normalised with the training statistics of that moment. Episodes depend only on their seed
(scenario, initial state, noise) and on the actions, never on the training seed, so
evaluations of different seeds and times are paired. An evaluation runs at the start of the
first rollout at or after every multiple of ``eval_freq`` environment steps (the policy
has then been updated on exactly the steps it is labelled with) and after the last
rollout. The geometric controller (:class:`agents.policies.GeometricPolicy`: a zero
residual, or the controller's commands in the motor and wrench modes) flies the same
episodes once per run: the baseline of the learning curve.
"""

from __future__ import annotations

import io
import math
import pickle
from pathlib import Path

import numpy as np
from gymnasium import spaces

from agents.policies import GeometricPolicy
from quad_fault_env.envs.config import require_full_info
from quadfault.errors import ConfigError
from quadfault.fileio import atomic_write_bytes, atomic_write_files
from quadfault.progress import progress_bar

VECNORM_FILE = "vecnormalize.pkl"
EVALUATIONS_FILE = "evaluations.npz"
#: SB3 policy names; None picks MultiInputPolicy for Dict observations, MlpPolicy otherwise
POLICIES = ("MlpPolicy", "MultiInputPolicy", "CnnPolicy")


def choose_policy(requested: str | None, observation_space, env_id: str) -> str:
    """The SB3 policy for ``observation_space``: ``requested`` when it can read it (else a
    one-line :class:`ConfigError`), or the default for the space (None)."""
    from stable_baselines3.common.preprocessing import is_image_space

    is_dict = isinstance(observation_space, spaces.Dict)
    if requested is None:
        return "MultiInputPolicy" if is_dict else "MlpPolicy"
    if is_dict and requested != "MultiInputPolicy":
        raise ConfigError(
            f"policy {requested} cannot read the Dict observation of {env_id}; "
            "use MultiInputPolicy (the default for Dict observations)"
        )
    if not is_dict and requested == "MultiInputPolicy":
        raise ConfigError(
            f"policy MultiInputPolicy needs a Dict observation, {env_id} has "
            f"{type(observation_space).__name__}; use MlpPolicy (the default)"
        )
    if requested == "CnnPolicy" and not is_image_space(observation_space):
        raise ConfigError(
            f"policy CnnPolicy needs image observations, {env_id} has a "
            f"{type(observation_space).__name__} of shape "
            f"{observation_space.shape}; use MlpPolicy (the default)"
        )
    return requested


def steps_per_rollout(model) -> int:
    """Environment steps the algorithm collects between two checks of its step budget."""
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
    from stable_baselines3.common.type_aliases import TrainFrequencyUnit

    if isinstance(model, OnPolicyAlgorithm):
        return int(model.n_steps * model.n_envs)
    freq = model.train_freq
    if freq.unit != TrainFrequencyUnit.STEP:
        raise ConfigError(
            "train_freq counted in episodes cannot honour a step budget; give "
            "train_freq in steps (an integer)"
        )
    return int(freq.frequency * model.n_envs)


def planned_timesteps(requested: int, rollout: int) -> int:
    """``requested`` rounded to the nearest whole number of rollouts of ``rollout`` steps
    (halves round up; at least one rollout)."""
    return max(1, math.floor(requested / rollout + 0.5)) * rollout


def budget_line(algo: str, seed: int, requested: int, planned: int, model) -> str:
    """The one line that says how many steps run when it differs from the request."""
    rollout = steps_per_rollout(model)
    per_env = rollout // model.n_envs
    what = "n_steps" if hasattr(model, "n_steps") else "train_freq"
    return (
        f"{algo} seed {seed}: training {planned:,} steps = {planned // rollout} rollouts of "
        f"{model.n_envs} envs x {per_env:,} steps ({what}), the nearest whole rollout to "
        f"the {requested:,} asked"
    )


def evaluation_seeds(config) -> list[int]:
    """Reset seeds of the evaluation episodes (the same for every evaluation and run)."""
    return [config.eval_seed + i for i in range(config.eval_episodes)]


def fly_episodes(policy, env, seeds, normalizer=None, *, tracking: bool = True) -> dict:
    """One deterministic episode of ``policy`` (anything with SB3's ``predict``; None: the
    zero action) in ``env`` per reset seed; ``normalizer`` (a ``VecNormalize``) normalises the
    observations the policy sees. Returns per episode ``returns`` (the environment's own
    rewards), ``lengths`` (steps), ``crashed`` (terminated) and, for QuadFault environments,
    ``rmse``: the RMS of ``info["tracking_error"]`` [m] over the flown steps (NaN otherwise,
    or without ``tracking``). ``tracking`` needs a QuadFault environment made with
    ``info="full"`` (a light one is a ``ConfigError``)."""
    if tracking:
        require_full_info(env, "fly_episodes")
    out = {"returns": [], "lengths": [], "crashed": [], "rmse": []}
    for seed in seeds:
        obs, _ = env.reset(seed=int(seed))
        total, errs, done, terminated = 0.0, [], False, False
        while not done:
            if policy is None:
                action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
            else:
                o = obs if normalizer is None else normalizer.normalize_obs(obs)
                action, _ = policy.predict(o, deterministic=True)
            obs, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            errs.append(float(info.get("tracking_error", np.nan)) if tracking else np.nan)
            done = terminated or truncated
        out["returns"].append(total)
        out["lengths"].append(len(errs))
        out["crashed"].append(bool(terminated))
        out["rmse"].append(float(np.sqrt(np.mean(np.square(errs)))))
    return {k: np.asarray(v, dtype=int if k == "lengths" else None) for k, v in out.items()}


def evaluate_episodes(policy, env, seeds, normalizer=None) -> tuple[np.ndarray, np.ndarray]:
    """``(returns, lengths)`` of :func:`fly_episodes` (any ``info``)."""
    flown = fly_episodes(policy, env, seeds, normalizer, tracking=False)
    return flown["returns"], flown["lengths"]


def geometric_baseline(env):
    """The geometric controller as a policy of ``env``, or None when ``env`` is not a
    QuadFault environment or a wrapper changed its observation."""
    try:
        if env.observation_space.shape != env.unwrapped.observation_space.shape:
            return None  # a wrapper (a frame stack) changed what a policy sees
        return GeometricPolicy.from_env(env)
    except AttributeError:
        return None


def model_files(model, zip_path: Path, vecnorm_path: Path | None) -> dict:
    """``{path: bytes}`` of a model's zip and (when it trains on one) its ``VecNormalize``
    pickle: what ``model.save`` and ``VecNormalize.save`` write, for one atomic write."""
    buf = io.BytesIO()
    model.save(buf)
    files = {Path(zip_path): buf.getvalue()}
    vn = model.get_vec_normalize_env()
    if vn is not None and vecnorm_path is not None:
        files[Path(vecnorm_path)] = pickle.dumps(vn)
    return files


def callbacks(config, run_dir: Path, eval_env, total: int, progress: bool):
    """Fixed-episode evaluation (best model, ``evaluations.npz``), checkpoints and the
    progress bar. Every file they leave in ``run_dir`` is written atomically (temporary
    file + rename, :mod:`quadfault.fileio`): an interrupted run never leaves a truncated
    ``best/`` model or checkpoint."""
    from stable_baselines3.common.callbacks import BaseCallback

    seeds = evaluation_seeds(config)

    class Evaluation(BaseCallback):
        """Evaluations on the fixed episodes; ``best/`` holds the best one's model."""

        def _on_training_start(self) -> None:
            self.timesteps, self.results, self.lengths = [], [], []
            self.best = -math.inf
            self.next_at = config.eval_freq
            policy = geometric_baseline(eval_env)
            self.baseline = None if policy is None else evaluate_episodes(policy, eval_env, seeds)

        def _on_rollout_start(self) -> None:
            if self.num_timesteps >= self.next_at:
                self._evaluate()
                while self.next_at <= self.num_timesteps:
                    self.next_at += config.eval_freq

        def _on_step(self) -> bool:
            return True

        def _on_training_end(self) -> None:
            if not self.timesteps or self.timesteps[-1] != self.num_timesteps:
                self._evaluate()

        def _evaluate(self) -> None:
            returns, lengths = evaluate_episodes(
                self.model, eval_env, seeds, self.model.get_vec_normalize_env()
            )
            self.timesteps.append(self.num_timesteps)
            self.results.append(returns)
            self.lengths.append(lengths)
            if returns.mean() > self.best:
                self.best = float(returns.mean())
                best = run_dir / "best"
                best.mkdir(parents=True, exist_ok=True)
                atomic_write_files(
                    model_files(self.model, best / "best_model.zip", best / VECNORM_FILE),
                    force=True,
                )
            data = {
                "timesteps": np.asarray(self.timesteps),
                "results": np.asarray(self.results),
                "ep_lengths": np.asarray(self.lengths),
                "episode_seeds": np.asarray(seeds),
            }
            if self.baseline is not None:
                data["baseline_results"], data["baseline_ep_lengths"] = self.baseline
            buf = io.BytesIO()
            np.savez(buf, **data)
            atomic_write_bytes(run_dir / EVALUATIONS_FILE, buf.getvalue(), force=True)

    class Checkpoint(BaseCallback):
        """``checkpoints/model_<steps>_steps.zip`` (+ ``model_vecnormalize_<steps>_steps.pkl``,
        SB3's names) every ``every`` calls."""

        def __init__(self, every: int):
            super().__init__()
            self.every = every

        def _on_step(self) -> bool:
            if self.n_calls % self.every == 0:
                folder = run_dir / "checkpoints"
                folder.mkdir(parents=True, exist_ok=True)
                k = self.num_timesteps
                vn = folder / f"model_vecnormalize_{k}_steps.pkl" if config.vec_normalize else None
                atomic_write_files(
                    model_files(self.model, folder / f"model_{k}_steps.zip", vn), force=True
                )
            return True

    class Progress(BaseCallback):
        """quadfault's progress bar (quiet off a terminal and with --quiet)."""

        def _on_training_start(self) -> None:
            self.bar = progress_bar(total=total, desc=f"train {config.algo}", unit="step")

        def _on_step(self) -> bool:
            self.bar.update(self.model.num_timesteps - self.bar.n)
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    cbs = [Evaluation()]
    if config.checkpoint_freq:
        cbs.append(Checkpoint(max(1, config.checkpoint_freq // config.n_envs)))
    if progress:
        cbs.append(Progress())
    return cbs
