"""Interior-point solver of the IRLS estimator: SciPy cross-check, the full-KKT numpy oracle
(its Newton steps), KKT convergence, histories and guards."""

from __future__ import annotations

import numpy as np
import pytest
from oracles import irls_numpy as oracle
from scipy.optimize import lsq_linear

from estimators.ipm import IPMSettings, ipm_parameters, solve_box_qp
from estimators.irls import IRLSConfig, solve_window
from quadfault.errors import ConfigError

LO, HI = -0.001, 1.001
TIGHT = IPMSettings(tol_feas=1e-12, tol_gap=1e-12, backtrack_eps=0.0, max_iter=200)


def _problem(seed, x_true):
    """A weighted bounded least-squares problem shaped like one IRLS window."""
    rng = np.random.default_rng(seed)
    J = rng.standard_normal((90, 4)) * 0.05
    G = rng.choice([1.0, 50.0], 90) * rng.uniform(0.5, 1.5, 90)
    r0 = -J @ np.asarray(x_true) + 0.002 * rng.standard_normal(90)
    gamma, x_prev = 5e-3, rng.uniform(0.2, 0.9, 4)
    H = J.T @ (G[:, None] * J) + gamma * np.eye(4)
    q = J.T @ (G * r0) - gamma * x_prev
    # scipy: min ||A x - b||^2 with sqrt(G) rows and sqrt(gamma) rows for the smoothness term
    A = np.vstack((np.sqrt(G)[:, None] * J, np.sqrt(gamma) * np.eye(4)))
    b = np.concatenate((-np.sqrt(G) * r0, np.sqrt(gamma) * x_prev))
    return H, q, A, b


@pytest.mark.slow
@pytest.mark.parametrize(
    "seed,x_true",
    [
        (0, (0.9, 0.5, 0.7, 0.3)),  # interior
        (1, (1.3, 0.5, -0.4, 0.8)),  # two active bounds
        (2, (1.001, 1.2, 1.0, 0.0)),  # at / beyond the bounds
        (3, (-1.0, -1.0, 2.0, 0.5)),
    ],
)
def test_ipm_equals_scipy_lsq_linear(seed, x_true):
    H, q, A, b = _problem(seed, x_true)
    ref = lsq_linear(A, b, bounds=(LO, HI), method="bvls", tol=1e-14)
    res = solve_box_qp(H, q, LO, HI, np.full(4, 0.5), TIGHT)
    assert res.converged
    np.testing.assert_allclose(res.x, ref.x, atol=1e-6)
    # the default tolerances (1e-6 on the residual and the gap) land close to it as well
    res_default = solve_box_qp(H, q, LO, HI, np.full(4, 0.5))
    assert res_default.converged and np.max(np.abs(res_default.x - ref.x)) < 1e-3
    assert np.all(res_default.x > LO) and np.all(res_default.x < HI)


def test_kkt_convergence_histories():
    H, q, _, _ = _problem(1, (1.3, 0.5, -0.4, 0.8))
    res = solve_box_qp(H, q, LO, HI, np.full(4, 0.5), record_history=True)
    assert res.converged and res.iterations == len(res.gap_history) <= 80
    assert res.gap_history[-1] < 1e-6
    assert np.hypot(res.dual_history[-1], res.cent_history[-1]) < 1e-6
    assert res.gap_history[-1] < 1e-4 * res.gap_history[0]
    assert np.all(res.lam > 0)
    # complementary slackness: multipliers of inactive bounds vanish
    phi = np.concatenate((res.x - HI, LO - res.x))
    assert np.max(np.abs(res.lam * phi)) < 1e-6
    r_dual = H @ res.x + q + res.lam[:4] - res.lam[4:]
    assert np.linalg.norm(r_dual) < 1e-6


@pytest.mark.parametrize("seed", range(6))
def test_reduced_newton_steps_follow_the_full_kkt_system(seed):
    """The kernel eliminates dlambda and factors by Cholesky; the oracle solves the full
    3n x 3n system of eq. (42) with numpy. Same iterates to rounding, same count."""
    x_true = np.random.default_rng(100 + seed).uniform(-0.5, 1.5, 4)  # some bounds active
    H, q, _, _ = _problem(seed, x_true)
    x0 = np.random.default_rng(seed).uniform(0.05, 0.95, 4)
    for cfg in (IPMSettings(), TIGHT, IPMSettings(max_iter=3)):
        res = solve_box_qp(H, q, LO, HI, x0, cfg, record_history=True)
        _x, it, converged, iterates = oracle.ipm(
            H, q, LO, HI, x0, ipm_parameters(cfg), cfg.max_iter
        )
        assert (res.iterations, res.converged) == (it, converged)
        np.testing.assert_allclose(res.x_history, iterates, rtol=0, atol=1e-10)


