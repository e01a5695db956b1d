"""The accelerometer in the Kalman filters (``EKFConfig.accelerometer``,
``UKFConfig.accelerometer``): one more measurement row, the body-z specific force
``-T(eta) / m`` of the sample's own command. Off is the plain filter bit for bit (the goldens
check whole recordings); on, the compiled EKF equals the numpy oracle with that row and the
UKF a linear Kalman filter where its model is linear; online = offline = batched; a held
reading is not measured again; under the INDIflight preset's sensors the filters with it
are closer to the truth; bad settings and readings are one-line errors."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest

from estimators.accelerometer import AccelerometerMissing
from estimators.base import samples
from estimators.batched import BatchedEKF
from estimators.ekf import NOISE_REFERENCE_DT, EKFConfig, MotorEfficiencyEKF
from estimators.metrics import score
from estimators.ukf import BatchedUKF, UKFConfig, UnscentedKalmanFilter
from quadfault.errors import ConfigError
from quadfault.io.sample import Sample
from quadfault.model.scenarios import named_scenario
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import SimConfig, simulate
from tests.oracles.ekf_numpy import measurement_update, predict


@pytest.fixture(scope="module")
def flight():
    """2 s of the abrupt scenario, noise-free sensors, thrust noise 0.07: every accelerometer
    reading fresh."""
    rec = simulate(
        named_scenario("abrupt", 2.0), config=SimConfig(saturate=False), seed=5, thrust_noise=0.07
    )
    assert rec.accel is not None
    return rec


FILTERS = {
    "ekf": (MotorEfficiencyEKF, EKFConfig, BatchedEKF),
    "ukf": (UnscentedKalmanFilter, UKFConfig, BatchedUKF),
}


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_off_ignores_the_readings_and_auto_without_them_is_the_plain_filter(flight, name):
    single, config, _ = FILTERS[name]
    rec = flight.without_truth()
    plain = single(rec.vehicle).run(rec)
    off = single(rec.vehicle, config(accelerometer="off")).run(rec)
    np.testing.assert_array_equal(off.eta, plain.eta)
    none = dataclasses.replace(rec, accel=None)
    auto = single(rec.vehicle, config(accelerometer="auto")).run(none)
    np.testing.assert_array_equal(auto.eta, plain.eta)
    on = single(rec.vehicle, config(accelerometer="on")).run(rec)
    assert not np.array_equal(on.eta, plain.eta)


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_on_without_readings_says_so_once_and_runs_plain(flight, name):
    single, config, _ = FILTERS[name]
    rec = dataclasses.replace(flight.without_truth(), accel=None)
    plain = single(rec.vehicle).run(rec)
    with pytest.warns(AccelerometerMissing, match="no accelerometer"):
        on = single(rec.vehicle, config(accelerometer="on")).run(rec)
    np.testing.assert_array_equal(on.eta, plain.eta)
    est = single(rec.vehicle, config(accelerometer="on"))
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        for s in list(samples(rec))[:5]:
            est.update(s)
    assert sum(issubclass(w.category, AccelerometerMissing) for w in said) == 1


@pytest.mark.slow
def test_compiled_filter_with_the_accelerometer_equals_the_numpy_oracle(flight):
    """The accelerometer's row ``a_z = ha . eta``, ``ha_j = -A[0, j] f_j / m`` with the
    sample's own command, variance ``r_accel + accel_scatter^2 |ha|^2``, added to the numpy
    oracle's update (dense, Joseph form): the same estimates over 300 samples."""
    rec = flight.slice(0, 300).without_truth()
    cfg = EKFConfig(q_eta=1e-4, accelerometer="on", r_accel=0.2, accel_scatter=0.3)
    ekf = MotorEfficiencyEKF(rec.vehicle, cfg)
    offline = ekf.run(rec)
    rows = list(samples(rec))
    veh = rec.vehicle
    x = np.concatenate(
        (rows[0].p, rows[0].v, rows[0].w, rows[0].R.reshape(9, order="F"), np.ones(4))
    )
    P = cfg.p0 * np.eye(22)
    for k in range(1, len(rows)):
        dt = rows[k].t - rows[k - 1].t
        Q = np.diag(ekf.q_diag * (dt / NOISE_REFERENCE_DT))
        f = np.clip(rows[k - 1].f, 0.0, veh.rotor_max_thrust)
        x, P, _ = predict(x, P, f, dt, veh, Q)
        h = -np.asarray(veh.allocation)[0] * np.clip(rows[k].f, 0.0, veh.rotor_max_thrust)
        h = h / veh.mass
        var = cfg.r_accel + cfg.accel_scatter**2 * float(h @ h)
        accel = (rows[k].accel[2], h, var)
        x, P = measurement_update(x, P, rows[k], ekf.r_diag, cfg.eta_bounds, accel)
        np.testing.assert_allclose(offline.eta[k], x[18:], rtol=0, atol=1e-9)
        np.testing.assert_allclose(offline.sd[k], np.sqrt(np.diag(P)[18:]), rtol=1e-8)


