"""The compiled window solver (Algorithm 2) against the numpy oracle (the same rounds with the
full-KKT interior point) and against scipy (each round's box QP solved exactly), on real
windows of a seeded fault flight, with the paper scaling, and for six rotors."""

from __future__ import annotations

import numpy as np
import pytest
from oracles import irls_numpy as oracle

from estimators.irls import IRLSConfig, solve_window
from quadfault.model.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Circle
from quadfault.sim.simulator import simulate


@pytest.fixture(scope="module")
def fault_flight():
    """A motor fault in the middle, so the windows see outliers and a step."""
    sc = Scenario(
        "fault",
        0.5,
        EfficiencySchedule(
            ConstantEfficiency((1.0, 0.9, 0.8, 0.95)),
            (AbruptFault(motor=2, onset=0.25, level=0.5),),
        ),
        Circle(),
    )
    return simulate(sc, seed=11).without_truth()


def _windows(rec, cfg, starts):
    models = oracle.segment_models(
        rec.vehicle,
        rec.t,
        rec.position,
        rec.velocity,
        rec.rotation,
        rec.omega,
        np.clip(rec.thrust_cmd, 0.0, rec.vehicle.rotor_max_thrust),
    )
    c, b, H = oracle.quadratic_terms(models, cfg.segment_weights)
    m = cfg.window - 1
    return [(c[k : k + m], b[k : k + m], H[k : k + m]) for k in starts]


@pytest.mark.parametrize("scaling", ["reference", "paper"])
def test_window_solver_equals_the_numpy_oracle(fault_flight, scaling):
    cfg = IRLSConfig(scaling=scaling)
    rng = np.random.default_rng(1)
    for c, b, H in _windows(fault_flight, cfg, range(200, 320, 7)):
        x_prev = rng.uniform(0.5, 1.0, 4)
        x, sd, diag = solve_window(c, b, H, x_prev, cfg)
        x_ref, w_ref = oracle.solve_window(c, b, H, x_prev, cfg)
        assert diag.status == "ok"
        np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-9)
        np.testing.assert_allclose(diag.weights, w_ref, rtol=0, atol=1e-9)
        np.testing.assert_allclose(
            sd, oracle.window_uncertainty(c, b, H, w_ref, x_ref, cfg), rtol=1e-7
        )
        assert diag.cond == pytest.approx(
            oracle.condition_number_1(
                np.tensordot(w_ref, H, 1) * (1 / 9 if scaling == "paper" else 1)
            ),
            rel=1e-9,
        )


def test_window_solver_agrees_with_an_exact_scipy_solve(fault_flight):
    """With tight interior-point tolerances every IRLS round is solved to the minimiser scipy
    finds, so the window's estimate and weights are scipy's."""
    from estimators.ipm import IPMSettings

    cfg = IRLSConfig(
        ipm=IPMSettings(tol_feas=1e-11, tol_gap=1e-11, backtrack_eps=0.0, max_iter=200)
    )
    for c, b, H in _windows(fault_flight, cfg, range(100, 400, 25)):
        x, _sd, diag = solve_window(c, b, H, np.full(4, 0.9), cfg)
        x_ref, w_ref = oracle.solve_window_scipy(c, b, H, np.full(4, 0.9), cfg)
        np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-6)
        np.testing.assert_allclose(diag.weights, w_ref, rtol=0, atol=1e-5)


@pytest.mark.slow
@pytest.mark.parametrize("scaling", ["reference", "paper"])
def test_window_with_six_rotors_equals_the_oracle(scaling):
    """The kernels are written for any number of rotors."""
    rng = np.random.default_rng(3)
    m, n = 9, 6
    J = rng.standard_normal((m, 10, n)) * 0.05
    r0 = -(J @ rng.uniform(0.5, 1.0, n)) + 1e-4 * rng.standard_normal((m, 10))
    r0[4] += 0.05  # one corrupted segment: rejected by the robust weights
    cfg = IRLSConfig(scaling=scaling)
    c, b, H = oracle.quadratic_terms(
        oracle.SegmentModels(r0, J, np.full(m, 1e-3), np.full(m, 5.0)), cfg.segment_weights
    )
    x, sd, diag = solve_window(c, b, H, np.full(n, 0.9), cfg)
    x_ref, w_ref = oracle.solve_window(c, b, H, np.full(n, 0.9), cfg)
    assert diag.status == "ok" and 4 in diag.rejected
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(diag.weights, w_ref, atol=1e-9)
    assert sd.shape == (n,) and np.all(sd > 0)


def test_malformed_window_terms_are_a_clear_error():
    from quadfault.errors import ConfigError

    with pytest.raises(ConfigError, match="window terms"):
        solve_window(np.zeros(9), np.zeros((9, 4)), np.zeros((9, 4, 3)), np.ones(4), IRLSConfig())


def test_the_quadrotor_and_the_any_size_interior_point_give_the_same_window(fault_flight):
    """The window solve compiled for the literal four rotors (``any_n`` None, what a
    quadrotor's estimators run) and for any size (``any_n`` True) are the same algorithm:
    identical estimates, sd, weights and iteration counts on real windows."""
    from estimators.window import solve_window_into, window_settings, workspace

    cfg = IRLSConfig()
    m, n = cfg.window - 1, 4
    fp, ip = window_settings(cfg, m)
    hist = np.zeros((1, 0, 4 + n))
    x_prev = np.full(n, 0.9)
    for c, b, H in _windows(fault_flight, cfg, range(150, 400, 31)):
        out = []
        for any_n in (None, True):
            w, iters, x, sd = (
                np.zeros(m),
                np.zeros(cfg.max_irls, np.int64),
                np.empty(n),
                np.empty(n),
            )
            code, rounds, cond = solve_window_into(
                c, b, H, 0, x_prev, fp, ip, *workspace(m, n), w, iters, hist, x, sd, any_n
            )
            out.append((code, rounds, cond, x, sd, w, iters))
        (code4, rounds4, cond4, *arrays4), (code_n, rounds_n, cond_n, *arrays_n) = out
        assert (code4, rounds4, cond4) == (code_n, rounds_n, cond_n)
        assert rounds4 >= 1
        for a4, an in zip(arrays4, arrays_n):
            np.testing.assert_array_equal(a4, an)
