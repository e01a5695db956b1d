"""Compiled (numba) twin of :mod:`estimators.residuals` for one segment at a time.

``segment_terms_into`` builds the quadratic terms ``(c, b, H)`` of one segment's weighted
residual energy (paper eqs. 13-26) with scalar 3x3 algebra and no allocation; the online IRLS
update calls it through :func:`segment_terms`, the batched estimator through
:func:`segment_terms_batch` (parallel over vehicles, writing into the ring of window terms).
``tests/test_estimators_irls_numba.py`` checks it against the vectorised numpy model.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True)
def segment_terms_into(dt, p0, p1, v0, v1, R0, R1, w0, w1, f, mass, g, Jmat, Jinv, A, G,
                       r0, J, b, H):
    """One segment's quadratic terms without allocating: fills ``b`` (n,) and ``H`` (n, n)
    (``r0`` (10,) and ``J`` (10, n) are scratch) and returns ``(c, thrust)``. The compiled
    twin of :func:`estimators.residuals.segment_models` +
    :func:`~estimators.residuals.quadratic_terms` for one segment."""
    n = f.size
    thrust = 0.0
    for j in range(n):
        thrust += A[0, j] * f[j]
    # velocity / position (eqs. 13, 14, 17, 18)
    for a in range(3):
        ge = g if a == 2 else 0.0
        r0[a] = v1[a] - v0[a] - ge * dt
        r0[3 + a] = p1[a] - p0[a] - v0[a] * dt - ge * 0.5 * dt * dt
        for j in range(n):
            dv = R0[a, 2] * f[j] * A[0, j] / mass
            J[a, j] = dv * dt
            J[3 + a, j] = dv * (0.5 * dt * dt)
    # rate (eqs. 15, 19): gyro = W x (J W), W_hat0 = W - J^-1 gyro dt
    jw0 = Jmat[0, 0] * w0[0] + Jmat[0, 1] * w0[1] + Jmat[0, 2] * w0[2]
    jw1 = Jmat[1, 0] * w0[0] + Jmat[1, 1] * w0[1] + Jmat[1, 2] * w0[2]
    jw2 = Jmat[2, 0] * w0[0] + Jmat[2, 1] * w0[1] + Jmat[2, 2] * w0[2]
    gy0 = w0[1] * jw2 - w0[2] * jw1
    gy1 = w0[2] * jw0 - w0[0] * jw2
    gy2 = w0[0] * jw1 - w0[1] * jw0
    wh0 = w0[0] - (Jinv[0, 0] * gy0 + Jinv[0, 1] * gy1 + Jinv[0, 2] * gy2) * dt
    wh1 = w0[1] - (Jinv[1, 0] * gy0 + Jinv[1, 1] * gy1 + Jinv[1, 2] * gy2) * dt
    wh2 = w0[2] - (Jinv[2, 0] * gy0 + Jinv[2, 1] * gy1 + Jinv[2, 2] * gy2) * dt
    r0[6] = w1[0] - wh0
    r0[7] = w1[1] - wh1
    r0[8] = w1[2] - wh2
    for a in range(3):
        for j in range(n):
            ja = 0.0
            for k in range(3):
                ja += Jinv[a, k] * A[1 + k, j]
            J[6 + a, j] = -ja * f[j] * dt
    # rotation (eqs. 20-22): r_R = 1/2 (3 - tr dR) - dt vee(dR) . W_hat, dR = R0^T R1
    d00 = R0[0, 0] * R1[0, 0] + R0[1, 0] * R1[1, 0] + R0[2, 0] * R1[2, 0]
    d11 = R0[0, 1] * R1[0, 1] + R0[1, 1] * R1[1, 1] + R0[2, 1] * R1[2, 1]
    d22 = R0[0, 2] * R1[0, 2] + R0[1, 2] * R1[1, 2] + R0[2, 2] * R1[2, 2]
    d21 = R0[0, 2] * R1[0, 1] + R0[1, 2] * R1[1, 1] + R0[2, 2] * R1[2, 1]
    d12 = R0[0, 1] * R1[0, 2] + R0[1, 1] * R1[1, 2] + R0[2, 1] * R1[2, 2]
    d02 = R0[0, 0] * R1[0, 2] + R0[1, 0] * R1[1, 2] + R0[2, 0] * R1[2, 2]
    d20 = R0[0, 2] * R1[0, 0] + R0[1, 2] * R1[1, 0] + R0[2, 2] * R1[2, 0]
    d10 = R0[0, 1] * R1[0, 0] + R0[1, 1] * R1[1, 0] + R0[2, 1] * R1[2, 0]
    d01 = R0[0, 0] * R1[0, 1] + R0[1, 0] * R1[1, 1] + R0[2, 0] * R1[2, 1]
    u0 = 0.5 * (d21 - d12) * dt
    u1 = 0.5 * (d02 - d20) * dt
    u2 = 0.5 * (d10 - d01) * dt
    r0[9] = 0.5 * (3.0 - (d00 + d11 + d22)) - (u0 * wh0 + u1 * wh1 + u2 * wh2)
    for j in range(n):
        J[9, j] = u0 * J[6, j] + u1 * J[7, j] + u2 * J[8, j]
    # weighted energy c + 2 b.eta + eta^T H eta (eq. 26)
    c = 0.0
    for j in range(n):
        b[j] = 0.0
        for k in range(n):
            H[j, k] = 0.0
    for r in range(10):
        c += r0[r] * G[r] * r0[r]
        for j in range(n):
            gj = G[r] * J[r, j]
            b[j] += gj * r0[r]
            for k in range(n):
                H[j, k] += gj * J[r, k]
    return c, thrust


def segment_terms(dt, p0, p1, v0, v1, R0, R1, w0, w1, f, mass, g, Jmat, Jinv, A, G):
    """``(c, b, H, thrust)`` of one segment (the online ``update``'s numba path)."""
    n = f.size
    b, H = np.empty(n), np.empty((n, n))
    c, thrust = segment_terms_into(float(dt), p0, p1, v0, v1, np.ascontiguousarray(R0),
                                   np.ascontiguousarray(R1), w0, w1, f, mass, g, Jmat, Jinv, A,
                                   G, np.empty(10), np.empty((10, n)), b, H)
    return c, b, H, thrust


@njit(cache=True, parallel=True)
def segment_terms_batch(rows, slot, t0, p0, v0, R0, w0, f0, t1, p1, v1, R1, w1, mass, g, Jmat,
                        Jinv, A, G, c, b, H, thrust, chunks):
    """:func:`segment_terms_into` for the vehicles ``rows`` (segment old -> new sample of each),
    written into ring slot ``slot`` of ``c`` (N, m), ``b`` (N, m, n), ``H`` (N, m, n, n) and
    ``thrust`` (N, m); parallel over ``chunks`` chunks of rows (:func:`batch_chunks`), one
    scratch per chunk."""
    K, n = rows.size, f0.shape[1]
    for ch in prange(chunks):
        r0, J = np.empty(10), np.empty((10, n))
        for k in range(ch * K // chunks, (ch + 1) * K // chunks):
            i = rows[k]
            ci, ti = segment_terms_into(t1[i] - t0[i], p0[i], p1[i], v0[i], v1[i], R0[i], R1[i],
                                        w0[i], w1[i], f0[i], mass, g, Jmat, Jinv, A, G, r0, J,
                                        b[i, slot], H[i, slot])
            c[i, slot] = ci
            thrust[i, slot] = ti
