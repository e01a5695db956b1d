"""Time-blocked cross-validation of an effect set, and the rules that read its folds.

Folds are contiguous time segments of the blocks; each fold's fit sees the other folds only,
and predicts its own. Held-out errors are scored with the recording's fixed weights
(:mod:`quadfault.diagnosis.scores`).

Fold agreement (:func:`fold_agreement`): the leave-one-fold-out parameter vectors give a
jackknife standard error ``sd_j = sqrt((k - 1) / k * sum_i (x_ij - mean_j)^2)`` of every
parameter. An effect's folds agree when, for the parameter that departs most from the nominal
value in units of that error, the all-data departure is at least ``FOLD_Z`` (3) jackknife
standard errors, every fold departs to the same side, and no fold has that parameter at a
bound that matters (:func:`bound_mask`). A parameter the all-data fit leaves at a bound that
does not matter is never the one read. A fit that
one part of the flight asks for and another contradicts fails it.

At a bound (:func:`at_bound`): a parameter within ``BOUND_MARGIN`` (2 %) of the span of its
bounds from a bound that is not the effect's neutral value (``Candidate.x0``; a drag
coefficient at its lower bound 0 is "no drag on that axis", an inertia scale at 2 is "the
data asks for more than this effect allows") and, given the recording, whose part of the
model matters: putting the parameters at a bound back to their neutral values changes the
model's channels by more than the noise (root-sum-square over the channels of the RMS change
in noise units at least 1), or makes the fit over the whole flight worse (its weighted RMS
by ``BOUND_GAIN``, 1 %: a change below the noise in every sample that the flight as a whole
asks for); then each of them that does so alone is at a bound that matters (all of them when
only together). A
parameter
whose whole range hardly changes the model -- quadratic rate damping over a flight at low
rates, next to the linear term that carries the signal -- ends at a bound without the data
asking for anything.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from quadfault.diagnosis.fit import Fit, Linearisation, _split, fit, linearisation, solve_linear
from quadfault.diagnosis.library import predict
from quadfault.diagnosis.residuals import Replay

FOLD_Z = 3.0
BOUND_MARGIN = 0.02
#: a bound matters over the flight when the parameters at it, put back to neutral, make the
#: fit's weighted RMS over the flight this much worse [-]
BOUND_GAIN = 0.01


@dataclass(frozen=True, eq=False)
class CrossValidation:
    """Held-out result of one effect set.

    Attributes:
        residual: held-out block residual (B, C) in channel units (each block predicted by the
            fit that did not see its fold).
        sse: winsorised weighted sum of squares of the held-out residual over the scored
            blocks (:meth:`~quadfault.diagnosis.scores.Scoring.sse`).
        fold_x: per fold, the parameter vector of each effect (fit without that fold).
    """

    residual: np.ndarray
    sse: float
    fold_x: tuple = ()


def folds_of(n_blocks: int, k: int) -> list[np.ndarray]:
    k = max(2, min(k, n_blocks // 5))
    return np.array_split(np.arange(n_blocks), k)


def cross_validate(
    rp: Replay, cands, sc, x_init, folds, *, full: Fit | None = None, fixed=(), **kw
) -> CrossValidation:
    """Time-blocked cross-validation of ``cands`` (on top of ``fixed``) with the scoring
    ``sc``.

    The effects are first fitted on all blocks (``full``, or a fit started from ``x_init``);
    each fold's fit is then the bounded robust least-squares solution of the model linearised
    at that optimum (:class:`~quadfault.diagnosis.fit.Linearisation`: exact for affine effect
    sets, one Gauss-Newton step otherwise), and the held-out blocks are predicted by the exact
    model at the fold's parameters. One replay per fold instead of a nonlinear fit per fold.
    """
    fixed = list(fixed)
    if not cands:
        res = rp.measured - predict(rp, fixed)
        return CrossValidation(res, sc.sse(res), ())
    cands = list(cands)
    scale = sc.divisor
    if full is None:
        full = fit(rp, cands, scale, init=x_init, fixed=fixed, **kw)
    xs = np.concatenate(full.x)
    lo = np.concatenate([c.lower for c in cands])
    hi = np.concatenate([c.upper for c in cands])
    lin = linearisation(rp, cands, fixed, xs, scale)
    if lin is None:
        lin = Linearisation(rp, cands, fixed, xs, exact=False)
    res = np.empty_like(rp.measured)
    fold_x = []
    for idx in folds:
        mask = np.ones(rp.n_blocks, dtype=bool)
        mask[idx] = False
        sol = solve_linear(lin, rp.measured, scale, mask, xs, lo, hi)
        fold_x.append(tuple(_split(sol.x, cands)))
        pred = lin.at(sol.x) if lin.exact else lin.model(rp, sol.x)
        res[idx] = rp.measured[idx] - pred[idx]
    return CrossValidation(res, sc.sse(res), tuple(fold_x))


def held_out(rp: Replay, sc, terms, folds) -> tuple[CrossValidation, Fit]:
    """Fit the terms ``[(cand, x_start), ...]`` jointly (started from their ``x``) and
    cross-validate them on ``folds``: ``(held-out result, fit)``."""
    cands = [c for c, _ in terms]
    f = fit(rp, cands, sc.divisor, init=[np.asarray(x, dtype=float) for _, x in terms])
    return cross_validate(rp, cands, sc, None, folds, full=f), f


class Gain(NamedTuple):
    """How much a model beats another on the same held-out folds.

    Attributes:
        gain: ``1 - RMS(after) / RMS(before)`` over all channels (fixed weights) [-].
        best: the largest such gain of one channel [-].
        lo: lower end of the 95 % interval of ``gain`` (segment bootstrap) [-].
        passes: the bar every effect meets on top of a model: ``gain`` at least ``m`` or
            ``best`` at least ``3 m``, with ``lo`` above 0.
    """

    gain: float
    best: float
    lo: float
    passes: bool


def gain_over(rp: Replay, sc, before: CrossValidation, after: CrossValidation, m: float) -> Gain:
    """The held-out :class:`Gain` of ``after`` over ``before`` (same folds), against the
    bar ``m`` (``min_improvement``)."""
    table, (lo, _) = sc.channel_table(before.residual, after.residual, rp.block_dur[sc.rows])
    gain = 1.0 - float(np.sqrt(after.sse / max(before.sse, 1e-300)))
    best = max(v["improvement"] for v in table.values())
    return Gain(gain, best, lo, not (lo <= 0.0 or (gain < m and best < 3 * m)))


def _near_bound(cand, x) -> np.ndarray:
    """Per parameter: within ``BOUND_MARGIN`` of a bound that is not the neutral value."""
    x = np.asarray(x, dtype=float)
    if cand.pinned:  # fixed by direct evidence: its bounds only hold it there
        return np.zeros(x.shape, dtype=bool)
    lo, hi, x0 = (np.asarray(v, dtype=float) for v in (cand.lower, cand.upper, cand.x0))
    margin = BOUND_MARGIN * (hi - lo)
    tiny = 1e-9 * (hi - lo)
    low = (x <= lo + margin) & (np.abs(lo - x0) > tiny)
    high = (x >= hi - margin) & (np.abs(hi - x0) > tiny)
    return low | high


def bound_mask(cand, x, rp: Replay | None = None, sc=None, others=()) -> np.ndarray:
    """Per parameter of ``cand`` at ``x``: at (or within the margin of) a bound; with the
    replay ``rp`` and its scoring ``sc``, only where that parameter's part of the model (with
    the terms ``others``) is above the noise (module docstring)."""
    near = _near_bound(cand, x)
    if rp is None or not near.any():
        return near
    x = np.asarray(x, dtype=float)
    others = list(others)
    model = predict(rp, others + [(cand, x)])

    fit_sse = sc.sse(rp.measured - model)

    def matters(idx) -> bool:
        back = x.copy()
        back[idx] = np.asarray(cand.x0, dtype=float)[idx]
        other = predict(rp, others + [(cand, back)])
        change = (model - other) / sc.noise
        if np.sqrt(np.sum(np.mean(change**2, axis=0))) >= 1.0:
            return True
        # over the flight: a small change in every sample that the whole flight asks for
        return 1.0 - np.sqrt(fit_sse / max(sc.sse(rp.measured - other), 1e-300)) >= BOUND_GAIN

    idx = np.flatnonzero(near)
    if not matters(idx):  # all of them together below the noise
        return np.zeros_like(near)
    alone = np.array([matters([i]) for i in idx])
    near[idx] = alone if alone.any() else True  # together they matter
    return near


def at_bound(cand, x, rp: Replay | None = None, sc=None, others=()) -> bool:
    """Whether a parameter of ``cand`` at ``x`` sits at a bound that matters
    (:func:`bound_mask`)."""
    return bool(np.any(bound_mask(cand, x, rp, sc, others)))


def fit_bound_mask(rp: Replay, sc, f: Fit, j: int, x=None) -> np.ndarray:
    """:func:`bound_mask` for effect ``j`` of the fit ``f`` (at ``x``, default its fitted
    value), the fit's other effects at their fitted values."""
    terms = list(f.terms)
    x = terms[j][1] if x is None else x
    return bound_mask(f.candidates[j], x, rp, sc, terms[:j] + terms[j + 1 :])


