"""Compiled twin of :mod:`estimators.ekf` (the optional ``fast`` extra, numba).

The same predict / update as ``ekf.predict`` and ``ekf.measurement_update``, written in the
subset of numpy that numba compiles, so a whole recording runs in one compiled loop.
``tests/test_estimators_ekf.py`` checks that both paths agree to 1e-9; change them together.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimators.ekf import IDLE_THRUST
from quadfault._sim_numba import expm_so3, hat, matvec  # the core's compiled mirrors


@njit(cache=True, fastmath=True)
def _mm(A, B):
    """Matrix product by loops (faster than a BLAS call for these small sizes)."""
    n, m, p = A.shape[0], A.shape[1], B.shape[1]
    out = np.zeros((n, p))
    for i in range(n):
        for k in range(m):
            a = A[i, k]
            if a != 0.0:
                for j in range(p):
                    out[i, j] += a * B[k, j]
    return out


@njit(cache=True, fastmath=True)
def _mm_bt(A, B):
    """``A @ B.T`` by row dot products (both operands read contiguously)."""
    n, m, p = A.shape[0], A.shape[1], B.shape[0]
    out = np.empty((n, p))
    for i in range(n):
        for j in range(p):
            acc = 0.0
            for k in range(m):
                acc += A[i, k] * B[j, k]
            out[i, j] = acc
    return out


@njit(cache=True, fastmath=True)
def _gain(S, HP):
    """Kalman gain ``K = P H^T S^-1 = (S^-1 H P)^T`` for symmetric positive-definite ``S``
    (Cholesky ``S = L L^T``; row i of K solves ``S k = (H P)[:, i]``)."""
    n, m = S.shape[0], HP.shape[1]
    L = np.zeros((n, n))
    for j in range(n):
        d = S[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return np.ascontiguousarray(np.linalg.solve(S, HP).T)  # not PD: general solver
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, n):
            acc = S[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            L[i, j] = acc / L[j, j]
    K = np.empty((m, n))
    for c in range(m):
        for i in range(n):  # L z = b
            acc = HP[i, c]
            for k in range(i):
                acc -= L[i, k] * K[c, k]
            K[c, i] = acc / L[i, i]
        for i in range(n - 1, -1, -1):  # L^T x = z
            acc = K[c, i]
            for k in range(i + 1, n):
                acc -= L[k, i] * K[c, k]
            K[c, i] = acc / L[i, i]
    return K


@njit(cache=True)
def _right_jacobian(phi):
    th2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    if th2 < 1e-8:
        a = 0.5 - th2 / 24.0
        b = 1.0 / 6.0 - th2 / 120.0
    else:
        th = math.sqrt(th2)
        a = (1.0 - math.cos(th)) / th2
        b = (th - math.sin(th)) / (th2 * th)
    K = hat(phi)
    return np.eye(3) - a * K + b * _mm(K, K)


@njit(cache=True)
def _log(M):
    """Rotation vector of a rotation matrix (accurate away from pi)."""
    s0 = 0.5 * (M[2, 1] - M[1, 2])
    s1 = 0.5 * (M[0, 2] - M[2, 0])
    s2 = 0.5 * (M[1, 0] - M[0, 1])
    s = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    c = 0.5 * (M[0, 0] + M[1, 1] + M[2, 2] - 1.0)
    scale = 1.0 if s < 1e-12 else math.atan2(s, c) / s
    return np.array([s0 * scale, s1 * scale, s2 * scale])


@njit(cache=True)
def _vec(M):
    out = np.empty(9)
    for j in range(3):
        for i in range(3):
            out[3 * j + i] = M[i, j]
    return out


@njit(cache=True)
def _unvec(x, start):
    M = np.empty((3, 3))
    for j in range(3):
        for i in range(3):
            M[i, j] = x[start + 3 * j + i]
    return M


@njit(cache=True)
def _inv3(M):
    """Inverse of a 3x3 matrix by cofactors."""
    C = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
            C[j, i] = M[i1, j1] * M[i2, j2] - M[i1, j2] * M[i2, j1]
    det = M[0, 0] * C[0, 0] + M[0, 1] * C[1, 0] + M[0, 2] * C[2, 0]
    return C / det


@njit(cache=True)
def _project_so3(M):
    """Closest rotation (polar factor), as ``quadfault.rotation.orthonormalize``: Newton
    iterations ``M <- (M + M^-T) / 2`` when ``M`` is near SO(3) (the EKF's case), else SVD."""
    E = _mm(M.T, M) - np.eye(3)
    if np.max(np.abs(E)) < 1e-3 and np.linalg.det(M) > 0:
        for _ in range(3):
            M = 0.5 * (M + _inv3(M).T)
        return M
    U, _, Vt = np.linalg.svd(M)
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt))
    return U @ D @ Vt


