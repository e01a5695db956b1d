"""Compiled (numba) twin of the IRLS window update, used when numba is importable.

The same algorithm as :func:`estimators.irls.solve_window` (MAD weights, conditioning guard,
interior-point rounds, uncertainty), written as scalar loops over the per-segment quadratic
terms so a whole recording runs in one compiled call. Results agree with the numpy path to
rounding (summation order, LU vs Cholesky for the information matrix; tested to 1e-9).

The kernels allocate nothing per window: every temporary lives in a :func:`workspace` made
once per recording (``run_windows_numba``), per estimator (``solve_window_numba``) or per batch
chunk (:func:`solve_ring_batch`, parallel over vehicles; the segment terms come from
:mod:`estimators._residuals_numba`, built the same way), so the
single estimator and the batched one run the same compiled window solver
(:func:`_solve_window_into`). A window is read from a ring of per-segment terms: segment ``s``
(0 = oldest) sits at index ``(start + s) % m``; a recording's window is the ring with
``start = 0``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import get_num_threads, njit, prange

from estimators.base import (STATUS_ILL_CONDITIONED, STATUS_MAX_ITER, STATUS_NO_EXCITATION,
                             STATUS_OK, STATUS_REJECTED, STATUSES)
from estimators._residuals_numba import (segment_terms, segment_terms_batch,  # noqa: F401
                                        segment_terms_into)
from estimators.ipm import ipm4

# the interior point of the 4-rotor case: the very function the numpy path runs, compiled
_ipm4 = njit(cache=True)(ipm4)

_OK = STATUSES.index(STATUS_OK)
_ILL = STATUSES.index(STATUS_ILL_CONDITIONED)
_NO_EXC = STATUSES.index(STATUS_NO_EXCITATION)
_REJ = STATUSES.index(STATUS_REJECTED)
_MAXIT = STATUSES.index(STATUS_MAX_ITER)

# rows of the vector workspace V (n columns) and of the matrix workspace M (n x n each)
_X, _PU, _PL, _LU, _LL, _DLU, _DLL, _XT, _LUT, _LLT, _RHS, _DX = range(12)
_XCUR, _Q, _BW, _UNIT, _COL = range(12, 17)
_N_VEC = 17
_JGJ, _HQ, _K, _L, _GJ, _INV = range(6)
_N_MAT = 6
# rows of the segment workspace S (m columns): energies, |e - median|, sort scratch
_E, _DEV, _TMP = range(3)


class KernelParams(tuple):
    """``(fp, ip)`` of a configuration; :func:`solve_window_numba` keeps its window workspace
    here, so an estimator that caches its parameters reuses one workspace."""

    workspace = None


def kernel_parameters(cfg, m: int) -> KernelParams:
    """Pack an :class:`~estimators.irls.IRLSConfig` into the kernels' float/int arrays."""
    from estimators.irls import _START_MARGIN

    ipm = cfg.ipm
    scale = 1.0 / m if cfg.scaling == "paper" else 1.0
    fp = np.array([cfg.lower, cfg.upper, cfg.gamma, scale, cfg.z_soft, cfg.soft_power,
                   cfg.z_hard, cfg.w_min, cfg.mad_eps, cfg.irls_tol, cfg.cond_max, ipm.mu,
                   ipm.alpha, ipm.beta, ipm.step_fraction, ipm.backtrack_eps, ipm.min_step,
                   ipm.tol_feas, ipm.tol_gap, _START_MARGIN], dtype=np.float64)
    paper = cfg.scaling == "paper"
    ip = np.array([cfg.max_irls, ipm.max_iter, int(cfg.hard_drop), int(not paper), int(paper)],
                  dtype=np.int64)
    return KernelParams((fp, ip))


@njit(cache=True)
def workspace(m, n, rounds):
    """Scratch of one window solve (m segments, n rotors, at most ``rounds`` IRLS rounds):
    ``(V (17, n), M (6, n, n), S (3, m), iters (rounds,), w (m,), nohist (0, 7))`` (``nohist``
    is :func:`estimators.ipm.ipm4`'s "record no history")."""
    return (np.zeros((_N_VEC, n)), np.zeros((_N_MAT, n, n)), np.zeros((3, m)),
            np.zeros(rounds, dtype=np.int64), np.zeros(m), np.zeros((0, 7)))


def batch_chunks(rows: int) -> int:
    """Work units of the batch kernels: 4 per numba thread (load balance), at most ``rows``
    (numba's thread count is read here, in Python: inside a kernel it would block caching)."""
    return max(1, min(rows, 4 * get_num_threads()))