def test_ukf_equals_a_linear_kalman_filter_at_rest_with_the_accelerometer():
    """Hovering level with no rate the UKF's model is linear (v' = v + (g e3 - T e3 / m) dt,
    Omega' = Omega + J^-1 M dt) and so is the accelerometer's row (a_z = h . eta): its
    sigma-point moments equal a Kalman filter's with H = [I_6 0; 0 h^T] written here."""
    veh = Vehicle()
    cfg = UKFConfig(eta_bounds=None, accelerometer="on", r_accel=0.3, accel_scatter=0.2)
    ukf = UnscentedKalmanFilter(veh, cfg)
    n, dt = 4, 1e-3
    A, m, g = veh.allocation, veh.mass, veh.gravity
    rng = np.random.default_rng(5)
    f = np.full(n, veh.hover_thrust)
    F = np.eye(6 + n)
    F[2, 6:] = -A[0] * f / m * dt
    F[3:6, 6:] = veh.inertia_inverse @ (A[1:] * f) * dt
    u = np.zeros(6 + n)
    u[2] = g * dt
    Q = np.diag(
        np.r_[np.full(3, cfg.q_velocity), np.full(3, cfg.q_rate), np.full(n, cfg.q_eta)]
    ) * (dt / 1e-3)
    h = -A[0] * f / m
    Rn = np.diag(
        np.r_[np.full(3, cfg.r_velocity), np.full(3, cfg.r_rate), cfg.r_accel + 0.04 * h @ h]
    )
    H = np.zeros((7, 6 + n))
    H[:6, :6] = np.eye(6)
    H[6, 6:] = h
    x, P = np.r_[np.zeros(6), np.ones(n)], cfg.p0 * np.eye(6 + n)
    a0 = np.array([0.0, 0.0, -g])
    ukf.update(Sample(0.0, np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3), f, a0))
    for k in range(1, 4):
        z = 1e-3 * rng.normal(size=7)  # small, so the gyroscopic term stays negligible
        z[6] = -g + 0.05 * rng.normal()
        x, P = F @ x + u, F @ P @ F.T + Q
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + Rn)
        x, P = x + K @ (z - H @ x), (np.eye(6 + n) - K @ H) @ P
        s = Sample(k * dt, np.zeros(3), z[:3], np.eye(3), z[3:6], f, np.r_[0.0, 0.0, z[6]])
        est = ukf.update(s)
        np.testing.assert_allclose(ukf.x, x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(ukf.P, P, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(est.sd, np.sqrt(np.diag(P)[6:]), rtol=1e-6)


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_online_offline_and_batched_agree(flight, name):
    single, config, batched = FILTERS[name]
    rec = flight.slice(0, 200).without_truth()
    vehicle = rec.vehicle.replace(max_thrust=math.inf)  # unsaturated, as run() reads it
    cfg = config(accelerometer="on")
    offline = single(vehicle, cfg).run(rec)
    online = single(vehicle, cfg)
    batch = batched(vehicle, 2, cfg)
    for k, s in enumerate(samples(rec)):
        eta = online.update(s).eta
        np.testing.assert_array_equal(eta, offline.eta[k])
        out = batch.update(
            *(np.array([getattr(s, a)] * 2) for a in ("t", "p", "v", "R", "w", "f", "accel"))
        )
        np.testing.assert_array_equal(out.eta[1], eta)


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_a_held_reading_is_not_measured_again(flight, name):
    """Every other reading repeated bit for bit (a 500 Hz accelerometer on a 1 kHz log) runs
    as if those rows had no reading (NaN) at all."""
    single, config, _ = FILTERS[name]
    rec = flight.slice(0, 400).without_truth()
    held, missing = rec.accel.copy(), rec.accel.copy()
    held[1::2] = held[0:-1:2]
    missing[1::2] = np.nan
    cfg = config(accelerometer="on")
    a = single(rec.vehicle, cfg).run(dataclasses.replace(rec, accel=held))
    b = single(rec.vehicle, cfg).run(dataclasses.replace(rec, accel=missing))
    np.testing.assert_array_equal(a.eta, b.eta)


@pytest.fixture(scope="module")
def indiflight():
    """10 s of the abrupt scenario with the INDIflight preset's sensors (velocity 0.18 m/s of
    coloured noise at 105 Hz, accelerometer 0.15 m/s^2 white with a bias)."""
    return simulate(
        named_scenario("abrupt", 10.0),
        config=SimConfig(saturate=False, sensor_noise="indiflight"),
        seed=1,
        thrust_noise=0.07,
    )


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FILTERS))
def test_the_accelerometer_helps_under_the_indiflight_preset(indiflight, name):
    """The filter with the accelerometer's row is closer to the truth, default tuning."""
    single, config, _ = FILTERS[name]
    rec, data = indiflight, indiflight.without_truth()
    rmse = {
        mode: float(
            np.mean(score(rec, single(rec.vehicle, config(accelerometer=mode)).run(data)).rmse)
        )
        for mode in ("off", "on")
    }
    assert rmse["on"] < 0.9 * rmse["off"], rmse


