"""The tasks' scenario generators: smooth random tracks and abrupt rotor losses."""

import math

import numpy as np
import pytest

from quadfault.errors import ConfigError
from quadfault.model.task_scenarios import (
    REFERENCE_ARM,
    SmoothTrack,
    arm_length,
    rotor_loss_scenario,
    size_scale,
    track_scenario,
)
from quadfault.model.vehicle import Vehicle


def crazyflie() -> Vehicle:
    return Vehicle.from_arm(0.046, 0.006, mass=0.03, inertia=np.diag([1.4e-5, 1.4e-5, 2.2e-5]))


def test_smooth_track_derivatives_are_exact_and_it_starts_at_rest():
    tr = SmoothTrack((1.0, -2.0, -1.5), (0.8, -1.2, 0.1), (0.7, 0.4, 0.9), 0.3, 0.2)
    t = np.linspace(0.0, 20.0, 4001)
    out = tr(t)
    h = t[1] - t[0]
    fd_v = np.gradient(out.position, h, axis=0, edge_order=2)
    fd_a = np.gradient(out.velocity, h, axis=0, edge_order=2)
    assert np.max(np.abs(fd_v - out.velocity)) < 1e-4
    assert np.max(np.abs(fd_a - out.acceleration)) < 1e-4
    start = tr(0.0)
    assert np.allclose(start.position, (1.0, -2.0, -1.5))
    assert np.allclose(start.velocity, 0.0)
    assert np.allclose(out.b1d[:, 2], 0.0) and np.allclose(np.linalg.norm(out.b1d, axis=1), 1.0)
    yaw = np.unwrap(np.arctan2(out.b1d[:, 1], out.b1d[:, 0]))
    assert np.allclose(np.diff(yaw) / h, 0.2)


def test_track_scenario_draws_speed_and_curvature_in_their_ranges():
    for seed in range(20):
        sc = track_scenario(
            np.random.default_rng(seed),
            30.0,
            speed=(0.5, 1.5),
            curvature=(0.4, 0.8),
            yaw_rate=(-0.2, 0.1),
        )
        tr = sc.trajectory
        t = np.linspace(0.0, 200.0, 20001)
        v = tr(t).velocity
        for i in range(2):
            peak = np.max(np.abs(v[:, i]))
            assert 0.5 - 1e-3 <= peak <= 1.5 + 1e-9
            assert 0.4 - 1e-12 <= 1.0 / abs(tr.amplitude[i]) <= 0.8 + 1e-12
        assert tr.amplitude[2] == 0.0 and -0.2 <= tr.yaw_rate <= 0.1
        assert sc.duration == 30.0 and sc.efficiency(np.array([0.0, 29.0])).min() == 1.0


def test_track_scenario_is_deterministic_per_generator_and_froude_scaled():
    a = track_scenario(np.random.default_rng(7))
    b = track_scenario(np.random.default_rng(7))
    assert a.trajectory == b.trajectory
    cf = crazyflie()
    s = size_scale(cf)
    assert math.isclose(arm_length(cf.allocation) / REFERENCE_ARM, s) and 0.15 < s < 0.25
    c = track_scenario(np.random.default_rng(7), vehicle=cf)
    # lengths times s, speeds times sqrt(s): the peak accelerations stay the same
    assert np.allclose(np.abs(c.trajectory.amplitude), s * np.abs(a.trajectory.amplitude))
    t = np.linspace(0.0, 60.0, 6001)
    acc_a = np.max(np.abs(a.trajectory(t).acceleration), axis=0)
    acc_c = np.max(np.abs(c.trajectory(t).acceleration), axis=0)
    assert np.allclose(acc_a, acc_c, rtol=0.02)
    assert math.isclose(c.trajectory.center[2], s * a.trajectory.center[2])


def test_rotor_loss_draws_one_rotor_level_and_onset_in_range():
    motors = set()
    for seed in range(40):
        sc = rotor_loss_scenario(
            np.random.default_rng(seed), 10.0, level=(0.0, 0.4), onset=(0.2, 0.5)
        )
        (fault,) = sc.efficiency.faults
        motors.add(fault.motor)
        assert 2.0 <= fault.onset <= 5.0 and 0.0 <= fault.level <= 0.4
        assert math.isinf(fault.duration) and fault.ramp == 0.0
        eta = sc.efficiency(np.array([fault.onset - 0.01, fault.onset + 0.01, 9.99]))
        assert np.all(eta[0] == 1.0)
        assert np.allclose(eta[1:, fault.motor - 1], fault.level, rtol=0, atol=1e-12)
        assert np.allclose(sc.trajectory(0.0).velocity, 0.0)
    assert motors == {1, 2, 3, 4}


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda g: track_scenario(g, speed=(2.0, 1.0)), "speed"),
        (lambda g: track_scenario(g, curvature=(0.0, 1.0)), "curvature must be > 0"),
        (lambda g: track_scenario(g, yaw_rate="fast"), "yaw_rate"),
        (lambda g: track_scenario(g, duration=-1.0), "duration"),
        (lambda g: rotor_loss_scenario(g, level=(0.2, 1.5)), "level"),
        (lambda g: rotor_loss_scenario(g, onset=(0.5, 0.2)), "onset"),
        (lambda g: SmoothTrack(omega=(-1.0, 0.0, 0.0)), "omega"),
    ],
)
def test_bad_ranges_are_refused_with_a_clear_error(call, match):
    with pytest.raises(ConfigError, match=match):
        call(np.random.default_rng(0))


def test_track_with_degradation_and_a_fault_keeps_the_healthy_tracks_trajectory():
    healthy = track_scenario(np.random.default_rng(5))
    faulty = track_scenario(
        np.random.default_rng(5), degradation=(0.8, 0.9), level=(0.3, 0.4), onset=(0.4, 0.5)
    )
    assert faulty.trajectory == healthy.trajectory
    np.testing.assert_array_equal(healthy.efficiency(np.array([0.0, 19.9])), 1.0)
    (fault,) = faulty.efficiency.faults
    assert 0.4 * 20 <= fault.onset <= 0.5 * 20 and 0.3 <= fault.level <= 0.4
    eta = faulty.efficiency(np.array([0.0, fault.onset - 0.01, 20.0]))
    np.testing.assert_allclose(eta[0], 1.0)
    others = np.delete(eta, fault.motor - 1, axis=1)
    assert np.all(np.diff(others, axis=0) < 0)  # every motor degrades gradually
    assert 0.8 <= others[-1, 0] <= 0.9  # to the drawn end level
    assert eta[-1, fault.motor - 1] == pytest.approx(fault.level)


def test_track_degradation_out_of_range_is_a_config_error():
    with pytest.raises(ConfigError, match="degradation"):
        track_scenario(np.random.default_rng(0), degradation=(0.0, 0.9))
