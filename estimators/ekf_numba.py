"""Compiled twin of :mod:`estimators.ekf` (the optional ``fast`` extra, numba).

The same predict / update as ``ekf.predict`` and ``ekf.measurement_update``, written in the
subset of numpy that numba compiles, so a whole recording runs in one compiled loop.
``tests/test_estimators_ekf.py`` checks that both paths agree to 1e-9; change them together.

The step (:func:`step_ws`) allocates nothing but the core's ``expm_so3`` result: its matrices
live in a :func:`workspace` made once per recording or per batch chunk, and it uses the
structure of the 22-state filter instead of dense 22 x 22 products:

* the transition Jacobian ``F`` is the identity plus a few 3 x 3 / 3 x n / 9 x 3 / 9 x n blocks
  (the eta block is a random walk), so ``F P F^T`` runs over F's non-zeros (about 150 of 484);
* the measurement Jacobian is ``[I_9 0]`` plus a 3 x 9 attitude block, so ``H P``,
  ``H P H^T`` and ``(I - K H) P`` read rows of ``P`` instead of multiplying by ``H``;
* the Joseph update computes each symmetric pair of entries once.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimators.ekf import IDLE_THRUST
from quadfault._sim_numba import expm_so3  # the core's compiled mirror


#: fastmath flags of the step's loops: reassociation (vectorised sums), FMA contraction, no
#: signed zeros, reciprocals -- but not ``nnan`` / ``ninf``, so NaN and inf still propagate and
#: are tested as in numpy (results differ from the numpy path by rounding only, tested).
FAST = {"reassoc", "contract", "nsz", "arcp"}

# workspace slots: matrices (ns x ns), (ns x 12), (12 x 12), small blocks and vectors
_F, _FP, _PP, _FPT = range(4)
_S, _L = range(2)


@njit(cache=True)
def workspace(ns):
    """Scratch of one EKF step for ``ns`` states (18 + rotors), with the transition Jacobian
    ``F`` set to the identity and the column indices of its structural non-zeros per row
    (:func:`_jacobian_pattern`); a step writes only those entries."""
    nr = ns - 18
    ws = (np.zeros((4, ns, ns)), np.zeros((ns, 12)), np.zeros((2, 12, 12)),
          np.zeros((12, ns)), np.zeros((ns, ns), dtype=np.int64), np.zeros(ns, dtype=np.int64),
          np.zeros((6, 3, 3)), np.zeros((9, 3)), np.zeros((3, nr)), np.zeros((3, 9)),
          np.zeros((2, ns)), np.zeros(12))
    for i in range(ns):
        ws[0][_F, i, i] = 1.0
    _jacobian_pattern(ws[4], ws[5])
    return ws


@njit(cache=True)
def _jacobian_pattern(cols, nnz):
    """Columns (ascending) that the prediction writes in each row of ``F``: p row i:
    p_i, v_i, (R e3)_i, eta; v row i: v_i, (R e3)_i, eta; Omega rows: Omega, eta; vec(R) row
    3 jb + k: Omega, the k-th entry of each column of R, eta; eta rows: the diagonal."""
    ns = cols.shape[0]
    for i in range(ns):
        nnz[i] = 0
    for i in range(ns):
        if i < 3:
            base = (i, 3 + i, 15 + i)
        elif i < 6:
            base = (i, 12 + i, -1)
        elif i < 18:
            base = (6, 7, 8)
        else:
            base = (i, -1, -1)
        for j in base:
            if j >= 0:
                cols[i, nnz[i]] = j
                nnz[i] += 1
        if 9 <= i < 18:
            k = (i - 9) % 3
            for j in (9 + k, 12 + k, 15 + k):
                cols[i, nnz[i]] = j
                nnz[i] += 1
        if i < 18:
            for j in range(18, ns):
                cols[i, nnz[i]] = j
                nnz[i] += 1


@njit(cache=True)
def _right_jacobian_into(phi0, phi1, phi2, Jr):
    """Right Jacobian of SO(3) (``ekf.right_jacobian_so3``): ``I - a K + b K^2``."""
    th2 = phi0 * phi0 + phi1 * phi1 + phi2 * phi2
    if th2 < 1e-8:
        a = 0.5 - th2 / 24.0
        b = 1.0 / 6.0 - th2 / 120.0
    else:
        th = math.sqrt(th2)
        a = (1.0 - math.cos(th)) / th2
        b = (th - math.sin(th)) / (th2 * th)
    K = ((0.0, -phi2, phi1), (phi2, 0.0, -phi0), (-phi1, phi0, 0.0))
    for i in range(3):
        for j in range(3):
            kk = 0.0
            for k in range(3):
                kk += K[i][k] * K[k][j]
            Jr[i, j] = (1.0 if i == j else 0.0) - a * K[i][j] + b * kk


@njit(cache=True)
def _det3(M):
    return (M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
            - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
            + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]))


@njit(cache=True)
def _project_so3_into(M, C):
    """Closest rotation (polar factor) of ``M`` in place, as
    ``quadfault.rotation.orthonormalize``: Newton iterations ``M <- (M + M^-T) / 2`` when ``M``
    is near SO(3) (the EKF's case), else SVD. ``C`` is 3 x 3 scratch."""
    err = 0.0
    for i in range(3):
        for j in range(3):
            s = 0.0
            for k in range(3):
                s += M[k, i] * M[k, j]
            err = max(err, abs(s - (1.0 if i == j else 0.0)))
    if err < 1e-3 and _det3(M) > 0:
        for _ in range(3):
            for i in range(3):  # C = cofactor matrix^T = adj(M); inv(M) = C / det
                for j in range(3):
                    i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
                    C[j, i] = M[i1, j1] * M[i2, j2] - M[i1, j2] * M[i2, j1]
            det = M[0, 0] * C[0, 0] + M[0, 1] * C[1, 0] + M[0, 2] * C[2, 0]
            for i in range(3):
                for j in range(3):
                    M[i, j] = 0.5 * (M[i, j] + C[j, i] / det)
        return
    U, _, Vt = np.linalg.svd(M)
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt))
    M[:, :] = U @ D @ Vt


