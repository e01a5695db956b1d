"""The compiled IRLS path gives the numpy path's results (to 1e-9)."""

from __future__ import annotations

import numpy as np
import pytest

import estimators.irls as irls_mod
from estimators.base import samples
from estimators.irls import IRLSConfig, SlidingWindowIRLS
from quadfault.errors import ConfigError
from quadfault.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.simulator import simulate
from quadfault.trajectory import Circle


@pytest.fixture(scope="module")
def fault_flight():
    """A motor fault in the middle, so the window sees outliers and a step."""
    sc = Scenario("fault", 0.5, EfficiencySchedule(
        ConstantEfficiency((1.0, 0.9, 0.8, 0.95)), (AbruptFault(motor=2, onset=0.25, level=0.5),)),
        Circle())
    return simulate(sc, seed=11).without_truth()


@pytest.mark.slow  # the first call compiles the kernels (cached afterwards)
@pytest.mark.parametrize("scaling", ["reference", "paper"])
def test_numba_run_equals_numpy_run(fault_flight, scaling):
    pytest.importorskip("numba")
    a = SlidingWindowIRLS(fault_flight.vehicle, IRLSConfig(backend="numpy", scaling=scaling))
    b = SlidingWindowIRLS(fault_flight.vehicle, IRLSConfig(backend="numba", scaling=scaling))
    assert b.backend == "numba"
    ra, rb = a.run(fault_flight), b.run(fault_flight)
    np.testing.assert_allclose(rb.eta, ra.eta, rtol=0, atol=1e-9)
    np.testing.assert_allclose(rb.sd, ra.sd, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(rb.status, ra.status)
    assert np.mean(ra.status == "ok") > 0.5


@pytest.mark.slow
def test_numba_online_update_equals_numpy(fault_flight):
    pytest.importorskip("numba")
    a = SlidingWindowIRLS(fault_flight.vehicle, IRLSConfig(backend="numpy"))
    b = SlidingWindowIRLS(fault_flight.vehicle, IRLSConfig(backend="numba"))
    for s in samples(fault_flight.slice(240, 300)):
        ea, eb = a.update(s), b.update(s)
        assert ea.status == eb.status
        np.testing.assert_allclose(eb.eta, ea.eta, rtol=0, atol=1e-9)
        if ea.diagnostics.weights is not None:
            np.testing.assert_allclose(eb.diagnostics.weights, ea.diagnostics.weights, atol=1e-9)
            assert ea.diagnostics.inner_iterations == eb.diagnostics.inner_iterations


def test_backend_choice(monkeypatch, fault_flight):
    veh = fault_flight.vehicle
    assert SlidingWindowIRLS(veh, IRLSConfig(backend="numpy")).backend == "numpy"
    # histories are built by the numpy path only
    assert SlidingWindowIRLS(veh, IRLSConfig(record_history=True)).backend == "numpy"
    monkeypatch.setattr(irls_mod, "numba_available", lambda: False)
    assert SlidingWindowIRLS(veh, IRLSConfig()).backend == "numpy"
    with pytest.raises(ConfigError, match="fast"):
        SlidingWindowIRLS(veh, IRLSConfig(backend="numba"))


@pytest.mark.slow
def test_compiled_segment_terms_equal_numpy(fault_flight):
    pytest.importorskip("numba")
    from estimators._residuals_numba import segment_terms
    from estimators.residuals import quadratic_terms, residual_weights, segment_models

    rec, veh = fault_flight, fault_flight.vehicle
    G = residual_weights(50, 50, 1, 50)
    sl = slice(100, 140)
    models = segment_models(veh, rec.t[sl], rec.position[sl], rec.velocity[sl],
                            rec.rotation[sl], rec.omega[sl], rec.thrust_cmd[sl])
    c, b, H = quadratic_terms(models, G)
    R = rec.rotation
    for i, k in enumerate(range(100, 139)):
        ci, bi, Hi, Ti = segment_terms(rec.t[k + 1] - rec.t[k], rec.position[k],
                                       rec.position[k + 1], rec.velocity[k], rec.velocity[k + 1],
                                       R[k], R[k + 1], rec.omega[k], rec.omega[k + 1],
                                       rec.thrust_cmd[k], veh.mass, veh.gravity, veh.inertia,
                                       veh.inertia_inverse, veh.allocation, G)
        assert ci == pytest.approx(c[i], rel=1e-9)
        np.testing.assert_allclose(bi, b[i], rtol=1e-9, atol=1e-18)
        np.testing.assert_allclose(Hi, H[i], rtol=1e-9, atol=1e-18)
        assert Ti == pytest.approx(models.thrust[i], rel=1e-12)


def test_compiled_interior_point_is_the_python_one():
    """The compiled kernel runs estimators.ipm.ipm4 itself: same iterates as on Python floats."""
    pytest.importorskip("numba")
    from estimators._irls_numba import _ipm4
    from estimators.ipm import IPMSettings, ipm4

    s = IPMSettings()
    rng = np.random.default_rng(5)
    for _ in range(20):
        J = rng.standard_normal((90, 4)) * 0.05
        H = J.T @ J * 50.0 + 5e-3 * np.eye(4)
        q = J.T @ (-J @ rng.uniform(-0.3, 1.3, 4)) * 50.0
        x0 = rng.uniform(0.05, 0.95, 4)
        args = (-0.001, 1.001)
        consts = (s.mu, s.alpha, s.beta, s.step_fraction, s.backtrack_eps, s.min_step,
                  s.tol_feas, s.tol_gap, s.max_iter)
        py = ipm4(H.ravel().tolist(), q.tolist(), *args, x0.tolist(), *consts, np.empty((0, 7)))
        nb = _ipm4(tuple(H.ravel()), tuple(q), *args, tuple(x0), *consts, np.empty((0, 7)))
        assert py[12:] == nb[12:]  # iterations and convergence flag
        np.testing.assert_allclose(nb[:12], py[:12], rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("scaling", ["reference", "paper"])
def test_compiled_window_with_six_rotors_equals_numpy(scaling):
    """n != 4 runs the general interior point in both paths (no unrolled 4x4 algebra)."""
    pytest.importorskip("numba")
    from estimators._irls_numba import solve_window_numba
    from estimators.irls import solve_window
    from estimators.residuals import SegmentModels, quadratic_terms

    rng = np.random.default_rng(3)
    m, n = 9, 6
    J = rng.standard_normal((m, 10, n)) * 0.05
    r0 = -(J @ rng.uniform(0.5, 1.0, n)) + 1e-4 * rng.standard_normal((m, 10))
    r0[4] += 0.05  # one corrupted segment: rejected by the robust weights
    cfg = IRLSConfig(scaling=scaling)
    c, b, H = quadratic_terms(SegmentModels(r0, J, np.full(m, 1e-3), np.full(m, 5.0)),
                              cfg.segment_weights)
    xa, sa, da = solve_window(c, b, H, np.full(n, 0.9), cfg)
    xb, sb, db = solve_window_numba(c, b, H, np.full(n, 0.9), cfg)
    assert da.status == db.status == "ok"
    assert da.inner_iterations == db.inner_iterations and da.rejected == db.rejected
    assert 4 in da.rejected
    np.testing.assert_allclose(xb, xa, rtol=0, atol=1e-9)
    np.testing.assert_allclose(sb, sa, rtol=1e-9)
    np.testing.assert_allclose(db.weights, da.weights, atol=1e-9)
