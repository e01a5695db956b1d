"""EKF baseline: the numpy oracle's Jacobians vs finite differences and its update vs a
textbook KF, the compiled filter vs a hand-written linear KF and vs the oracle over a flight,
seeded accuracy and clear errors."""

import dataclasses

import numpy as np
import pytest
from oracles.ekf_numpy import (
    NOISE_REFERENCE_DT,
    attitude_jacobian,
    kalman_update,
    measurement_update,
    predict,
)

from estimators.base import Sample, samples
from estimators.ekf import EKFConfig, MotorEfficiencyEKF
from estimators.freshness import HELD_VARIANCE
from quadfault.errors import ConfigError
from quadfault.model.rotation import expm_so3, hat, logm_so3, vee
from quadfault.model.scenarios import ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Circle
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import simulate

TRUE_ETA = (0.9, 0.75, 1.0, 0.6)


@pytest.fixture(scope="module")
def vehicle():
    return Vehicle()


@pytest.fixture(scope="module")
def recording():
    """2 s of a circle with fixed, unequal efficiencies and sigma_f = 0.07 (seeded)."""
    sc = Scenario(
        "const", 2.0, EfficiencySchedule(ConstantEfficiency(TRUE_ETA)), Circle(), thrust_noise=0.07
    )
    return simulate(sc, seed=3)


def _random_state(rng, n=4):
    R = expm_so3(rng.normal(size=3))
    return np.concatenate(
        (
            rng.normal(size=3),
            rng.normal(size=3),
            rng.normal(size=3) * 2,
            R.reshape(9, order="F"),
            rng.uniform(0.5, 1.0, n),
        )
    )


def test_predict_jacobian_matches_central_differences(vehicle):
    rng = np.random.default_rng(0)
    x = _random_state(rng)
    f = rng.uniform(1.0, 4.0, 4)
    dt = 0.01  # large step so every block of F is far from identity
    Q = np.zeros((22, 22))
    _, _, F = predict(x, np.eye(22), f, dt, vehicle, Q)
    h = 1e-6
    F_num = np.empty_like(F)
    for i in range(22):
        d = np.zeros(22)
        d[i] = h
        F_num[:, i] = (
            predict(x + d, np.eye(22), f, dt, vehicle, Q)[0]
            - predict(x - d, np.eye(22), f, dt, vehicle, Q)[0]
        ) / (2 * h)
    np.testing.assert_allclose(F, F_num, atol=1e-8)
    # the gyroscopic block is not the identity the reference used
    assert np.max(np.abs(F[6:9, 6:9] - np.eye(3))) > 1e-4


def test_predicted_attitude_stays_on_so3(vehicle):
    rng = np.random.default_rng(1)
    x = _random_state(rng)
    xp, _, _ = predict(x, np.eye(22), rng.uniform(1, 4, 4), 0.02, vehicle, np.zeros((22, 22)))
    R = xp[9:18].reshape(3, 3, order="F")
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-13)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-13)


def test_attitude_jacobian_is_the_derivative_of_the_rotation_error():
    rng = np.random.default_rng(2)
    R_meas = expm_so3(rng.normal(size=3))
    R_est = R_meas @ expm_so3(1e-3 * rng.normal(size=3))

    def g(vecR):
        A = vecR.reshape(3, 3, order="F").T @ R_meas
        return vee(0.5 * (A - A.T))

    H = attitude_jacobian(R_meas)
    v0 = R_est.reshape(9, order="F")
    num = np.stack([(g(v0 + 1e-6 * e) - g(v0 - 1e-6 * e)) / 2e-6 for e in np.eye(9)], axis=1)
    np.testing.assert_allclose(H, -num, atol=1e-9)
    # well-defined at zero error: full rank, unlike d acos / d vec(R)
    assert np.linalg.matrix_rank(attitude_jacobian(np.eye(3))) == 3
    # innovation log(R_est^T R_meas) agrees with the skew part to first order
    np.testing.assert_allclose(logm_so3(R_est.T @ R_meas), g(v0), rtol=1e-5)  # theta^2 / 6


def test_joseph_update_equals_textbook_kalman_filter():
    rng = np.random.default_rng(4)
    n, m = 22, 12
    L = rng.normal(size=(n, n))
    P = L @ L.T + n * np.eye(n)
    H = rng.normal(size=(m, n))
    Rn = np.diag(rng.uniform(0.1, 1.0, m))
    x, y = rng.normal(size=n), rng.normal(size=m)
    x1, P1 = kalman_update(x, P, y, H, Rn)
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + Rn)
    np.testing.assert_allclose(x1, x + K @ y, atol=1e-9)
    np.testing.assert_allclose(P1, (np.eye(n) - K @ H) @ P, atol=1e-9)


