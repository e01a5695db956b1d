"""The compiled EKF step (estimators/ekf_filter.py) against the numpy oracle's predict +
update, one step from random states (every block of the structured F P F^T and the
square-root update), its fallbacks (a covariance that is not positive definite, an attitude far
from SO(3)), and the covariance invariants over a whole recording."""

import numpy as np
import pytest
from oracles.ekf_numpy import NOISE_REFERENCE_DT, measurement_update, predict

from estimators.base import Sample
from estimators.ekf import EKFConfig, MotorEfficiencyEKF, constant_arrays
from estimators.ekf_filter import Measurement, _project_so3_into, predict_update_into, workspace
from quadfault.model.rotation import expm_so3, orthonormalize
from quadfault.model.scenarios import ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Circle
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import simulate


def _random_case(rng, n_rotors=4):
    """A state far from hover (fast rates, tilted attitude), a dense SPD covariance of very
    unequal scales, commands, dt and a measurement near the prediction."""
    R = expm_so3(rng.normal(size=3))
    x = np.concatenate(
        (
            rng.normal(size=3),
            rng.normal(size=3),
            3.0 * rng.normal(size=3),
            R.reshape(9, order="F"),
            rng.uniform(0.5, 1.0, n_rotors),
        )
    )
    n = x.size
    L = rng.normal(size=(n, n)) * np.geomspace(1e-3, 1.0, n)
    P = L @ L.T + 1e-4 * np.eye(n)
    f = rng.uniform(0.5, 4.0, n_rotors)
    dt = float(rng.uniform(5e-4, 5e-3))
    z = Sample(
        dt,
        x[:3] + 0.01 * rng.normal(size=3),
        x[3:6] + 0.01 * rng.normal(size=3),
        R @ expm_so3(0.02 * rng.normal(size=3)),
        x[6:9] + 0.01 * rng.normal(size=3),
        f,
    )
    return x, P, f, dt, z


def _numpy_step(ekf, x, P, f, dt, z):
    Q = np.diag(ekf.q_diag * (dt / NOISE_REFERENCE_DT))
    xp, Pp, _ = predict(x.copy(), P.copy(), f, dt, ekf.vehicle, Q)
    return measurement_update(xp, Pp, z, ekf.r_diag, ekf.config.eta_bounds)


def _compiled_step(ekf, x, P, f, dt, z):
    x, P = x.copy(), P.copy()
    model = constant_arrays(ekf._const, ekf.n_rotors)  # the filter's model of the vehicle
    np.testing.assert_array_equal(model.qc, ekf.q_diag / NOISE_REFERENCE_DT)
    np.testing.assert_array_equal(model.r, ekf.r_diag)
    predict_update_into(
        x,
        P,
        f,
        dt,
        Measurement(z.p, z.v, z.w, np.ascontiguousarray(z.R)),
        model,
        workspace(ekf.n_rotors),
    )
    return x, P


def _hexarotor():
    ang = np.arange(6) * np.pi / 3
    pos = 0.1 * np.stack((np.cos(ang), np.sin(ang), np.zeros(6)), axis=1)
    return Vehicle.from_rotors(pos, (1, -1, 1, -1, 1, -1), 0.006)


@pytest.mark.parametrize("seed", range(6))
def test_compiled_step_equals_numpy_step_from_random_states(seed):
    """Seeds 0-4: the quadrotor (22 states); seed 5: a hexarotor (24 states)."""
    rng = np.random.default_rng(seed)
    vehicle = Vehicle() if seed < 5 else _hexarotor()
    ekf = MotorEfficiencyEKF(
        vehicle, EKFConfig(q_eta=float(rng.uniform(1e-4, 1.0)), eta_bounds=None)
    )
    x, P, f, dt, z = _random_case(rng, vehicle.n_rotors)
    x_np, P_np = _numpy_step(ekf, x, P, f, dt, z)
    x_nb, P_nb = _compiled_step(ekf, x, P, f, dt, z)
    np.testing.assert_allclose(x_nb, x_np, rtol=0, atol=1e-10)
    np.testing.assert_allclose(P_nb, P_np, rtol=0, atol=1e-10 * np.abs(P_np).max())
    np.testing.assert_array_equal(P_nb, P_nb.T)  # mirrored, exactly symmetric
    assert np.linalg.eigvalsh(P_nb).min() > 0


def test_indefinite_covariance_takes_the_general_solver_and_still_matches_numpy():
    """S = H P H^T + R not positive definite (a corrupted P): the compiled step falls back to
    Gauss-Jordan and ``P - K H P``, which equals the numpy Joseph form for
    ``K = P H^T S^-1``."""
    rng = np.random.default_rng(11)
    ekf = MotorEfficiencyEKF(Vehicle(), EKFConfig(eta_bounds=None))
    x, P, f, dt, z = _random_case(rng)
    P[:9, :9] -= 5.0 * np.eye(9)  # S has negative eigenvalues, still invertible
    x_np, P_np = _numpy_step(ekf, x, P, f, dt, z)
    x_nb, P_nb = _compiled_step(ekf, x, P, f, dt, z)
    np.testing.assert_allclose(x_nb, x_np, rtol=0, atol=1e-8)
    np.testing.assert_allclose(P_nb, P_np, rtol=0, atol=1e-8 * np.abs(P_np).max())


def test_covariance_stays_symmetric_and_positive_definite_over_a_flight():
    sc = Scenario(
        "const",
        1.5,
        EfficiencySchedule(ConstantEfficiency((0.9, 0.75, 1.0, 0.6))),
        Circle(),
        thrust_noise=0.07,
    )
    rec = simulate(sc, seed=5).without_truth()
    for q_eta in (1e-6, 0.5, 10.0):  # slow, default and very fast random walk
        ekf = MotorEfficiencyEKF(rec.vehicle, EKFConfig(q_eta=q_eta))
        series = ekf.run(rec)
        assert np.all(np.isfinite(series.sd[1:])) and np.all(series.sd[1:] > 0)
        np.testing.assert_array_equal(ekf.P, ekf.P.T)
        assert np.linalg.eigvalsh(ekf.P).min() > 0


@pytest.mark.parametrize("seed", range(8))
def test_attitude_projection_is_the_closest_rotation(seed):
    """Near SO(3) (Newton iterations) and far from it (the SVD through M^T M), as
    quadfault.model.rotation.orthonormalize."""
    rng = np.random.default_rng(seed)
    R = expm_so3(rng.normal(size=3))
    for M in (
        R + 1e-5 * rng.normal(size=(3, 3)),
        R + 0.3 * rng.normal(size=(3, 3)),
        R @ np.diag([1.0, 1.0, -1.0]) + 0.1 * rng.normal(size=(3, 3)),
    ):
        out = M.copy()
        _project_so3_into(out, np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)))
        np.testing.assert_allclose(out, orthonormalize(M), rtol=0, atol=1e-9)
        np.testing.assert_allclose(out.T @ out, np.eye(3), atol=1e-12)
        assert np.linalg.det(out) == pytest.approx(1.0)