@njit(cache=True)
def _copy(src, dst):
    for i in range(src.size):
        dst[i] = src[i]


@njit(cache=True)
def _cholesky_solve_into(A, rhs, L, out):
    """Solve ``A out = rhs`` for symmetric positive definite ``A`` (``L`` is scratch);
    returns False (``out`` undefined) when ``A`` is not positive definite."""
    n = A.shape[0]
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    for i in range(n):  # forward: L y = rhs (y stored in out)
        s = rhs[i]
        for k in range(i):
            s -= L[i, k] * out[k]
        out[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):  # back: L^T out = y
        s = out[i]
        for k in range(i + 1, n):
            s -= L[k, i] * out[k]
        out[i] = s / L[i, i]
    return True


@njit(cache=True)
def _cond1_into(A, M, inv):
    """1-norm condition number (Gauss-Jordan inverse with partial pivoting, in the scratch
    ``M`` and ``inv``); inf if singular."""
    n = A.shape[0]
    for r in range(n):
        for k in range(n):
            M[r, k] = A[r, k]
            inv[r, k] = 1.0 if r == k else 0.0
    for col in range(n):
        piv = col
        for r in range(col + 1, n):
            if abs(M[r, col]) > abs(M[piv, col]):
                piv = r
        if M[piv, col] == 0.0:
            return np.inf
        for k in range(n):
            M[col, k], M[piv, k] = M[piv, k], M[col, k]
            inv[col, k], inv[piv, k] = inv[piv, k], inv[col, k]
        d = M[col, col]
        for k in range(n):
            M[col, k] /= d
            inv[col, k] /= d
        for r in range(n):
            if r != col:
                f = M[r, col]
                for k in range(n):
                    M[r, k] -= f * M[col, k]
                    inv[r, k] -= f * inv[col, k]
    na = 0.0
    ni = 0.0
    for k in range(n):
        sa = 0.0
        si = 0.0
        for r in range(n):
            sa += abs(A[r, k])
            si += abs(inv[r, k])
        na = max(na, sa)
        ni = max(ni, si)
    value = na * ni
    return value if math.isfinite(value) else np.inf


@njit(cache=True)
def _energies_into(c, b, H, start, x, scale, e):
    """Segment energies ``e_s`` of the ring window (eq. 26), oldest segment first."""
    m, n = b.shape[0], b.shape[1]
    for s in range(m):
        i = (start + s) % m
        acc = 0.0
        for j in range(n):
            hx = 0.0
            for k in range(n):
                hx += H[i, j, k] * x[k]
            acc += x[j] * hx + 2.0 * b[i, j] * x[j]
        e[s] = (c[i] + acc) * scale


@njit(cache=True)
def _median(a, tmp):
    """Median of ``a`` (insertion sort into ``tmp``), as ``estimators.robust._median``."""
    m = a.size
    for i in range(m):
        v = a[i]
        j = i - 1
        while j >= 0 and tmp[j] > v:
            tmp[j + 1] = tmp[j]
            j -= 1
        tmp[j + 1] = v
    k = m // 2
    if m % 2:
        return tmp[k]
    return 0.5 * (tmp[k - 1] + tmp[k])


@njit(cache=True)
def _mad_weights_into(e, fp, ip, w, dev, tmp):
    """Robust weights (eqs. 27-30), as :func:`estimators.robust.mad_weights`, into ``w``."""
    m = e.size
    med = _median(e, tmp)
    for i in range(m):
        dev[i] = abs(e[i] - med)
    mad = 1.4826 * _median(dev, tmp)
    if mad < fp[8]:
        for i in range(m):
            w[i] = 1.0
        return
    hard_drop, median_normalize, floor = ip[2] == 1, ip[3] == 1, ip[4] == 1
    for i in range(m):
        z = dev[i] / max(mad, fp[8])
        wi = 1.0 / (1.0 + (z / fp[4]) ** fp[5])
        if floor or not hard_drop:
            wi = max(wi, fp[7])
        if hard_drop and z > fp[6]:
            wi = 0.0
        w[i] = wi
    if median_normalize:
        medw = _median(w, tmp)
        if medw > 0:
            for i in range(m):
                w[i] = w[i] / medw


