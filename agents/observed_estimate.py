"""What a policy observes of the motor efficiency, apart from what the base controller flies on.

In residual mode the environment's base controller (``allocation="estimate-aware"`` or
``"relaxed-hover"``) reads the estimate of the environment's ``estimator``; the same estimate
fills the observation's ``eta_hat`` / ``eta_sd`` slots. A study of what the *policy* gains from
the estimate must keep the base the same and change only what the policy sees.
:class:`ObservedEstimateVectorEnv` does that: the vector env flies exactly as with its
``estimator`` (the base, the physics, the reward), and the two slots carry ``observe``
instead:

* ``"irls"``, ``"ekf"``, ... (a batched estimator of :mod:`estimators.registry`): that
  estimator, run on the same measurement records as the base's (the env's own when it is the
  same name);
* ``"none"``: the nominal belief (efficiency 1, sd ``NOMINAL_PRIOR_SD``), as with
  ``estimator="none"``;
* ``"truth"``: the labelled oracle, the true efficiency with sd 0 (as ``estimator="truth"``).

Every other element of the observation is the env's own (the test checks it). The estimators
see measurements only; the oracle is the only way truth reaches the observation.
"""

from __future__ import annotations

import numpy as np

from estimators.baselines import NOMINAL_PRIOR_SD
from estimators.registry import estimator_names, make_estimator
from quad_fault_env.sb3_vec import QuadFaultSB3VecEnv
from quad_fault_env.tasks import registered_kwargs
from quad_fault_env.vector import QuadFaultVectorEnv
from quadfault.errors import ConfigError

#: what the policy may observe (besides the batched estimators: the belief and the oracle)
OBSERVED = tuple(estimator_names(batched=True)) + ("none", "truth")


class ObservedEstimateVectorEnv(QuadFaultVectorEnv):
    """A :class:`QuadFaultVectorEnv` whose observation carries ``observe``'s estimate while
    the base controller flies on ``estimator``'s (module docstring). ``observe=None`` or
    the env's own estimator name: the plain vector env."""

    def __init__(self, num_envs: int = 1, estimator: str = "irls", *args, observe=None, **kw):
        super().__init__(num_envs, estimator, *args, **kw)
        if observe is not None and observe not in OBSERVED:
            raise ConfigError(f"observe must be one of {', '.join(OBSERVED)}, got {observe!r}")
        #: what the observation's estimate slots carry (None: the env's own estimate)
        self.observe = None if observe == estimator else observe
        n, N = self.vehicle.n_rotors, self.num_envs
        self._obs_estimator = None
        if self.observe is not None and self.estimator is None:
            raise ConfigError(
                f"observe={observe!r} is updated with the env's estimator: the env's "
                f"estimator must be a batched one ({', '.join(estimator_names(batched=True))})"
            )
        if self.observe is not None and self.single_env.observation_kind != "flat":
            raise ConfigError(f"observe={observe!r} needs the flat observation")
        if self.observe in estimator_names(batched=True):
            self._obs_estimator = make_estimator(self.observe, self.vehicle, num=N)
        self._obs_eta, self._obs_sd = np.ones((N, n)), np.full((N, n), np.nan)
        self._final_eta, self._final_sd = self._obs_eta.copy(), self._obs_sd.copy()

    # -- the observed estimate, kept beside the env's -----------------------------------------
    def _start_rows(self, rows) -> None:
        """What the observed estimate is at an episode's start."""
        if self.observe == "none":
            self._obs_eta[rows], self._obs_sd[rows] = 1.0, NOMINAL_PRIOR_SD
        elif self.observe == "truth":
            self._obs_eta[rows], self._obs_sd[rows] = self.eta_true[rows], 0.0
        else:
            self._obs_eta[rows], self._obs_sd[rows] = 1.0, np.nan
        if self._obs_estimator is not None:
            mask = np.zeros(self.num_envs, dtype=bool)
            mask[rows] = True
            self._obs_estimator.reset(mask)

    def episodes_started(self, rows) -> None:
        if self.observe is not None:
            self._start_rows(rows)

    def estimate_updated(self, restarted_rows) -> None:
        if self.observe is None:
            return
        if self._obs_estimator is not None:
            res = self.estimate_on_records(self._obs_estimator)
            self._obs_eta[:], self._obs_sd[:] = res.eta, res.sd
        elif self.observe == "truth":
            self._obs_eta[:] = self.eta_true
        if restarted_rows is not None:
            self._start_rows(restarted_rows)
        # the values of this step, before any row's same-step reset (its final observation)
        self._final_eta[:], self._final_sd[:] = self._obs_eta, self._obs_sd

    def _write(self, obs, eta, sd) -> None:
        """The observed estimate into the flat observations ``obs`` (the layout's bounds and
        fills: NaN sd is "none given")."""
        self.layout.write(obs, "eta_hat", eta)
        self.layout.write(obs, "eta_sd", sd)

    def reset(self, *, seed=None, options=None):
        obs, info = super().reset(seed=seed, options=options)
        if self.observe is not None:
            obs = np.array(obs, copy=True)
            self._write(obs, self._obs_eta, self._obs_sd)
        return obs, info

    def step(self, actions):
        obs, rew, term, trunc, info = super().step(actions)
        if self.observe is None:
            return obs, rew, term, trunc, info
        obs = np.array(obs, copy=True)
        self._write(obs, self._obs_eta, self._obs_sd)
        if "final_obs" in info:
            done = info["_final_obs"]
            final = np.array(info["final_obs"], copy=True)
            self._write(final, self._final_eta, self._final_sd)
            info["final_obs"] = np.where(done[:, None], final, info["final_obs"])
        return obs, rew, term, trunc, info


def observed_sb3_vec_env(
    num_envs: int, env_id: str, observe, seed: int | None = None, **kwargs
) -> QuadFaultSB3VecEnv:
    """An SB3 VecEnv of ``num_envs`` rows of the registered ``env_id`` (its keywords, then
    ``kwargs``) observing ``observe``, seeded ``seed .. seed + num_envs - 1``."""
    venv = ObservedEstimateVectorEnv(
        num_envs,
        autoreset_mode="same_step",
        observe=observe,
        **registered_kwargs(env_id, **kwargs),
    )
    env = QuadFaultSB3VecEnv(venv)
    if seed is not None:
        env.seed(seed)
    return env
