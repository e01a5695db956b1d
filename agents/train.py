"""Train a stable-baselines3 agent (PPO or SAC) on a QuadFault environment.

``python -m agents.train`` or ``quadfault train``. Settings come from flags or a JSON config
file (``--config``; the same keys as :class:`TrainConfig`, flags given explicitly win)::

    quadfault train --algo ppo --env QuadFaultHover-v1 \\
        --env-kwargs '{"estimator": "irls", "action_mode": "residual", "duration": 5}' \\
        --timesteps 20000 --seeds 0 1 2 --n-envs 2 --out runs/ppo_residual

Per seed, ``OUT/seed_<k>/`` holds ``model.zip`` + ``vecnormalize.pkl`` (final),
``best/best_model.zip`` + ``best/vecnormalize.pkl`` (best evaluation on the fixed seeded
episodes of :mod:`agents.train_eval`), ``checkpoints/`` (with their normalisation
statistics), ``evaluations.npz`` (with the geometric controller's returns on the same
episodes), ``monitor/`` and ``train_config.json`` (with the steps actually run:
PPO and SAC train in whole rollouts, :func:`agents.train_eval.planned_timesteps`);
``OUT/learning_curve.png`` is the curve over the seeds (:mod:`agents.learning_curve`);
``--tensorboard`` adds TensorBoard logs. :func:`load_agent` loads a model together with its
``VecNormalize`` statistics.

Needs the ``rl`` extra (stable-baselines3, torch); without it the command stops with a
one-line error.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

from agents.learning_curve import CONFIG_FILE, CURVE_FILE, matching_runs, write_learning_curve
from agents.train_eval import (
    POLICIES,
    VECNORM_FILE,
    budget_line,
    callbacks,
    choose_policy,
    model_files,
    planned_timesteps,
    steps_per_rollout,
)
from estimators.registry import estimator_names
from quadfault.errors import ConfigError, QuadfaultError
from quadfault.fileio import atomic_write_files, atomic_write_text

ALGORITHMS = ("ppo", "sac")
MODEL_FILE = "model.zip"


def require_sb3():
    """Import stable-baselines3 (and torch) or raise a one-line error naming the extra."""
    try:
        import stable_baselines3
        import torch  # noqa: F401
    except ImportError as exc:
        raise QuadfaultError(
            f"training needs stable-baselines3 and torch ({exc.name or exc} is missing): install "
            "a CPU torch, then pip install 'quadfault[rl]' (see the README)"
        ) from None
    import stable_baselines3

    return stable_baselines3


@dataclass(frozen=True)
class TrainConfig:
    """One training run per seed.

    Attributes:
        algo: ``"ppo"`` or ``"sac"``.
        env_id: a registered Gymnasium id (``QuadFault-v1``, ``QuadFaultHover-v1``, ...).
        env_kwargs: keywords of the environment (estimator, action_mode, duration, ...).
        timesteps: environment steps per seed, rounded to the nearest whole rollout (the
            steps run are printed and saved as ``timesteps_run``; :mod:`agents.train_eval`).
        seeds: one run per seed (seeds the algorithm and the environments).
        n_envs: parallel environments (subprocesses when > 1; sub-envs of one array-stepped
            vector env with ``vector_env``).
        vector_env: train on :class:`quad_fault_env.sb3_vec.QuadFaultSB3VecEnv` (``n_envs``
            quadrotors stepped as arrays in this process, the same episodes as the single
            env; QuadFault ids and the named estimators only). Several times more steps per
            CPU second than subprocesses of single envs (docs/throughput.md).
        vec_normalize: normalise observations and rewards (``VecNormalize``).
        policy: an SB3 policy name of :data:`POLICIES`, checked against the observation
            space; None picks ``MultiInputPolicy`` for Dict observations (``observation=
            "dict"``) and ``MlpPolicy`` otherwise.
        eval_freq: evaluate every this many environment steps (all environments together;
            at the start of the first rollout at or after each multiple, and at the end).
        eval_episodes: episodes per evaluation: reset seeds ``eval_seed`` ... ``eval_seed +
            eval_episodes - 1``, the same for every evaluation and every training seed.
        eval_seed: reset seed of the first evaluation episode.
        checkpoint_freq: save a checkpoint every this many steps (0: none).
        tensorboard: TensorBoard log folder, or None.
        progress_bar: SB3's progress bar (needs ``rich``); otherwise quadfault's own bar is
            shown on a terminal.
        algo_kwargs: extra keywords of the algorithm (``learning_rate``, ``n_steps``, ...).
        device: torch device (``"cpu"`` by default).
        torch_threads: CPU threads torch may use. 1 by default: these networks are small
            (two layers of 64), so a second thread adds synchronisation and no speed, and on a
            loaded machine torch's threads wait on each other (docs/agents.md, "torch
            threads"; ``benchmarks/train_speed.py --torch-threads 2`` measures it on yours).
            Kept through the vector env's steps by :func:`set_threads`.
        frame_stack: observations of the last this many steps, oldest first, concatenated
            (SB3's ``VecFrameStack`` in training, gymnasium's ``FrameStackObservation`` in
            evaluation, zeros before the episode's first step): a policy with a short
            memory. 1: the current observation only.
        numba_threads: threads of numba's parallel kernels (the batched estimator and
            physics) in the vector env's steps (``vector_env``). None: the vector env's rule
            (one thread below ``quad_fault_env.vector.THREADS_MIN_BATCH`` sub-envs, numba's
            count when ``NUMBA_NUM_THREADS`` is set): training envs have tens of rows, where a
            parallel region costs more than it saves and idle workers spin, burning CPU that
            parallel runs need (docs/throughput.md, "numba threads").
    """

    algo: str = "ppo"
    env_id: str = "QuadFaultHover-v1"
    env_kwargs: dict = field(default_factory=lambda: {"action_mode": "residual"})
    timesteps: int = 20_000
    seeds: tuple = (0,)
    n_envs: int = 1
    vector_env: bool = False
    vec_normalize: bool = True
    policy: str | None = None
    eval_freq: int = 5_000
    eval_episodes: int = 10
    eval_seed: int = 10_000
    checkpoint_freq: int = 0
    tensorboard: str | None = None
    progress_bar: bool = False
    algo_kwargs: dict = field(default_factory=dict)
    device: str = "cpu"
    torch_threads: int = 1
    numba_threads: int | None = None
    frame_stack: int = 1

    def __post_init__(self):
        if self.algo not in ALGORITHMS:
            raise ConfigError(f"algo must be one of {ALGORITHMS}, got {self.algo!r}")
        if not isinstance(self.env_kwargs, dict) or not isinstance(self.algo_kwargs, dict):
            raise ConfigError("env_kwargs and algo_kwargs must be JSON objects")
        for key in (
            "timesteps",
            "n_envs",
            "eval_freq",
            "eval_episodes",
            "torch_threads",
            "frame_stack",
        ):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"{key} must be a positive integer, got {value!r}")
        if self.policy is not None and self.policy not in POLICIES:
            raise ConfigError(f"policy must be one of {POLICIES} or null, got {self.policy!r}")
        if (
            isinstance(self.eval_seed, bool)
            or not isinstance(self.eval_seed, int)
            or self.eval_seed < 0
        ):
            raise ConfigError(f"eval_seed must be an integer >= 0, got {self.eval_seed!r}")
        if not isinstance(self.checkpoint_freq, int) or self.checkpoint_freq < 0:
            raise ConfigError(
                f"checkpoint_freq must be an integer >= 0, got {self.checkpoint_freq!r}"
            )
        if self.numba_threads is not None and (
            isinstance(self.numba_threads, bool)
            or not isinstance(self.numba_threads, int)
            or self.numba_threads < 1
        ):
            raise ConfigError(
                f"numba_threads must be a positive integer or null, got {self.numba_threads!r}"
            )
        seeds = tuple(self.seeds) if isinstance(self.seeds, (list, tuple)) else (self.seeds,)
        if not seeds or any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds):
            raise ConfigError(f"seeds must be a list of integers >= 0, got {self.seeds!r}")
        object.__setattr__(self, "seeds", seeds)

    @classmethod
    def from_file(cls, path) -> TrainConfig:
        try:
            data = json.loads(Path(path).read_text())
        except json.JSONDecodeError as exc:
            raise ConfigError(f"{path}: not valid JSON ({exc.msg}, line {exc.lineno})") from None
        if not isinstance(data, dict):
            raise ConfigError(f"{path}: the config must be a JSON object")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(
                f"{path}: unknown key(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}"
            )
        return cls(**data)

    def to_dict(self) -> dict:
        out = asdict(self)
        out["seeds"] = list(self.seeds)
        return out


class EnvMaker:
    """Picklable environment constructor (subprocess workers import the registrations)."""

    def __init__(self, env_id: str, env_kwargs: dict):
        self.env_id, self.env_kwargs = env_id, dict(env_kwargs)

    def __call__(self):
        import gymnasium as gym

        import quad_fault_env  # noqa: F401  (registers the ids)

        return gym.make(self.env_id, **self.env_kwargs)


def _env_factory(env_id: str, env_kwargs: dict) -> EnvMaker:
    import gymnasium as gym

    make = EnvMaker(env_id, env_kwargs)
    try:
        make().close()
    except gym.error.Error as exc:
        raise ConfigError(f"environment {env_id!r}: {exc}") from None
    except TypeError as exc:
        raise ConfigError(f"environment {env_id!r} rejected env_kwargs: {exc}") from None
    return make


def make_vec_env(config: TrainConfig, seed: int, n_envs: int, monitor_dir=None):
    """The (optionally subprocess or array-stepped) vectorised, monitored environment, its
    observations stacked over ``config.frame_stack`` steps."""
    from stable_baselines3.common.env_util import make_vec_env as sb3_make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecFrameStack

    make = _env_factory(config.env_id, config.env_kwargs)
    if config.vector_env:
        env = _array_vec_env(config, seed, n_envs, monitor_dir)
    else:
        vec_cls = SubprocVecEnv if n_envs > 1 else DummyVecEnv
        env = sb3_make_vec_env(
            make,
            n_envs=n_envs,
            seed=seed,
            vec_env_cls=vec_cls,
            monitor_dir=None if monitor_dir is None else str(monitor_dir),
        )
    return VecFrameStack(env, config.frame_stack) if config.frame_stack > 1 else env


def make_eval_env(config: TrainConfig):
    """One environment of the run's id and keywords, as its policy sees it (observations
    stacked like the training env's)."""
    env = _env_factory(config.env_id, config.env_kwargs)()
    if config.frame_stack > 1:
        from gymnasium.wrappers import FlattenObservation, FrameStackObservation

        env = FlattenObservation(
            FrameStackObservation(env, config.frame_stack, padding_type="zero")
        )
    return env