@njit(cache=True)
def _ipm_into(H, q, x0, fp, max_iter, V, K, L):
    """Algorithm 1 on ``1/2 x^T H x + q^T x``, box [fp[0], fp[1]], from ``x0``; the solution
    is left in ``V[_X]``. Returns ``(iterations, converged)``.

    Mirrors :func:`estimators.ipm.solve_box_qp` (workspace rows of ``V``, no histories)."""
    n = x0.size
    lo, hi = fp[0], fp[1]
    mu, alpha, beta, frac, bt_eps, min_step, tol_feas, tol_gap = (fp[11], fp[12], fp[13], fp[14],
                                                                   fp[15], fp[16], fp[17], fp[18])
    x, pu, pl, lu, ll = V[_X], V[_PU], V[_PL], V[_LU], V[_LL]
    dlu, dll, x_t, lu_t, ll_t, rhs, dx = (V[_DLU], V[_DLL], V[_XT], V[_LUT], V[_LLT], V[_RHS],
                                          V[_DX])
    for i in range(n):
        x[i] = x0[i]
        pu[i], pl[i] = x[i] - hi, lo - x[i]
        lu[i], ll[i] = -1.0 / pu[i], -1.0 / pl[i]
    for it in range(1, max_iter + 1):
        gap = 0.0
        for i in range(n):
            gap -= pu[i] * lu[i] + pl[i] * ll[i]
        inv_t = max(gap, 1e-12) / (mu * 2 * n)
        r2 = 0.0
        for i in range(n):
            s = q[i] + lu[i] - ll[i]
            for k in range(n):
                s += H[i, k] * x[k]
            cu = -lu[i] * pu[i] - inv_t
            cl = -ll[i] * pl[i] - inv_t
            r2 += s * s + cu * cu + cl * cl
            rhs[i] = cl / pl[i] - cu / pu[i] - s
            for k in range(n):
                K[i, k] = H[i, k]
            K[i, i] -= lu[i] / pu[i] + ll[i] / pl[i]
        r_norm = math.sqrt(r2)
        if not _cholesky_solve_into(K, rhs, L, dx):
            return it, False
        smax = 1.0
        for i in range(n):
            cu = -lu[i] * pu[i] - inv_t
            cl = -ll[i] * pl[i] - inv_t
            dlu[i] = (cu - lu[i] * dx[i]) / pu[i]
            dll[i] = (cl + ll[i] * dx[i]) / pl[i]
            if dlu[i] < 0:
                smax = min(smax, -lu[i] / dlu[i])
            if dll[i] < 0:
                smax = min(smax, -ll[i] / dll[i])
            if dx[i] > 0:
                smax = min(smax, -pu[i] / dx[i])
            elif dx[i] < 0:
                smax = min(smax, pl[i] / dx[i])
        s = frac * smax
        while True:
            for i in range(n):
                x_t[i] = x[i] + s * dx[i]
                lu_t[i] = lu[i] + s * dlu[i]
                ll_t[i] = ll[i] + s * dll[i]
            r2 = 0.0
            for i in range(n):
                v = q[i] + lu_t[i] - ll_t[i]
                for k in range(n):
                    v += H[i, k] * x_t[k]
                cu = -lu_t[i] * (x_t[i] - hi) - inv_t
                cl = -ll_t[i] * (lo - x_t[i]) - inv_t
                r2 += v * v + cu * cu + cl * cl
            r_try = math.sqrt(r2)
            if r_try <= (1.0 - alpha * s) * r_norm + bt_eps or s < min_step:
                break
            s *= beta
        gap = 0.0
        for i in range(n):
            x[i], lu[i], ll[i] = x_t[i], lu_t[i], ll_t[i]
            pu[i], pl[i] = x[i] - hi, lo - x[i]
            gap -= pu[i] * lu[i] + pl[i] * ll[i]
        if r_try < tol_feas and gap < tol_gap:
            return it, True
    return max_iter, False


