"""RLS with forgetting and the UKF: a seeded abrupt fault recovered as well as the EKF does,
the compiled RLS against a numpy RLS, the UKF against a linear Kalman filter, seeded
determinism, online = offline = batched, and clean errors."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimators.base import Sample, samples
from estimators.ekf import MotorEfficiencyEKF
from estimators.metrics import fault_windows, score
from estimators.residuals import segment_terms
from estimators.rls import BatchedRLS, RecursiveLeastSquares, RLSConfig
from estimators.ukf import BatchedUKF, UKFConfig, UnscentedKalmanFilter
from quadfault.cli import main
from quadfault.errors import ConfigError
from quadfault.io.recording import read_recording
from quadfault.model.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Circle
from quadfault.sim.simulator import simulate

NEW = {"rls": RecursiveLeastSquares, "ukf": UnscentedKalmanFilter}


@pytest.fixture(scope="module")
def abrupt(tmp_path_factory):
    """``quadfault simulate --scenario abrupt --duration 40 --seed 11 --no-saturation``."""
    out = tmp_path_factory.mktemp("abrupt") / "abrupt.csv"
    assert (
        main(
            [
                "simulate",
                "--scenario",
                "abrupt",
                "--duration",
                "40",
                "--seed",
                "11",
                "--no-saturation",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    return read_recording(out)


@pytest.fixture(scope="module")
def ekf_rmse(abrupt):
    return float(
        np.mean(score(abrupt, MotorEfficiencyEKF(abrupt.vehicle).run(abrupt.without_truth())).rmse)
    )


@pytest.fixture(scope="module")
def short():
    """1 s of a circle with unequal efficiencies, a fault at 0.5 s and sigma_f = 0.07."""
    sched = EfficiencySchedule(
        ConstantEfficiency((0.9, 0.8, 1.0, 0.95)), (AbruptFault(motor=2, onset=0.5, level=0.5),)
    )
    return simulate(Scenario("short", 1.0, sched, Circle(), thrust_noise=0.07), seed=4)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(NEW))
def test_recovers_the_seeded_abrupt_faults(abrupt, ekf_rmse, name):
    est = NEW[name](abrupt.vehicle).run(abrupt.without_truth())
    rmse = float(np.mean(score(abrupt, est).rmse))
    assert rmse <= max(0.05, 1.5 * ekf_rmse), (name, rmse, ekf_rmse)
    windows = fault_windows(abrupt)
    assert len(windows) == 4
    for motor, t0, _ in windows:
        k0, k1 = np.searchsorted(est.t, [t0, t0 + 0.5])
        assert est.eta[k0:k1, motor - 1].min() < 0.75, (name, motor, t0)
        before = est.eta[np.searchsorted(est.t, t0 - 0.5), motor - 1]
        assert before > 0.9, (name, motor, before)  # it was healthy before the fault


@pytest.mark.parametrize("name", sorted(NEW))
def test_seeded_runs_are_identical_and_online_equals_offline(short, name):
    rec = short.without_truth()
    a = NEW[name](rec.vehicle).run(rec)
    b = NEW[name](rec.vehicle).run(rec)
    np.testing.assert_array_equal(a.eta, b.eta)
    np.testing.assert_array_equal(a.status, b.status)
    est = NEW[name](rec.vehicle)
    rows = [est.update(s) for s in samples(rec)]
    np.testing.assert_array_equal(np.array([r.eta for r in rows]), a.eta)
    assert rows[0].status == "warmup"
    assert rows[-1].status == "ok" and np.all(rows[-1].sd > 0)
    # the run starts afresh: a second run after online updates gives the same series
    np.testing.assert_array_equal(est.run(rec).eta, a.eta)


@pytest.mark.parametrize("name", sorted(NEW))
def test_short_flight_accuracy(short, name):
    est = NEW[name](short.vehicle).run(short.without_truth())
    truth = short.eta_true
    late = est.t > 0.85  # settled after the fault at 0.5 s
    err = np.abs(est.eta[late] - truth[late]).max(axis=0)
    assert np.all(err < 0.1), (name, err)


def test_rls_equals_a_numpy_rls_over_the_segments(short):
    """The textbook covariance-form RLS in numpy (rows one at a time, weights from the
    rotors' thrust sensitivities) on the residual model of :mod:`estimators.residuals`."""
    rec = short.without_truth().slice(0, 300)
    lam = 0.98
    f = np.clip(rec.thrust_cmd, 0.0, rec.vehicle.rotor_max_thrust)
    seg = segment_terms(
        rec.vehicle, rec.t, rec.position, rec.velocity, rec.rotation, rec.omega, f, np.ones(10)
    )
    theta, P = np.ones(4), np.eye(4)
    expected = [theta.copy()]
    for k in range(len(seg.dt)):
        P = P / lam ** (seg.dt[k] / 1e-3)
        for r in (0, 1, 2, 6, 7, 8):
            phi, y = seg.J[k, r], -seg.r0[k, r]
            c2 = np.sum((phi / f[k]) ** 2)
            if c2 == 0.0:  # a row the thrusts do not reach (level attitude: v_x, v_y)
                continue
            g = 1.0 / c2
            Pphi = P @ phi
            den = 1.0 / g + phi @ Pphi
            theta = theta + Pphi * (y - phi @ theta) / den
            P = P - np.outer(Pphi, Pphi) / den
        theta = np.clip(theta, -0.001, 1.2)
        expected.append(theta.copy())
    cfg = RLSConfig(forgetting=lam, prefilter=0.0)  # the textbook RLS
    got = RecursiveLeastSquares(rec.vehicle, cfg).run(rec)
    np.testing.assert_allclose(got.eta, np.array(expected), rtol=0, atol=1e-10)


def test_ukf_equals_a_linear_kalman_filter_at_rest():
    """Hovering level with no rate, the UKF's model is linear (v' = v + (g e3 - T e3 / m) dt,
    Omega' = Omega + J^-1 M dt): its sigma-point moments equal the Kalman filter's."""
    from quadfault.model.vehicle import Vehicle

    veh = Vehicle()
    cfg = UKFConfig(eta_bounds=None)
    ukf = UnscentedKalmanFilter(veh, cfg)
    n, dt = 4, 1e-3
    A, m, g = veh.allocation, veh.mass, veh.gravity
    Jinv = veh.inertia_inverse
    rng = np.random.default_rng(5)
    f = np.full(n, veh.hover_thrust)
    F = np.eye(6 + n)
    F[2, 6:] = -A[0] * f / m * dt
    F[3:6, 6:] = Jinv @ (A[1:] * f) * dt
    u = np.zeros(6 + n)
    u[2] = g * dt
    Q = np.diag(
        np.r_[np.full(3, cfg.q_velocity), np.full(3, cfg.q_rate), np.full(n, cfg.q_eta)]
    ) * (dt / 1e-3)
    Rn = np.diag(np.r_[np.full(3, cfg.r_velocity), np.full(3, cfg.r_rate)])
    H = np.hstack((np.eye(6), np.zeros((6, n))))
    x, P = np.r_[np.zeros(6), np.ones(n)], cfg.p0 * np.eye(6 + n)
    ukf.update(Sample(0.0, np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3), f))
    for k in range(1, 4):
        z = 1e-3 * rng.normal(size=6)  # small, so the gyroscopic term stays negligible
        x, P = F @ x + u, F @ P @ F.T + Q
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + Rn)
        x, P = x + K @ (z - H @ x), (np.eye(6 + n) - K @ H) @ P
        est = ukf.update(Sample(k * dt, np.zeros(3), z[:3], np.eye(3), z[3:], f))
        np.testing.assert_allclose(ukf.x, x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(ukf.P, P, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(est.sd, np.sqrt(np.diag(P)[6:]), rtol=1e-6)


@pytest.mark.parametrize("name,batched", [("rls", BatchedRLS), ("ukf", BatchedUKF)])
def test_batch_rows_equal_single_filters(short, name, batched):
    recs = [short.without_truth().slice(0, 200), short.without_truth().slice(300, 500)]
    singles = [NEW[name](r.vehicle).run(r) for r in recs]
    batch = batched(recs[0].vehicle, 2)
    rows = [list(samples(r)) for r in recs]
    for k in range(200):
        s = [rows[0][k], rows[1][k]]
        out = batch.update(
            *(np.array([getattr(x, a) for x in s]) for a in ("t", "p", "v", "R", "w", "f"))
        )
        for i in range(2):
            np.testing.assert_array_equal(out.eta[i], singles[i].eta[k])
    batch.reset(mask=[True, False])
    out = batch.update(
        *(
            np.array([getattr(x, a) for x in (rows[0][0], rows[1][0])])
            for a in ("t", "p", "v", "R", "w", "f")
        )
    )
    assert out.status_names[0] == "warmup"


@pytest.mark.parametrize("name", sorted(NEW))
def test_bad_samples_are_skipped_and_time_must_increase(short, name):
    rec = short.without_truth()
    est = NEW[name](rec.vehicle)
    rows = list(samples(rec.slice(0, 20)))
    for s in rows[:10]:
        eta = est.update(s).eta
    bad = est.update(rows[9])  # time not after the previous sample
    assert bad.status == "bad_sample"
    np.testing.assert_array_equal(bad.eta, eta)
    nan = rows[10]._replace(v=np.array([np.nan, 0.0, 0.0]))
    out = est.update(nan)
    assert out.status == "bad_sample"
    np.testing.assert_array_equal(out.eta, eta)
    assert est.update(rows[11]).status in ("ok", "warmup")


@pytest.mark.parametrize("name", sorted(NEW))
def test_malformed_input_is_a_clear_error(short, name):
    est = NEW[name](short.vehicle)
    s = next(samples(short))
    with pytest.raises(ConfigError, match="shapes"):
        est.update(s._replace(f=np.ones(3)))
    with pytest.raises(ConfigError, match="not a sample"):
        est.update("row")
    with pytest.raises(ConfigError, match="Recording"):
        est.run("flight.csv")
    with pytest.raises(ConfigError, match="eta0"):
        est.reset([1.0, 2.0])
    imu = dataclasses.replace(short, position=None, velocity=None, quaternion=None)
    with pytest.raises(ConfigError, match="IMU-only"):
        est.run(imu)
    with pytest.raises(ConfigError, match="Vehicle"):
        NEW[name]("vehicle")
    with pytest.raises(ConfigError, match="config"):
        NEW[name](short.vehicle, config=UKFConfig() if name == "rls" else RLSConfig())


@pytest.mark.parametrize(
    "changes",
    [
        {"forgetting": 0.0},
        {"forgetting": 1.5},
        {"forgetting": True},
        {"p0": -1.0},
        {"eta_bounds": (1.0, 0.0)},
        {"eta0": (1.0, 1.0)},
    ],
)
def test_bad_rls_config_is_a_clear_error(short, changes):
    with pytest.raises(ConfigError, match="RLSConfig"):
        RecursiveLeastSquares(short.vehicle, RLSConfig(**changes))


@pytest.mark.parametrize(
    "changes",
    [
        {"q_eta": 0.0},
        {"r_rate": float("nan")},
        {"alpha": -1.0},
        {"kappa": "x"},
        {"kappa": -11.0},
        {"eta_bounds": (0.5, 0.5)},
        {"eta0": "one"},
    ],
)
def test_bad_ukf_config_is_a_clear_error(short, changes):
    with pytest.raises(ConfigError, match="UKFConfig"):
        UnscentedKalmanFilter(short.vehicle, UKFConfig(**changes))
