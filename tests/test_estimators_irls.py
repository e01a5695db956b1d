"""Sliding-window IRLS: residual model (compiled kernel vs the reference loop and the numpy
oracle), robust weights, accuracy, guards and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from oracles import irls_numpy as oracle

from estimators.base import Sample, samples
from estimators.irls import IRLSConfig, SlidingWindowIRLS, solve_window
from estimators.residuals import residual_weights, segment_terms
from estimators.robust import mad_weights
from quadfault.errors import ConfigError, QuadfaultError
from quadfault.io.recording import Recording, read_recording, write_recording
from quadfault.model.rotation import hat
from quadfault.model.scenarios import ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Circle, Hover
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import simulate

ETA = (0.9, 0.75, 0.95, 0.85)
AUTO = IRLSConfig()
G = residual_weights(50, 50, 1, 50)


def _flight(duration=3.0, eta=ETA, vehicle=None, seed=1, trajectory=None):
    sc = Scenario(
        "const", duration, EfficiencySchedule(ConstantEfficiency(eta)), trajectory or Circle()
    )
    return simulate(sc, vehicle=vehicle, seed=seed)


@pytest.fixture(scope="module")
def flight():
    return _flight()


@pytest.fixture(scope="module")
def flight_estimates(flight):
    return SlidingWindowIRLS(flight.vehicle, AUTO).run(flight.without_truth())


def _rmse(series, rec, skip=500):
    err = series.eta[skip:] - rec.eta_true[skip:]
    return np.sqrt(np.mean(err**2, axis=0))


# --- residual model -------------------------------------------------------------------
def _direct_residuals(veh, t, p, v, R, w, f, eta):
    """The reference code's residual loop (motor_estimator_irls.m), nonlinear form,
    with the wrench through the vehicle's allocation."""
    out = []
    for i in range(len(t) - 1):
        dt = t[i + 1] - t[i]
        T, *M = veh.allocation @ (eta * f[i])
        a = veh.gravity * np.array([0, 0, 1.0]) - T * R[i][:, 2] / veh.mass
        pred_v = v[i] + a * dt
        pred_p = p[i] + v[i] * dt + a * dt**2 / 2
        gyro = np.cross(w[i], veh.inertia @ w[i])
        pred_w = w[i] + veh.inertia_inverse @ (np.array(M) - gyro) * dt
        pred_R = R[i] @ (np.eye(3) + hat(pred_w * dt))
        dR, dRh = R[i].T @ R[i + 1], R[i].T @ pred_R
        rR = np.trace(np.eye(3) - dR.T @ dRh) / 2
        out.append(np.concatenate((v[i + 1] - pred_v, p[i + 1] - pred_p, w[i + 1] - pred_w, [rR])))
    return np.array(out)


def _terms(rec, sl):
    return segment_terms(
        rec.vehicle,
        rec.t[sl],
        rec.position[sl],
        rec.velocity[sl],
        rec.rotation[sl],
        rec.omega[sl],
        rec.thrust_cmd[sl],
        G,
    )


def test_residuals_are_affine_and_match_the_reference_loop(flight):
    sl = slice(300, 310)
    args = (
        flight.t[sl],
        flight.position[sl],
        flight.velocity[sl],
        flight.rotation[sl],
        flight.omega[sl],
        flight.thrust_cmd[sl],
    )
    models = _terms(flight, sl)
    rng = np.random.default_rng(0)
    for eta in (np.zeros(4), np.ones(4), rng.uniform(0, 1, 4)):
        direct = _direct_residuals(flight.vehicle, *args, eta)
        np.testing.assert_allclose(models.residuals(eta), direct, rtol=1e-9, atol=1e-14)