@njit(cache=True, fastmath=True)
def _sandwich(F, P):
    """``F P F^T`` over the non-zeros of the sparse transition Jacobian (CSR rows)."""
    n = F.shape[0]
    nnz = np.zeros(n, dtype=np.int64)
    cols = np.empty((n, n), dtype=np.int64)
    vals = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            if F[i, j] != 0.0:
                cols[i, nnz[i]] = j
                vals[i, nnz[i]] = F[i, j]
                nnz[i] += 1
    FP = np.zeros((n, n))
    for i in range(n):
        for q in range(nnz[i]):
            j, f = cols[i, q], vals[i, q]
            for k in range(n):
                FP[i, k] += f * P[j, k]
    out = np.empty((n, n))
    for i in range(n):
        for k in range(i, n):
            acc = 0.0
            for q in range(nnz[k]):
                acc += FP[i, cols[k, q]] * vals[k, q]
            out[i, k] = acc
            out[k, i] = acc
    return out


@njit(cache=True)
def step_inplace(x, P, f, dt, zp, zv, zw, zR, A, m, g, J, Jinv, qc, r, lo, hi):
    """One predict + update; ``x`` and ``P`` are overwritten."""
    ns = x.shape[0]
    nr = ns - 18
    p, v, w = x[0:3].copy(), x[3:6].copy(), x[6:9].copy()
    R = _unvec(x, 9)
    eta = x[18:].copy()
    # ---- predict (eqs. 1-4, 12)
    ef = eta * f
    T = 0.0
    for j in range(nr):
        T += A[0, j] * ef[j]
    M = matvec(A[1:], ef)
    b3 = R[:, 2].copy()
    a = -(T / m) * b3
    a[2] += g
    wdot = matvec(Jinv, M - np.cross(w, matvec(J, w)))
    phi = w * dt + 0.5 * wdot * dt * dt
    E = expm_so3(phi)
    Rn = _mm(R, E)
    xp = np.empty(ns)
    xp[0:3] = p + v * dt + 0.5 * a * dt * dt
    xp[3:6] = v + a * dt
    xp[6:9] = w + wdot * dt
    xp[9:18] = _vec(Rn)
    xp[18:] = eta
    F = np.eye(ns)
    B = _mm(Jinv, A[1:] * f.reshape(1, nr))
    G = _mm(Jinv, hat(matvec(J, w)) - _mm(hat(w), J))
    for i in range(3):
        F[i, 3 + i] = dt
        F[i, 15 + i] = -(T / m) * 0.5 * dt * dt
        F[3 + i, 15 + i] = -(T / m) * dt
        for j in range(nr):
            dTj = A[0, j] * f[j]
            F[i, 18 + j] = -b3[i] * dTj * (0.5 * dt * dt / m)
            F[3 + i, 18 + j] = -b3[i] * dTj * (dt / m)
            F[6 + i, 18 + j] = dt * B[i, j]
        for j in range(3):
            F[6 + i, 6 + j] += dt * G[i, j]
    # vec(R E) = (E^T kron I3) vec(R)
    for jb in range(3):
        for ib in range(3):
            for k in range(3):
                F[9 + 3 * jb + k, 9 + 3 * ib + k] = E[ib, jb]
    Jr = _right_jacobian(phi)
    dR = np.empty((9, 3))
    for i in range(3):
        dR[:, i] = _vec(_mm(Rn, hat(Jr[:, i].copy())))
    F[9:18, 6:9] = _mm(dR, dt * np.eye(3) + 0.5 * dt * dt * G)
    F[9:18, 18:] = _mm(dR, 0.5 * dt * dt * B)
    Pp = _sandwich(F, P)
    for i in range(ns):
        Pp[i, i] += qc[i] * dt
    # ---- update (p, v, Omega, attitude rotation error)
    y = np.empty(12)
    y[0:3] = zp - xp[0:3]
    y[3:6] = zv - xp[3:6]
    y[6:9] = zw - xp[6:9]
    y[9:12] = _log(_mm(np.ascontiguousarray(Rn.T), zR))
    HR = np.zeros((3, 9))  # attitude rows of H (columns 9..17); rows 0..8 are [I 0]
    for (k, ia, ib) in ((0, 2, 1), (1, 0, 2), (2, 1, 0)):
        for i in range(3):
            HR[k, 3 * ia + i] -= 0.5 * zR[i, ib]
            HR[k, 3 * ib + i] += 0.5 * zR[i, ia]
    HP = np.empty((12, ns))  # H P
    HP[0:9] = Pp[0:9]
    HP[9:12] = _mm(HR, Pp[9:18])
    S = np.empty((12, 12))  # H P H^T + R
    S[:, 0:9] = HP[:, 0:9]
    S[:, 9:12] = _mm_bt(HP[:, 9:18], HR)
    for i in range(12):
        S[i, i] += r[i]
    K = _gain(S, HP)
    xn = xp + matvec(K, y)
    # Joseph form (I - K H) P (I - K H)^T + K R K^T, associated as A - (A H^T - K R) K^T
    # with A = (I - K H) P = P - K (H P)
    A = Pp - _mm(K, HP)
    AHt = np.empty((ns, 12))
    AHt[:, 0:9] = A[:, 0:9]
    AHt[:, 9:12] = _mm_bt(A[:, 9:18], HR)
    Pn = A - _mm(AHt - K * r.reshape(1, 12), np.ascontiguousarray(K.T))
    Pn = 0.5 * (Pn + Pn.T)
    xn[9:18] = _vec(_project_so3(_unvec(xn, 9)))
    for j in range(nr):
        xn[18 + j] = min(max(xn[18 + j], lo), hi)
    x[:] = xn
    P[:, :] = Pn