@njit(cache=True)
def _solve_window_into(c, b, H, start, x_prev, fp, ip, V, M, S, iters, w, nohist, x_out,
                       sd_out):
    """Algorithm 2 on the ring window ``(c, b, H)`` (segment s at ``(start + s) % m``),
    allocation-free. Fills ``x_out``, ``sd_out`` (NaN on a guard), ``w`` (final weights) and
    ``iters``; returns ``(status code, rounds, cond)``."""
    m, n = b.shape[0], b.shape[1]
    lo, hi, gamma, scale = fp[0], fp[1], fp[2], fp[3]
    x_cur, q, bw, unit, col = V[_XCUR], V[_Q], V[_BW], V[_UNIT], V[_COL]
    JGJ, Hq, K, L, GJ, INV = M[_JGJ], M[_HQ], M[_K], M[_L], M[_GJ], M[_INV]
    e, dev, tmp = S[_E], S[_DEV], S[_TMP]
    for j in range(n):
        x_cur[j] = min(max(x_prev[j], lo + fp[19]), hi - fp[19])
        sd_out[j] = np.nan
    for i in range(m):
        w[i] = 1.0
    cond = np.nan
    converged = True
    rounds = 0
    for _r in range(ip[0]):
        _energies_into(c, b, H, start, x_cur, scale, e)
        _mad_weights_into(e, fp, ip, w, dev, tmp)
        any_pos = False
        for s in range(m):
            any_pos = any_pos or w[s] > 0
        if not any_pos:
            _copy(x_prev, x_out)
            return _REJ, rounds, cond
        for j in range(n):
            bw[j] = 0.0
            for k in range(n):
                JGJ[j, k] = 0.0
        for s in range(m):
            i = (start + s) % m
            for j in range(n):
                bw[j] += w[s] * b[i, j]
                for k in range(n):
                    JGJ[j, k] += w[s] * H[i, j, k]
        for j in range(n):
            for k in range(n):
                JGJ[j, k] *= scale
        cond = _cond1_into(JGJ, GJ, INV)
        if not cond <= fp[10]:
            _copy(x_prev, x_out)
            return _ILL, rounds, cond
        for j in range(n):
            q[j] = bw[j] * scale - gamma * x_prev[j]
            for k in range(n):
                Hq[j, k] = JGJ[j, k]
            Hq[j, j] += gamma
        if n == 4:  # closed-form 4x4 algebra on scalars (estimators.ipm.ipm4)
            out = _ipm4((Hq[0, 0], Hq[0, 1], Hq[0, 2], Hq[0, 3], Hq[1, 0], Hq[1, 1], Hq[1, 2],
                         Hq[1, 3], Hq[2, 0], Hq[2, 1], Hq[2, 2], Hq[2, 3], Hq[3, 0], Hq[3, 1],
                         Hq[3, 2], Hq[3, 3]), (q[0], q[1], q[2], q[3]), lo, hi,
                        (x_cur[0], x_cur[1], x_cur[2], x_cur[3]), fp[11], fp[12], fp[13],
                        fp[14], fp[15], fp[16], fp[17], fp[18], ip[1], nohist)
            V[_X, 0], V[_X, 1], V[_X, 2], V[_X, 3] = out[0], out[1], out[2], out[3]
            it, converged = out[12], out[13] == 1
        else:
            it, converged = _ipm_into(Hq, q, x_cur, fp, ip[1], V, K, L)
        iters[rounds] = it
        rounds += 1
        step = 0.0
        for j in range(n):
            step = max(step, abs(V[_X, j] - x_cur[j]))
            x_cur[j] = V[_X, j]
        if step < fp[9]:
            break
    # uncertainty from the information matrix with the final weights
    _energies_into(c, b, H, start, x_cur, scale, e)
    active = 0
    s2 = 0.0
    for s in range(m):
        s2 += w[s] * e[s]
        if w[s] > 0:
            active += 1
    s2 = max(s2, 0.0) / max(10 * active - n, 1)
    info = JGJ
    for j in range(n):
        for k in range(n):
            info[j, k] = 0.0
    for s in range(m):
        i = (start + s) % m
        for j in range(n):
            for k in range(n):
                info[j, k] += w[s] * H[i, j, k]
    for j in range(n):
        for k in range(n):
            info[j, k] *= scale
        info[j, j] += gamma
    for j in range(n):
        for k in range(n):
            unit[k] = 0.0
        unit[j] = 1.0
        if _cholesky_solve_into(info, unit, L, col):
            sd_out[j] = math.sqrt(max(col[j], 0.0) * s2)
        else:
            sd_out[j] = np.nan
    _copy(x_cur, x_out)
    return (_OK if converged else _MAXIT), rounds, cond


@njit(cache=True)
def _run_windows(c, b, H, excited, x0, s0, fp, ip, m, eta, sd, status):
    n = x0.size
    x = x0.copy()
    s = s0.copy()
    V, M, S, iters, w, nohist = workspace(m, n, ip[0])
    x_out = np.empty(n)
    sd_out = np.empty(n)
    for k in range(excited.size):
        if excited[k]:
            code, _rounds, _cond = _solve_window_into(c[k:k + m], b[k:k + m], H[k:k + m], 0, x,
                                                      fp, ip, V, M, S, iters, w, nohist,
                                                      x_out, sd_out)
            if code == _OK or code == _MAXIT:
                _copy(x_out, x)
                _copy(sd_out, s)
            status[k] = code
        else:
            status[k] = _NO_EXC
        eta[k] = x
        sd[k] = s
    return x, s


