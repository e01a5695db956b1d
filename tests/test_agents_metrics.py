"""Flight metrics on synthetic traces."""

import math

import numpy as np
import pytest

from agents.metrics import RecoveryConfig, flight_metrics, recovery_times, tilt_angle


def _trace(dt=0.01):
    t = np.arange(0, 10, dt)
    e = np.full_like(t, 0.1)
    bump = (t >= 4.0) & (t < 5.5)
    e[bump] = 1.0  # fault at 4 s, error back to 0.1 at 5.5 s
    return t, e


def test_recovery_time_of_a_bump():
    t, e = _trace()
    (rec,) = recovery_times(t, e, [4.0])
    assert rec == pytest.approx(1.5, abs=0.011)


def test_recovery_zero_when_error_never_leaves_threshold():
    t = np.arange(0, 10, 0.01)
    assert recovery_times(t, np.full_like(t, 0.1), [4.0]) == (0.0,)


def test_never_recovers_is_inf():
    t, e = _trace()
    e[t >= 4.0] = 1.0
    assert recovery_times(t, e, [4.0]) == (math.inf,)
    # back below the threshold too late to hold for 0.5 s before the next onset
    t, e = _trace()
    assert recovery_times(t, e, [4.0, 5.8])[0] == math.inf


def test_threshold_floor():
    t = np.arange(0, 10, 0.01)
    e = np.where(t >= 4.0, 0.04, 0.0)  # below the 5 cm floor: no recovery needed
    assert recovery_times(t, e, [4.0], RecoveryConfig(floor=0.05)) == (0.0,)
    assert recovery_times(t, e, [4.0], RecoveryConfig(floor=0.01)) == (math.inf,)


def test_tilt_angle_and_energy():
    assert tilt_angle([0, 0, 1.0], [0, 0, 1.0]) == pytest.approx(0.0)
    assert tilt_angle([0, 1.0, 0], [0, 0, 1.0]) == pytest.approx(90.0)
    t = np.arange(0, 1, 0.001)
    f = np.full((t.size, 4), 2.0)
    f[:, 0] = 10.0  # clipped at f_max = 4.9
    m = flight_metrics(t, np.zeros(t.size), np.zeros(t.size), f, 4.9, 0.001, None, [])
    assert m.energy == pytest.approx((4.9 + 3 * 2.0) * 1.0)
    assert not m.crashed and m.recovery_times == ()
    assert m.to_dict()["crash_time"] is None
