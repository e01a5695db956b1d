"""One window of the sliding-window IRLS (the paper's Algorithm 2).

Given the per-segment quadratic terms ``(c_i, b_i, H_i)`` of a window's segments
(:mod:`estimators.residuals`, eq. 26), solve::

    min_eta  1/2 sum_i w_i e_i(eta) + gamma/2 ||eta - eta_prev||^2                  (eq. 24)
    s.t.     eta_min - eps <= eta <= eta_max + eps                                   (eq. 25)

by an outer IRLS loop: robust MAD z-score weights ``w_i`` of the energies at the current
estimate (:mod:`estimators.robust`, eqs. 27-30), a conditioning guard, and the primal-dual
interior point (:mod:`estimators.ipm`, Algorithm 1) on the weighted quadratic, warm-started
from ``eta_prev``; at most ``max_irls`` rounds, until the estimate moves less than
``irls_tol``.

Guards (the previous estimate is kept, ``sd`` is NaN): every segment rejected (``rejected``),
``cond_1(J^T W G J) > cond_max`` (``ill_conditioned``, the reference's ``rcond < 1e-4``).

Uncertainty, from the window's information matrix with the final weights::

    s^2 = sum_i w_i e_i(eta) / max(10 k - n, 1)        (k = segments with w_i > 0)
    sd  = sqrt(diag(s^2 (J^T W G J + gamma I)^-1))

:func:`solve_window_into` is the algorithm, plain Python compiled by
:func:`quadfault.jit.jit`, allocation-free: it reads the window from a ring of segment terms
(segment ``s``, 0 = oldest, at index ``(start + s) % m``) and works in a :func:`workspace`.
The online estimator, its offline ``run()`` and the batched estimator all run it;
:func:`solve_window` calls it on one window given as arrays.
"""

from __future__ import annotations

import math

import numpy as np

from estimators.base import (
    STATUS_ILL_CONDITIONED,
    STATUS_MAX_ITER,
    STATUS_OK,
    STATUS_REJECTED,
    STATUSES,
)
from estimators.ipm import N_WORK_ROWS, ipm_into, ipm_parameters
from estimators.irls_config import IRLSConfig, window_diagnostics
from estimators.linalg import cholesky_into, cholesky_solve_into, cond1_into
from estimators.robust import mad_weights_into
from quadfault.errors import ConfigError
from quadfault.jit import jit

START_MARGIN = 1e-6  #: the interior-point start is kept this far inside the bounds

OK = STATUSES.index(STATUS_OK)
ILL_CONDITIONED = STATUSES.index(STATUS_ILL_CONDITIONED)
REJECTED = STATUSES.index(STATUS_REJECTED)
MAX_ITER = STATUSES.index(STATUS_MAX_ITER)

# float settings (fp) and integer settings (ip) of a window solve, by position
(P_LO, P_HI, P_GAMMA, P_SCALE, P_Z_SOFT, P_POWER, P_Z_HARD, P_W_MIN, P_MAD_EPS, P_IRLS_TOL,
 P_COND_MAX, P_IPM) = range(12)  # P_IPM: the 8 settings of estimators.ipm.ipm_parameters
N_FLOAT_SETTINGS = P_IPM + 8
I_MAX_IRLS, I_IPM_MAX_ITER, I_HARD_DROP, I_MEDIAN_NORMALIZE, I_FLOOR = range(5)
N_INT_SETTINGS = 5

# rows of the workspace's vectors V (n each), matrices M (n x n each) and segment rows S (m)
(V_XCUR, V_Q, V_ZERO, V_UNIT, V_COL, V_IPM) = range(6)  # V_IPM: the interior point's rows
N_VECTORS = V_IPM + N_WORK_ROWS
M_JGJ, M_HQ, M_L, M_A, M_B = range(5)
N_MATRICES = 5
S_E, S_Z, S_TMP = range(3)