@njit(cache=True, fastmath=FAST, error_model="numpy")
def _sandwich_into(F, P, out, FP, FPT, cols, nnz):
    """``out = F P F^T`` over the structural non-zeros of the transition Jacobian (column
    indices of each row in ``cols``/``nnz``, :func:`_jacobian_pattern`); ``FP``, ``FPT`` are
    scratch. Both products stream whole rows: ``FP = F P`` and
    ``out[k] = sum_j F[k, j] (F P)^T[j]``."""
    n = F.shape[0]
    for i in range(n):  # FP = F P
        for k in range(n):
            FP[i, k] = 0.0
        for q in range(nnz[i]):
            j = cols[i, q]
            f = F[i, j]
            for k in range(n):
                FP[i, k] += f * P[j, k]
    for i in range(n):
        for k in range(n):
            FPT[k, i] = FP[i, k]
    for k in range(n):  # out = F (F P)^T, lower triangle mirrored
        for i in range(n):
            out[k, i] = 0.0
        for q in range(nnz[k]):
            j = cols[k, q]
            f = F[k, j]
            for i in range(k + 1):
                out[k, i] += f * FPT[j, i]
    for k in range(n):
        for i in range(k + 1, n):
            out[k, i] = out[i, k]


@njit(cache=True, error_model="numpy")
def _cholesky_into(S, L):
    """Lower Cholesky factor ``S = L L^T`` of the symmetric matrix ``S`` (only its lower
    triangle is read) into ``L``'s lower triangle; False when ``S`` is not positive definite
    (or not finite). No fastmath, so the test ``not d > 0`` keeps seeing NaN."""
    n = S.shape[0]
    for j in range(n):
        d = S[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, n):
            acc = S[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            L[i, j] = acc / L[j, j]
    return True


@njit(cache=True)
def step_inplace(x, P, f, dt, zp, zv, zw, zR, A, m, g, J, Jinv, qc, r, lo, hi):
    """One predict + update; ``x`` and ``P`` are overwritten (a fresh workspace)."""
    step_ws(x, P, f, dt, zp, zv, zw, zR, A, m, g, J, Jinv, qc, r, lo, hi,
            workspace(x.shape[0]))


@njit(cache=True, fastmath=FAST, error_model="numpy")
def step_ws(x, P, f, dt, zp, zv, zw, zR, A, m, g, J, Jinv, qc, r, lo, hi, ws):
    """One predict + update with the scratch ``ws`` (:func:`workspace`); ``x`` and ``P`` are
    overwritten."""
    mats, WT, s12, HP, cols, nnz, M3, dR, B, HR, vecs, y = ws
    F, FP, Pp, FPT = mats[_F], mats[_FP], mats[_PP], mats[_FPT]
    S, L = s12[_S], s12[_L]
    R, Rn, Jr, G, Mr, C = M3[0], M3[1], M3[2], M3[3], M3[4], M3[5]
    xp, phi = vecs[0], vecs[1, 0:3]
    ns = x.shape[0]
    nr = ns - 18
    for j in range(3):
        for i in range(3):
            R[i, j] = x[9 + 3 * j + i]
    # ---- predict (eqs. 1-4, 12)
    T = mo0 = mo1 = mo2 = 0.0  # wrench [T; M] = A diag(eta) f
    for j in range(nr):
        ef = x[18 + j] * f[j]
        T += A[0, j] * ef
        mo0 += A[1, j] * ef
        mo1 += A[2, j] * ef
        mo2 += A[3, j] * ef
    w0, w1, w2 = x[6], x[7], x[8]
    jw = (J[0, 0] * w0 + J[0, 1] * w1 + J[0, 2] * w2, J[1, 0] * w0 + J[1, 1] * w1 + J[1, 2] * w2,
          J[2, 0] * w0 + J[2, 1] * w1 + J[2, 2] * w2)
    tq = (mo0 - (w1 * jw[2] - w2 * jw[1]), mo1 - (w2 * jw[0] - w0 * jw[2]),
          mo2 - (w0 * jw[1] - w1 * jw[0]))
    wdot = (Jinv[0, 0] * tq[0] + Jinv[0, 1] * tq[1] + Jinv[0, 2] * tq[2],
            Jinv[1, 0] * tq[0] + Jinv[1, 1] * tq[1] + Jinv[1, 2] * tq[2],
            Jinv[2, 0] * tq[0] + Jinv[2, 1] * tq[1] + Jinv[2, 2] * tq[2])
    for i in range(3):
        phi[i] = x[6 + i] * dt + 0.5 * wdot[i] * dt * dt
    E = expm_so3(phi)
    for i in range(3):
        for j in range(3):
            Rn[i, j] = R[i, 0] * E[0, j] + R[i, 1] * E[1, j] + R[i, 2] * E[2, j]
    for i in range(3):
        a = -(T / m) * R[i, 2] + (g if i == 2 else 0.0)
        xp[i] = x[i] + x[3 + i] * dt + 0.5 * a * dt * dt
        xp[3 + i] = x[3 + i] + a * dt
        xp[6 + i] = x[6 + i] + wdot[i] * dt
    for j in range(3):
        for i in range(3):
            xp[9 + 3 * j + i] = Rn[i, j]
    for j in range(nr):
        xp[18 + j] = x[18 + j]
    # Jacobian F = d x_pred / d x: identity (set by the workspace) plus blocks, written here
    for i in range(3):  # B = J^-1 A_M diag(f), G = J^-1 ([J w]x - [w]x J)
        for j in range(nr):
            B[i, j] = (Jinv[i, 0] * (A[1, j] * f[j]) + Jinv[i, 1] * (A[2, j] * f[j])
                       + Jinv[i, 2] * (A[3, j] * f[j]))
    hjw = ((0.0, -jw[2], jw[1]), (jw[2], 0.0, -jw[0]), (-jw[1], jw[0], 0.0))
    hw = ((0.0, -w2, w1), (w2, 0.0, -w0), (-w1, w0, 0.0))
    for k in range(3):
        for j in range(3):
            Mr[k, j] = hjw[k][j] - (hw[k][0] * J[0, j] + hw[k][1] * J[1, j] + hw[k][2] * J[2, j])
    for i in range(3):
        for j in range(3):
            G[i, j] = Jinv[i, 0] * Mr[0, j] + Jinv[i, 1] * Mr[1, j] + Jinv[i, 2] * Mr[2, j]
    for i in range(3):
        F[i, 3 + i] = dt
        F[i, 15 + i] = -(T / m) * 0.5 * dt * dt
        F[3 + i, 15 + i] = -(T / m) * dt
        for j in range(nr):
            dTj = A[0, j] * f[j]
            F[i, 18 + j] = -R[i, 2] * dTj * (0.5 * dt * dt / m)
            F[3 + i, 18 + j] = -R[i, 2] * dTj * (dt / m)
            F[6 + i, 18 + j] = dt * B[i, j]
        for j in range(3):
            F[6 + i, 6 + j] = (1.0 if i == j else 0.0) + dt * G[i, j]
    # vec(R E) = (E^T kron I3) vec(R)
    for jb in range(3):
        for ib in range(3):
            for k in range(3):
                F[9 + 3 * jb + k, 9 + 3 * ib + k] = E[ib, jb]
    _right_jacobian_into(phi[0], phi[1], phi[2], Jr)
    for i in range(3):  # dR[:, i] = vec(Rn [Jr[:, i]]x)
        h = ((0.0, -Jr[2, i], Jr[1, i]), (Jr[2, i], 0.0, -Jr[0, i]), (-Jr[1, i], Jr[0, i], 0.0))
        for cc in range(3):
            for rr in range(3):
                dR[3 * cc + rr, i] = Rn[rr, 0] * h[0][cc] + Rn[rr, 1] * h[1][cc] \
                    + Rn[rr, 2] * h[2][cc]
    for rr in range(9):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += dR[rr, k] * ((dt if k == j else 0.0) + 0.5 * dt * dt * G[k, j])
            F[9 + rr, 6 + j] = acc
        for j in range(nr):
            acc = 0.0
            for k in range(3):
                acc += dR[rr, k] * (0.5 * dt * dt * B[k, j])
            F[9 + rr, 18 + j] = acc
    _sandwich_into(F, P, Pp, FP, FPT, cols, nnz)
    for i in range(ns):
        Pp[i, i] += qc[i] * dt
    # ---- update (p, v, Omega, attitude rotation error); H = [I_9 0; 0 HR 0]
    for i in range(3):
        y[i] = zp[i] - xp[i]
        y[3 + i] = zv[i] - xp[3 + i]
        y[6 + i] = zw[i] - xp[6 + i]
    for i in range(3):  # Mr = Rn^T zR, y[9:12] = log(Mr)
        for j in range(3):
            Mr[i, j] = Rn[0, i] * zR[0, j] + Rn[1, i] * zR[1, j] + Rn[2, i] * zR[2, j]
    s0 = 0.5 * (Mr[2, 1] - Mr[1, 2])
    s1 = 0.5 * (Mr[0, 2] - Mr[2, 0])
    s2 = 0.5 * (Mr[1, 0] - Mr[0, 1])
    sn = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    cs = 0.5 * (Mr[0, 0] + Mr[1, 1] + Mr[2, 2] - 1.0)
    scale = 1.0 if sn < 1e-12 else math.atan2(sn, cs) / sn
    y[9], y[10], y[11] = s0 * scale, s1 * scale, s2 * scale
    for k in range(3):
        for i in range(9):
            HR[k, i] = 0.0
    for (k, ia, ib) in ((0, 2, 1), (1, 0, 2), (2, 1, 0)):
        for i in range(3):
            HR[k, 3 * ia + i] -= 0.5 * zR[i, ib]
            HR[k, 3 * ib + i] += 0.5 * zR[i, ia]
    _update(x, P, xp, Pp, HR, y, r, HP, WT, S, L)
    for j in range(3):  # project R back to SO(3), clamp eta
        for i in range(3):
            C[i, j] = x[9 + 3 * j + i]
    _project_so3_into(C, Mr)
    for j in range(3):
        for i in range(3):
            x[9 + 3 * j + i] = C[i, j]
    for j in range(nr):
        x[18 + j] = min(max(x[18 + j], lo), hi)


@njit(cache=True, fastmath=FAST, error_model="numpy")
def _update(x, P, xp, Pp, HR, y, r, HP, WT, S, L):
    """Measurement update of ``(xp, Pp)`` into ``(x, P)`` with ``H = [I_9 0; 0 HR 0]`` and
    ``R = diag(r)``, in the square-root form of the optimal gain::

        S = H Pp H^T + R = L L^T,   W = L^-1 H Pp,   x = xp + W^T (L^-1 y),   P = Pp - W^T W

    which is ``K = Pp H^T S^-1``, ``x = xp + K y`` and ``P = (I - K H) Pp = Pp - K S K^T``:
    equal to ``ekf.kalman_update``'s Joseph form for this (optimal) gain up to rounding,
    symmetric by construction (lower triangle computed, mirrored) and positive
    semi-definite up to rounding. ``HP`` (12 x ns) becomes ``W``, ``WT`` is its transpose,
    ``y`` becomes ``L^-1 y``. If ``S`` is not positive definite (a corrupted covariance;
    it has ``diag(r) > 0`` added) the general solver and ``P = sym(Pp - K H Pp)`` are used."""
    ns = Pp.shape[0]
    for i in range(9):  # H P: rows of P, and the attitude rows
        for k in range(ns):
            HP[i, k] = Pp[i, k]
    for i in range(3):
        for k in range(ns):
            HP[9 + i, k] = 0.0
        for j in range(9):
            h = HR[i, j]
            if h != 0.0:
                for k in range(ns):
                    HP[9 + i, k] += h * Pp[9 + j, k]
    for i in range(12):  # lower triangle of S = H P H^T + R
        for k in range(min(i + 1, 9)):
            S[i, k] = HP[i, k]
        for k in range(9, i + 1):
            acc = 0.0
            for j in range(9):
                acc += HP[i, 9 + j] * HR[k - 9, j]
            S[i, k] = acc
        S[i, i] += r[i]
    if not _cholesky_into(S, L):
        _update_general(x, P, xp, Pp, y, HP, S)
        return
    for i in range(12):  # W = L^-1 H P (forward substitution on whole rows, in place)
        for k in range(i):
            lik = L[i, k]
            for c in range(ns):
                HP[i, c] -= lik * HP[k, c]
        d = L[i, i]
        for c in range(ns):
            HP[i, c] = HP[i, c] / d
    for i in range(12):  # y <- L^-1 y
        acc = y[i]
        for k in range(i):
            acc -= L[i, k] * y[k]
        y[i] = acc / L[i, i]
    for i in range(ns):
        acc = 0.0
        for c in range(12):
            WT[i, c] = HP[c, i]
            acc += HP[c, i] * y[c]
        x[i] = xp[i] + acc
    for i in range(ns):  # P = Pp - W^T W
        for k in range(i + 1):
            acc = 0.0
            for c in range(12):
                acc += WT[i, c] * WT[k, c]
            P[i, k] = Pp[i, k] - acc
            P[k, i] = P[i, k]


@njit(cache=True)
def _update_general(x, P, xp, Pp, y, HP, S):
    """Fallback of :func:`_update` for an ``S`` that is not positive definite: ``K^T`` by
    LU (``np.linalg.solve``, allocates), ``x = xp + K y``, ``P = sym(Pp - K H Pp)``."""
    ns, m = Pp.shape[0], S.shape[0]
    for i in range(m):
        for k in range(i + 1, m):
            S[i, k] = S[k, i]
    KT = np.linalg.solve(S, HP)
    for i in range(ns):
        acc = 0.0
        for c in range(m):
            acc += KT[c, i] * y[c]
        x[i] = xp[i] + acc
    for i in range(ns):
        for k in range(i + 1):
            a = Pp[i, k] + Pp[k, i]
            for c in range(m):
                a -= KT[c, i] * HP[c, k] + KT[c, k] * HP[c, i]
            P[i, k] = 0.5 * a
            P[k, i] = P[i, k]


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
    ws = workspace(x.shape[0])
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
            for jj in range(3):
                for ii in range(3):
                    x[9 + 3 * jj + ii] = R[k, ii, jj]
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
            step_ws(x, P, f[last], dt, p[k], v[k], w[k], R[k], A, m, g, J, Jinv, qc, r, lo, hi,
                    ws)
            if idle:
                freeze_eta(x, P, eta_keep, P_keep, qc, dt)
        last = k
        eta[k] = x[18:]
        for j in range(nr):
            sd[k, j] = math.sqrt(P[18 + j, 18 + j])
    return eta, sd, ok, x, P, last
