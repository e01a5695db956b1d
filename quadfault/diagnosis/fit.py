"""Bounded robust least squares of a set of library effects (the optimizer).

The residual vector is the normalised block residual ``(measured - model) / scale`` over the
blocks in ``mask`` and all channels; ``scipy.optimize.least_squares`` (trust-region
reflective, bounds from the library) minimises it with the ``soft_l1`` loss so dropouts and
spikes have bounded influence. One-sigma uncertainties come from the Jacobian at the optimum,
``sd = sqrt(diag(s^2 (J^T J)^-1))`` with ``s^2`` the residual variance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

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
    """

    candidates: tuple
    x: tuple
    sd: tuple
    sse: float
    n: int
    status: int = 0
    message: str = ""
    n_fixed: int = 0

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
        out.append(np.asarray(x[i:i + c.size], dtype=float))
        i += c.size
    return out


def _clip_inside(x, lo, hi):
    span = hi - lo
    return np.clip(x, lo + 1e-9 * span, hi - 1e-9 * span)


def residual_vector(rp: Replay, terms, scale: np.ndarray, mask) -> np.ndarray:
    return ((rp.measured[mask] - predict(rp, terms)[mask]) / scale).ravel()


def fit(rp: Replay, candidates: list[Candidate], scale: np.ndarray, mask=None, init=None,
        loss: str = "soft_l1", f_scale: float = 2.0, max_nfev: int = 30,
        fixed=()) -> Fit:
    """Fit ``candidates`` jointly on the blocks in ``mask`` (all by default).

    ``init`` gives start vectors (None entries: the candidate's own start guesses, the best
    of which by cost is used). ``fixed`` terms ``[(cand, x), ...]`` are part of the model but
    not fitted (their parameters still count in :meth:`Fit.bic`).
    """
    fixed = list(fixed)
    cands = list(candidates)
    mask = np.ones(rp.n_blocks, dtype=bool) if mask is None else mask
    init = list(init) if init is not None else [None] * len(cands)
    lo = np.concatenate([c.lower for c in cands])
    hi = np.concatenate([c.upper for c in cands])
    # pick starting guesses of the new candidates by cost (others keep their values)
    x = []
    for c, xi in zip(cands, init):
        x.append(np.asarray(c.starts[0] if xi is None else xi, dtype=float))
    for j, (c, xi) in enumerate(zip(cands, init)):
        if xi is not None or len(c.starts) == 1:
            continue
        best, best_cost = x[j], np.inf
        for s in c.starts:
            trial = x[:j] + [np.asarray(s, dtype=float)] + x[j + 1:]
            r = residual_vector(rp, fixed + list(zip(cands, trial)), scale, mask)
            cost = float(np.sum(np.log1p(r * r / f_scale ** 2)))
            if cost < best_cost:
                best, best_cost = np.asarray(s, dtype=float), cost
        x[j] = best
    x0 = _clip_inside(np.concatenate(x), lo, hi)

    def fun(xv):
        return residual_vector(rp, fixed + list(zip(cands, _split(xv, cands))), scale, mask)

    res = least_squares(fun, x0, bounds=(lo, hi), loss=loss, f_scale=f_scale,
                        max_nfev=max_nfev * len(x0), x_scale="jac", method="trf")
    r = res.fun
    n, p = r.size, len(res.x)
    s2 = float(r @ r) / max(n - p, 1)
    J = res.jac
    try:
        cov = s2 * np.linalg.pinv(J.T @ J)
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        sd = np.full(p, np.nan)
    return Fit(tuple(cands), tuple(_split(res.x, cands)), tuple(_split(sd, cands)),
               float(r @ r), n, int(res.status), str(res.message),
               sum(c.size for c, _ in fixed))
