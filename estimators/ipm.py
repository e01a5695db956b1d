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
  solved with ``numpy.linalg.solve``; this is the same Newton step as the full system
  (tested), at a fraction of the cost;
* step ``s = 0.99 s_max`` (eq. 43), where ``s_max <= 1`` keeps ``lambda > 0`` *and* the primal
  iterate strictly inside the box (the reference code ratio-tests only ``lambda``);
* backtracking (eq. 44): accept when ``||r(y + s dy)|| <= (1 - alpha s) ||r(y)|| + eps_bt``
  or ``s < s_min``, else ``s <- beta s``;
* stop when ``||[r_dual; r_cent]|| < tol_feas`` and ``gap < tol_gap`` (both after the step;
  the reference mixes the gap's ``phi`` from before the step with ``lambda`` from after).
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


def newton_step(H, r_dual, r_cent, phi, lam) -> tuple[np.ndarray, np.ndarray]:
    """Solve eq. (42) for ``(dx, dlambda)`` by eliminating ``dlambda``."""
    n = len(r_dual)
    pu, pl = phi[:n], phi[n:]
    lu, ll = lam[:n], lam[n:]
    cu, cl = r_cent[:n], r_cent[n:]
    K = H + np.diag(-lu / pu - ll / pl)
    dx = np.linalg.solve(K, -r_dual - cu / pu + cl / pl)
    dlam = np.concatenate(((cu - lu * dx) / pu, (cl + ll * dx) / pl))
    return dx, dlam


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
    H = np.asarray(H, dtype=float)
    q = np.asarray(q, dtype=float)
    x = np.array(x0, dtype=float)
    n = len(x)
    if not (lo < hi) or np.any(x <= lo) or np.any(x >= hi):
        raise ConfigError(f"interior-point start must lie strictly inside ({lo}, {hi}), got {x}")
    m = 2 * n
    # upper (u) and lower (l) halves kept apart: phi_u = x - hi, phi_l = lo - x
    pu, pl = x - hi, lo - x
    lu, ll = -1.0 / pu, -1.0 / pl
    hist = ([], [], [], []) if record_history else None
    converged = False
    it = 0
    solve = np.linalg.solve
    err = np.seterr(divide="ignore", invalid="ignore")  # ratio test divides by dx = 0
    K = np.empty_like(H)
    diag = np.arange(n)
    try:
        for it in range(1, cfg.max_iter + 1):
            gap = -float(pu @ lu + pl @ ll)
            inv_t = max(gap, 1e-12) / (cfg.mu * m)  # 1/t, t = mu m / gap
            r_dual = H @ x + q + lu - ll
            cu = -lu * pu - inv_t
            cl = -ll * pl - inv_t
            r_norm = math.sqrt(float(r_dual @ r_dual + cu @ cu + cl @ cl))
            # Newton step of eq. (42) with dlambda eliminated (see newton_step)
            K[:] = H
            K[diag, diag] -= lu / pu + ll / pl
            dx = solve(K, cl / pl - cu / pu - r_dual)
            dlu = (cu - lu * dx) / pu
            dll = (cl + ll * dx) / pl
            # eq. (43): keep lambda > 0 and lo < x < hi
            ratios = np.concatenate((-lu / dlu, -ll / dll, -pu / dx, pl / dx))
            ratios = ratios[ratios > 0]
            s = cfg.step_fraction * min(1.0, float(ratios.min()) if ratios.size else 1.0)
            while True:  # backtracking, eq. (44)
                x_try = x + s * dx
                lu_try = lu + s * dlu
                ll_try = ll + s * dll
                pu_try, pl_try = x_try - hi, lo - x_try
                rd = H @ x_try + q + lu_try - ll_try
                rcu = -lu_try * pu_try - inv_t
                rcl = -ll_try * pl_try - inv_t
                r_try = math.sqrt(float(rd @ rd + rcu @ rcu + rcl @ rcl))
                if r_try <= (1.0 - cfg.alpha * s) * r_norm + cfg.backtrack_eps or s < cfg.min_step:
                    break
                s *= cfg.beta
            x, lu, ll, pu, pl = x_try, lu_try, ll_try, pu_try, pl_try
            gap = -float(pu @ lu + pl @ ll)
            if hist is not None:
                hist[0].append(math.sqrt(float(rd @ rd)))
                hist[1].append(math.sqrt(float(rcu @ rcu + rcl @ rcl)))
                hist[2].append(gap)
                hist[3].append(x.copy())
            if r_try < cfg.tol_feas and gap < cfg.tol_gap:
                converged = True
                break
    finally:
        np.seterr(**err)
    lam = np.concatenate((lu, ll))
    if hist is None:
        return IPMResult(x, lam, it, converged)
    return IPMResult(x, lam, it, converged, np.array(hist[0]), np.array(hist[1]),
                     np.array(hist[2]), np.array(hist[3]).reshape(-1, n))