@njit(cache=True)
def _finite_row(t, p, v, R, w, f, k):
    ok = math.isfinite(t[k])
    for i in range(3):
        ok = ok and math.isfinite(p[k, i]) and math.isfinite(v[k, i]) and math.isfinite(w[k, i])
        for j in range(3):
            ok = ok and math.isfinite(R[k, i, j])
    for j in range(f.shape[1]):
        ok = ok and math.isfinite(f[k, j])
    return ok


@njit(cache=True)
def freeze_eta(x, P, eta_keep, P_keep, qc, dt):
    """Mirror of ``ekf._freeze_eta``: a step without excitation leaves eta where it was."""
    ns = x.shape[0]
    for i in range(18, ns):
        x[i] = eta_keep[i - 18]
        for j in range(18):
            P[i, j] = 0.0
            P[j, i] = 0.0
        for j in range(18, ns):
            P[i, j] = P_keep[i - 18, j - 18]
        P[i, i] += qc[i] * dt


@njit(cache=True)
def run_series(t, p, v, R, w, f, eta0, x, P0, A, m, g, J, Jinv, qc, r, lo, hi):
    """Filter a whole recording; returns ``(eta, sd, ok, x, P, last_good_row)``."""
    n, nr = t.shape[0], f.shape[1]
    eta = np.empty((n, nr))
    sd = np.full((n, nr), np.nan)
    ok = np.zeros(n, dtype=np.bool_)
    P = P0.copy()
    last = -1
    for k in range(n):
        if not _finite_row(t, p, v, R, w, f, k):
            if last < 0:
                eta[k] = eta0
            else:
                eta[k] = x[18:]
                for j in range(nr):
                    sd[k, j] = math.sqrt(P[18 + j, 18 + j])
            continue
        ok[k] = True
        if last < 0:
            x[0:3] = p[k]
            x[3:6] = v[k]
            x[6:9] = w[k]
            x[9:18] = _vec(R[k])
            x[18:] = eta0
        else:
            dt = t[k] - t[last]
            idle = False
            for j in range(nr):
                if f[last, j] <= IDLE_THRUST:
                    idle = True
            if idle:
                eta_keep = x[18:].copy()
                P_keep = P[18:, 18:].copy()
            step_inplace(x, P, f[last], dt, p[k], v[k], w[k], R[k].copy(),
                         A, m, g, J, Jinv, qc, r, lo, hi)
            if idle:
                freeze_eta(x, P, eta_keep, P_keep, qc, dt)
        last = k
        eta[k] = x[18:]
        for j in range(nr):
            sd[k, j] = math.sqrt(P[18 + j, 18 + j])
    return eta, sd, ok, x, P, last
