"""GeometricPolicy: SB3-like predict on the environment's observations."""

import numpy as np
import pytest

from agents.policies import GeometricPolicy
from quadfault.errors import ConfigError
from quadfault.model.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Hover

gym = pytest.importorskip("gymnasium")


def _env(action_mode, estimator="truth", duration=1.0):
    import quad_fault_env  # noqa: F401

    sched = EfficiencySchedule(ConstantEfficiency(), (AbruptFault(1, 0.2, level=0.5),))
    sc = Scenario("hover_fault", duration, sched, Hover(), thrust_noise=0.0)
    return gym.make(
        "QuadFault-v0",
        estimator=estimator,
        scenario=sc,
        duration=duration,
        action_mode=action_mode,
        max_episode_steps=int(duration * 100),
        info="full",
    )


def _episode(env, policy, seed=0):
    obs, _ = env.reset(seed=seed)
    errs = []
    while True:
        action, state = policy.predict(obs, deterministic=True)
        assert state is None and action.dtype == np.float32 and action.shape == (4,)
        obs, _, term, trunc, info = env.step(action)
        errs.append(info["tracking_error"])
        if term or trunc:
            return np.array(errs), term


def test_residual_geometric_policy_is_zero_and_batched():
    env = _env("residual")
    policy = GeometricPolicy.from_env(env)
    obs, _ = env.reset(seed=0)
    a, _ = policy.predict(obs)
    np.testing.assert_array_equal(a, np.zeros(4))
    batch, _ = policy.predict(np.stack([obs, obs, obs]))
    assert batch.shape == (3, 4)
    with pytest.raises(ConfigError, match="elements"):
        policy.predict(obs[:5])


def test_estimate_aware_motor_policy_beats_nominal_motor_policy():
    env = _env("motor")
    nominal, _ = _episode(env, GeometricPolicy.from_env(env))
    aware, crashed = _episode(env, GeometricPolicy.from_env(env, estimate_aware=True))
    assert not crashed
    assert np.sqrt(np.mean(aware**2)) < 0.8 * np.sqrt(np.mean(nominal**2))


def test_motor_policy_hovers_at_nominal():
    env = _env("motor")
    obs, _ = env.reset(seed=0)
    a, _ = GeometricPolicy.from_env(env).predict(obs)
    hover = env.unwrapped.vehicle.hover_thrust / env.unwrapped.f_max
    np.testing.assert_allclose(0.5 * (a + 1), hover, atol=0.02)


def test_wrench_mode_cannot_be_estimate_aware():
    with pytest.raises(ConfigError, match="wrench"):
        GeometricPolicy(action_mode="wrench", estimate_aware=True)