def fit_at_bound(rp: Replay, sc, f: Fit, j: int, x=None) -> bool:
    return bool(np.any(fit_bound_mask(rp, sc, f, j, x)))


def fold_agreement(cand, x, fold_x, mask=None) -> tuple[bool, str]:
    """``(agree, detail)``: the fold-agreement rule of the module docstring for the effect
    ``cand`` fitted at ``x`` with the per-fold vectors ``fold_x`` (k, p); ``mask(x)`` gives
    the parameters at a bound that matters (default :func:`bound_mask` without the
    recording). The rule reads the one parameter that departs most; parameters the all-data
    fit leaves at a bound that does not matter are never that parameter (their spread says
    nothing)."""
    X = np.asarray(fold_x, dtype=float)
    x = np.asarray(x, dtype=float)
    k = len(X)
    if k < 2:
        return True, "one fold"
    mask = mask or (lambda xi: bound_mask(cand, xi))
    use = ~(_near_bound(cand, x) & ~mask(x))
    if not use.any():
        use[:] = True
    x0 = np.asarray(cand.x0, dtype=float)
    span = np.asarray(cand.upper, dtype=float) - np.asarray(cand.lower, dtype=float)
    sd = np.sqrt((k - 1) / k * np.sum((X - X.mean(axis=0)) ** 2, axis=0))
    sd = np.maximum(sd, 1e-12 * span)
    z = np.where(use, np.abs(x - x0) / sd, -1.0)
    j = int(np.argmax(z))
    label = cand.labels[j] if j < len(cand.labels) else f"parameter {j}"
    same_side = bool(np.all(np.sign(X[:, j] - x0[j]) == np.sign(x[j] - x0[j])))
    bound_folds = int(sum(bool(mask(xi)[j]) for xi in X))
    size = "every fold gives the same value" if z[j] > 1e6 else f"{z[j]:.1f} jackknife sd"
    detail = (
        f"folds: {label} departs from nominal by {size} (needs {FOLD_Z:g})"
        + ("" if same_side else ", folds on both sides of nominal")
        + (f", {bound_folds} of {k} folds at a bound" if bound_folds else "")
    )
    return bool(z[j] >= FOLD_Z and same_side and bound_folds == 0), detail
