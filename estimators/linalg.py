"""Small dense linear algebra of the estimators' compiled kernels.

Plain Python compiled by :func:`quadfault.jit.jit`; nothing allocates (the caller passes the
scratch). Used by the interior point (its Newton step), the IRLS window (its uncertainty and
conditioning guard), the change completion (its weak direction) and the EKF (its update):

* :func:`cholesky_into` / :func:`cholesky_solve_into` -- ``A + diag(shift) = L L^T`` and the
  two triangular solves (the shift is the interior point's barrier diagonal and the EKF's
  measurement noise; zero elsewhere);
* :func:`gauss_jordan_into` -- ``A X = B`` by Gauss-Jordan elimination with partial pivoting,
  for a general square ``A``; :func:`cond1_into` -- the 1-norm condition number
  ``||A||_1 ||A^-1||_1`` with it (MATLAB's ``1 / rcond`` up to its estimate);
* :func:`symmetric_eigen_into` -- the eigenvalues and eigenvectors of a symmetric matrix by
  cyclic Jacobi rotations; :func:`smallest_eigenpair_into` -- its smallest pair.
"""

from __future__ import annotations

import math

from quadfault.jit import jit


@jit(inline="always")
def cholesky_into(A, shift, L, n) -> bool:
    """Lower Cholesky factor of ``A + diag(shift)`` into ``L``'s lower triangle (only ``A``'s
    lower triangle is read); False, with ``L`` undefined, when the matrix is not positive
    definite (or not finite). ``n``: the size, ``A.shape[0]`` (an argument, so a caller
    that knows it at compile time gets loops of known length)."""
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
def cholesky_solve_into(L, rhs, out, n) -> None:
    """Solve ``L L^T out = rhs`` given the factor of :func:`cholesky_into`."""
    _forward_into(L, rhs, out, n)
    _backward_into(L, out, n)


@jit(inline="always")
def _forward_into(L, rhs, y, n) -> None:
    """``L y = rhs``."""
    for i in range(n):
        s = rhs[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]


@jit(inline="always")
def _backward_into(L, y, n) -> None:
    """``L^T x = y``, ``x`` over ``y``. (Its own function, with a forward range: numba then
    compiles both substitutions without reference counting on the arrays.)"""
    for back in range(n):
        i = n - 1 - back
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * y[k]
        y[i] = s / L[i, i]


@jit(inner=True)
def gauss_jordan_into(A, X) -> bool:
    """Solve ``A Y = X`` in place: ``X`` (n, k) becomes ``Y``, ``A`` (n, n) is destroyed.
    Gauss-Jordan elimination with partial pivoting; False when ``A`` is singular."""
    n, k = A.shape[0], X.shape[1]
    for col in range(n):
        piv = col
        for r in range(col + 1, n):
            if abs(A[r, col]) > abs(A[piv, col]):
                piv = r
        if A[piv, col] == 0.0:
            return False
        for c in range(n):
            A[col, c], A[piv, c] = A[piv, c], A[col, c]
        for c in range(k):
            X[col, c], X[piv, c] = X[piv, c], X[col, c]
        d = A[col, col]
        for c in range(n):
            A[col, c] /= d
        for c in range(k):
            X[col, c] /= d
        for r in range(n):
            if r != col:
                f = A[r, col]
                for c in range(n):
                    A[r, c] -= f * A[col, c]
                for c in range(k):
                    X[r, c] -= f * X[col, c]
    return True


@jit(inline="always")
def cond1_into(A, M, inv) -> float:
    """``||A||_1 ||A^-1||_1`` (inf when ``A`` is singular); ``M`` and ``inv`` are n x n
    scratch (``inv`` holds ``A^-1`` afterwards). Inlined into its caller (the IRLS window,
    once): as a kernel of its own, numba would optimise and generate its code again in
    every kernel above it on a first run."""
    n = A.shape[0]
    for r in range(n):
        for c in range(n):
            M[r, c] = A[r, c]
            inv[r, c] = 1.0 if r == c else 0.0
    if not gauss_jordan_into(M, inv):
        return math.inf
    norm_a = 0.0
    norm_inv = 0.0
    for c in range(n):
        sa = 0.0
        si = 0.0
        for r in range(n):
            sa += abs(A[r, c])
            si += abs(inv[r, c])
        norm_a = max(norm_a, sa)
        norm_inv = max(norm_inv, si)
    value = norm_a * norm_inv
    return value if math.isfinite(value) else math.inf


@jit
def symmetric_eigen_into(A, D, V) -> None:
    """Eigen-decomposition of the symmetric part of ``A`` (n x n): the eigenvalues end on the
    diagonal of ``D``, the unit eigenvectors in the columns of ``V``.

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
            return
        for p in range(n - 1):
            for q in range(p + 1, n):
                if D[p, q] != 0.0:
                    _rotate(D, V, p, q)


@jit
def _rotate(D, V, p, q) -> None:
    """One Jacobi rotation zeroing ``D[p, q]``: ``D <- J^T D J``, ``V <- V J``."""
    n = D.shape[0]
    theta = (D[q, q] - D[p, p]) / (2.0 * D[p, q])
    t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
    if theta < 0.0:
        t = -t
    c = 1.0 / math.sqrt(t * t + 1.0)
    s = t * c
    for k in range(n):
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


@jit
def smallest_eigenpair_into(A, D, V, v) -> float:
    """Smallest eigenvalue of the symmetric part of ``A`` (n x n); its unit eigenvector goes
    into ``v`` (sign: largest entry positive). ``D`` and ``V`` are n x n scratch
    (:func:`symmetric_eigen_into`)."""
    n = A.shape[0]
    symmetric_eigen_into(A, D, V)
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
