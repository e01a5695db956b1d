"""Compiled twin of :mod:`estimators.ekf` (the optional ``fast`` extra, numba).

The same predict / update as ``ekf.predict`` and ``ekf.measurement_update``, written in the
subset of numpy that numba compiles, so a whole recording runs in one compiled loop.
``tests/test_estimators_ekf.py`` checks that both paths agree to 1e-9; change them together.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _hat(w):
    out = np.zeros((3, 3))
    out[0, 1], out[0, 2] = -w[2], w[1]
    out[1, 0], out[1, 2] = w[2], -w[0]
    out[2, 0], out[2, 1] = -w[1], w[0]
    return out


@njit(cache=True)
def _expm(phi):
    th2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    if th2 < 1e-8:
        a = 1.0 - th2 / 6.0 + th2 * th2 / 120.0
        b = 0.5 - th2 / 24.0 + th2 * th2 / 720.0
    else:
        th = math.sqrt(th2)
        a = math.sin(th) / th
        b = (1.0 - math.cos(th)) / th2
    K = _hat(phi)
    return np.eye(3) + a * K + b * (K @ K)


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
    K = _hat(phi)
    return np.eye(3) - a * K + b * (K @ K)


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
    M = A[1:] @ ef
    b3 = R[:, 2].copy()
    a = -(T / m) * b3
    a[2] += g
    wdot = Jinv @ (M - np.cross(w, J @ w))
    phi = w * dt + 0.5 * wdot * dt * dt
    E = _expm(phi)
    Rn = R @ E
    xp = np.empty(ns)
    xp[0:3] = p + v * dt + 0.5 * a * dt * dt
    xp[3:6] = v + a * dt
    xp[6:9] = w + wdot * dt
    xp[9:18] = _vec(Rn)
    xp[18:] = eta
    F = np.eye(ns)
    B = Jinv @ (A[1:] * f.reshape(1, nr))
    G = Jinv @ (_hat(J @ w) - _hat(w) @ J)
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
        dR[:, i] = _vec(Rn @ _hat(Jr[:, i].copy()))
    F[9:18, 6:9] = dR @ (dt * np.eye(3) + 0.5 * dt * dt * G)
    F[9:18, 18:] = dR @ (0.5 * dt * dt * B)
    Pp = F @ P @ F.T
    for i in range(ns):
        Pp[i, i] += qc[i] * dt
    # ---- update (p, v, Omega, attitude rotation error)
    y = np.empty(12)
    y[0:3] = zp - xp[0:3]
    y[3:6] = zv - xp[3:6]
    y[6:9] = zw - xp[6:9]
    y[9:12] = _log(Rn.T @ zR)
    H = np.zeros((12, ns))
    for i in range(9):
        H[i, i] = 1.0
    for (k, ia, ib) in ((0, 2, 1), (1, 0, 2), (2, 1, 0)):
        for i in range(3):
            H[9 + k, 9 + 3 * ia + i] -= 0.5 * zR[i, ib]
            H[9 + k, 9 + 3 * ib + i] += 0.5 * zR[i, ia]
    HP = H @ Pp
    S = HP @ H.T
    for i in range(12):
        S[i, i] += r[i]
    K = np.linalg.solve(S, HP).T
    xn = xp + K @ y
    IKH = np.eye(ns) - K @ H
    Pn = IKH @ Pp @ IKH.T + (K * r.reshape(1, 12)) @ K.T
    Pn = 0.5 * (Pn + Pn.T)
    U, _, Vt = np.linalg.svd(_unvec(xn, 9))
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt))
    xn[9:18] = _vec(U @ D @ Vt)
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
            step_inplace(x, P, f[last], t[k] - t[last], p[k], v[k], w[k], R[k].copy(),
                         A, m, g, J, Jinv, qc, r, lo, hi)
        last = k
        eta[k] = x[18:]
        for j in range(nr):
            sd[k, j] = math.sqrt(P[18 + j, 18 + j])
    return eta, sd, ok, x, P, last