@pytest.mark.parametrize("n", [2, 6])
def test_other_sizes_equal_the_oracle(n):
    rng = np.random.default_rng(n)
    J = rng.standard_normal((40, n)) * 0.1
    H = J.T @ J + 5e-3 * np.eye(n)
    q = J.T @ (-J @ rng.uniform(-0.2, 1.2, n))
    x0 = np.full(n, 0.5)
    res = solve_box_qp(H, q, LO, HI, x0)
    x, it, converged, _ = oracle.ipm(H, q, LO, HI, x0, ipm_parameters(IPMSettings()))
    assert res.converged and converged and res.iterations == it
    np.testing.assert_allclose(res.x, x, rtol=0, atol=1e-10)


def test_ipm_rejects_infeasible_start_and_bad_settings():
    H, q, _, _ = _problem(0, (0.5, 0.5, 0.5, 0.5))
    with pytest.raises(ConfigError, match="strictly inside"):
        solve_box_qp(H, q, LO, HI, np.array([0.5, 0.5, 1.5, 0.5]))
    with pytest.raises(ConfigError):
        IPMSettings(mu=0.5)
    with pytest.raises(ConfigError):
        IPMSettings(max_iter=0)


def _window(seed, m):
    """``(c, b, H)`` of a synthetic window of ``m`` segments (eq. 26's quadratic terms)."""
    rng = np.random.default_rng(seed)
    J = rng.standard_normal((m, 10, 4)) * 0.01
    G = np.array([50.0] * 6 + [1.0] * 3 + [50.0])
    r0 = -J @ np.array([0.8, 0.7, 0.9, 0.6]) + 1e-4 * rng.standard_normal((m, 10))
    c = np.einsum("si,i,si->s", r0, G, r0)
    b = np.einsum("sin,i,si->sn", J, G, r0)
    H = np.einsum("sin,i,sim->snm", J, G, J)
    return c, b, H


@pytest.mark.slow
def test_window_history_records_each_round():
    """The diagnostics carry the paper's KKT figure data when record_history is on."""
    m = 9
    c, b, H = _window(7, m)
    cfg = IRLSConfig(record_history=True)
    eta, sd, diag = solve_window(c, b, H, np.full(4, 0.5), cfg, record_history=True)
    assert diag.status == "ok" and 1 <= len(diag.inner_iterations) <= 3
    assert len(diag.gap_history) == len(diag.inner_iterations)
    assert all(len(g) == n for g, n in zip(diag.gap_history, diag.inner_iterations))
    assert diag.gap_history[-1][-1] < 1e-6 and diag.residual_history[0][-1] > 0
    assert diag.weights.shape == (m,) and np.all(np.isfinite(sd)) and np.all(sd > 0)
    fast = solve_window(c, b, H, np.full(4, 0.5), IRLSConfig())
    np.testing.assert_array_equal(fast[0], eta)
    assert fast[2].gap_history is None


def test_iteration_limit_gives_usable_max_iter_estimate():
    c, b, H = _window(8, 9)
    cfg = IRLSConfig(ipm=IPMSettings(max_iter=2))
    eta, sd, diag = solve_window(c, b, H, np.ones(4), cfg)
    assert diag.status == "max_iter" and "2 iterations" in diag.message
    assert all(n == 2 for n in diag.inner_iterations)
    assert np.all(np.isfinite(eta)) and np.all((eta > cfg.lower) & (eta < cfg.upper))


def test_a_non_positive_definite_newton_matrix_is_reported():
    H = -20.0 * np.eye(4)  # not convex: the first Newton matrix H + diag(~8) is indefinite
    with pytest.raises(np.linalg.LinAlgError):
        solve_box_qp(H, np.zeros(4), LO, HI, np.full(4, 0.5), IPMSettings())


def test_window_residual_history_is_the_weighted_residual_norm_of_each_iterate():
    c, b, H = _window(9, 9)
    cfg = IRLSConfig(record_history=True, max_irls=1)
    eta, _sd, diag = solve_window(c, b, H, np.full(4, 0.5), cfg, record_history=True)
    w = diag.weights
    e = c + 2 * b @ eta + np.einsum("snm,n,m->s", H, eta, eta)
    assert diag.residual_history[0][-1] == pytest.approx(np.sqrt(w @ e), rel=1e-9)
