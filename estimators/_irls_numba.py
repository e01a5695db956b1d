"""Compiled (numba) twin of the IRLS window update, used when numba is importable.

The same algorithm as :func:`estimators.irls.solve_window` (MAD weights, conditioning guard,
interior-point rounds, uncertainty), written as scalar loops over the per-segment quadratic
terms so a whole recording runs in one compiled call. Results agree with the numpy path to
rounding (summation order, LU vs Cholesky for the information matrix; tested to 1e-9).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimators.base import (STATUS_ILL_CONDITIONED, STATUS_MAX_ITER, STATUS_NO_EXCITATION,
                             STATUS_OK, STATUS_REJECTED, STATUSES)

_OK = STATUSES.index(STATUS_OK)
_ILL = STATUSES.index(STATUS_ILL_CONDITIONED)
_NO_EXC = STATUSES.index(STATUS_NO_EXCITATION)
_REJ = STATUSES.index(STATUS_REJECTED)
_MAXIT = STATUSES.index(STATUS_MAX_ITER)


def kernel_parameters(cfg, m: int):
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
    return fp, ip


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
def segment_terms(dt, p0, p1, v0, v1, R0, R1, w0, w1, f, mass, g, Jmat, Jinv, A, G):
    """One segment's quadratic terms ``(c, b, H, thrust)``: the compiled twin of
    :func:`estimators.residuals.segment_models` + :func:`~estimators.residuals.quadratic_terms`
    for a single segment (used by the online ``update``)."""
    n = f.size
    r0 = np.empty(10)
    J = np.empty((10, n))
    b3 = R0[:, 2]
    thrust = 0.0
    for j in range(n):
        thrust += A[0, j] * f[j]
    # velocity / position (eqs. 13, 14, 17, 18)
    for a in range(3):
        ge = g if a == 2 else 0.0
        r0[a] = v1[a] - v0[a] - ge * dt
        r0[3 + a] = p1[a] - p0[a] - v0[a] * dt - ge * 0.5 * dt * dt
        for j in range(n):
            dv = b3[a] * f[j] * A[0, j] / mass
            J[a, j] = dv * dt
            J[3 + a, j] = dv * (0.5 * dt * dt)
    # rate (eqs. 15, 19)
    Jw = np.zeros(3)
    for a in range(3):
        for k in range(3):
            Jw[a] += Jmat[a, k] * w0[k]
    gyro = np.empty(3)
    gyro[0] = w0[1] * Jw[2] - w0[2] * Jw[1]
    gyro[1] = w0[2] * Jw[0] - w0[0] * Jw[2]
    gyro[2] = w0[0] * Jw[1] - w0[1] * Jw[0]
    w_hat0 = np.empty(3)
    for a in range(3):
        s = 0.0
        for k in range(3):
            s += Jinv[a, k] * gyro[k]
        w_hat0[a] = w0[a] - s * dt
        r0[6 + a] = w1[a] - w_hat0[a]
        for j in range(n):
            ja = 0.0
            for k in range(3):
                ja += Jinv[a, k] * A[1 + k, j]
            J[6 + a, j] = -ja * f[j] * dt
    # rotation (eqs. 20-22): r_R = 1/2 (3 - tr dR) - dt vee(dR) . W_hat
    dR = np.zeros((3, 3))
    for a in range(3):
        for k in range(3):
            for i in range(3):
                dR[a, k] += R0[i, a] * R1[i, k]
    u = np.empty(3)
    u[0] = 0.5 * (dR[2, 1] - dR[1, 2]) * dt
    u[1] = 0.5 * (dR[0, 2] - dR[2, 0]) * dt
    u[2] = 0.5 * (dR[1, 0] - dR[0, 1]) * dt
    r0[9] = 0.5 * (3.0 - (dR[0, 0] + dR[1, 1] + dR[2, 2])) - (u[0] * w_hat0[0] + u[1] * w_hat0[1]
                                                                + u[2] * w_hat0[2])
    for j in range(n):
        J[9, j] = u[0] * J[6, j] + u[1] * J[7, j] + u[2] * J[8, j]
    c = 0.0
    b = np.zeros(n)
    H = np.zeros((n, n))
    for r in range(10):
        c += r0[r] * G[r] * r0[r]
        for j in range(n):
            gj = G[r] * J[r, j]
            b[j] += gj * r0[r]
            for k in range(n):
                H[j, k] += gj * J[r, k]
    return c, b, H, thrust


@njit(cache=True)
def _cond1(A):
    """1-norm condition number (Gauss-Jordan inverse with partial pivoting); inf if singular."""
    n = A.shape[0]
    M = A.copy()
    inv = np.eye(n)
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
def _energies(c, b, H, x, scale):
    m, n = b.shape
    e = np.empty(m)
    for i in range(m):
        s = 0.0
        for j in range(n):
            hx = 0.0
            for k in range(n):
                hx += H[i, j, k] * x[k]
            s += x[j] * hx + 2.0 * b[i, j] * x[j]
        e[i] = (c[i] + s) * scale
    return e


@njit(cache=True)
def _mad_weights(e, fp, ip):
    m = e.size
    w = np.ones(m)
    med = np.median(e)
    dev = np.abs(e - med)
    mad = 1.4826 * np.median(dev)
    if mad < fp[8]:
        return w
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
        medw = np.median(w)
        if medw > 0:
            w = w / medw
    return w


@njit(cache=True)
def _ipm(H, q, x0, fp, max_iter):
    """Algorithm 1 on ``1/2 x^T H x + q^T x``, box [fp[0], fp[1]]; returns (x, iters, ok).

    Mirrors :func:`estimators.ipm.solve_box_qp` (preallocated buffers, no histories)."""
    n = x0.size
    lo, hi = fp[0], fp[1]
    mu, alpha, beta, frac, bt_eps, min_step, tol_feas, tol_gap = (fp[11], fp[12], fp[13], fp[14],
                                                                   fp[15], fp[16], fp[17], fp[18])
    x = x0.copy()
    pu, pl = x - hi, lo - x
    lu, ll = -1.0 / pu, -1.0 / pl
    K = np.empty((n, n))
    rhs = np.empty(n)
    dlu = np.empty(n)
    dll = np.empty(n)
    x_t, lu_t, ll_t = np.empty(n), np.empty(n), np.empty(n)
    L = np.empty((n, n))
    dx = np.empty(n)
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
            return x, it, False
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
            return x, it, True
    return x, max_iter, False


@njit(cache=True)
def _solve_window(c, b, H, x_prev, fp, ip, x_out, sd_out, iters_out):
    """One window (Algorithm 2). Fills x_out/sd_out/iters_out; returns (status, rounds,
    cond, weights)."""
    m, n = b.shape
    lo, hi, gamma, scale = fp[0], fp[1], fp[2], fp[3]
    x_cur = np.minimum(np.maximum(x_prev, lo + fp[19]), hi - fp[19])
    w = np.ones(m)
    cond = np.nan
    converged = True
    rounds = 0
    for _r in range(ip[0]):
        e = _energies(c, b, H, x_cur, scale)
        w = _mad_weights(e, fp, ip)
        if not np.any(w > 0):
            x_out[:] = x_prev
            return _REJ, rounds, cond, w
        JGJ = np.zeros((n, n))
        bw = np.zeros(n)
        for i in range(m):
            for j in range(n):
                bw[j] += w[i] * b[i, j]
                for k in range(n):
                    JGJ[j, k] += w[i] * H[i, j, k]
        JGJ *= scale
        cond = _cond1(JGJ)
        if not cond <= fp[10]:
            x_out[:] = x_prev
            return _ILL, rounds, cond, w
        Hq = JGJ.copy()
        q = bw * scale - gamma * x_prev
        for j in range(n):
            Hq[j, j] += gamma
        x_new, it, converged = _ipm(Hq, q, x_cur, fp, ip[1])
        iters_out[rounds] = it
        rounds += 1
        step = np.max(np.abs(x_new - x_cur))
        x_cur = x_new
        if step < fp[9]:
            break
    # uncertainty from the information matrix with the final weights
    e = _energies(c, b, H, x_cur, scale)
    active = 0
    s2 = 0.0
    for i in range(m):
        s2 += w[i] * e[i]
        if w[i] > 0:
            active += 1
    s2 = max(s2, 0.0) / max(10 * active - n, 1)
    info = np.zeros((n, n))
    for i in range(m):
        for j in range(n):
            for k in range(n):
                info[j, k] += w[i] * H[i, j, k]
    info *= scale
    for j in range(n):
        info[j, j] += gamma
    unit = np.zeros(n)
    col = np.empty(n)
    L = np.empty((n, n))
    for j in range(n):
        unit[:] = 0.0
        unit[j] = 1.0
        if _cholesky_solve_into(info, unit, L, col):
            sd_out[j] = math.sqrt(max(col[j], 0.0) * s2)
        else:
            sd_out[j] = np.nan
    x_out[:] = x_cur
    return (_OK if converged else _MAXIT), rounds, cond, w


@njit(cache=True)
def _run_windows(c, b, H, excited, x0, s0, fp, ip, m, eta, sd, status):
    n = x0.size
    x = x0.copy()
    s = s0.copy()
    x_out = np.empty(n)
    sd_out = np.empty(n)
    iters = np.zeros(ip[0], dtype=np.int64)
    for k in range(excited.size):
        if excited[k]:
            code, _rounds, _cond, _w = _solve_window(c[k:k + m], b[k:k + m], H[k:k + m], x,
                                                    fp, ip, x_out, sd_out, iters)
            if code == _OK or code == _MAXIT:
                x = x_out.copy()
                s = sd_out.copy()
            status[k] = code
        else:
            status[k] = _NO_EXC
        eta[k] = x
        sd[k] = s
    return x, s


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


def solve_window_numba(c, b, H, x_prev, cfg, params=None):
    """Compiled :func:`estimators.irls.solve_window` (no histories); ``params`` are the
    cached :func:`kernel_parameters` of ``cfg``."""
    from estimators.irls import _diag

    m, n = np.shape(b)
    fp, ip = kernel_parameters(cfg, m) if params is None else params
    x_out = np.empty(n)
    sd_out = np.empty(n)
    iters = np.zeros(cfg.max_irls, dtype=np.int64)
    code, rounds, cond, w = _solve_window(np.ascontiguousarray(c, dtype=float),
                                          np.ascontiguousarray(b, dtype=float),
                                          np.ascontiguousarray(H, dtype=float),
                                          np.asarray(x_prev, dtype=float), fp, ip, x_out,
                                          sd_out, iters)
    status = STATUSES[code]
    message = ""
    if code == _REJ:
        message = "every segment rejected"
    elif code == _MAXIT:
        message = f"interior point stopped at {cfg.ipm.max_iter} iterations"
    elif code == _ILL:
        message = f"cond(J^T G J) = {cond:.3g} > {cfg.cond_max:g}"
    diag = _diag(status, message, [int(i) for i in iters[:rounds]], w, cond, None)
    if code in (_OK, _MAXIT):
        return x_out, sd_out, diag
    return np.asarray(x_prev, dtype=float), None, diag
