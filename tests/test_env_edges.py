"""QuadFaultEnv at its edges: a diverging state, NaN / inf in the observation, the deprecated
physics keyword."""

import numpy as np
import pytest

from estimators.base import Estimate
from quad_fault_env.envs.quad_fault import QuadFaultEnv
from quadfault.errors import ConfigError
from quadfault.sim.simulator import SensorNoise

FAULT_NOISE = dict(
    scenario="combined",
    duration=1.2,
    thrust_noise=0.07,
    sensor_noise=SensorNoise(position=0.01, velocity=0.02, attitude=0.002, gyro=0.01, accel=0.1),
)


def test_a_diverging_state_stops_the_substeps_and_terminates_non_finite():
    env = QuadFaultEnv("none", **FAULT_NOISE, info="full")
    env.reset(seed=3)
    env.step(np.zeros(4, np.float32))
    env.plant.vehicles.w[0] = (1e80, -2e80, 3e80)  # finite, but its gyroscopic term overflows
    with np.errstate(over="ignore", invalid="ignore"):
        _, _, term, _, info = env.step(np.zeros(4, np.float32))
    assert term and info["termination_reason"] == "non_finite"
    flown = len(info["samples"])
    assert 0 < flown < env.substeps
    for key, width in (("specific_force_samples", 3), ("eta_true_samples", 4)):
        rows = info[key]  # one row per substep of a step; the ones not flown are NaN
        assert rows.shape == (env.substeps, width)
        assert np.isfinite(rows[:flown]).all() and np.isnan(rows[flown:]).all()


def test_observation_is_the_layouts_values_even_for_nan_and_inf():
    """The env's one-vector observation equals ObservationLayout.values (NaN -> fill,
    +-inf -> bound, clipped) for the flat and the dict layouts."""
    for kind in ("flat", "dict"):
        env = QuadFaultEnv("none", "hover", observation=kind)
        env.reset(seed=0)
        env._meas.p[:] = (np.nan, np.inf, -3.0)
        env._meas.w[:] = (-np.inf, 60.0, 0.1)
        env._estimate = Estimate(0.0, np.array([np.nan, 3.0, -1.0, 0.5]), None)
        ref = env.scenario.trajectory(0.0)
        got = env._observation(ref)
        m = env._meas
        want = env.layout.values(
            pos_err=m.p - ref.position,
            vel_err=m.v - ref.velocity,
            R=m.R,
            omega=m.w,
            eta_hat=env._estimate.eta,
            eta_sd=None,
            ref_acc=ref.acceleration,
        )
        if kind == "flat":
            np.testing.assert_array_equal(got, env.layout.flatten(want))
            assert got.dtype == np.float32
        else:
            assert list(got) == list(want)
            for name in want:
                np.testing.assert_array_equal(got[name], want[name])


def test_unknown_keyword_is_a_one_line_error_naming_the_closest():
    import gymnasium as gym

    import quad_fault_env  # noqa: F401  (registers the ids)

    with pytest.raises(
        ConfigError,
        match=r"unknown keyword 'estimater'; did you mean "
        r"'estimator'\?",
    ) as err:
        gym.make("QuadFault-v1", estimater="ekf")
    assert "\n" not in str(err.value)
    with pytest.raises(ConfigError, match="'sensor_nois'; did you mean 'sensor_noise'"):
        QuadFaultEnv("none", "hover", sensor_nois={"position": 0.01})
    # no close match: the valid keywords are listed; the removed no-op keyword is unknown
    with pytest.raises(ConfigError, match="unknown keyword 'xyz'; valid keywords: .*estimator"):
        QuadFaultEnv("none", xyz=1)
    with pytest.raises(ConfigError, match="unknown keyword 'physics'"):
        QuadFaultEnv("none", physics="numpy")


def test_a_configuration_given_whole_flies_as_its_keywords():
    import dataclasses

    from quad_fault_env.envs.env_config import KEYWORDS, EnvConfig

    keywords = dict(scenario="abrupt", duration=0.2, action_mode="wrench", sensor_noise=None)
    cfg = EnvConfig(estimator="none", **keywords)
    assert "estimator" in KEYWORDS and "physics_draws" not in KEYWORDS
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.duration = 1.0  # type: ignore[misc]
    assert cfg.substeps == 10 and cfg.sensor_noise == SensorNoise()
    a, b = QuadFaultEnv(config=cfg), QuadFaultEnv("none", **keywords)
    oa, _ = a.reset(seed=3)
    ob, _ = b.reset(seed=3)
    np.testing.assert_array_equal(oa, ob)
    action = np.array([0.1, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(a.step(action)[0], b.step(action)[0])
    with pytest.raises(ConfigError, match="config must be an EnvConfig, given alone"):
        QuadFaultEnv(config=cfg, duration=1.0)
    with pytest.raises(ConfigError, match="duration must be positive"):
        dataclasses.replace(cfg, duration=-1.0)