def test_ekf_step_equals_linear_kalman_filter_at_level_attitude(vehicle):
    """R = I, Omega = 0 and equal rotor commands at equal efficiency: the attitude stays level
    (zero moment), so the model is linear at this point and one EKF cycle must equal a plain
    KF written here by hand (F and H derived independently of the EKF code)."""
    dt, m, f0 = 1e-3, vehicle.mass, 2.0
    cfg = EKFConfig(q_eta=1e-3)
    ekf = MotorEfficiencyEKF(vehicle, cfg)
    z0 = Sample(
        0.0,
        np.array([1.0, 2.0, -1.0]),
        np.array([0.5, -0.2, 0.1]),
        np.eye(3),
        np.zeros(3),
        np.full(4, f0),
    )
    ekf.update(z0)
    z1 = Sample(
        dt,
        np.array([1.0006, 1.9998, -0.9999]),
        np.array([0.49, -0.21, 0.12]),
        np.eye(3),
        np.array([0.01, -0.02, 0.003]),
        np.full(4, f0),
    )
    ekf.update(z1)
    # --- plain KF by hand
    x = np.concatenate((z0.p, z0.v, z0.w, np.eye(3).reshape(9, order="F"), np.ones(4)))
    T = 4 * f0
    e3 = np.array([0.0, 0.0, 1.0])
    a = vehicle.gravity * e3 - T / m * e3
    F = np.eye(22)
    F[0:3, 3:6] = dt * np.eye(3)
    F[0:3, 15:18] = -(T / m) * dt * dt / 2 * np.eye(3)
    F[3:6, 15:18] = -(T / m) * dt * np.eye(3)
    F[0:3, 18:] = -np.outer(e3, np.full(4, f0)) / m * dt * dt / 2
    F[3:6, 18:] = -np.outer(e3, np.full(4, f0)) / m * dt
    B = vehicle.inertia_inverse @ vehicle.allocation[1:] * f0  # d Omega' / d eta
    F[6:9, 18:] = dt * B
    for i in range(3):  # d vec(R exp(phi)) / d phi at R = I, phi = 0: vec(hat(e_i))
        F[9:18, 6 + i] = hat(np.eye(3)[i]).reshape(9, order="F") * dt
        F[9:18, 18:] += np.outer(hat(np.eye(3)[i]).reshape(9, order="F"), 0.5 * dt * dt * B[i])
    x_pred = x.copy()
    x_pred[0:3] += x[3:6] * dt + 0.5 * a * dt * dt
    x_pred[3:6] += a * dt
    P = cfg.p0 * np.eye(22)
    P = F @ P @ F.T + np.diag(ekf.q_diag)
    H = np.zeros((12, 22))
    H[:9, :9] = np.eye(9)
    for k, (i, j) in enumerate(((2, 1), (0, 2), (1, 0))):  # -d vee(skew(R)) / d vec(R)
        H[9 + k, 9 + 3 * j + i] = -0.5
        H[9 + k, 9 + 3 * i + j] = 0.5
    Rm = np.diag(ekf.r_diag[:12])  # (no accelerometer: its row is the last)
    # the attitude repeats bit for bit: a held stream, not measured again (estimators.freshness)
    Rm[9:, 9:] = HELD_VARIANCE * np.eye(3)
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + Rm)
    y = np.concatenate((np.concatenate((z1.p, z1.v, z1.w)) - x_pred[:9], np.zeros(3)))
    x_new = x_pred + K @ y  # the attitude innovation is zero: R_pred = R_meas = I
    P_new = (np.eye(22) - K @ H) @ P
    np.testing.assert_allclose(ekf.x[:9], x_new[:9], atol=1e-9)
    np.testing.assert_allclose(ekf.x[18:], x_new[18:], atol=1e-9)
    np.testing.assert_allclose(ekf.P, P_new, atol=1e-9)


