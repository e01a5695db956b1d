"""Effect selection: greedy forward search with time-blocked cross-validation and BIC.

At each step every remaining candidate is fitted jointly with the effects accepted so far on
all blocks and ranked by BIC; the best ``screen_top`` are cross-validated on ``folds``
contiguous time segments (fit on the other segments, predict the held-out one). The best is
accepted only if it lowers the held-out residual RMS by at least ``min_improvement``
(relative to the current model) -- or by three times that in one of the channels it acts on
(fitted signal above the noise), so that an effect is still found when other, unexplained
channels dominate the total -- *and* lowers BIC by more than ``bic_margin``. Up to
``screen_top`` candidates are tried in BIC order; the search stops when none passes.
Equivalent pairs (``thrust_scale`` / ``motor_efficiency``) are never both accepted.
Effects in ``IV_CHECKED`` (``inertia``) must also pass an instrumental-variable check against
closed-loop feedback bias (:func:`iv_slope`). Held-out errors count only the scored blocks
(calibration rows excluded, ``Replay.scored``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from quadfault.diagnosis.fit import Fit, Linearisation, _split, fit, linearisation, solve_linear
from quadfault.diagnosis.library import Candidate, predict
from quadfault.diagnosis.residuals import Replay

EXCLUSIVE = {"thrust_scale": "motor_efficiency", "motor_efficiency": "thrust_scale"}


@dataclass(frozen=True, eq=False)
class CrossValidation:
    """Held-out result of one effect set.

    Attributes:
        residual: held-out block residual (B, 6) in channel units (each block predicted by the
            fit that did not see its fold).
        sse: sum of squared normalised held-out residuals over the scored blocks (calibration
            blocks excluded, ``Replay.scored``).
        fold_x: parameter vectors of each fold's fit.
    """

    residual: np.ndarray
    sse: float
    fold_x: tuple = ()


@dataclass(frozen=True, eq=False)
class Step:
    """One accepted effect."""

    candidate: Candidate
    fit: Fit
    cv: CrossValidation
    improvement_step: float  # held-out RMS reduction relative to the previous model
    rivals: dict = field(default_factory=dict)  # name -> in-sample SSE ratio to the winner
    iv: float | None = None  # instrumental-variable slope (IV_CHECKED effects)


@dataclass(frozen=True, eq=False)
class Selection:
    baseline: CrossValidation
    steps: tuple
    final: Fit | None
    final_cv: CrossValidation
    screening: tuple  # (name, bic) of the last screening round


def x_terms(cands, xs) -> list:
    return list(zip(cands, xs))


def folds_of(n_blocks: int, k: int) -> list[np.ndarray]:
    k = max(2, min(k, n_blocks // 5))
    return np.array_split(np.arange(n_blocks), k)


#: Effects that must pass the instrumental-variable check. Every effect is regressed on
#: closed-loop commands and states: within a block the controller reacts to the block's own
#: thrust noise, so an effect that reweights commands in time (lag, delay) or scales the
#: response (inertia, efficiency) can fit that reaction instead of physics -- on a 1 kHz
#: effect-free flight with thrust noise 0.05, least squares "finds" a 0.07 s motor lag.
IV_CHECKED = frozenset({"motor_efficiency", "thrust_scale", "ground_effect", "delay", "motor_lag",
                        "drag", "wind", "com_offset", "inertia", "blade_flapping", "rotor_inertia",
                        "battery_thrust", "thrust_curve", "mass", "rate_damping"})
IV_Z = 2.0  # the IV slope must be this many standard errors above 0
#: least held-out gain of an effect whose signal the instrument cannot predict at all
IV_UNVERIFIED_GAIN = 0.5
IV_MIN = 0.5  # least IV slope (1: the fitted signal is all real, 0: all feedback bias)


def iv_slope(rp: Replay, before, after, scale, residual, channels) -> tuple[float, float]:
    """Instrumental-variable slope of ``residual`` (B, 6, normalised) on the fitted signal
    (the model change from the terms ``before`` to the terms ``after``, e.g. a candidate fitted
    jointly with the accepted effects) over ``channels``, and its standard error.

    The instrument is the same signal on the :func:`frozen_replay`, which knows only what
    happened before each block began, so it is blind to the block's own process noise and to
    the controller's reaction to it: ``sum(z r) / sum(z s)`` is ~1 when the fitted signal is
    real and ~0 when least squares fitted that reaction (closed-loop feedback bias). Only the
    channels of ``channels`` in which the instrument predicts the signal (``sum(z s) > 0``)
    count; NaN when there are none."""
    ch = np.asarray(channels, dtype=int)
    if ch.size == 0:
        return float("nan"), float("nan")
    sig = (predict(rp, list(after)) - predict(rp, list(before))) / scale
    fr = frozen_replay(rp)
    z = (predict(fr, list(after)) - predict(fr, list(before))) / scale
    ch = ch[np.sum(z[:, ch] * sig[:, ch], axis=0) > 0]  # channels the instrument predicts
    if ch.size == 0:
        return float("nan"), float("nan")
    den = float(np.sum(z[:, ch] * sig[:, ch]))  # > 0: a sum of positive channel terms
    beta = float(np.sum(z[:, ch] * residual[:, ch])) / den
    u = residual[:, ch] - beta * sig[:, ch]
    return beta, float(np.sqrt(np.sum((z[:, ch] * u) ** 2))) / den


def frozen_replay(rp: Replay) -> Replay:
    """``rp`` with every block's inputs replaced by what was known when the block began.

    The state (``p, v, R, w``) of a block's first row holds over the block; the command is
    the first row's command extrapolated linearly with its rate of change over the recording
    row just before the block (no trend at the start of a run). Intervals outside blocks keep
    their inputs. Cached on ``rp``.

    A model signal computed on it depends only on what happened before each block started
    (the first command was chosen from the state at the block's start), so it is blind to the
    block's own process noise and to the controller's reaction to it -- the instrument of
    :func:`iv_slope`. It keeps an effect's memory (a lag's carried-over thrust, a delay's
    earlier commands) and the trajectory-driven part of the commands."""
    fr = rp.__dict__.get("_frozen")
    if fr is not None:
        return fr
    ok = np.flatnonzero(rp.block >= 0)
    blk = rp.block[ok]
    heads = np.r_[0, np.flatnonzero(np.diff(blk)) + 1]
    start = ok[heads]  # first interval of each block (blocks are numbered in time order)
    first = np.arange(len(rp.dt))
    first[ok] = start[blk]
    src = rp.starts or {"f": rp.f, "p": rp.p, "v": rp.v, "R": rp.R, "w": rp.w}
    f0, t0 = src["f"][start], rp.t[start]  # command and time at each block's first row
    # trend: the command's rate of change over the last recording row before the block
    rows_f, rows_t = (rp.raw["f"], rp.raw["t"]) if rp.raw is not None else (rp.f, rp.t)
    k0 = rp.knots[start] if rp.raw is not None else start
    trend = np.zeros_like(f0)
    cont = np.r_[False, rp.block_run[1:] == rp.block_run[:-1]]
    kc = k0[cont]
    trend[cont] = (rows_f[kc] - rows_f[kc - 1]) / (rows_t[kc] - rows_t[kc - 1])[:, None]

    def commands(t_rows, block_of_row, own):
        out = own.copy()
        inside = block_of_row >= 0
        b = block_of_row[inside]
        out[inside] = f0[b] + (t_rows[inside] - t0[b])[:, None] * trend[b]
        return out

    raw = rp.raw
    if raw is not None:
        seg = raw["seg"]
        raw = dict(raw, f=commands(raw["t"][:-1], rp.block[seg], raw["f"]))
        f = np.asarray(raw["merge"] @ raw["f"])
    else:
        f = commands(rp.t[:-1], rp.block, src["f"])
    take = (lambda a: None if a is None else a[first])
    fr = replace(rp, f=f, p=take(src["p"]), v=take(src["v"]), R=take(src["R"]), w=take(src["w"]),
                 raw=raw)
    object.__setattr__(rp, "_frozen", fr)
    return fr


def scored_rows(rp: Replay) -> np.ndarray:
    """Blocks held-out scores use (all but calibration blocks, see ``Replay.scored``)."""
    return np.ones(rp.n_blocks, dtype=bool) if rp.scored is None else rp.scored


def scored_sse(rp: Replay, residual, scale) -> float:
    z = residual[scored_rows(rp)] / scale
    return float(np.sum(z * z))


def cross_validate(rp: Replay, cands, scale, x_init, folds, *, full: Fit | None = None,
                   fixed=(), **kw) -> CrossValidation:
    """Time-blocked cross-validation of ``cands`` (on top of ``fixed``).

    The effects are first fitted on all blocks (``full``, or a fit started from ``x_init``);
    each fold's fit is then the bounded robust least-squares solution of the model linearised
    at that optimum (:class:`~quadfault.diagnosis.fit.Linearisation`: exact for affine effect
    sets, one Gauss-Newton step otherwise), and the held-out blocks are predicted by the exact
    model at the fold's parameters. One replay per fold instead of a nonlinear fit per fold.
    """
    fixed = list(fixed)
    if not cands:
        res = rp.measured - predict(rp, fixed)
        return CrossValidation(res, scored_sse(rp, res, scale), ())
    cands = list(cands)
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
    return CrossValidation(res, scored_sse(rp, res, scale), tuple(fold_x))


def select(rp: Replay, library: list[Candidate], scale: np.ndarray, *, folds: int = 5,
           max_effects: int = 3, min_improvement: float = 0.05, bic_margin: float = 10.0,
           screen_top: int = 3, progress=None) -> Selection:
    fl = folds_of(rp.n_blocks, folds)
    baseline = cross_validate(rp, [], scale, [], fl)
    n = rp.measured.size
    current: list[Candidate] = []
    x_cur: list = []
    cur_cv = baseline
    cur_bic = n * np.log(float(np.sum((baseline.residual / scale) ** 2)) / n)  # in-sample
    steps = []
    final = None
    screening = ()
    for _ in range(max_effects):
        chosen = {c.name for c in current}
        pool = [c for c in library if c.name not in chosen and EXCLUSIVE.get(c.name) not in chosen
                and not chosen & set(c.excludes) and not any(c.name in o.excludes for o in current)
                and c.testable(rp)]
        if not pool:
            break
        fits = []
        fixed = list(zip(current, x_cur))
        for c in pool:  # screening: the new effect alone on top of the current model
            f = fit(rp, [c], scale, fixed=fixed)
            fits.append((f.bic(), c, f))
            if progress is not None:
                progress()
        fits.sort(key=lambda item: item[0])
        screening = tuple((c.name, b) for b, c, _ in fits)
        best = None
        # cross-validate, in BIC order, the candidates that lower BIC enough; keep the one
        # with the lowest held-out error among those that pass the acceptance test
        cur_pred = predict(rp, x_terms(current, x_cur))
        for b, c, f in [item for item in fits if item[0] < cur_bic - bic_margin][:screen_top]:
            if current:  # joint refit of the candidate with the accepted effects
                f = fit(rp, current + [c], scale, init=x_cur + list(f.x))
                b = f.bic()
            if b > cur_bic - bic_margin:
                continue
            cv = cross_validate(rp, current + [c], scale, None, fl, full=f)
            gain = 1.0 - np.sqrt(cv.sse / cur_cv.sse)
            # channels the effect acts on (fitted signal above the noise): a real effect must
            # clearly improve those, even when unexplained channels dominate the total
            sig = (predict(rp, x_terms(current, x_cur) + list(f.terms)[-1:]) - cur_pred) / scale
            touched = np.sqrt(np.mean(sig ** 2, axis=0)) >= 1.0
            gain_touched = 0.0
            if touched.any():  # best held-out gain among the channels the effect acts on
                rows = scored_rows(rp)
                before = np.sum((cur_cv.residual[rows] / scale)[:, touched] ** 2, axis=0)
                after = np.sum((cv.residual[rows] / scale)[:, touched] ** 2, axis=0)
                gain_touched = float(np.max(1.0 - np.sqrt(after / before)))
            if gain < min_improvement and gain_touched < 3 * min_improvement:
                continue
            iv = None
            if c.name in IV_CHECKED:  # feedback bias: the signal must survive an IV check
                iv, iv_se = iv_slope(rp, x_terms(current, x_cur), f.terms, scale,
                                            (rp.measured - cur_pred) / scale,
                                            np.flatnonzero(touched) if touched.any() else [3, 4, 5])
                if not np.isfinite(iv):
                    if gain < IV_UNVERIFIED_GAIN:
                        continue  # the instrument cannot vouch for it: it must explain more
                # the fitted signal must be significantly real (slope above 0) and mostly
                # real (slope at least IV_MIN): a weak instrument widens the first test only
                elif not (iv >= IV_MIN and iv - IV_Z * iv_se > 0.0):
                    continue
            if best is None or cv.sse < best[3].sse:
                best = (b, c, f, cv, gain, iv)
        if best is None:
            break
        b, c, f, cv, gain, iv = best
        rivals = {rc.name: rf.sse / max(f.sse, 1e-300) for _, rc, rf in fits if rc is not c}
        steps.append(Step(c, f, cv, float(gain), rivals, iv))
        current.append(c)
        x_cur = list(f.x)
        cur_cv, cur_bic, final = cv, b, f
    return Selection(baseline, tuple(steps), final, cur_cv, screening)
