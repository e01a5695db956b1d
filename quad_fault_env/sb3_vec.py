"""stable-baselines3 adapter: :class:`QuadFaultSB3VecEnv` wraps a
:class:`~quad_fault_env.vector.QuadFaultVectorEnv` as an SB3 ``VecEnv``, so PPO / SAC train on
N quadrotors stepped as arrays (no subprocesses)::

    from stable_baselines3 import PPO
    from quad_fault_env.sb3_vec import make_sb3_vec_env

    env = make_sb3_vec_env(64, seed=0, estimator="none", scenario="combined")
    PPO("MlpPolicy", env, n_steps=64).learn(100_000)

SB3 conventions: the vector env runs in ``same_step`` autoreset mode; infos are one dict per
sub-env; a finished sub-env's info is that of its episode's last step, with its last
observation in ``infos[i]["terminal_observation"]`` and ``infos[i]["TimeLimit.truncated"]``
telling truncation from termination. Needs the ``rl`` extra.
"""

from __future__ import annotations

import numpy as np
from gymnasium.vector import AutoresetMode

from quad_fault_env.tasks import registered_kwargs
from quad_fault_env.vector import QuadFaultVectorEnv
from quadfault.errors import ConfigError

try:
    from stable_baselines3.common.vec_env import VecEnv
except ImportError:  # pragma: no cover - the rl extra is optional
    VecEnv = None

_INFO_KEYS = (
    "t",
    "eta_true",
    "eta_hat",
    "eta_sd",
    "estimator_status",
    "tracking_error",
    "termination_reason",
    "scenario",
)


def _base():
    if VecEnv is None:
        raise ConfigError("the SB3 adapter needs stable-baselines3 (install the 'rl' extra)")
    return VecEnv


class QuadFaultSB3VecEnv(VecEnv if VecEnv is not None else object):
    """An SB3 ``VecEnv`` over a same-step-autoreset :class:`QuadFaultVectorEnv`."""

    def __init__(self, venv: QuadFaultVectorEnv):
        _base()
        if not isinstance(venv, QuadFaultVectorEnv):
            raise ConfigError(
                f"QuadFaultSB3VecEnv wraps a QuadFaultVectorEnv, got {type(venv).__name__}"
            )
        if venv.metadata["autoreset_mode"] != AutoresetMode.SAME_STEP:
            raise ConfigError("QuadFaultSB3VecEnv needs autoreset_mode='same_step'")
        self.venv = venv
        self.render_mode = None
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self._actions = None

    def reset(self):
        seeds = self._seeds
        if all(s is None for s in seeds):
            obs, info = self.venv.reset()
        else:
            base = [
                s if s is not None else int(np.random.SeedSequence().entropy % 2**31) for s in seeds
            ]
            obs, info = self.venv.reset(seed=base)
        self.reset_infos = self._split(info)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.clip(
            np.asarray(actions, dtype=float).reshape(self.num_envs, -1), -1.0, 1.0
        )

    def step_wait(self):
        obs, rew, term, trunc, info = self.venv.step(self._actions)
        infos = self._split(info)
        done = term | trunc
        for i in np.flatnonzero(done):  # SB3: the info of the episode's last step
            infos[i] = self._split(info["final_info"], [i])[0]
            infos[i]["terminal_observation"] = _row(info["final_obs"], i)
            infos[i]["TimeLimit.truncated"] = bool(trunc[i] and not term[i])
        return obs, rew.astype(np.float32), done, infos

    def _split(self, info: dict, rows=None) -> list[dict]:
        rows = range(self.num_envs) if rows is None else rows
        return [{k: info[k][i] for k in _INFO_KEYS if k in info} for i in rows]

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name, indices=None):
        """An attribute of the sub-envs' one configuration (the vector env's ``single_env``:
        its vehicle, spaces, action and reward settings), once per index."""
        if attr_name == "render_mode":
            return [None] * len(self._indices(indices))
        return [getattr(self.venv.single_env, attr_name)] * len(self._indices(indices))

    def set_attr(self, attr_name, value, indices=None) -> None:
        raise ConfigError(
            "the sub-envs share one configuration, fixed when the vector env "
            "is made: pass keywords to make_sb3_vec_env instead of set_attr"
        )

    def env_method(self, method_name, *method_args, indices=None, **method_kwargs):
        raise ConfigError(
            "the sub-envs are rows of one vector env, not env objects: call "
            "the vector env (QuadFaultSB3VecEnv.venv) instead of env_method"
        )

    def env_is_wrapped(self, wrapper_class, indices=None):
        return [False] * len(self._indices(indices))

    def _indices(self, indices):
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return indices


def _row(obs, i):
    if isinstance(obs, dict):
        return {k: v[i] for k, v in obs.items()}
    return obs[i]


def make_sb3_vec_env(
    num_envs: int, seed: int | None = None, env_id: str | None = None, **kwargs
) -> QuadFaultSB3VecEnv:
    """A :class:`QuadFaultSB3VecEnv` of ``num_envs`` sub-envs, seeded with ``seed .. seed +
    num_envs - 1``.

    ``env_id``: a registered QuadFault id (``"QuadFaultHover-v1"``): its task's keywords, and
    its step limit when it registers one (``-v0``), as ``gym.make`` and ``gym.make_vec`` use
    them; ``kwargs`` (keywords of :class:`QuadFaultVectorEnv`) override them. Without an id,
    ``kwargs`` alone (the class defaults: the ``-v1`` reward and episode rule)."""
    if env_id is not None:
        kwargs = registered_kwargs(env_id, **kwargs)
    venv = QuadFaultVectorEnv(num_envs, autoreset_mode="same_step", **kwargs)
    env = QuadFaultSB3VecEnv(venv)
    if seed is not None:
        env.seed(seed)
    return env


__all__ = ["QuadFaultSB3VecEnv", "make_sb3_vec_env"]