@pytest.mark.slow
def test_compiled_filter_equals_the_numpy_oracle_over_a_flight(recording):
    """The one compiled filter (square-root update, structured F P F^T) against the numpy
    oracle (dense F, Joseph form) over 400 samples, offline and online."""
    rec = recording.slice(0, 400).without_truth()
    ekf = MotorEfficiencyEKF(rec.vehicle, EKFConfig(q_eta=1e-4))
    offline = ekf.run(rec)
    rows = list(samples(rec))
    x = np.concatenate(
        (rows[0].p, rows[0].v, rows[0].w, rows[0].R.reshape(9, order="F"), np.ones(4))
    )
    P = ekf.config.p0 * np.eye(22)
    for k in range(1, len(rows)):
        dt = rows[k].t - rows[k - 1].t
        Q = np.diag(ekf.q_diag * (dt / NOISE_REFERENCE_DT))
        f = np.clip(rows[k - 1].f, 0.0, rec.vehicle.rotor_max_thrust)
        x, P, _ = predict(x, P, f, dt, rec.vehicle, Q)
        x, P = measurement_update(x, P, rows[k], ekf.r_diag, ekf.config.eta_bounds)
        np.testing.assert_allclose(offline.eta[k], x[18:], rtol=0, atol=1e-9)
        np.testing.assert_allclose(offline.sd[k], np.sqrt(np.diag(P)[18:]), rtol=1e-9)
    np.testing.assert_allclose(ekf.P, P, rtol=0, atol=1e-9 * np.abs(P).max())
    online = MotorEfficiencyEKF(rec.vehicle, EKFConfig(q_eta=1e-4))
    etas = np.array([online.update(s).eta for s in rows])
    np.testing.assert_array_equal(etas, offline.eta)  # one kernel: bit for bit


def test_seeded_accuracy_on_constant_efficiencies(recording):
    # a slow filter (q_eta = 1e-5) over 2 s: the box at 1 tells it the healthy rotor 3 cannot
    # read above 1, which settles the weakly observed yaw-differential direction in time
    # (with the default box up to 1.2 that direction takes longer than this flight)
    cfg = EKFConfig(q_eta=1e-5, eta_bounds=(-0.001, 1.001))
    est = MotorEfficiencyEKF(recording.vehicle, cfg).run(recording.without_truth())
    assert est.estimator == "ekf" and est.eta.shape == (len(recording), 4)
    assert est.status[0] == "warmup" and set(est.status[1:]) == {"ok"}
    final = est.eta[-200:].mean(axis=0)
    np.testing.assert_allclose(final, TRUE_ETA, atol=0.05)
    # the measurements inform eta: sd ends below the prior's random-walk growth
    prior_sd = np.sqrt(1e-2 + (len(recording) - 1) * 1e-5)
    assert np.all(est.sd[-1] < 0.8 * prior_sd) and np.all(est.sd[-1] > 1e-4)
    assert est.seconds > 0


def test_reference_clamp_and_default_bounds(recording):
    rec = recording.slice(0, 300).without_truth()
    wild = MotorEfficiencyEKF(rec.vehicle, EKFConfig(q_eta=5.0, eta_bounds=None)).run(rec)
    assert wild.eta.max() > 1.001 or wild.eta.min() < -0.001  # the clamp matters here
    ref = MotorEfficiencyEKF(rec.vehicle, EKFConfig.reference(q_eta=5.0)).run(rec)
    assert ref.eta[1:].min() >= 1e-3 and ref.eta[1:].max() <= 1 - 1e-3  # row 0: eta0
    ours = MotorEfficiencyEKF(rec.vehicle, EKFConfig(q_eta=5.0)).run(rec)
    assert ours.eta.min() >= -0.001 and ours.eta.max() <= 1.2


@pytest.mark.parametrize(
    "changes",
    [{"q_eta": 0.0}, {"r_attitude": -1.0}, {"p0": float("nan")}, {"eta_bounds": (1.0, 0.0)}],
)
def test_bad_config_is_a_clear_error(changes):
    with pytest.raises(ConfigError, match="EKFConfig"):
        EKFConfig(**changes)


def test_time_must_increase_and_bad_samples_are_skipped(vehicle):
    ekf = MotorEfficiencyEKF(vehicle, EKFConfig())
    s = Sample(0.0, np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3), np.full(4, 2.45))
    assert ekf.update(s).status == "warmup"
    bad = s._replace(t=0.001, p=np.array([np.nan, 0, 0]))
    assert ekf.update(bad).status == "bad_sample"
    before = ekf.x.copy()
    repeated = ekf.update(s)  # t = 0.0 again: skipped, state kept (as IRLS does)
    assert repeated.status == "bad_sample"
    np.testing.assert_array_equal(ekf.x, before)


def test_malformed_sample_is_a_clear_error(vehicle):
    ekf = MotorEfficiencyEKF(vehicle, EKFConfig())
    s = Sample(0.0, np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3), np.full(3, 2.45))
    with pytest.raises(ConfigError, match="shapes"):
        ekf.update(s)


def test_imu_only_recording_is_refused(recording):
    imu = dataclasses.replace(recording, position=None, velocity=None, quaternion=None)
    with pytest.raises(ConfigError, match="IMU-only"):
        MotorEfficiencyEKF(recording.vehicle, EKFConfig()).run(imu)
