"""Bounded robust least squares of a set of library effects (the optimizer).

The residual vector is the normalised block residual ``(measured - model) / scale`` over the
blocks in ``mask`` and all channels, minimised with the ``soft_l1`` loss so dropouts and
spikes have bounded influence, within the library's bounds. Effect sets whose model is affine
in their parameters (:func:`is_affine`) are solved on a verified linear model of the replay
(:class:`Linearisation`, :func:`solve_linear`: iteratively reweighted least squares, the same
optimum as ``scipy.optimize.least_squares``); the others by ``scipy.optimize.least_squares``
(trust-region reflective) on the exact replay. One-sigma uncertainties come from the Jacobian
at the optimum, ``sd = sqrt(diag(s^2 (J^T J)^-1))`` with ``s^2`` the residual variance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares, lsq_linear

from quadfault.diagnosis.library import Candidate, predict
from quadfault.diagnosis.residuals import Replay


@dataclass(frozen=True, eq=False)
class Fit:
    """Fitted effects.

    Attributes:
        candidates: the effects, in fit order.
        x: parameter vector of each effect.
        sd: one-sigma uncertainty of each parameter.
        sse: sum of squared normalised residuals over the fitted blocks.
        n: number of residuals (blocks x channels).
        status, message: of the optimizer.
        n_fixed: parameters of the fixed terms (they count in :meth:`bic`).
        s2: residual variance ``sd`` was scaled with (``sd / sqrt(s2)`` is the geometry
            alone: how well the model's structure determines each parameter).
    """

    candidates: tuple
    x: tuple
    sd: tuple
    sse: float
    n: int
    status: int = 0
    message: str = ""
    n_fixed: int = 0
    s2: float = 1.0  # residual variance the uncertainties were scaled with

    @property
    def terms(self) -> list:
        return list(zip(self.candidates, self.x))

    @property
    def n_params(self) -> int:
        return sum(c.size for c in self.candidates) + self.n_fixed

    def bic(self) -> float:
        """Gaussian BIC ``n ln(SSE / n) + p ln n`` (normalised residuals)."""
        return self.n * np.log(max(self.sse, 1e-300) / self.n) + self.n_params * np.log(self.n)


def _split(x, cands):
    out, i = [], 0
    for c in cands:
        out.append(np.asarray(x[i : i + c.size], dtype=float))
        i += c.size
    return out


def _clip_inside(x, lo, hi):
    span = hi - lo
    return np.clip(x, lo + 1e-9 * span, hi - 1e-9 * span)


def residual_vector(rp: Replay, terms, scale: np.ndarray, mask) -> np.ndarray:
    return ((rp.measured[mask] - predict(rp, terms)[mask]) / scale).ravel()


def is_affine(cands) -> bool:
    """Whether the model is affine in the joint parameter vector of ``cands``: each is affine
    alone (``Candidate.affine``: the wrench is linear in the rotor thrusts, and every thrust
    stage is a linear operator on them), and no two multiply -- at most one thrust stage, and
    none with a wrench proportional to the thrust (``Candidate.uses_thrust``)."""
    cands = list(cands)
    if not all(c.affine for c in cands):
        return False
    n_thrust = sum(c.stage == "thrust" for c in cands)
    return n_thrust == 0 or (n_thrust == 1 and not any(c.uses_thrust for c in cands))


def _key(cands, fixed):
    return (
        tuple(c.name for c in cands),
        tuple((c.name, np.asarray(x, dtype=float).tobytes()) for c, x in fixed),
    )


class Linearisation:
    """Block-mean model channels ``P(x) ~ P(x0) + Phi (x - x0)`` (B, 6) of ``cands`` on top of
    the fixed terms ``fixed``.

    For an affine effect set (:func:`is_affine`) ``Phi`` is built from unit steps and checked
    against the exact model at one more point, so the surrogate *is* the model (to rounding)
    and least squares, cross-validation folds and screening all reuse it without replaying the
    recording again. Otherwise ``Phi`` is the forward-difference Jacobian at ``x0`` (used for
    the cross-validation folds, one Gauss-Newton step from the all-data optimum).

    Attributes:
        x0: linearisation point; base: ``P(x0)`` (B, 6); phi: (B, 6, p); exact: affine model.
    """

    def __init__(self, rp: Replay, cands, fixed, x0, exact: bool, scale=None):
        self.cands, self.fixed = list(cands), list(fixed)
        self.x0 = np.asarray(x0, dtype=float)
        lo = np.concatenate([c.lower for c in cands])
        hi = np.concatenate([c.upper for c in cands])
        span = hi - lo
        self.base = self.model(rp, self.x0)
        p = len(self.x0)
        self.phi = np.empty(self.base.shape + (p,))
        for j in range(p):
            h = (0.1 if exact else 1e-5) * span[j]
            if not exact and self.x0[j] + h > hi[j]:
                h = -h
            xj = self.x0.copy()
            xj[j] += h
            self.phi[..., j] = (self.model(rp, xj) - self.base) / h
        self.exact = False
        if exact:  # verify the affine structure at one more point (normalised units)
            xt = self.x0 + 0.05 * span * np.where(np.arange(p) % 2, -1.0, 1.0)
            err = self.model(rp, xt) - self.at(xt)
            ref = rp.floors() if scale is None else scale
            self.exact = bool(np.max(np.abs(err) / ref) < 1e-6)

    def model(self, rp, x):
        return predict(rp, self.fixed + list(zip(self.cands, _split(x, self.cands))))

    def at(self, x) -> np.ndarray:
        return self.base + self.phi @ (np.asarray(x, dtype=float) - self.x0)


def linearisation(rp: Replay, cands, fixed, x0, scale) -> Linearisation | None:
    """The verified affine model of ``cands`` over ``fixed`` (cached on ``rp``), or None."""
    if not is_affine(cands):
        return None
    cache = rp.__dict__.setdefault("_affine", {})
    key = _key(cands, fixed)
    lin = cache.get(key)
    if lin is None:
        if len(cache) > 256:
            cache.clear()
        lin = Linearisation(rp, cands, fixed, x0, exact=True, scale=scale)
        cache[key] = lin
    return lin if lin.exact else None


@dataclass(frozen=True, eq=False)
class LinearSolution:
    """Result of :func:`solve_linear` (the fields ``least_squares`` results have)."""

    x: np.ndarray
    fun: np.ndarray  # residuals at x
    jac: np.ndarray  # d fun / dx scaled by the loss as scipy does (J^T J ~ Hessian)
    status: int
    message: str


def solve_linear(
    lin: Linearisation,
    measured,
    scale,
    mask,
    x_start,
    lo,
    hi,
    loss="soft_l1",
    f_scale=2.0,
    iterations=200,
) -> LinearSolution:
    """Bounded robust least squares of the surrogate ``lin`` on the blocks in ``mask``.

    The residual ``r = z - A x`` is affine, so the ``soft_l1`` problem is convex; it is solved
    by iteratively reweighted least squares (weights ``(1 + (r / c)^2)^(-1/2)``, a
    majorise-minimise step that cannot increase the cost), each step a bounded least-squares
    problem of size p (``scipy.optimize.lsq_linear`` on the Cholesky factor of the weighted
    normal equations). Same optimum as ``scipy.optimize.least_squares`` with that loss.
    """
    A = (lin.phi[mask] / scale[None, :, None]).reshape(-1, lin.phi.shape[-1])
    z = ((measured - lin.base)[mask] / scale).ravel() + A @ lin.x0
    x = _clip_inside(np.asarray(x_start, dtype=float), lo, hi)
    p = len(x)
    status, message = 0, "iteration limit"
    for _ in range(iterations if loss == "soft_l1" else 1):
        r = z - A @ x
        w = 1.0 / np.sqrt(1.0 + (r / f_scale) ** 2) if loss == "soft_l1" else np.ones_like(r)
        Aw = A * w[:, None]
        if p < 3:  # BLAS' gemm/gemv on a (N, 1) operand is pathologically slow here
            H, g = np.einsum("ij,ik->jk", A, Aw), np.einsum("ij,i->j", Aw, z)
        else:
            H, g = A.T @ Aw, Aw.T @ z
        H[np.diag_indices(p)] += 1e-12 * max(float(np.max(np.diag(H))), 1e-300)
        try:
            x_new = np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            x_new = np.linalg.lstsq(H, g, rcond=None)[0]
        if np.any(x_new < lo) or np.any(x_new > hi):
            try:
                L = np.linalg.cholesky(H)
                x_new = lsq_linear(L.T, np.linalg.solve(L, g), bounds=(lo, hi), method="bvls").x
            except np.linalg.LinAlgError:
                x_new = np.clip(x_new, lo, hi)
        if np.array_equal(x_new, x):  # a fixed point: every further step repeats this one
            status, message = 1, "converged (fixed point)"
            break
        # converged: the step is far below the statistical uncertainty of every parameter
        sd = _pinv_diag_sqrt(H, 1e-300)
        step = np.max(np.abs(x_new - x) / np.maximum(sd, 1e-12 * (hi - lo)))
        x = x_new
        if step < 1e-4:
            status, message = 1, "converged"
            break
    r = z - A @ x
    if loss == "soft_l1":
        jscale = np.sqrt((1.0 + (r / f_scale) ** 2) ** -1.5)
    else:
        jscale = np.ones_like(r)
    return LinearSolution(x, r, -A * jscale[:, None], status, message)


def _pinv_diag_sqrt(M: np.ndarray, floor: float = 0.0) -> np.ndarray:
    """``sqrt(max(diag(pinv(M)), floor))`` of a normal matrix without overflow: ``pinv`` of
    ``M / c`` (c its largest entry) is ``c pinv(M)``; a matrix of a few subnormal numbers (a
    parameter without signal) gave ``1 / 1e-310`` inside ``pinv``. A zero matrix gives the
    floor, as ``pinv`` does."""
    c = float(np.max(np.abs(M))) if M.size else 0.0
    if not np.isfinite(c):  # as pinv does (it raises on NaN)
        return np.sqrt(np.maximum(np.diag(np.linalg.pinv(M)), floor))
    if not c > 0:
        return np.full(len(M), np.sqrt(floor))
    v = np.diag(np.linalg.pinv(M / c))
    return np.maximum(np.sqrt(np.maximum(v, 0.0)) / np.sqrt(c), np.sqrt(floor))


def fit(
    rp: Replay,
    candidates: list[Candidate],
    scale: np.ndarray,
    mask=None,
    init=None,
    loss: str = "soft_l1",
    f_scale: float = 2.0,
    max_nfev: int = 30,
    fixed=(),
) -> Fit:
    """Fit ``candidates`` jointly on the blocks in ``mask`` (all by default).

    ``init`` gives start vectors (None entries: the candidate's own start guesses, the best
    of which by cost is used). ``fixed`` terms ``[(cand, x), ...]`` are part of the model but
    not fitted (their parameters still count in :meth:`Fit.bic`). Affine effect sets are
    solved on their verified linear model (:class:`Linearisation`), others on the replay.
    """
    fixed = list(fixed)
    cands = list(candidates)
    mask = np.ones(rp.n_blocks, dtype=bool) if mask is None else mask
    init = list(init) if init is not None else [None] * len(cands)
    lo = np.concatenate([c.lower for c in cands])
    hi = np.concatenate([c.upper for c in cands])
    x = []
    for c, xi in zip(cands, init):
        x.append(np.asarray(c.starts[0] if xi is None else xi, dtype=float))
    lin = linearisation(rp, cands, fixed, _clip_inside(np.concatenate(x), lo, hi), scale)

    def resid(xv):
        if lin is not None:
            return ((rp.measured[mask] - lin.at(xv)[mask]) / scale).ravel()
        return residual_vector(rp, fixed + list(zip(cands, _split(xv, cands))), scale, mask)

    # pick starting guesses of the new candidates by cost (others keep their values)
    for j, (c, xi) in enumerate(zip(cands, init)):
        if xi is not None or len(c.starts) == 1:
            continue
        best, best_cost = x[j], np.inf
        for s in c.starts:
            trial = x[:j] + [np.asarray(s, dtype=float)] + x[j + 1 :]
            r = resid(np.concatenate(trial))
            cost = float(np.sum(np.log1p(r * r / f_scale**2)))
            if cost < best_cost:
                best, best_cost = np.asarray(s, dtype=float), cost
        x[j] = best
    x0 = _clip_inside(np.concatenate(x), lo, hi)
    if lin is not None:
        res = solve_linear(lin, rp.measured, scale, mask, x0, lo, hi, loss, f_scale)
    else:
        res = least_squares(
            resid,
            x0,
            bounds=(lo, hi),
            loss=loss,
            f_scale=f_scale,
            max_nfev=max_nfev * len(x0),
            x_scale="jac",
            method="trf",
        )
    r = res.fun
    n, p = r.size, len(res.x)
    s2 = float(r @ r) / max(n - p, 1)
    J = res.jac
    try:
        sd = np.sqrt(s2) * _pinv_diag_sqrt(J.T @ J)
    except np.linalg.LinAlgError:
        sd = np.full(p, np.nan)
    return Fit(
        tuple(cands),
        tuple(_split(res.x, cands)),
        tuple(_split(sd, cands)),
        float(r @ r),
        n,
        int(res.status),
        str(res.message),
        sum(c.size for c, _ in fixed),
        s2,
    )