def window_settings(cfg: IRLSConfig, m: int) -> tuple[np.ndarray, np.ndarray]:
    """``(fp, ip)``: the settings of :func:`solve_window_into` for windows of ``m`` segments."""
    scale = 1.0 / m if cfg.scaling == "paper" else 1.0
    paper = cfg.scaling == "paper"
    fp = np.concatenate(([cfg.lower, cfg.upper, cfg.gamma, scale, cfg.z_soft, cfg.soft_power,
                          cfg.z_hard, cfg.w_min, cfg.mad_eps, cfg.irls_tol, cfg.cond_max],
                         ipm_parameters(cfg.ipm)))
    ip = np.array([cfg.max_irls, cfg.ipm.max_iter, int(cfg.hard_drop), int(not paper),
                   int(paper)], dtype=np.int64)
    return fp, ip


def workspace(m: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scratch of one window solve of ``m`` segments and ``n`` rotors: ``(V, M, S)``."""
    return np.zeros((N_VECTORS, n)), np.zeros((N_MATRICES, n, n)), np.zeros((3, m))


def no_history(n: int) -> np.ndarray:
    """The ``hist`` argument of :func:`solve_window_into` that records nothing."""
    return np.zeros((1, 0, 4 + n))


def history(cfg: IRLSConfig, n: int) -> np.ndarray:
    """A ``hist`` argument of :func:`solve_window_into` that records every round."""
    return np.zeros((cfg.max_irls, cfg.ipm.max_iter, 4 + n))


@jit(inline="always")
def energies_into(c, b, H, start, x, scale, e, n) -> None:
    """Segment energies ``e_s = (c + 2 b . x + x^T H x) * scale`` of the ring window (eq. 26),
    oldest segment first (``n``: the unknowns, ``b.shape[1]``)."""
    m = b.shape[0]
    for s in range(m):
        i = (start + s) % m
        acc = 0.0
        for j in range(n):
            hx = 0.0
            for k in range(n):
                hx += H[i, j, k] * x[k]
            acc += x[j] * hx + 2.0 * b[i, j] * x[j]
        e[s] = (c[i] + acc) * scale


@jit
def solve_window_into(c, b, H, start, x_prev, fp, ip, V, M, S, w, iters, hist, x_out, sd_out):
    """Algorithm 2 on the ring window ``(c, b, H)`` (segment s at ``(start + s) % m``) from
    the previous estimate ``x_prev``.

    Fills ``x_out`` (``x_prev`` on a guard), ``sd_out`` (NaN on a guard), the final robust
    weights ``w`` (m,), the interior-point iterations of each round ``iters`` and, when
    ``hist`` is (rounds, ipm iterations, 4 + n), per round and iteration ``||r_dual||,
    ||r_cent||, gap, x, sqrt(sum w e(x))`` (a (1, 0, 4 + n) ``hist`` records nothing).
    ``M[M_JGJ]`` keeps ``J^T W G J`` of the last round. Returns ``(status code, rounds,
    cond)``.
    """
    m, n = b.shape[0], b.shape[1]
    lo, hi, gamma, scale = fp[P_LO], fp[P_HI], fp[P_GAMMA], fp[P_SCALE]
    x_cur, q, zero = V[V_XCUR], V[V_Q], V[V_ZERO]
    JGJ, Hq, L = M[M_JGJ], M[M_HQ], M[M_L]
    e, z, tmp = S[S_E], S[S_Z], S[S_TMP]
    record = hist.shape[1] > 0
    for j in range(n):
        x_cur[j] = min(max(x_prev[j], lo + START_MARGIN), hi - START_MARGIN)
        sd_out[j] = np.nan
        zero[j] = 0.0
    for s in range(m):
        w[s] = 1.0
    cond = np.nan
    converged = True
    rounds = 0
    for _round in range(ip[I_MAX_IRLS]):
        energies_into(c, b, H, start, x_cur, scale, e, n)  # eq. 26
        mad_weights_into(e, fp[P_Z_SOFT], fp[P_POWER], fp[P_Z_HARD], fp[P_W_MIN],
                         fp[P_MAD_EPS], ip[I_HARD_DROP] == 1, ip[I_MEDIAN_NORMALIZE] == 1,
                         ip[I_FLOOR] == 1, w, z, tmp)
        any_kept = False
        for s in range(m):
            any_kept = any_kept or w[s] > 0
        if not any_kept:
            for j in range(n):
                x_out[j] = x_prev[j]
            return REJECTED, rounds, cond
        for j in range(n):  # J^T W G J and J^T W G r0 (eq. 24's normal equations)
            q[j] = 0.0
            for k in range(n):
                JGJ[j, k] = 0.0
        for s in range(m):
            i = (start + s) % m
            for j in range(n):
                q[j] += w[s] * b[i, j]
                for k in range(n):
                    JGJ[j, k] += w[s] * H[i, j, k]
        for j in range(n):
            for k in range(n):
                JGJ[j, k] *= scale
        cond = cond1_into(JGJ, M[M_A], M[M_B])
        if not cond <= fp[P_COND_MAX]:
            for j in range(n):
                x_out[j] = x_prev[j]
            return ILL_CONDITIONED, rounds, cond
        for j in range(n):  # the quadratic of the interior point: Hq = JGJ + gamma I
            q[j] = q[j] * scale - gamma * x_prev[j]
            for k in range(n):
                Hq[j, k] = JGJ[j, k]
            Hq[j, j] += gamma
        for j in range(n):
            x_out[j] = x_cur[j]
        h = hist[rounds] if record else hist[0]
        it, flag = ipm_into(Hq, q, lo, hi, x_out, fp[P_IPM:P_IPM + 8], ip[I_IPM_MAX_ITER],
                            V[V_IPM:], L, h)
        converged = flag == 1
        iters[rounds] = it
        if record:
            for k in range(it):  # the weighted residual norm of each iterate
                energies_into(c, b, H, start, hist[rounds, k, 3:3 + n], scale, e, n)
                acc = 0.0
                for s in range(m):
                    acc += w[s] * e[s]
                hist[rounds, k, 3 + n] = math.sqrt(max(acc, 0.0))
        rounds += 1
        step = 0.0
        for j in range(n):
            step = max(step, abs(x_out[j] - x_cur[j]))
            x_cur[j] = x_out[j]
        if step < fp[P_IRLS_TOL]:
            break
    # uncertainty: information matrix Hq = J^T W G J + gamma I of the final weights
    energies_into(c, b, H, start, x_cur, scale, e, n)
    active = 0
    s2 = 0.0
    for s in range(m):
        s2 += w[s] * e[s]
        if w[s] > 0:
            active += 1
    s2 = max(s2, 0.0) / max(10 * active - n, 1)
    if cholesky_into(Hq, zero, L, n):
        unit, col = V[V_UNIT], V[V_COL]
        for j in range(n):
            for k in range(n):
                unit[k] = 0.0
            unit[j] = 1.0
            cholesky_solve_into(L, unit, col, n)
            sd_out[j] = math.sqrt(max(col[j], 0.0) * s2)
    return (OK if converged else MAX_ITER), rounds, cond


def solve_window(c, b, H, x_prev, config: IRLSConfig, record_history: bool = False):
    """Algorithm 2 on one window given its per-segment quadratic terms (:func:`solve_window_into`).

    Args:
        c, b, H: the window's segment terms, oldest first, (m,), (m, n), (m, n, n).
        x_prev: previous estimate (warm start and smoothness anchor), (n,).
        record_history: keep the per-round KKT histories in the diagnostics.

    Returns:
        ``(eta, sd, diagnostics)``; on a guard ``eta`` is ``x_prev`` and ``sd`` is None.
    """
    c, b, H = (np.ascontiguousarray(a, dtype=float) for a in (c, b, H))
    x_prev = np.ascontiguousarray(x_prev, dtype=float)
    if b.ndim != 2 or c.shape != b.shape[:1] or H.shape != b.shape + b.shape[1:] \
            or x_prev.shape != b.shape[1:]:
        raise ConfigError(f"window terms must be c (m,), b (m, n), H (m, n, n), x_prev (n,); "
                          f"got {c.shape}, {b.shape}, {H.shape}, {x_prev.shape}")
    m, n = b.shape
    fp, ip = window_settings(config, m)
    w, iters = np.zeros(m), np.zeros(config.max_irls, dtype=np.int64)
    hist = history(config, n) if record_history else no_history(n)
    x, sd = np.empty(n), np.empty(n)
    code, rounds, cond = solve_window_into(c, b, H, 0, x_prev, fp, ip, *workspace(m, n), w,
                                           iters, hist, x, sd)
    diag = window_diagnostics(code, rounds, cond, iters, w, config,
                              hist if record_history else None)
    if code in (OK, MAX_ITER):
        return x, sd, diag
    return x_prev.copy(), None, diag
