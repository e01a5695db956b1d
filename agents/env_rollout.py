"""Flights of policies that act through the Gymnasium environment (trained SB3 models and
:class:`agents.policies.GeometricPolicy`), scored with the same metrics as :func:`fly`.

The environment runs the scenario at its control rate (100 Hz by default, physics 1 kHz);
traces are kept per control step. The tilt error is measured against the desired body axis
``b3d`` of the geometric controller (eq. 9) evaluated on the true state -- a scoring
quantity only, never shown to the policy.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import quad_fault_env  # noqa: F401  (registers the ids)
from agents.metrics import flight_metrics, tilt_angle
from agents.rollout import Flight, FlightConfig
from quad_fault_env.envs.config import require_full_info
from quadfault.model.controller import ControllerConfig, GeometricController
from quadfault.model.scenarios import Scenario


def make_scenario_env(env_id: str, env_kwargs: dict, scenario: Scenario):
    """``gym.make(env_id)`` flying ``scenario`` for its whole duration, with the full
    ``info`` that :func:`fly_env` scores."""
    kwargs = dict(env_kwargs)
    kwargs.update(scenario=scenario, duration=scenario.duration, info="full")
    rate = float(kwargs.get("control_rate", 100.0))
    return gym.make(env_id, max_episode_steps=int(round(scenario.duration * rate)), **kwargs)


def fly_env(
    policy,
    env,
    scenario: Scenario,
    seed: int,
    *,
    label: str,
    estimator: str,
    normalizer=None,
    config: FlightConfig | None = None,
) -> Flight:
    """One episode of ``policy`` (anything with SB3's ``predict``) in ``env``.

    ``normalizer``: a ``VecNormalize`` whose frozen statistics normalise the observations.
    """
    require_full_info(env, "fly_env")
    cfg = config or FlightConfig()
    inner = env.unwrapped
    obs, info = env.reset(seed=int(seed))
    ctrl = GeometricController(
        inner.vehicle, scenario.trajectory, getattr(inner, "controller_config", ControllerConfig())
    )
    dt = inner.control_period
    ts, err, tilt, fcmd, pos, eta_hat, eta_true, wz = [], [], [], [], [], [], [], []
    crash_time = None
    while True:
        state = inner.plant.state
        t = inner.time
        out = ctrl.compute(t, state.p, state.v, state.R, state.w)
        o = obs if normalizer is None else normalizer.normalize_obs(obs)
        action, _ = policy.predict(o, deterministic=True)
        action = np.clip(np.asarray(action, dtype=float).reshape(-1), -1.0, 1.0)
        obs, _, terminated, truncated, info = env.step(action)
        ts.append(t)
        tilt.append(float(tilt_angle(state.R[:, 2], out.Rd[:, 2])))
        err.append(float(np.linalg.norm(state.p - scenario.trajectory(t).position)))
        fcmd.append(info["motor_command"])
        pos.append(state.p.copy())
        eta_hat.append(info["eta_hat"])
        eta_true.append(info["eta_true"])
        wz.append(float(state.w[2]))
        if terminated:
            crash_time = float(inner.time)
            break
        if truncated:
            break
    t = np.asarray(ts)
    f = np.asarray(fcmd)
    onsets = [a for _, a, _ in scenario.fault_windows()]
    metrics = flight_metrics(
        t, err, tilt, f, inner.vehicle.rotor_max_thrust, dt, crash_time, onsets, cfg.recovery
    )
    return Flight(
        label,
        estimator,
        scenario.name,
        int(seed),
        metrics,
        t,
        np.asarray(pos),
        scenario.trajectory(t).position,
        np.asarray(err),
        np.asarray(tilt),
        np.asarray(wz),
        f,
        np.asarray(eta_hat),
        np.asarray(eta_true),
        {},
    )
