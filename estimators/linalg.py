"""Small dense linear algebra of the estimators' compiled kernels.

Plain Python compiled by :func:`quadfault.jit.jit`; nothing allocates (the caller passes the
scratch). Used by the interior point (its Newton step), the IRLS window (its uncertainty and
conditioning guard), the change completion (its weak direction) and the EKF (its update):

* :func:`cholesky_into` / :func:`cholesky_solve_into` -- ``A + diag(shift) = L L^T`` and the
  two triangular solves (the shift is the interior point's barrier diagonal and the EKF's
  measurement noise; zero elsewhere);
* :func:`cond1_into` -- the 1-norm condition number ``||A||_1 ||A^-1||_1`` by Gauss-Jordan
  elimination with partial pivoting (MATLAB's ``1 / rcond`` up to its estimate);
* :func:`smallest_eigenpair_into` -- the smallest eigenvalue of a symmetric matrix and its
  unit eigenvector, by cyclic Jacobi rotations.
"""

from __future__ import annotations

import math

from quadfault.jit import jit


@jit(inline="always")
def cholesky_into(A, shift, L) -> bool:
    """Lower Cholesky factor of ``A + diag(shift)`` into ``L``'s lower triangle (only ``A``'s
    lower triangle is read); False, with ``L`` undefined, when the matrix is not positive
    definite (or not finite)."""
    n = A.shape[0]
    for j in range(n):
        s = A[j, j] + shift[j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / d
    return True


@jit(inline="always")
def cholesky_solve_into(L, rhs, out) -> None:
    """Solve ``L L^T out = rhs`` given the factor of :func:`cholesky_into`."""
    _forward_into(L, rhs, out)
    _backward_into(L, out)


@jit(inline="always")
def _forward_into(L, rhs, y) -> None:
    """``L y = rhs``."""
    for i in range(rhs.shape[0]):
        s = rhs[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]


@jit(inline="always")
def _backward_into(L, y) -> None:
    """``L^T x = y``, ``x`` over ``y``. (Its own function, with a forward range: numba then
    compiles both substitutions without reference counting on the arrays.)"""
    n = y.shape[0]
    for back in range(n):
        i = n - 1 - back
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * y[k]
        y[i] = s / L[i, i]


@jit
def cond1_into(A, M, inv) -> float:
    """``||A||_1 ||A^-1||_1`` (inf when ``A`` is singular); ``M`` and ``inv`` are n x n
    scratch (``inv`` holds ``A^-1`` afterwards)."""
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
            return math.inf
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
    norm_a = 0.0
    norm_inv = 0.0
    for k in range(n):
        sa = 0.0
        si = 0.0
        for r in range(n):
            sa += abs(A[r, k])
            si += abs(inv[r, k])
        norm_a = max(norm_a, sa)
        norm_inv = max(norm_inv, si)
    value = norm_a * norm_inv
    return value if math.isfinite(value) else math.inf


@jit
def smallest_eigenpair_into(A, D, V, v) -> float:
    """Smallest eigenvalue of the symmetric part of ``A`` (n x n); its unit eigenvector goes
    into ``v`` (sign: largest entry positive). ``D`` and ``V`` are n x n scratch.

    Cyclic Jacobi: each sweep zeroes every off-diagonal entry once by a plane rotation
    (Golub & Van Loan, Algorithm 8.4.3); it converges quadratically and stops when the
    off-diagonal mass is below ``1e-30`` of the whole or after 50 sweeps."""
    n = A.shape[0]
    total = 0.0
    for i in range(n):
        for j in range(n):
            D[i, j] = 0.5 * (A[i, j] + A[j, i])
            V[i, j] = 1.0 if i == j else 0.0
            total += D[i, j] * D[i, j]
    for _sweep in range(50):
        off = 0.0
        for i in range(n):
            for j in range(i + 1, n):
                off += D[i, j] * D[i, j]
        if not off > 1e-30 * total:
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                if D[p, q] == 0.0:
                    continue
                theta = (D[q, q] - D[p, p]) / (2.0 * D[p, q])
                t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(n):  # D <- J^T D J, V <- V J
                    dkp, dkq = D[k, p], D[k, q]
                    D[k, p] = c * dkp - s * dkq
                    D[k, q] = s * dkp + c * dkq
                for k in range(n):
                    dpk, dqk = D[p, k], D[q, k]
                    D[p, k] = c * dpk - s * dqk
                    D[q, k] = s * dpk + c * dqk
                for k in range(n):
                    vkp, vkq = V[k, p], V[k, q]
                    V[k, p] = c * vkp - s * vkq
                    V[k, q] = s * vkp + c * vkq
    best = 0
    for i in range(1, n):
        if D[i, i] < D[best, best]:
            best = i
    big = 0
    for i in range(1, n):
        if abs(V[i, best]) > abs(V[big, best]):
            big = i
    sign = 1.0 if V[big, best] >= 0.0 else -1.0
    for i in range(n):
        v[i] = sign * V[i, best]
    return D[best, best]
