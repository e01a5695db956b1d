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
* Newton step from the KKT system (eq. 42)::

      [ H               D phi^T     ] [dx     ]     [ r_dual ]
      [ -diag(lambda) D phi   -diag(phi) ] [dlambda] = - [ r_cent ]

  solved by eliminating ``dlambda`` (its block is diagonal): ``(H + diag(d)) dx = rhs`` with
  ``d = -lambda_hi/phi_hi - lambda_lo/phi_lo > 0``, a symmetric positive definite n x n system
  solved by Cholesky (:mod:`estimators.linalg`, no inverse); this is the same Newton step as
  the full system (tested against it);
* step ``s = 0.99 s_max`` (eq. 43), where ``s_max <= 1`` keeps ``lambda > 0`` *and* the primal
  iterate strictly inside the box (the reference code ratio-tests only ``lambda``);
* backtracking (eq. 44): accept when ``||r(y + s dy)|| <= (1 - alpha s) ||r(y)|| + eps_bt``
  or ``s < s_min``, else ``s <- beta s``;
* stop when ``||[r_dual; r_cent]|| < tol_feas`` and ``gap < tol_gap`` (both after the step;
  the reference mixes the gap's ``phi`` from before the step with ``lambda`` from after).

:func:`ipm_into` is the algorithm, plain Python compiled by :func:`quadfault.jit.jit` and
allocation-free; the IRLS window runs its steps (:func:`ipm_steps`) in place on its workspace,
compiled for the vehicle's size only (:func:`any_size`); :func:`solve_box_qp` calls it on one
problem and returns an :class:`IPMResult`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimators.linalg import cholesky_into, cholesky_solve_into
from estimators.state import counts, fields, pack
from quadfault.errors import ConfigError
from quadfault.jit import jit


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
        for key in (
            "mu",
            "alpha",
            "beta",
            "step_fraction",
            "backtrack_eps",
            "min_step",
            "tol_feas",
            "tol_gap",
        ):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ConfigError(f"IPM setting {key} must be a finite number >= 0, got {value!r}")
        if not self.mu > 1:
            raise ConfigError(f"IPM setting mu must be > 1, got {self.mu!r}")
        if not (0 < self.beta < 1 and 0 < self.step_fraction < 1 and 0 <= self.alpha < 1):
            raise ConfigError(
                "IPM settings need 0 < beta < 1, 0 < step_fraction < 1, 0 <= alpha < 1"
            )
        if not (isinstance(self.max_iter, int) and self.max_iter >= 1):
            raise ConfigError(
                f"IPM setting max_iter must be an integer >= 1, got {self.max_iter!r}"
            )


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


#: the float settings of :func:`ipm_into`, by name (:func:`ipm_parameters` packs them)
SETTINGS = fields(
    "IPMSettingRows",
    "mu",
    "alpha",
    "beta",
    "step_fraction",
    "backtrack_eps",
    "min_step",
    "tol_feas",
    "tol_gap",
)
#: rows of the interior point's workspace ``W`` (:func:`ipm_into`)
WORK = fields(
    "IPMWorkRows", "lam_hi", "lam_lo", "d", "rhs", "dx", "dlam_hi", "dlam_lo", "hx", "hdx"
)
N_SETTINGS, N_WORK_ROWS = SETTINGS.size, WORK.size


def ipm_parameters(settings: IPMSettings) -> np.ndarray:
    """The float settings of :func:`ipm_into` (:data:`SETTINGS`): ``mu, alpha, beta,
    step_fraction, backtrack_eps, min_step, tol_feas, tol_gap``."""
    return pack(SETTINGS, **{key: getattr(settings, key) for key in counts(SETTINGS)})


@jit
def ipm_into(H, q, lo, hi, x, settings, max_iter, W, L, hist):
    """Algorithm 1 on ``1/2 x^T H x + q^T x`` over the box ``[lo, hi]``, in place.

    Args:
        H: (n, n) symmetric positive definite; q: (n,).
        x: the start on entry, strictly inside the box; the last iterate on return.
        settings: :func:`ipm_parameters`; max_iter: at most this many Newton iterations.
        W: (9, n) workspace; on return its rows ``WORK.lam_hi``, ``WORK.lam_lo`` hold the
            multipliers of ``x <= hi`` and ``lo <= x``. L: (n, n) scratch.
        hist: (max_iter, >= 3 + n) receives ``||r_dual||, ||r_cent||, gap, x`` after each
            iteration, or a (0, 3 + n) array to record nothing.

    Returns:
        ``(iterations, flag)``: flag 1 = converged, 0 = iteration limit, -1 = the Newton
        matrix was not positive definite (stopped there).
    """
    n = q.shape[0]
    if n == 4:  # a quadrotor: the same steps compiled for a size known in advance
        return ipm_steps(H, q, lo, hi, x, settings, max_iter, W, L, hist, 4)
    return ipm_steps(H, q, lo, hi, x, settings, max_iter, W, L, hist, n)


def any_size(n: int):
    """The ``any_n`` argument of the kernels that run :func:`ipm_steps` (the IRLS window):
    None for 4 unknowns (a quadrotor), else True. numba drops the branches of a None argument
    before compiling (and only of a None one), so a quadrotor's kernels compile the steps for
    the literal 4 alone (loops of known length); any other size compiles both."""
    return None if n == 4 else True


@jit(inner=True)
def ipm_steps(H, q, lo, hi, x, settings, max_iter, W, L, hist, n):
    """:func:`ipm_into` for ``n`` unknowns (its loops' length; a constant lets the compiler
    unroll them). A call, not inlined: numba compiles it once per type of ``n`` (the literal
    4 and int64); inlined twice into :func:`ipm_into`, the copies of its IR cost about a
    CPU-second more to compile, with the same machine code. The IRLS window calls it
    directly, for one size (:func:`any_size`)."""
    mu, alpha = settings[SETTINGS.mu], settings[SETTINGS.alpha]
    beta, step_fraction = settings[SETTINGS.beta], settings[SETTINGS.step_fraction]
    bt_eps, min_step = settings[SETTINGS.backtrack_eps], settings[SETTINGS.min_step]
    tol_feas, tol_gap = settings[SETTINGS.tol_feas], settings[SETTINGS.tol_gap]
    # the workspace rows as views made once (no reference counting in the loop)
    lam_hi, lam_lo, d, rhs, dx_ = (
        W[WORK.lam_hi],
        W[WORK.lam_lo],
        W[WORK.d],
        W[WORK.rhs],
        W[WORK.dx],
    )
    dlam_hi, dlam_lo, hx_, hdx_ = W[WORK.dlam_hi], W[WORK.dlam_lo], W[WORK.hx], W[WORK.hdx]
    gap = 0.0  # surrogate gap -phi^T lambda, eq. (45); phi = [x - hi; lo - x]
    for i in range(n):
        pu = x[i] - hi
        pl = lo - x[i]
        lam_hi[i] = -1.0 / pu
        lam_lo[i] = -1.0 / pl
        gap -= pu * lam_hi[i] + pl * lam_lo[i]
    scale_t = mu * 2 * n
    for it in range(1, max_iter + 1):
        inv_t = max(gap, 1e-12) / scale_t  # 1/t, t = mu m / gap
        r2 = 0.0
        for i in range(n):  # KKT residual, eq. (39), and the reduced Newton system, eq. (42)
            pu = x[i] - hi
            pl = lo - x[i]
            lu, ll = lam_hi[i], lam_lo[i]
            hx = 0.0
            for k in range(n):
                hx += H[i, k] * x[k]
            hx_[i] = hx
            rd = q[i] + lu - ll + hx
            cu = -lu * pu - inv_t
            cl = -ll * pl - inv_t
            r2 += rd * rd + cu * cu + cl * cl
            d[i] = -(lu / pu + ll / pl)  # (H + diag(d)) dx = rhs
            rhs[i] = cl / pl - cu / pu - rd
        r_norm = math.sqrt(r2)
        if not cholesky_into(H, d, L, n):
            return it, -1
        cholesky_solve_into(L, rhs, dx_, n)
        s_max = 1.0  # eq. (43): keep lambda > 0 and lo < x < hi
        for i in range(n):
            pu = x[i] - hi
            pl = lo - x[i]
            lu, ll, dx = lam_hi[i], lam_lo[i], dx_[i]
            dlu = (-lu * pu - inv_t - lu * dx) / pu
            dll = (-ll * pl - inv_t + ll * dx) / pl
            dlam_hi[i] = dlu
            dlam_lo[i] = dll
            if dlu < 0:
                s_max = min(s_max, -lu / dlu)
            if dll < 0:
                s_max = min(s_max, -ll / dll)
            if dx > 0:
                s_max = min(s_max, -pu / dx)
            elif dx < 0:
                s_max = min(s_max, pl / dx)
            hdx = 0.0  # H dx: the trial points' H x is then H x + s H dx
            for k in range(n):
                hdx += H[i, k] * dx_[k]
            hdx_[i] = hdx
        s = step_fraction * s_max
        while True:  # backtracking, eq. (44), on the KKT residual at the trial point
            d2 = 0.0
            c2 = 0.0
            for i in range(n):
                lu = lam_hi[i] + s * dlam_hi[i]
                ll = lam_lo[i] + s * dlam_lo[i]
                v = q[i] + lu - ll + hx_[i] + s * hdx_[i]
                d2 += v * v
                xt = x[i] + s * dx_[i]
                cu = -lu * (xt - hi) - inv_t
                cl = -ll * (lo - xt) - inv_t
                c2 += cu * cu + cl * cl
            r_try = math.sqrt(d2 + c2)
            if r_try <= (1.0 - alpha * s) * r_norm + bt_eps or s < min_step:
                break
            s *= beta
        gap = 0.0
        for i in range(n):
            x[i] = x[i] + s * dx_[i]
            lam_hi[i] = lam_hi[i] + s * dlam_hi[i]
            lam_lo[i] = lam_lo[i] + s * dlam_lo[i]
            gap -= (x[i] - hi) * lam_hi[i] + (lo - x[i]) * lam_lo[i]
        if hist.shape[0] > 0:
            hist[it - 1, 0] = math.sqrt(d2)
            hist[it - 1, 1] = math.sqrt(c2)
            hist[it - 1, 2] = gap
            for i in range(n):
                hist[it - 1, 3 + i] = x[i]
        if r_try < tol_feas and gap < tol_gap:
            return it, 1
    return max_iter, 0


def solve_box_qp(
    H,
    q,
    lo: float,
    hi: float,
    x0,
    settings: IPMSettings | None = None,
    record_history: bool = False,
) -> IPMResult:
    """Minimise ``1/2 x^T H x + q^T x`` over ``lo <= x <= hi`` (Algorithm 1, :func:`ipm_into`).

    Args:
        H: (n, n) symmetric positive definite; q: (n,).
        lo, hi: bounds, ``lo < hi``.
        x0: start, strictly inside the box (``lambda`` starts at ``-1/phi(x0)``, so the first
            barrier parameter is ``mu``).
        record_history: keep per-iteration residual, gap and iterate histories.

    Raises:
        ConfigError: a start outside the box; numpy.linalg.LinAlgError: a Newton matrix that
        is not positive definite.
    """
    cfg = settings or IPMSettings()
    x = np.array(x0, dtype=float).reshape(-1)
    n = x.shape[0]
    lo, hi = float(lo), float(hi)
    if not (lo < hi) or not np.all((lo < x) & (x < hi)):
        raise ConfigError(f"interior-point start must lie strictly inside ({lo}, {hi}), got {x0}")
    H = np.ascontiguousarray(H, dtype=float)
    q = np.ascontiguousarray(q, dtype=float)
    W = np.zeros((N_WORK_ROWS, n))
    hist = np.zeros((cfg.max_iter if record_history else 0, 3 + n))
    it, flag = ipm_into(
        H, q, lo, hi, x, ipm_parameters(cfg), cfg.max_iter, W, np.empty((n, n)), hist
    )
    if flag < 0:
        raise np.linalg.LinAlgError("Newton matrix is not positive definite")
    lam = np.concatenate((W[WORK.lam_hi], W[WORK.lam_lo]))
    if not record_history:
        return IPMResult(x, lam, it, flag == 1)
    h = hist[:it]
    return IPMResult(
        x, lam, it, flag == 1, h[:, 0].copy(), h[:, 1].copy(), h[:, 2].copy(), h[:, 3:].copy()
    )