@pytest.mark.parametrize(
    "changes,match",
    [
        ({"accelerometer": "maybe"}, "accelerometer must be one of off, auto, on"),
        ({"r_accel": 0.0}, "r_accel must be a positive number"),
        ({"r_accel": "0.1"}, "r_accel must be a positive number"),
        ({"accel_scatter": -0.1}, "accel_scatter must be >= 0"),
        ({"accel_scatter": math.nan}, "accel_scatter must be a finite number"),
    ],
)
@pytest.mark.parametrize("name", sorted(FILTERS))
def test_bad_settings_are_one_line_errors(changes, match, name):
    with pytest.raises(ConfigError, match=match) as err:
        FILTERS[name][1](**changes)
    assert "\n" not in str(err.value)


def test_a_reading_of_the_wrong_shape_is_a_one_line_error(flight):
    rec = flight.without_truth()
    s = next(iter(samples(rec)))._replace(accel=np.zeros(4))
    with pytest.raises(ConfigError, match="accelerometer reading of shape") as err:
        MotorEfficiencyEKF(rec.vehicle, EKFConfig(accelerometer="on")).update(s)
    assert "\n" not in str(err.value)
    batch = BatchedEKF(rec.vehicle, 2, EKFConfig(accelerometer="on"))
    s = next(iter(samples(rec)))
    args = (np.array([getattr(s, a)] * 2) for a in ("t", "p", "v", "R", "w", "f"))
    with pytest.raises(ConfigError, match="shape"):
        batch.update(*args, accel=np.zeros((2, 4)))
