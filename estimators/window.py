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
    ILL_CONDITIONED,
    MAX_ITER,
    OK,
    REJECTED,
)
from estimators.ipm import N_SETTINGS as N_IPM_SETTINGS
from estimators.ipm import N_WORK_ROWS, any_size, ipm_parameters, ipm_steps
from estimators.irls_config import IRLSConfig, window_diagnostics
from estimators.linalg import cholesky_into, cholesky_solve_into, cond1_into
from estimators.robust import mad_weights_into
from estimators.state import fields, pack
from quadfault.errors import ConfigError
from quadfault.jit import jit

START_MARGIN = 1e-6  #: the interior-point start is kept this far inside the bounds


#: the float settings of a window solve (``fp``), by name; ``ipm``: the interior point's
#: (:data:`estimators.ipm.SETTINGS`)
SETTINGS = fields(
    "WindowSettings",
    "lo",
    "hi",
    "gamma",
    "scale",
    "z_soft",
    "power",
    "z_hard",
    "w_min",
    "mad_eps",
    "irls_tol",
    "cond_max",
    ("ipm", N_IPM_SETTINGS),
)
#: the integer settings of a window solve (``ip``), by name
INT_SETTINGS = fields(
    "WindowIntSettings", "max_irls", "ipm_max_iter", "hard_drop", "median_normalize", "floor"
)
#: rows of the workspace's vectors ``V`` (n each; ``ipm``: the interior point's rows),
#: matrices ``M`` (n x n each) and segment rows ``S`` (m each)
VECTORS = fields("WindowVectors", "xcur", "q", "zero", "unit", "col", ("ipm", N_WORK_ROWS))
MATRICES = fields("WindowMatrices", "JGJ", "Hq", "L", "A", "B")
SEGMENT_ROWS = fields("WindowSegmentRows", "e", "z", "tmp")
N_FLOAT_SETTINGS, N_INT_SETTINGS = SETTINGS.size, INT_SETTINGS.size
N_VECTORS, N_MATRICES, N_SEGMENT_ROWS = VECTORS.size, MATRICES.size, SEGMENT_ROWS.size


def window_settings(cfg: IRLSConfig, m: int) -> tuple[np.ndarray, np.ndarray]:
    """``(fp, ip)``: the settings of :func:`solve_window_into` for windows of ``m`` segments."""
    scale = 1.0 / m if cfg.scaling == "paper" else 1.0
    paper = cfg.scaling == "paper"
    fp = pack(
        SETTINGS,
        lo=cfg.lower,
        hi=cfg.upper,
        gamma=cfg.gamma,
        scale=scale,
        z_soft=cfg.z_soft,
        power=cfg.soft_power,
        z_hard=cfg.z_hard,
        w_min=cfg.w_min,
        mad_eps=cfg.mad_eps,
        irls_tol=cfg.irls_tol,
        cond_max=cfg.cond_max,
        ipm=ipm_parameters(cfg.ipm),
    )
    ip = pack(
        INT_SETTINGS,
        max_irls=cfg.max_irls,
        ipm_max_iter=cfg.ipm.max_iter,
        hard_drop=int(cfg.hard_drop),
        median_normalize=int(not paper),
        floor=int(paper),
    ).astype(np.int64)
    return fp, ip


