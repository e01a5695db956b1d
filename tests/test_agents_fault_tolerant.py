"""Closed loop: the estimate-aware controller against the plain geometric one."""

import math

import numpy as np
import pytest

from agents.fault_tolerant import EstimateAwareController, FaultTolerantConfig, bounded_heading
from agents.rollout import FlightConfig, fly
from agents.suite import single_motor_failure
from quadfault.errors import ConfigError
from quadfault.model.rotation import expm_so3
from quadfault.model.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Circle, Hover
from quadfault.model.vehicle import Vehicle


def _abrupt(duration=2.0, onset=0.5, level=0.5):
    sched = EfficiencySchedule(ConstantEfficiency(), (AbruptFault(1, onset, level=level),))
    return Scenario("abrupt_short", duration, sched, Circle(), thrust_noise=0.07)


@pytest.mark.slow
def test_estimate_aware_with_irls_beats_plain_on_abrupt_fault():
    sc = _abrupt(duration=1.5, onset=0.4)
    plain = fly(sc, "geometric", "none", seed=3)
    aware = fly(sc, "estimate-aware", "irls", seed=3)
    assert not aware.metrics.crashed
    assert aware.metrics.rmse < 0.8 * plain.metrics.rmse
    # the estimate the controller used found the weak motor (the loop really closed on it)
    assert abs(aware.eta_hat[-1, 0] - 0.5) < 0.1
    assert np.all(np.abs(aware.eta_hat[-1, 1:] - 1.0) < 0.1)


def test_estimate_aware_equals_plain_without_fault():
    sc = Scenario("nominal", 0.5, EfficiencySchedule(), Circle(), thrust_noise=0.0)
    a = fly(sc, "geometric", "none", seed=0)
    b = fly(sc, "estimate-aware", "none", seed=0)
    np.testing.assert_allclose(a.f_cmd, b.f_cmd, atol=1e-9)
    assert b.modes == {"exact": 500}


@pytest.mark.slow
def test_single_motor_at_03_plain_crashes_estimate_aware_survives():
    sc = single_motor_failure(level=0.3, duration=3.0, onset=0.5)
    plain = fly(sc, "geometric", "none", seed=0)
    aware = fly(sc, "estimate-aware", "truth", seed=0)
    assert plain.metrics.crashed
    assert not aware.metrics.crashed and aware.metrics.rmse < 0.05
    assert aware.modes.get("yaw_released", 0) > 0  # it gave yaw up to stay level
    assert abs(aware.yaw_rate[-1]) > 1.0  # ... and spins


def test_flight_is_deterministic_under_seed():
    sc = _abrupt(duration=0.3, onset=0.1)
    a = fly(sc, "estimate-aware", "truth", seed=5)
    b = fly(sc, "estimate-aware", "truth", seed=5)
    c = fly(sc, "estimate-aware", "truth", seed=6)
    np.testing.assert_array_equal(a.p, b.p)
    assert a.metrics == b.metrics
    assert not np.array_equal(a.p, c.p)


def test_controller_never_reads_truth_attribute():
    """The estimate-aware controller's command depends on eta_hat, not on the plant."""
    veh = Vehicle()
    ctrl = EstimateAwareController(veh, Hover())
    p, v, R, w = np.array([0, 0, -1.0]), np.zeros(3), np.eye(3), np.zeros(3)
    f1 = ctrl.command(0.0, p, v, R, w, np.ones(4)).f
    f2 = ctrl.command(0.0, p, v, R, w, np.array([0.5, 1, 1, 1])).f
    np.testing.assert_allclose(f1, veh.hover_thrust)
    assert f2[0] > f1[0]  # the weak motor is asked for more


def test_bounded_heading():
    R = expm_so3(np.array([0.0, 0.0, 0.2]))
    ref = np.array([1.0, 0.0, 0.0])
    assert bounded_heading(R, ref, 0.5) is ref
    b = bounded_heading(expm_so3(np.array([0.0, 0.0, 2.0])), ref, 0.5)
    assert math.atan2(b[1], b[0]) == pytest.approx(1.5)
    with pytest.raises(ConfigError, match="max_heading_error"):
        FaultTolerantConfig(max_heading_error=-1.0)


def test_unknown_estimator_and_controller():
    sc = _abrupt(duration=0.1)
    with pytest.raises(ConfigError, match="unknown estimator"):
        fly(sc, "estimate-aware", "kalman")
    with pytest.raises(ConfigError, match="unknown controller"):
        fly(sc, "pid", "none")
    with pytest.raises(ConfigError, match="estimator_every"):
        FlightConfig(estimator_every=0)
