"""Primal-dual interior-point method for a box-constrained quadratic program (Algorithm 1).

Problem (one IRLS round of the estimator, paper eqs. 24-25 with fixed weights)::

    min_x  1/2 x^T H x + q^T x     s.t.  lo <= x <= hi

with ``H = J^T G J + gamma I`` and ``q = J^T G r0 - gamma x_prev``. The constraints are
written ``phi(x) = [x - hi; lo - x] <= 0`` (eq. 31), ``D phi = [I; -I]`` (eq. 40), with
``m = 2 n`` multipliers ``lambda > 0``.

Per iteration:

* surrogate gap ``gap = -phi^T lambda`` (eq. 45) and barrier parameter ``t = mu m / gap``;
* KKT residual (eq. 39): ``r_dual = H x + q + D phi^T lambda``,
  ``r_cent = -diag(lambda) phi - 1/t``;
* Newton step from the KKT system (eq. 42, :func:`kkt_matrix`)::

      [ H               D phi^T     ] [dx     ]     [ r_dual ]
      [ -diag(lambda) D phi   -diag(phi) ] [dlambda] = - [ r_cent ]

  solved by eliminating ``dlambda`` (its block is diagonal): ``(H + diag(d)) dx = rhs`` with
  ``d = -lambda_hi/phi_hi - lambda_lo/phi_lo > 0``, a symmetric positive definite n x n system
  solved by Cholesky (no inverse); this is the same Newton step as the full system (tested);
* step ``s = 0.99 s_max`` (eq. 43), where ``s_max <= 1`` keeps ``lambda > 0`` *and* the primal
  iterate strictly inside the box (the reference code ratio-tests only ``lambda``);
* backtracking (eq. 44): accept when ``||r(y + s dy)|| <= (1 - alpha s) ||r(y)|| + eps_bt``
  or ``s < s_min``, else ``s <- beta s``;
* stop when ``||[r_dual; r_cent]|| < tol_feas`` and ``gap < tol_gap`` (both after the step;
  the reference mixes the gap's ``phi`` from before the step with ``lambda`` from after).

With n = 4 unknowns every numpy call costs more than its arithmetic, so the iteration runs on
Python floats: for n = 4 (the quadrotor) :func:`ipm4`, unrolled with a closed-form 4x4
Cholesky factor (same iterates as the general list loop, bit for bit, ~3.7x faster), which
:mod:`estimators._irls_numba` also compiles and runs; other n use the general loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadfault.errors import ConfigError


@dataclass(frozen=True)
class IPMSettings:
    """Settings of the interior-point method (the reference code's values).

    Attributes:
        mu: barrier growth factor (``t = mu m / gap``).
        alpha: sufficient-decrease factor of the backtracking test (kappa in the paper).
        beta: backtracking shrink factor (zeta in the paper).
        step_fraction: fraction of the maximum feasible step taken first.
        backtrack_eps: additive tolerance ``eps_tol`` of the backtracking test.
        min_step: a step shorter than this is accepted unconditionally.
        tol_feas: stop when the KKT residual norm is below this.
        tol_gap: ... and the surrogate duality gap is below this.
        max_iter: at most this many Newton iterations.
    """

    mu: float = 4.0
    alpha: float = 0.1
    beta: float = 0.5
    step_fraction: float = 0.99
    backtrack_eps: float = 1e-3
    min_step: float = 1e-6
    tol_feas: float = 1e-6
    tol_gap: float = 1e-6
    max_iter: int = 80

    def __post_init__(self):
        for key in ("mu", "alpha", "beta", "step_fraction", "backtrack_eps", "min_step",
                    "tol_feas", "tol_gap"):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ConfigError(f"IPM setting {key} must be a finite number >= 0, got {value!r}")
        if not self.mu > 1:
            raise ConfigError(f"IPM setting mu must be > 1, got {self.mu!r}")
        if not (0 < self.beta < 1 and 0 < self.step_fraction < 1 and 0 <= self.alpha < 1):
            raise ConfigError("IPM settings need 0 < beta < 1, 0 < step_fraction < 1, "
                              "0 <= alpha < 1")
        if not (isinstance(self.max_iter, int) and self.max_iter >= 1):
            raise ConfigError(f"IPM setting max_iter must be an integer >= 1, "
                              f"got {self.max_iter!r}")


@dataclass(frozen=True)
class IPMResult:
    """Outcome of :func:`solve_box_qp`.

    Attributes:
        x: solution (n,); lam: multipliers ``[lambda_hi; lambda_lo]`` (2n,).
        iterations: Newton iterations taken; converged: tolerances met.
        dual_history, cent_history, gap_history: ``||r_dual||``, ``||r_cent||`` and the
            surrogate gap after each iteration (``None`` unless ``record_history``).
        x_history: iterates (iterations, n) (``None`` unless ``record_history``).
    """

    x: np.ndarray
    lam: np.ndarray
    iterations: int
    converged: bool
    dual_history: np.ndarray | None = None
    cent_history: np.ndarray | None = None
    gap_history: np.ndarray | None = None
    x_history: np.ndarray | None = None


def constraint_values(x, lo: float, hi: float) -> np.ndarray:
    """``phi(x) = [x - hi; lo - x]`` (eq. 31); feasible when all are <= 0."""
    x = np.asarray(x, dtype=float)
    return np.concatenate((x - hi, lo - x))


def kkt_matrix(H, phi, lam) -> np.ndarray:
    """The full Newton matrix of eq. (42), ``(3n, 3n)`` (for checks; the solver eliminates
    ``dlambda``)."""
    n = len(H)
    Dphi = np.vstack((np.eye(n), -np.eye(n)))
    top = np.hstack((H, Dphi.T))
    bottom = np.hstack((-lam[:, None] * Dphi, -np.diag(phi)))
    return np.vstack((top, bottom))


def kkt_residual(H, q, x, lam, lo, hi, t) -> tuple[np.ndarray, np.ndarray]:
    """``(r_dual, r_cent)`` of eq. (39) at barrier parameter ``t``."""
    n = len(x)
    phi = constraint_values(x, lo, hi)
    r_dual = H @ x + q + lam[:n] - lam[n:]
    r_cent = -lam * phi - 1.0 / t
    return r_dual, r_cent


def _cholesky_solve(K: list, rhs: list) -> list:
    """Solve ``K x = rhs`` for a symmetric positive definite ``K`` (lists of floats)."""
    n = len(rhs)
    L = [[0.0] * n for _ in range(n)]
    for j in range(n):
        Lj = L[j]
        s = K[j][j]
        for k in range(j):
            s -= Lj[k] * Lj[k]
        if not s > 0.0:
            raise np.linalg.LinAlgError("Newton matrix is not positive definite")
        d = math.sqrt(s)
        Lj[j] = d
        for i in range(j + 1, n):
            Li = L[i]
            s = K[i][j]
            for k in range(j):
                s -= Li[k] * Lj[k]
            Li[j] = s / d
    x = [0.0] * n
    for i in range(n):  # L y = rhs
        s = rhs[i]
        Li = L[i]
        for k in range(i):
            s -= Li[k] * x[k]
        x[i] = s / Li[i]
    for i in range(n - 1, -1, -1):  # L^T x = y
        s = x[i]
        for k in range(i + 1, n):
            s -= L[k][i] * x[k]
        x[i] = s / L[i][i]
    return x


def _newton_step(H: list, rd, cu, cl, pu, pl, lu, ll):
    """Eq. (42) with ``dlambda`` eliminated, on lists: returns ``(dx, dlambda_hi, dlambda_lo)``."""
    n = len(rd)
    K = [row[:] for row in H]
    rhs = [0.0] * n
    for i in range(n):
        K[i][i] -= lu[i] / pu[i] + ll[i] / pl[i]
        rhs[i] = cl[i] / pl[i] - cu[i] / pu[i] - rd[i]
    dx = _cholesky_solve(K, rhs)
    dlu = [(cu[i] - lu[i] * dx[i]) / pu[i] for i in range(n)]
    dll = [(cl[i] + ll[i] * dx[i]) / pl[i] for i in range(n)]
    return dx, dlu, dll


def newton_step(H, r_dual, r_cent, phi, lam) -> tuple[np.ndarray, np.ndarray]:
    """Solve eq. (42) for ``(dx, dlambda)`` by eliminating ``dlambda`` (the solver's step)."""
    n = len(r_dual)
    rc, ph, la = (np.asarray(a, dtype=float).tolist() for a in (r_cent, phi, lam))
    dx, dlu, dll = _newton_step(np.asarray(H, dtype=float).tolist(),
                                np.asarray(r_dual, dtype=float).tolist(), rc[:n], rc[n:],
                                ph[:n], ph[n:], la[:n], la[n:])
    return np.array(dx), np.array(dlu + dll)


def _gap(pu, pl, lu, ll) -> float:
    """Surrogate duality gap ``-phi^T lambda`` (eq. 45)."""
    g = 0.0
    for i in range(len(pu)):
        g -= pu[i] * lu[i] + pl[i] * ll[i]
    return g


def _kkt_norm(H, q, x, lu, ll, hi, lo, inv_t):
    """``(||r||, ||r_dual||, ||r_cent||)`` of eq. (39) (lists)."""
    n = len(x)
    d2 = c2 = 0.0
    for i in range(n):
        v = q[i] + lu[i] - ll[i]
        Hi = H[i]
        for k in range(n):
            v += Hi[k] * x[k]
        a = -lu[i] * (x[i] - hi) - inv_t
        b = -ll[i] * (lo - x[i]) - inv_t
        d2 += v * v
        c2 += a * a + b * b
    return math.sqrt(d2 + c2), math.sqrt(d2), math.sqrt(c2)


def solve_box_qp(H, q, lo: float, hi: float, x0, settings: IPMSettings | None = None,
                 record_history: bool = False) -> IPMResult:
    """Minimise ``1/2 x^T H x + q^T x`` over ``lo <= x <= hi`` (Algorithm 1).

    Args:
        H: (n, n) symmetric positive definite; q: (n,).
        lo, hi: bounds, ``lo < hi``.
        x0: start, strictly inside the box (``lambda`` starts at ``-1/phi(x0)``, so the first
            barrier parameter is ``mu``).
        record_history: keep per-iteration residual, gap and iterate histories.
    """
    cfg = settings or IPMSettings()
    xl = np.asarray(x0, dtype=float).tolist()
    n = len(xl)
    lo, hi = float(lo), float(hi)
    if not (lo < hi) or any(not lo < xi < hi for xi in xl):
        raise ConfigError(f"interior-point start must lie strictly inside ({lo}, {hi}), got {x0}")
    Hl = np.asarray(H, dtype=float).tolist()
    ql = np.asarray(q, dtype=float).tolist()
    if n == 4:  # the quadrotor: the same iteration on scalar locals (see _solve_box_qp4)
        return _solve_box_qp4(Hl, ql, lo, hi, xl, cfg, record_history)
    return _solve_box_qp_general(Hl, ql, lo, hi, xl, cfg, record_history)


def _solve_box_qp_general(Hl: list, ql: list, lo: float, hi: float, x: list, cfg: IPMSettings,
                          record_history: bool) -> IPMResult:
    """Algorithm 1 on lists of floats, any n (the loop :func:`solve_box_qp` runs)."""
    n = len(x)
    rn = range(n)
    pu = [xi - hi for xi in x]  # phi = [x - hi; lo - x] kept as its two halves
    pl = [lo - xi for xi in x]
    lu = [-1.0 / p for p in pu]
    ll = [-1.0 / p for p in pl]
    scale_t = cfg.mu * 2 * n
    gap = _gap(pu, pl, lu, ll)
    hist = ([], [], [], []) if record_history else None
    converged = False
    it = 0
    for it in range(1, cfg.max_iter + 1):
        inv_t = max(gap, 1e-12) / scale_t  # 1/t, t = mu m / gap
        rd, cu, cl = [0.0] * n, [0.0] * n, [0.0] * n
        r2 = 0.0
        for i in rn:  # KKT residual, eq. (39)
            v = ql[i] + lu[i] - ll[i]
            Hi = Hl[i]
            for k in rn:
                v += Hi[k] * x[k]
            a = -lu[i] * pu[i] - inv_t
            b = -ll[i] * pl[i] - inv_t
            rd[i], cu[i], cl[i] = v, a, b
            r2 += v * v + a * a + b * b
        r_norm = math.sqrt(r2)
        dx, dlu, dll = _newton_step(Hl, rd, cu, cl, pu, pl, lu, ll)
        s_max = 1.0  # eq. (43): keep lambda > 0 and lo < x < hi
        for i in rn:
            if dlu[i] < 0:
                s_max = min(s_max, -lu[i] / dlu[i])
            if dll[i] < 0:
                s_max = min(s_max, -ll[i] / dll[i])
            if dx[i] > 0:
                s_max = min(s_max, -pu[i] / dx[i])
            elif dx[i] < 0:
                s_max = min(s_max, pl[i] / dx[i])
        s = cfg.step_fraction * s_max
        while True:  # backtracking, eq. (44)
            x_t = [x[i] + s * dx[i] for i in rn]
            lu_t = [lu[i] + s * dlu[i] for i in rn]
            ll_t = [ll[i] + s * dll[i] for i in rn]
            r_try, rd_norm, rc_norm = _kkt_norm(Hl, ql, x_t, lu_t, ll_t, hi, lo, inv_t)
            if r_try <= (1.0 - cfg.alpha * s) * r_norm + cfg.backtrack_eps or s < cfg.min_step:
                break
            s *= cfg.beta
        x, lu, ll = x_t, lu_t, ll_t
        pu = [xi - hi for xi in x]
        pl = [lo - xi for xi in x]
        gap = _gap(pu, pl, lu, ll)
        if hist is not None:
            hist[0].append(rd_norm)
            hist[1].append(rc_norm)
            hist[2].append(gap)
            hist[3].append(x)
        if r_try < cfg.tol_feas and gap < cfg.tol_gap:
            converged = True
            break
    lam = np.array(lu + ll)
    if hist is None:
        return IPMResult(np.array(x), lam, it, converged)
    return IPMResult(np.array(x), lam, it, converged, np.array(hist[0]), np.array(hist[1]),
                     np.array(hist[2]), np.array(hist[3]).reshape(-1, n))


def _solve_box_qp4(Hl: list, ql: list, lo: float, hi: float, x: list, cfg: IPMSettings,
                   record_history: bool) -> IPMResult:
    """:func:`solve_box_qp` for n = 4 unknowns: :func:`ipm4` on Python floats."""
    hist = np.empty((cfg.max_iter if record_history else 0, 7))
    out = ipm4(Hl[0] + Hl[1] + Hl[2] + Hl[3], ql, lo, hi, x, cfg.mu, cfg.alpha, cfg.beta,
               cfg.step_fraction, cfg.backtrack_eps, cfg.min_step, cfg.tol_feas, cfg.tol_gap,
               cfg.max_iter, hist)
    it, flag = out[12], out[13]
    if flag < 0:
        raise np.linalg.LinAlgError("Newton matrix is not positive definite")
    x, lam, converged = np.array(out[0:4]), np.array(out[4:12]), flag == 1
    if not record_history:
        return IPMResult(x, lam, it, converged)
    h = hist[:it]
    return IPMResult(x, lam, it, converged, h[:, 0].copy(), h[:, 1].copy(), h[:, 2].copy(),
                     h[:, 3:7].copy())


def ipm4(H, q, lo, hi, x, mu, alpha, beta, step_fraction, bt_eps, min_step, tol_feas, tol_gap,
         max_iter, hist):
    """Algorithm 1 for n = 4 unknowns, unrolled on scalars; plain Python that numba also
    compiles (:mod:`estimators._irls_numba` runs this very function as its interior point).

    Line for line the generic loop of :func:`_solve_box_qp_general` (eqs. 39, 42-45), with the
    4x4 Cholesky factor of the reduced Newton matrix ``H + diag(d)`` written out and every
    operation in the generic loop's order, so the iterates are the same floating-point numbers
    (tested bit for bit); it avoids the per-element indexing that dominates the generic loop.

    Args:
        H: the 16 entries of H, row by row; q, x: 4 entries each (x strictly inside the box).
        hist: (max_iter, 7) array that receives ``||r_dual||, ||r_cent||, gap, x`` per
            iteration, or a (0, 7) array to record nothing.

    Returns:
        ``(x0..x3, lambda_hi 0..3, lambda_lo 0..3, iterations, flag)``; flag 1 = converged,
        0 = iteration limit, -1 = the Newton matrix was not positive definite (stopped there).
    """
    h00, h01, h02, h03, h10, h11, h12, h13, h20, h21, h22, h23, h30, h31, h32, h33 = H
    q0, q1, q2, q3 = q
    x0, x1, x2, x3 = x
    record = hist.shape[0] > 0
    pu0, pu1, pu2, pu3 = x0 - hi, x1 - hi, x2 - hi, x3 - hi  # phi = [x - hi; lo - x]
    pl0, pl1, pl2, pl3 = lo - x0, lo - x1, lo - x2, lo - x3
    lu0, lu1, lu2, lu3 = -1.0 / pu0, -1.0 / pu1, -1.0 / pu2, -1.0 / pu3
    ll0, ll1, ll2, ll3 = -1.0 / pl0, -1.0 / pl1, -1.0 / pl2, -1.0 / pl3
    scale_t = mu * 2 * 4
    gap = 0.0  # eq. (45)
    gap -= pu0 * lu0 + pl0 * ll0
    gap -= pu1 * lu1 + pl1 * ll1
    gap -= pu2 * lu2 + pl2 * ll2
    gap -= pu3 * lu3 + pl3 * ll3
    flag = 0
    it = 0
    for it in range(1, max_iter + 1):
        inv_t = max(gap, 1e-12) / scale_t  # 1/t, t = mu m / gap
        # KKT residual, eq. (39)
        rd0 = q0 + lu0 - ll0 + h00 * x0 + h01 * x1 + h02 * x2 + h03 * x3
        rd1 = q1 + lu1 - ll1 + h10 * x0 + h11 * x1 + h12 * x2 + h13 * x3
        rd2 = q2 + lu2 - ll2 + h20 * x0 + h21 * x1 + h22 * x2 + h23 * x3
        rd3 = q3 + lu3 - ll3 + h30 * x0 + h31 * x1 + h32 * x2 + h33 * x3
        cu0, cl0 = -lu0 * pu0 - inv_t, -ll0 * pl0 - inv_t
        cu1, cl1 = -lu1 * pu1 - inv_t, -ll1 * pl1 - inv_t
        cu2, cl2 = -lu2 * pu2 - inv_t, -ll2 * pl2 - inv_t
        cu3, cl3 = -lu3 * pu3 - inv_t, -ll3 * pl3 - inv_t
        r2 = 0.0
        r2 += rd0 * rd0 + cu0 * cu0 + cl0 * cl0
        r2 += rd1 * rd1 + cu1 * cu1 + cl1 * cl1
        r2 += rd2 * rd2 + cu2 * cu2 + cl2 * cl2
        r2 += rd3 * rd3 + cu3 * cu3 + cl3 * cl3
        r_norm = math.sqrt(r2)
        # Newton step, eq. (42) with dlambda eliminated: (H + diag(d)) dx = rhs, Cholesky
        k00 = h00 - (lu0 / pu0 + ll0 / pl0)
        k11 = h11 - (lu1 / pu1 + ll1 / pl1)
        k22 = h22 - (lu2 / pu2 + ll2 / pl2)
        k33 = h33 - (lu3 / pu3 + ll3 / pl3)
        b0 = cl0 / pl0 - cu0 / pu0 - rd0
        b1 = cl1 / pl1 - cu1 / pu1 - rd1
        b2 = cl2 / pl2 - cu2 / pu2 - rd2
        b3 = cl3 / pl3 - cu3 / pu3 - rd3
        if not k00 > 0.0:
            flag = -1
            break
        a00 = math.sqrt(k00)
        a10, a20, a30 = h10 / a00, h20 / a00, h30 / a00
        s = k11 - a10 * a10
        if not s > 0.0:
            flag = -1
            break
        a11 = math.sqrt(s)
        a21 = (h21 - a20 * a10) / a11
        a31 = (h31 - a30 * a10) / a11
        s = k22 - a20 * a20 - a21 * a21
        if not s > 0.0:
            flag = -1
            break
        a22 = math.sqrt(s)
        a32 = (h32 - a30 * a20 - a31 * a21) / a22
        s = k33 - a30 * a30 - a31 * a31 - a32 * a32
        if not s > 0.0:
            flag = -1
            break
        a33 = math.sqrt(s)
        y0 = b0 / a00  # L y = rhs
        y1 = (b1 - a10 * y0) / a11
        y2 = (b2 - a20 * y0 - a21 * y1) / a22
        y3 = (b3 - a30 * y0 - a31 * y1 - a32 * y2) / a33
        dx3 = y3 / a33  # L^T dx = y
        dx2 = (y2 - a32 * dx3) / a22
        dx1 = (y1 - a21 * dx2 - a31 * dx3) / a11
        dx0 = (y0 - a10 * dx1 - a20 * dx2 - a30 * dx3) / a00
        du0, dl0 = (cu0 - lu0 * dx0) / pu0, (cl0 + ll0 * dx0) / pl0
        du1, dl1 = (cu1 - lu1 * dx1) / pu1, (cl1 + ll1 * dx1) / pl1
        du2, dl2 = (cu2 - lu2 * dx2) / pu2, (cl2 + ll2 * dx2) / pl2
        du3, dl3 = (cu3 - lu3 * dx3) / pu3, (cl3 + ll3 * dx3) / pl3
        s_max = 1.0  # eq. (43): keep lambda > 0 and lo < x < hi (a comparison, not min():
        if du0 < 0:  # cheaper on Python floats, and the same value)
            r = -lu0 / du0
            if r < s_max:
                s_max = r
        if du1 < 0:
            r = -lu1 / du1
            if r < s_max:
                s_max = r
        if du2 < 0:
            r = -lu2 / du2
            if r < s_max:
                s_max = r
        if du3 < 0:
            r = -lu3 / du3
            if r < s_max:
                s_max = r
        if dl0 < 0:
            r = -ll0 / dl0
            if r < s_max:
                s_max = r
        if dl1 < 0:
            r = -ll1 / dl1
            if r < s_max:
                s_max = r
        if dl2 < 0:
            r = -ll2 / dl2
            if r < s_max:
                s_max = r
        if dl3 < 0:
            r = -ll3 / dl3
            if r < s_max:
                s_max = r
        if dx0 > 0:
            r = -pu0 / dx0
            if r < s_max:
                s_max = r
        elif dx0 < 0:
            r = pl0 / dx0
            if r < s_max:
                s_max = r
        if dx1 > 0:
            r = -pu1 / dx1
            if r < s_max:
                s_max = r
        elif dx1 < 0:
            r = pl1 / dx1
            if r < s_max:
                s_max = r
        if dx2 > 0:
            r = -pu2 / dx2
            if r < s_max:
                s_max = r
        elif dx2 < 0:
            r = pl2 / dx2
            if r < s_max:
                s_max = r
        if dx3 > 0:
            r = -pu3 / dx3
            if r < s_max:
                s_max = r
        elif dx3 < 0:
            r = pl3 / dx3
            if r < s_max:
                s_max = r
        s = step_fraction * s_max
        while True:  # backtracking, eq. (44)
            t0, t1, t2, t3 = x0 + s * dx0, x1 + s * dx1, x2 + s * dx2, x3 + s * dx3
            tu0, tu1, tu2, tu3 = lu0 + s * du0, lu1 + s * du1, lu2 + s * du2, lu3 + s * du3
            tl0, tl1, tl2, tl3 = ll0 + s * dl0, ll1 + s * dl1, ll2 + s * dl2, ll3 + s * dl3
            v0 = q0 + tu0 - tl0 + h00 * t0 + h01 * t1 + h02 * t2 + h03 * t3
            v1 = q1 + tu1 - tl1 + h10 * t0 + h11 * t1 + h12 * t2 + h13 * t3
            v2 = q2 + tu2 - tl2 + h20 * t0 + h21 * t1 + h22 * t2 + h23 * t3
            v3 = q3 + tu3 - tl3 + h30 * t0 + h31 * t1 + h32 * t2 + h33 * t3
            e0, f0 = -tu0 * (t0 - hi) - inv_t, -tl0 * (lo - t0) - inv_t
            e1, f1 = -tu1 * (t1 - hi) - inv_t, -tl1 * (lo - t1) - inv_t
            e2, f2 = -tu2 * (t2 - hi) - inv_t, -tl2 * (lo - t2) - inv_t
            e3, f3 = -tu3 * (t3 - hi) - inv_t, -tl3 * (lo - t3) - inv_t
            d2 = 0.0
            d2 += v0 * v0
            d2 += v1 * v1
            d2 += v2 * v2
            d2 += v3 * v3
            c2 = 0.0
            c2 += e0 * e0 + f0 * f0
            c2 += e1 * e1 + f1 * f1
            c2 += e2 * e2 + f2 * f2
            c2 += e3 * e3 + f3 * f3
            r_try = math.sqrt(d2 + c2)
            if r_try <= (1.0 - alpha * s) * r_norm + bt_eps or s < min_step:
                break
            s *= beta
        x0, x1, x2, x3 = t0, t1, t2, t3
        lu0, lu1, lu2, lu3 = tu0, tu1, tu2, tu3
        ll0, ll1, ll2, ll3 = tl0, tl1, tl2, tl3
        pu0, pu1, pu2, pu3 = x0 - hi, x1 - hi, x2 - hi, x3 - hi
        pl0, pl1, pl2, pl3 = lo - x0, lo - x1, lo - x2, lo - x3
        gap = 0.0
        gap -= pu0 * lu0 + pl0 * ll0
        gap -= pu1 * lu1 + pl1 * ll1
        gap -= pu2 * lu2 + pl2 * ll2
        gap -= pu3 * lu3 + pl3 * ll3
        if record:
            hist[it - 1, 0] = math.sqrt(d2)
            hist[it - 1, 1] = math.sqrt(c2)
            hist[it - 1, 2] = gap
            hist[it - 1, 3], hist[it - 1, 4], hist[it - 1, 5], hist[it - 1, 6] = x0, x1, x2, x3
        if r_try < tol_feas and gap < tol_gap:
            flag = 1
            break
    return (x0, x1, x2, x3, lu0, lu1, lu2, lu3, ll0, ll1, ll2, ll3, it, flag)