def workspace(m: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scratch of one window solve of ``m`` segments and ``n`` rotors: ``(V, M, S)``."""
    return np.zeros((N_VECTORS, n)), np.zeros((N_MATRICES, n, n)), np.zeros((N_SEGMENT_ROWS, m))


def no_history(n: int) -> np.ndarray:
    """The ``hist`` argument of :func:`solve_window_into` that records nothing."""
    return np.zeros((1, 0, 4 + n))


def history(cfg: IRLSConfig, n: int) -> np.ndarray:
    """A ``hist`` argument of :func:`solve_window_into` that records every round."""
    return np.zeros((cfg.max_irls, cfg.ipm.max_iter, 4 + n))


@jit(inner=True)
def energies_into(c, b, H, start, x, scale, e, n) -> None:
    """Segment energies ``e_s = (c + 2 b . x + x^T H x) * scale`` of the ring window (eq. 26),
    oldest segment first (``n``: the unknowns, ``b.shape[1]``). A call, not inlined: its three
    calls in :func:`solve_window_into` share one compiled copy (a first run compiles less)."""
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


@jit(inner=True)
def solve_window_into(
    c, b, H, start, x_prev, fp, ip, V, M, S, w, iters, hist, x_out, sd_out, any_n
):
    """Algorithm 2 on the ring window ``(c, b, H)`` (segment s at ``(start + s) % m``) from
    the previous estimate ``x_prev``.

    Fills ``x_out`` (``x_prev`` on a guard), ``sd_out`` (NaN on a guard), the final robust
    weights ``w`` (m,), the interior-point iterations of each round ``iters`` and, when
    ``hist`` is (rounds, ipm iterations, 4 + n), per round and iteration ``||r_dual||,
    ||r_cent||, gap, x, sqrt(sum w e(x))`` (a (1, 0, 4 + n) ``hist`` records nothing).
    ``M[MATRICES.JGJ]`` keeps ``J^T W G J`` of the last round. ``any_n``
    (:func:`estimators.ipm.any_size` of ``n``): None runs the interior point compiled for
    four unknowns only (a quadrotor), True the one for any ``n``. Returns ``(status code,
    rounds, cond)``.
    """
    m, n = b.shape[0], b.shape[1]
    lo, hi, gamma, scale = fp[SETTINGS.lo], fp[SETTINGS.hi], fp[SETTINGS.gamma], fp[SETTINGS.scale]
    x_cur, q, zero = V[VECTORS.xcur], V[VECTORS.q], V[VECTORS.zero]
    JGJ, Hq, L = M[MATRICES.JGJ], M[MATRICES.Hq], M[MATRICES.L]
    e, z, tmp = S[SEGMENT_ROWS.e], S[SEGMENT_ROWS.z], S[SEGMENT_ROWS.tmp]
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
    for _round in range(ip[INT_SETTINGS.max_irls]):
        energies_into(c, b, H, start, x_cur, scale, e, n)  # eq. 26
        mad_weights_into(
            e,
            fp[SETTINGS.z_soft],
            fp[SETTINGS.power],
            fp[SETTINGS.z_hard],
            fp[SETTINGS.w_min],
            fp[SETTINGS.mad_eps],
            ip[INT_SETTINGS.hard_drop] == 1,
            ip[INT_SETTINGS.median_normalize] == 1,
            ip[INT_SETTINGS.floor] == 1,
            w,
            z,
            tmp,
        )
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
        cond = cond1_into(JGJ, M[MATRICES.A], M[MATRICES.B])
        if not cond <= fp[SETTINGS.cond_max]:
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
        if any_n is None:  # the interior point (Algorithm 1) for 4 unknowns (a quadrotor)
            it, flag = ipm_steps(
                Hq,
                q,
                lo,
                hi,
                x_out,
                fp[SETTINGS.ipm : SETTINGS.size],
                ip[INT_SETTINGS.ipm_max_iter],
                V[VECTORS.ipm :],
                L,
                h,
                4,
            )
        else:
            it, flag = ipm_steps(
                Hq,
                q,
                lo,
                hi,
                x_out,
                fp[SETTINGS.ipm : SETTINGS.size],
                ip[INT_SETTINGS.ipm_max_iter],
                V[VECTORS.ipm :],
                L,
                h,
                n,
            )
        converged = flag == 1
        iters[rounds] = it
        if record:
            for k in range(it):  # the weighted residual norm of each iterate
                energies_into(c, b, H, start, hist[rounds, k, 3 : 3 + n], scale, e, n)
                acc = 0.0
                for s in range(m):
                    acc += w[s] * e[s]
                hist[rounds, k, 3 + n] = math.sqrt(max(acc, 0.0))
        rounds += 1
        step = 0.0
        for j in range(n):
            step = max(step, abs(x_out[j] - x_cur[j]))
            x_cur[j] = x_out[j]
        if step < fp[SETTINGS.irls_tol]:
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
        unit, col = V[VECTORS.unit], V[VECTORS.col]
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
    if (
        b.ndim != 2
        or c.shape != b.shape[:1]
        or H.shape != b.shape + b.shape[1:]
        or x_prev.shape != b.shape[1:]
    ):
        raise ConfigError(
            f"window terms must be c (m,), b (m, n), H (m, n, n), x_prev (n,); "
            f"got {c.shape}, {b.shape}, {H.shape}, {x_prev.shape}"
        )
    m, n = b.shape
    fp, ip = window_settings(config, m)
    w, iters = np.zeros(m), np.zeros(config.max_irls, dtype=np.int64)
    hist = history(config, n) if record_history else no_history(n)
    x, sd = np.empty(n), np.empty(n)
    code, rounds, cond = solve_window_into(
        c, b, H, 0, x_prev, fp, ip, *workspace(m, n), w, iters, hist, x, sd, any_size(n)
    )
    diag = window_diagnostics(
        code, rounds, cond, iters, w, config, hist if record_history else None
    )
    if code in (OK, MAX_ITER):
        return x, sd, diag
    return x_prev.copy(), None, diag