def test_jacobian_equals_reference_analytic_rows(flight):
    """The MATLAB analytic Jacobian for the paper layout (diag inertia)."""
    veh = flight.vehicle
    k = 500
    models = _terms(flight, slice(k, k + 2))
    J = models.J[0]
    dt, m = models.dt[0], veh.mass
    f1, f2, f3, f4 = flight.thrust_cmd[k]
    d, c = 0.225, 0.009012
    Jx, Jy, Jz = np.diag(veh.inertia)
    R = flight.rotation[k]
    fR = np.outer(R[:, 2], [f1, f2, f3, f4])
    np.testing.assert_allclose(J[0:3], dt / m * fR, rtol=1e-12)
    np.testing.assert_allclose(J[3:6], dt**2 / (2 * m) * fR, rtol=1e-12)
    Jw = dt * np.array(
        [
            [f1 * d / Jx, -f2 * d / Jx, -f3 * d / Jx, f4 * d / Jx],
            [-f1 * d / Jy, -f2 * d / Jy, f3 * d / Jy, f4 * d / Jy],
            [f1 * c / Jz, -f2 * c / Jz, f3 * c / Jz, -f4 * c / Jz],
        ]
    )
    np.testing.assert_allclose(J[6:9], Jw, rtol=1e-12)
    dR = R.T @ flight.rotation[k + 1]
    a, b_, e = dR[1, 2] - dR[2, 1], dR[2, 0] - dR[0, 2], dR[0, 1] - dR[1, 0]
    rrow = (dt**2 / 2) * np.array(
        [
            -a * f1 * d / Jx + b_ * f1 * d / Jy - e * f1 * c / Jz,
            a * f2 * d / Jx + b_ * f2 * d / Jy + e * f2 * c / Jz,
            a * f3 * d / Jx - b_ * f3 * d / Jy - e * f3 * c / Jz,
            -a * f4 * d / Jx - b_ * f4 * d / Jy + e * f4 * c / Jz,
        ]
    )
    np.testing.assert_allclose(J[9], rrow, rtol=1e-9, atol=1e-20)