def _array_vec_env(config: TrainConfig, seed: int, n_envs: int, monitor_dir=None):
    """``n_envs`` sub-envs of the registered id's :class:`QuadFaultVectorEnv` as an SB3
    VecEnv, monitored (``VecMonitor``: episode returns and lengths in ``monitor_dir``)."""
    from stable_baselines3.common.vec_env import VecMonitor

    from quad_fault_env.sb3_vec import make_sb3_vec_env

    threads = "auto" if config.numba_threads is None else config.numba_threads
    try:
        venv = make_sb3_vec_env(
            n_envs, seed=seed, env_id=config.env_id, numba_threads=threads, **config.env_kwargs
        )
    except TypeError as exc:
        raise ConfigError(
            f"environment {config.env_id!r} (vector) rejected env_kwargs: {exc}"
        ) from None
    if monitor_dir is not None:
        Path(monitor_dir).mkdir(parents=True, exist_ok=True)
        return VecMonitor(venv, str(Path(monitor_dir) / "monitor.csv"))
    return VecMonitor(venv)


def _installed(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None


def set_numba_threads(n: int | None) -> None:
    """Use ``n`` threads in numba's parallel kernels on the calling thread (capped at numba's
    maximum; nothing when ``n`` is None or numba is not installed)."""
    if n is None:
        return
    from quadfault import jit

    if jit.AVAILABLE:
        import numba

        jit.set_threads(min(n, numba.config.NUMBA_NUM_THREADS))


def set_threads(config: TrainConfig) -> None:
    """Set torch's and (for the vector env) numba's CPU threads of the calling thread.

    numba's OpenMP threading layer and torch share one OpenMP runtime. The vector env runs
    its step on its own numba thread count and then restores the caller's
    (``quadfault.jit.threads``), and restoring numba's default count also sets torch's: from
    the 1 asked for to the number of cores, after the first env step. The calling thread's
    numba count is therefore set to the env's own first, which makes the env's switch a
    no-op, and torch's count after it."""
    import torch

    if config.vector_env:
        from quad_fault_env.vector import default_threads

        set_numba_threads(config.numba_threads or default_threads(config.n_envs))
    torch.set_num_threads(config.torch_threads)


def train_one(
    config: TrainConfig, seed: int, run_dir: Path, *, force: bool = False, quiet: bool = False
):
    """Train one seed into ``run_dir``; returns the trained model.

    Runs ``config.timesteps`` rounded to the nearest whole rollout (one line says so when
    it differs, unless ``quiet``; ``train_config.json`` records ``timesteps_run``)."""
    sb3 = require_sb3()
    from stable_baselines3.common.vec_env import VecNormalize

    set_threads(config)
    if config.tensorboard and not _installed("tensorboard"):
        raise QuadfaultError(
            "--tensorboard needs the tensorboard package (pip install tensorboard)"
        )
    # SB3's own bar needs rich; otherwise (or by default) quadfault's tqdm bar is used
    sb3_bar = config.progress_bar and not quiet and _installed("rich") and _installed("tqdm")
    for name in (MODEL_FILE, VECNORM_FILE, CONFIG_FILE):
        if (run_dir / name).exists() and not force:
            raise QuadfaultError(f"{run_dir / name}: already exists; pass --force to overwrite")
    eval_env = make_eval_env(config)
    policy = choose_policy(config.policy, eval_env.observation_space, config.env_id)
    run_dir.mkdir(parents=True, exist_ok=True)
    env = make_vec_env(config, seed, config.n_envs, run_dir / "monitor")
    try:
        if config.vec_normalize:
            env = VecNormalize(env, norm_obs=True, norm_reward=True)
        algo_cls = {"ppo": sb3.PPO, "sac": sb3.SAC}[config.algo]
        kwargs = dict(config.algo_kwargs)
        if isinstance(kwargs.get("train_freq"), list):  # JSON has no tuples: [1, "episode"]
            kwargs["train_freq"] = tuple(kwargs["train_freq"])
        try:
            model = algo_cls(
                policy,
                env,
                seed=seed,
                device=config.device,
                verbose=0,
                tensorboard_log=config.tensorboard,
                **kwargs,
            )
        except (TypeError, ValueError) as exc:
            raise ConfigError(
                f"algo_kwargs rejected by {config.algo.upper()}: {' '.join(str(exc).split())}"
            ) from None
        if config.tensorboard is None:  # SB3's default logger makes an empty temp folder
            from stable_baselines3.common.logger import Logger

            model.set_logger(Logger(folder=None, output_formats=[]))
        rollout = steps_per_rollout(model)
        total = planned_timesteps(config.timesteps, rollout)
        if total != config.timesteps and not quiet:
            print(budget_line(config.algo, seed, config.timesteps, total, model), flush=True)
        model.learn(
            total_timesteps=total,
            callback=callbacks(config, run_dir, eval_env, total, not quiet and not sb3_bar),
            progress_bar=sb3_bar,
            tb_log_name=f"{config.algo}_seed{seed}",
        )
        save_agent(model, run_dir, force=force)
        saved = dict(
            config.to_dict(),
            seed=seed,
            policy=policy,
            timesteps_run=total,
            steps_per_rollout=rollout,
        )
        atomic_write_text(run_dir / CONFIG_FILE, json.dumps(saved, indent=2), force=True)
    finally:
        env.close()
        eval_env.close()
    return model


def save_agent(model, run_dir, *, force: bool = False) -> Path:
    """Save ``model.zip`` and, when the model trains on a ``VecNormalize``, its statistics."""
    run_dir = Path(run_dir)
    path = run_dir / MODEL_FILE
    if path.exists() and not force:
        raise QuadfaultError(f"{path}: already exists; pass --force to overwrite")
    atomic_write_files(model_files(model, path, run_dir / VECNORM_FILE), force=True)
    return path


def load_agent(path, env=None, device: str = "cpu"):
    """Load a saved agent: ``path`` is a run folder, its ``best/`` folder or a ``.zip``.

    Returns ``(model, venv)``: ``venv`` is ``env`` (a Gymnasium env or a VecEnv; ``None`` to
    build one from the saved ``train_config.json``) wrapped in the saved ``VecNormalize``
    statistics (frozen: ``training=False``, rewards not normalised) when there are any.
    """
    sb3 = require_sb3()
    from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecNormalize

    path = Path(path)
    zip_path = path
    if path.is_dir():  # a run folder, or its best/ folder
        zip_path = next(
            (path / n for n in (MODEL_FILE, "best_model.zip") if (path / n).exists()),
            path / MODEL_FILE,
        )
    if not zip_path.exists():
        raise QuadfaultError(f"{zip_path}: no saved model there")
    folder = zip_path.parent
    cfg_path = (
        folder / CONFIG_FILE if (folder / CONFIG_FILE).exists() else folder.parent / CONFIG_FILE
    )
    if env is None:
        if not cfg_path.exists():
            raise QuadfaultError(f"{folder}: no {CONFIG_FILE}; pass the environment explicitly")
        saved = json.loads(cfg_path.read_text())
        env = _env_factory(saved["env_id"], saved["env_kwargs"])()
    venv = env if isinstance(env, VecEnv) else DummyVecEnv([lambda: env])
    if (folder / VECNORM_FILE).exists():
        venv = VecNormalize.load(str(folder / VECNORM_FILE), venv)
        venv.training = False
        venv.norm_reward = False
    algo = None
    if cfg_path.exists():
        algo = json.loads(cfg_path.read_text()).get("algo")
    classes = {"ppo": sb3.PPO, "sac": sb3.SAC}
    order = [classes[algo]] if algo in classes else list(classes.values())
    for cls in order:
        try:
            return cls.load(str(zip_path), env=venv, device=device), venv
        except (KeyError, ValueError, TypeError, AttributeError):
            continue
    raise QuadfaultError(f"{zip_path}: not a PPO or SAC model")


# -- command line -----------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    d = TrainConfig()
    parser.add_argument("--config", help="JSON file with TrainConfig keys (flags override it)")
    parser.add_argument("--algo", choices=ALGORITHMS, help=f"algorithm (default {d.algo})")
    parser.add_argument("--env", dest="env_id", help=f"Gymnasium id (default {d.env_id})")
    parser.add_argument(
        "--env-kwargs",
        help="JSON object of environment keywords, e.g. "
        '\'{"estimator": "irls", "action_mode": "residual"}\'',
    )
    parser.add_argument(
        "--estimator",
        choices=estimator_names(),
        help="shortcut for env_kwargs.estimator (every registered estimator)",
    )
    parser.add_argument(
        "--action-mode",
        choices=("motor", "residual", "wrench"),
        help="shortcut for env_kwargs.action_mode",
    )
    parser.add_argument("--timesteps", type=int, help=f"steps per seed (default {d.timesteps})")
    parser.add_argument("--seeds", type=int, nargs="+", help="one run per seed (default 0)")
    parser.add_argument("--n-envs", type=int, help=f"parallel environments (default {d.n_envs})")
    parser.add_argument(
        "--vector-env",
        action="store_true",
        help="step the n-envs quadrotors as arrays in one process "
        "(QuadFaultVectorEnv; much faster than subprocesses)",
    )
    parser.add_argument(
        "--no-vec-normalize", action="store_true", help="do not normalise observations and rewards"
    )
    parser.add_argument(
        "--eval-freq", type=int, help=f"steps between evaluations (default {d.eval_freq})"
    )
    parser.add_argument(
        "--eval-episodes",
        type=int,
        help=f"fixed seeded episodes per evaluation (default {d.eval_episodes})",
    )
    parser.add_argument(
        "--eval-seed",
        type=int,
        help=f"reset seed of the first evaluation episode (default {d.eval_seed})",
    )
    parser.add_argument(
        "--policy",
        choices=POLICIES,
        help="SB3 policy (default: MultiInputPolicy for Dict observations, MlpPolicy otherwise)",
    )
    parser.add_argument("--checkpoint-freq", type=int, help="steps between checkpoints (0: none)")
    parser.add_argument("--algo-kwargs", help="JSON object of algorithm keywords")
    parser.add_argument("--tensorboard", help="TensorBoard log folder")
    parser.add_argument(
        "--numba-threads",
        type=int,
        help="threads of numba's parallel kernels in the vector env's steps "
        "(default: the vector env's rule by batch size, docs/throughput.md)",
    )
    parser.add_argument(
        "--frame-stack",
        type=int,
        help="stack the observations of the last "
        "this many steps (a policy with a short memory; default 1)",
    )
    parser.add_argument(
        "--torch-threads",
        type=int,
        help="CPU threads of torch (default 1: fastest for these small networks, see TrainConfig)",
    )
    parser.add_argument(
        "--progress",
        action="store_true",
        help="SB3's progress bar (needs rich; quadfault's bar otherwise)",
    )
    parser.add_argument("--out", required=True, help="output folder (one seed_<k>/ per seed)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing run")


def _json_arg(text: str, flag: str) -> dict:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{flag}: not valid JSON ({exc.msg})") from None
    if not isinstance(value, dict):
        raise ConfigError(f"{flag}: must be a JSON object")
    return value


def config_from_args(args) -> TrainConfig:
    cfg = TrainConfig.from_file(args.config) if args.config else TrainConfig()
    changes = {
        k: getattr(args, k)
        for k in (
            "algo",
            "env_id",
            "timesteps",
            "n_envs",
            "eval_freq",
            "eval_episodes",
            "eval_seed",
            "checkpoint_freq",
            "tensorboard",
            "numba_threads",
            "policy",
            "frame_stack",
            "torch_threads",
        )
        if getattr(args, k, None) is not None
    }
    if args.seeds is not None:
        changes["seeds"] = tuple(args.seeds)
    env_kwargs = dict(cfg.env_kwargs)
    if args.env_kwargs:
        env_kwargs.update(_json_arg(args.env_kwargs, "--env-kwargs"))
    if args.estimator:
        env_kwargs["estimator"] = args.estimator
    if args.action_mode:
        env_kwargs["action_mode"] = args.action_mode
    changes["env_kwargs"] = env_kwargs
    if args.algo_kwargs:
        changes["algo_kwargs"] = _json_arg(args.algo_kwargs, "--algo-kwargs")
    if args.no_vec_normalize:
        changes["vec_normalize"] = False
    if getattr(args, "vector_env", False):
        changes["vector_env"] = True
    if args.progress:
        changes["progress_bar"] = True
    return replace(cfg, **changes)


def run(args) -> int:
    config = config_from_args(args)
    require_sb3()
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise QuadfaultError(f"{out}: exists and is not a folder")
    quiet = getattr(args, "quiet", False)
    for seed in config.seeds:
        run_dir = out / f"seed_{seed}"
        model = train_one(config, seed, run_dir, force=args.force, quiet=quiet)
        best = _best_mean_reward(run_dir)
        if not quiet:
            best_text = "n/a" if math.isnan(best) else f"{best:.3f}"
            print(
                f"{config.algo} seed {seed}: {model.num_timesteps} steps, best evaluation "
                f"return {best_text} ({config.eval_episodes} fixed episodes) -> {run_dir}"
            )
    saved = json.loads((out / f"seed_{config.seeds[-1]}" / CONFIG_FILE).read_text())
    runs, other = matching_runs(out, saved)
    data = write_learning_curve(
        runs, out / CURVE_FILE, label=f"{config.algo.upper()} on {config.env_id}"
    )
    if not quiet and data["runs"]:
        note = f"; left out {len(other)} run(s) with other settings" if other else ""
        print(f"learning curve over {len(data['runs'])} seed(s) -> {out / CURVE_FILE}{note}")
    return 0


def _best_mean_reward(run_dir: Path) -> float:
    import numpy as np

    path = run_dir / "evaluations.npz"
    if not path.exists():
        return math.nan
    data = np.load(path)
    return float(np.max(data["results"].mean(axis=1))) if data["results"].size else math.nan


def main(argv=None) -> int:
    import sys

    from quadfault.cli import main as cli_main

    return cli_main(["train", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