@njit(cache=True, parallel=True)
def solve_ring_batch(c, b, H, start, rows, x_prev, fp, ip, x, sd, code, weights, chunks):
    """Algorithm 2 on the ring windows of the vehicles ``rows`` (ring arrays ``c`` (N, m),
    ``b`` (N, m, n), ``H`` (N, m, n, n); oldest segment at ``start``), in parallel over chunks
    of rows (:func:`batch_chunks`) with one workspace per chunk. Fills ``x``, ``sd`` (K, n),
    ``code`` (K,) and the final robust weights (K, m), oldest segment first."""
    K, m, n = rows.size, b.shape[1], b.shape[2]
    for ch in prange(chunks):
        V, M, S, iters, _w, nohist = workspace(m, n, ip[0])
        for k in range(ch * K // chunks, (ch + 1) * K // chunks):
            i = rows[k]
            code[k], _r, _cond = _solve_window_into(c[i], b[i], H[i], start, x_prev[i], fp, ip,
                                                    V, M, S, iters, weights[k], nohist, x[k],
                                                    sd[k])


def run_windows_numba(c, b, H, excited, x0, cfg, progress: bool = False):
    """All windows of a recording in compiled code; returns (eta, sd, status codes)."""
    from quadfault.progress import progress_bar

    m = cfg.window - 1
    fp, ip = kernel_parameters(cfg, m)
    n_win = len(excited)
    n = len(x0)
    eta = np.empty((n_win, n))
    sd = np.empty((n_win, n))
    status = np.empty(n_win, dtype=np.int64)
    x = np.asarray(x0, dtype=float).copy()
    s = np.full(n, np.nan)
    chunk = 20000
    bar = progress_bar(total=n_win, desc="irls", unit="win", disable=None if progress else True)
    for k0 in range(0, n_win, chunk):
        k1 = min(k0 + chunk, n_win)
        x, s = _run_windows(c[k0:k1 + m - 1], b[k0:k1 + m - 1], H[k0:k1 + m - 1],
                            np.ascontiguousarray(excited[k0:k1]), x, s, fp, ip, m,
                            eta[k0:k1], sd[k0:k1], status[k0:k1])
        bar.update(k1 - k0)
    bar.close()
    return eta, sd, status


def window_diagnostics(code: int, rounds: int, cond: float, iters, w, cfg):
    """The :class:`~estimators.irls.IRLSDiagnostics` of a compiled window solve (status
    ``code``, ``rounds`` IRLS rounds with ``iters`` interior-point iterations each, final
    weights ``w``, copied)."""
    from estimators.irls import IRLSDiagnostics

    message = ""
    if code == _REJ:
        message = "every segment rejected"
    elif code == _MAXIT:
        message = f"interior point stopped at {cfg.ipm.max_iter} iterations"
    elif code == _ILL:
        message = f"cond(J^T G J) = {cond:.3g} > {cfg.cond_max:g}"
    rejected = tuple(k for k, wk in enumerate(w.tolist()) if wk == 0)
    return IRLSDiagnostics(STATUSES[code], message, tuple(iters[:rounds].tolist()), w.copy(),
                           rejected, cond)


def solve_window_numba(c, b, H, x_prev, cfg, params=None):
    """Compiled :func:`estimators.irls.solve_window` (no histories); ``params`` are the
    cached :func:`kernel_parameters` of ``cfg``."""
    m, n = np.shape(b)
    params = kernel_parameters(cfg, m) if params is None else params
    fp, ip = params
    ws = getattr(params, "workspace", None)
    if ws is None or ws[0].shape[1] != n or ws[2].shape[1] != m:
        ws = workspace(m, n, int(ip[0]))
        if isinstance(params, KernelParams):
            params.workspace = ws
    V, M, S, iters, w, nohist = ws
    x_out = np.empty(n)
    sd_out = np.empty(n)
    code, rounds, cond = _solve_window_into(np.ascontiguousarray(c, dtype=float),
                                            np.ascontiguousarray(b, dtype=float),
                                            np.ascontiguousarray(H, dtype=float), 0,
                                            np.asarray(x_prev, dtype=float), fp, ip, V, M, S,
                                            iters, w, nohist, x_out, sd_out)
    diag = window_diagnostics(code, rounds, cond, iters, w, cfg)
    if code in (_OK, _MAXIT):
        return x_out, sd_out, diag
    return np.asarray(x_prev, dtype=float), None, diag