def test_compiled_segment_terms_equal_the_numpy_oracle(flight):
    """The one compiled residual model against the vectorised numpy form (eqs. 13-26)."""
    sl = slice(100, 140)
    terms = _terms(flight, sl)
    models = oracle.segment_models(
        flight.vehicle,
        flight.t[sl],
        flight.position[sl],
        flight.velocity[sl],
        flight.rotation[sl],
        flight.omega[sl],
        flight.thrust_cmd[sl],
    )
    c, b, H = oracle.quadratic_terms(models, G)
    np.testing.assert_allclose(terms.r0, models.r0, rtol=1e-9, atol=1e-16)
    np.testing.assert_allclose(terms.J, models.J, rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(terms.c, c, rtol=1e-9)
    np.testing.assert_allclose(terms.b, b, rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(terms.H, H, rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(terms.thrust, models.thrust, rtol=1e-12)


def test_quadratic_terms_reproduce_segment_energies(flight):
    models = _terms(flight, slice(0, 20))
    c, b, H = models.c, models.b, models.H
    x = np.array([0.8, 0.9, 0.7, 1.0])
    r = models.residuals(x)
    e_direct = np.einsum("si,i,si->s", r, G, r)
    e_quad = c + 2 * b @ x + np.einsum("snm,n,m->s", H, x, x)
    np.testing.assert_allclose(e_quad, e_direct, rtol=1e-6)


# --- robust weights -------------------------------------------------------------------
def test_mad_weights_equal_the_numpy_oracle():
    rng = np.random.default_rng(7)
    for case in range(40):
        e = rng.gamma(2.0, 1.0, 9) * 10.0 ** rng.uniform(-8, 2)
        if case % 5 == 0:
            e[rng.integers(9)] *= 100  # an outlier
        if case % 7 == 0:
            e[:] = 3.0  # MAD = 0
        for kw in ({}, {"floor": True, "median_normalize": False}, {"hard_drop": False}):
            w, z = mad_weights(e, **kw)
            w_ref, z_ref = oracle.mad_weights(e, **kw)
            np.testing.assert_allclose(w, w_ref, rtol=1e-12, atol=0)
            np.testing.assert_allclose(z, z_ref, rtol=1e-12, atol=0)


def test_mad_weights_reject_outlier_and_normalise_by_median():
    e = np.array([1.0, 1.1, 0.9, 1.05, 0.95, 1.02, 0.98, 1.01, 50.0])
    w, z = mad_weights(e)
    assert w[-1] == 0.0 and z[-1] > 2.5
    assert np.median(w) == pytest.approx(1.0)
    assert np.all(w[:-1] > 0)
    w_flat, z_flat = mad_weights(np.full(9, 3.0))
    assert np.all(w_flat == 1.0) and np.all(z_flat == 0.0)
    # paper variant: floor w_min on the kept ones, no median normalisation, still hard-drops
    w_p, _ = mad_weights(e, floor=True, median_normalize=False)
    assert w_p[-1] == 0.0 and np.all(w_p[:-1] >= 0.03) and np.all(w_p <= 1.0)
    # no hard drop: the floor applies instead
    w_s, _ = mad_weights(e, hard_drop=False, median_normalize=False)
    assert w_s[-1] == pytest.approx(0.03)


# --- accuracy -------------------------------------------------------------------------
def test_seeded_accuracy_constant_efficiency(flight, flight_estimates):
    s = flight_estimates
    assert len(s.t) == len(flight) and np.array_equal(s.t, flight.t)
    assert np.all(s.status[:9] == "warmup") and np.all(s.eta[:9] == 1.0)
    rmse = _rmse(s, flight)
    assert np.all(rmse < 0.03), rmse
    assert np.mean(s.status[9:] == "ok") > 0.9
    assert np.all(np.isfinite(s.eta))
    ok = s.status == "ok"
    assert np.all(s.sd[ok] > 0) and np.all(s.sd[ok] < 0.2)


def test_paper_scaling_is_also_accurate(flight, flight_estimates):
    """The 1/sqrt(n) factor makes gamma relatively 9x stronger: smoother, a little less
    accurate on the weakly observable yaw-differential mode."""
    s = SlidingWindowIRLS(flight.vehicle, IRLSConfig(scaling="paper")).run(flight)
    assert np.all(_rmse(s, flight) < 0.05)
    assert not np.allclose(s.eta, flight_estimates.eta)


def test_run_equals_online_updates(flight):
    rec = flight.slice(100, 160)
    est = SlidingWindowIRLS(rec.vehicle, AUTO)
    online = [est.update(s) for s in samples(rec)]
    batch = SlidingWindowIRLS(rec.vehicle, AUTO).run(rec)
    np.testing.assert_allclose(np.array([e.eta for e in online]), batch.eta, atol=1e-12)
    assert [e.status for e in online] == list(batch.status)
    assert [e.t for e in online] == list(rec.t)  # causal: t of the newest sample used


def test_bounds_respected_near_the_bounds():
    """A dead motor (eta = 0) and healthy ones (eta = 1): estimates stay in the box."""
    rec = _flight(0.25, eta=(1.0, 1.0, 1.0, 0.0), trajectory=Hover(), seed=3)
    cfg = AUTO
    s = SlidingWindowIRLS(rec.vehicle, cfg).run(rec)
    assert np.all(s.eta >= cfg.lower) and np.all(s.eta <= cfg.upper)
    late = s.eta[100:]
    assert np.all(np.abs(late[:, 3]) < 0.05)
    assert np.all(np.abs(late[:, :3] - 1.0) < 0.08)


def test_outlier_segment_is_rejected(flight):
    k = 600
    models = oracle.segment_models(
        flight.vehicle,
        flight.t[k : k + 10],
        flight.position[k : k + 10],
        flight.velocity[k : k + 10],
        flight.rotation[k : k + 10],
        flight.omega[k : k + 10],
        flight.thrust_cmd[k : k + 10],
    )
    x_prev = np.array(ETA)
    clean = solve_window(*oracle.quadratic_terms(models, G), x_prev, AUTO)
    r0 = models.r0.copy()
    r0[4, 0:3] += 0.05  # a velocity glitch of 5 cm/s in one segment
    bad = type(models)(r0, models.J, models.dt, models.thrust)
    robust = solve_window(*oracle.quadratic_terms(bad, G), x_prev, AUTO)
    assert 4 in robust[2].rejected
    assert np.max(np.abs(robust[0] - clean[0])) < 0.02
    naive = solve_window(
        *oracle.quadratic_terms(bad, G), x_prev, IRLSConfig(hard_drop=False, z_soft=1e9)
    )
    assert np.max(np.abs(naive[0] - clean[0])) > 5 * np.max(np.abs(robust[0] - clean[0]))


def test_non_uniform_sampling(flight):
    rng = np.random.default_rng(4)
    keep = np.sort(
        np.concatenate(([0], rng.choice(np.arange(1, len(flight)), 2000, replace=False)))
    )
    f = flight.thrust_cmd.copy()
    sub = Recording(
        t=flight.t[keep],
        omega=flight.omega[keep],
        thrust_cmd=f[keep],
        vehicle=flight.vehicle,
        position=flight.position[keep],
        velocity=flight.velocity[keep],
        quaternion=flight.quaternion[keep],
        eta_true=flight.eta_true[keep],
    )
    assert np.ptp(np.diff(sub.t)) > 2e-3  # really non-uniform
    s = SlidingWindowIRLS(sub.vehicle, AUTO).run(sub)
    assert np.all(_rmse(s, sub, skip=300) < 0.04)


def test_enu_frame_and_u_commands_give_the_same_estimates(flight, tmp_path):
    rec = flight.slice(0, 300)
    k = 1.0e-5
    u = np.sqrt(rec.thrust_cmd / k)
    rec_u = Recording(
        t=rec.t,
        omega=rec.omega,
        thrust_cmd=rec.thrust_cmd,
        vehicle=rec.vehicle,
        position=rec.position,
        velocity=rec.velocity,
        quaternion=rec.quaternion,
        commands_u=u,
        thrust_curve=(0.0, 0.0, k),
    )
    write_recording(rec_u, tmp_path / "enu.csv", frame="ENU")
    loaded = read_recording(tmp_path / "enu.csv")
    assert loaded.frame == "ENU" and loaded.commands_u is not None
    a = SlidingWindowIRLS(rec.vehicle, AUTO).run(rec)
    b = SlidingWindowIRLS(loaded.vehicle, AUTO).run(loaded)
    np.testing.assert_allclose(b.eta, a.eta, atol=1e-6)


def test_non_paper_allocation_is_as_accurate():
    arm = 0.17 / np.sqrt(2)  # an X layout with 0.17 m arms, different spin order
    pos = [(arm, arm), (-arm, -arm), (arm, -arm), (-arm, arm)]
    veh = Vehicle.from_rotors(
        pos, (1.0, 1.0, -1.0, -1.0), 0.012, mass=0.8, inertia=(0.008, 0.009, 0.015)
    )
    rec = _flight(vehicle=veh, seed=2)
    s = SlidingWindowIRLS(rec.vehicle, AUTO).run(rec)
    assert np.all(_rmse(s, rec) < 0.03)


# --- guards and bad input ---------------------------------------------------------------
def test_no_excitation_and_bad_samples_keep_the_previous_estimate(flight):
    est = SlidingWindowIRLS(flight.vehicle, AUTO)
    est.reset(eta0=[0.9, 0.9, 0.9, 0.9])
    for s in list(samples(flight.slice(0, 12))):
        out = est.update(s._replace(f=np.zeros(4)))
    assert out.status == "no_excitation" and np.all(out.eta == 0.9)
    bad = est.update(
        Sample(1.0, np.array([np.nan, 0, 0]), np.zeros(3), np.eye(3), np.zeros(3), np.ones(4))
    )
    assert bad.status == "bad_sample" and np.all(np.isfinite(bad.eta))
    nxt = est.update(next(samples(flight.slice(20, 21))))
    assert nxt.status == "warmup"  # the window restarts after a bad sample


def test_ill_conditioned_window_keeps_previous_estimate(flight):
    est = SlidingWindowIRLS(flight.vehicle, AUTO)
    for s in samples(flight.slice(0, 10)):
        out = est.update(s._replace(f=np.array([2.5, 0.0, 2.5, 2.5])))  # rotor 2 silent
    assert out.status == "ill_conditioned" and np.all(out.eta == 1.0)
    assert out.diagnostics.cond > 1e4


def test_recording_errors(flight):
    est = SlidingWindowIRLS(flight.vehicle, AUTO)
    imu = Recording(
        t=flight.t[:20],
        omega=flight.omega[:20],
        thrust_cmd=flight.thrust_cmd[:20],
        vehicle=flight.vehicle,
        accel=np.zeros((20, 3)),
    )
    with pytest.raises(ConfigError, match="IMU-only"):
        est.run(imu)
    with pytest.raises(ConfigError, match="longer than the recording"):
        est.run(flight.slice(0, 5))
    pos = flight.position[:30].copy()
    pos[7, 1] = np.nan
    nan_rec = Recording(
        t=flight.t[:30],
        omega=flight.omega[:30],
        thrust_cmd=flight.thrust_cmd[:30],
        vehicle=flight.vehicle,
        position=pos,
        velocity=flight.velocity[:30],
        quaternion=flight.quaternion[:30],
    )
    with pytest.raises(ConfigError, match="row 8"):
        est.run(nan_rec)


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(window=2),
        dict(gamma=-1.0),
        dict(eta_min=1, eta_max=0),
        dict(scaling="other"),
        {"change_hold": 0},
        {"output_median": 1.5},
        dict(max_irls=0),
        dict(g_v=float("nan")),
    ],
)
def test_config_errors(kwargs):
    with pytest.raises(QuadfaultError):
        IRLSConfig(**kwargs)


def test_eta0_validation_and_truth_never_read(flight):
    est = SlidingWindowIRLS(flight.vehicle, AUTO)
    with pytest.raises(ConfigError):
        est.reset(eta0=[1, 2])
    poisoned = Recording(
        t=flight.t[:40],
        omega=flight.omega[:40],
        thrust_cmd=flight.thrust_cmd[:40],
        vehicle=flight.vehicle,
        position=flight.position[:40],
        velocity=flight.velocity[:40],
        quaternion=flight.quaternion[:40],
        eta_true=np.full((40, 4), np.nan),
    )
    clean = flight.slice(0, 40).without_truth()
    np.testing.assert_array_equal(est.run(poisoned).eta, est.run(clean).eta)
