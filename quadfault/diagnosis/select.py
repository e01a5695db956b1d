"""Effect selection: forward search over single effects and pairs, held out, with BIC.

Each round:

1. **Screening**: every remaining candidate is fitted on top of the accepted effects (all
   blocks) and ranked by BIC. The first round's fits are each candidate alone on the nominal
   model (kept for the ``rejected`` list).
2. **Options**: the best ``screen_top`` candidates that lower BIC by more than ``bic_margin``,
   and -- while two more effects may be accepted -- every pair among the best ``pair_top``
   by BIC whose better member lowers BIC by that margin, fitted jointly (started from their
   single fits). Pairs let the search reach a
   model in which neither effect alone explains the residual (a payload: mass and inertia
   change together; a single ``wind`` fits the hover part of it better than either alone).
3. **Tests** of each option, refitted jointly with the accepted effects: BIC lower by more
   than ``bic_margin``; a fitted signal above the noise (root-sum-square over the channels
   of its RMS in noise units; else it is negligible); held-out RMS (5 contiguous folds, fixed weights) lower by at least
   ``min_improvement`` relative to the current model, or by three times that in one of the
   channels the option acts on (its fitted signal above the noise); the instrumental-variable
   check against closed-loop feedback bias (:mod:`~quadfault.diagnosis.feedback`); the fold
   agreement of every new effect (:func:`~quadfault.diagnosis.crossval.fold_agreement`);
   for a pair, a held-out RMS lower by ``min_improvement`` than each of its members alone;
   and for ``motor_efficiency``, a pattern the rotors' common factor or the vehicle's own
   imbalance does not explain as well (:mod:`~quadfault.diagnosis.rotors`); and, when the
   data asks for a motor lag or delay shorter than the log resolves, a gain over that time
   constant held at the limit of resolution (:mod:`~quadfault.diagnosis.resolution`: else
   the effect is indistinguishable from it in this log). When the search stops with such a
   time constant passing every test up to its resolution, ``Selection.unattributed`` says so
   (the model lacks a time constant the log cannot attribute).
4. An option that passes but has a parameter at a bound
   (:func:`~quadfault.diagnosis.crossval.at_bound`) is a **suspect**: the data asks for more
   than the effect allows, so another effect is likely missing; it is never accepted. Among
   the others the lowest held-out error wins, a pair only if its held-out RMS is lower than
   the best single's by ``min_improvement``. An option whose joint refit makes an accepted
   effect (or a pair member's single fit) much less certain (:func:`trade_off`) or pushes it
   to a bound fails: it would exchange, not add.

The search stops when no option passes or ``max_effects`` are accepted. An effect that
contains another (``Candidate.excludes``: ``motor_efficiency`` and ``thrust_curve`` contain
``thrust_scale``) is never accepted with it. Every candidate that was
fitted and not accepted keeps the reason it last failed.
"""

# The selection loop's helpers close over the loop's state and are called only within the
# iteration that defines them.
# ruff: noqa: B023

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from quadfault.diagnosis.crossval import (
    CrossValidation,
    cross_validate,
    fit_at_bound,
    fit_bound_mask,
    fold_agreement,
    folds_of,
)
from quadfault.diagnosis.feedback import IV_MIN, IV_UNVERIFIED_GAIN, IV_Z, frozen_replay, iv_slope
from quadfault.diagnosis.fit import Fit, fit
from quadfault.diagnosis.identifiability import too_short
from quadfault.diagnosis.library import Candidate, predict
from quadfault.diagnosis.residuals import Replay
from quadfault.diagnosis.resolution import (
    TimingCheck,
    Unattributed,
    Unresolved,
    below_resolution,
    unresolved,
)
from quadfault.diagnosis.rotors import rotors_differ

__all__ = [
    "Selection",
    "Step",
    "Verdict",
    "select",
    "frozen_replay",
    "iv_slope",
    "folds_of",
    "cross_validate",
    "CrossValidation",
]

PAIR_TOP = 3
INFLATION = 3.0


@dataclass(frozen=True, eq=False)
class Verdict:
    """What the selection concluded about one candidate it fitted.

    Attributes:
        candidate: the effect.
        status: ``"accepted"``, ``"suspect"`` or ``"rejected"``.
        reason: why (empty when accepted).
        fit: the fit it was judged with (jointly with the effects accepted before it).
        x: its parameter vector in ``fit``.
        sd: one-sigma uncertainty of ``x``.
        cv: the held-out result of that fit (None when it never got that far).
        gain: held-out RMS reduction when added to the model before it (None if not tested).
        iv: instrumental-variable slope (None if not tested).
        agreement: fold-agreement detail ("" if not tested).
        like: the time constant below the log's resolution it cannot be told from
            (:class:`~quadfault.diagnosis.resolution.Unresolved`), or None.
    """

    candidate: Candidate
    status: str
    reason: str
    fit: Fit
    x: np.ndarray
    sd: np.ndarray
    cv: CrossValidation | None = None
    gain: float | None = None
    iv: float | None = None
    agreement: str = ""
    like: Unresolved | None = None


@dataclass(frozen=True, eq=False)
class Step:
    """One accepted effect."""

    candidate: Candidate
    fit: Fit
    cv: CrossValidation
    improvement_step: float  # held-out RMS reduction relative to the previous model
    rivals: dict = field(default_factory=dict)  # name -> in-sample SSE ratio to the winner
    iv: float | None = None  # instrumental-variable slope
    agreement: str = ""


@dataclass(frozen=True, eq=False)
class Selection:
    baseline: CrossValidation
    steps: tuple
    final: Fit | None
    final_cv: CrossValidation
    screening: tuple  # (name, bic) of the last screening round
    alone: dict  # name -> Fit of the candidate alone on the nominal model (first round)
    verdicts: dict  # name -> Verdict of every candidate fitted and not accepted
    # a time constant below the resolution the final model lacks (the last round's), or None
    unattributed: Unattributed | None = None


def x_terms(cands, xs) -> list:
    return list(zip(cands, xs))


@dataclass(eq=False)
class _Option:
    cands: list
    fit: Fit
    bic: float
    cv: CrossValidation | None = None
    gain: float = 0.0
    iv: float | None = None
    failed: str = ""
    agreement: dict = field(default_factory=dict)
    like: Unresolved | None = None


def _signal(rp, sc, current, x_cur, opt, cur_pred) -> np.ndarray:
    """RMS of the option's fitted signal per channel, in noise units."""
    sig = (
        predict(rp, x_terms(current, x_cur) + list(opt.fit.terms)[len(current) :]) - cur_pred
    ) / sc.noise
    return np.sqrt(np.mean(sig**2, axis=0))


def _test(
    rp, sc, opt, current, x_cur, cur_cv, cur_bic, cur_pred, fl, kw, singles_cv, cur_fit, timing
):
    """Run the acceptance tests of one option in order (module docstring); fills
    ``opt.cv``, ``gain``, ``iv``, ``agreement`` and, on the first failure, ``failed``
    (and ``like`` when it is the time constant the log cannot resolve)."""
    if opt.bic > cur_bic - kw["bic_margin"]:
        opt.failed = f"BIC not lower by more than {kw['bic_margin']:g}"
        return
    opt.cv = cross_validate(rp, opt.cands, sc, None, fl, full=opt.fit)
    opt.gain = 1.0 - np.sqrt(opt.cv.sse / cur_cv.sse)
    signal = _signal(rp, sc, current, x_cur, opt, cur_pred)
    new = list(enumerate(opt.cands[len(current) :], start=len(current)))
    opt.failed = (
        _held_out(sc, opt, cur_cv, signal, kw["min_improvement"])
        or _pair(opt, new, singles_cv, kw["min_improvement"])
        or _feedback(rp, sc, opt, current, x_cur, cur_pred, signal)
        or _bounds_and_trade(rp, sc, opt, current, new, cur_fit)
        or _folds(rp, sc, opt, new)
        or rotors_differ(rp, sc, opt, current, fl, kw["min_improvement"])
    )
    if not opt.failed:
        opt.failed = timing.why_not(opt, [c for _, c in new])
        opt.like = timing.un if opt.failed else None


def _held_out(sc, opt, cur_cv, signal, m) -> str:
    if np.sqrt(np.sum(signal**2)) < 1.0:
        return "negligible: its fitted signal, over all channels, is below the noise"
    touched = signal >= 1.0  # the channels it acts on
    gain_touched = 0.0
    if touched.any():  # best held-out gain among the channels the option acts on
        before = sc.channel_sse(cur_cv.residual)[touched]
        after = sc.channel_sse(opt.cv.residual)[touched]
        gain_touched = float(np.max(1.0 - np.sqrt(after / np.maximum(before, 1e-300))))
    if opt.gain < m and gain_touched < 3 * m:
        return (
            f"held-out gain {opt.gain:.1%} (best channel {gain_touched:.1%}) below "
            f"{m:.0%} ({3 * m:.0%} in a channel it acts on)"
        )
    return ""


def _pair(opt, new, singles_cv, m) -> str:
    """A pair must beat each of its members alone, and add to their single fits."""
    if len(new) != 2:
        return ""
    for _, c in new:
        one, fit_one = singles_cv(c)
        if np.sqrt(opt.cv.sse / one.sse) > 1.0 - m:
            return f"the pair is not better than {c.name} alone by {m:.0%}"
        moved = trade_off(fit_one, [c.name], opt.fit)
        if moved:
            return moved
    return ""


def _feedback(rp, sc, opt, current, x_cur, cur_pred, signal) -> str:
    """The instrumental-variable check on the channels the option acts on."""
    touched = signal >= 1.0
    channels = np.flatnonzero(touched) if touched.any() else np.flatnonzero(signal > 0)
    opt.iv, iv_se = iv_slope(
        rp,
        x_terms(current, x_cur),
        opt.fit.terms,
        sc.divisor,
        (rp.measured - cur_pred) / sc.divisor,
        channels,
    )
    if not np.isfinite(opt.iv):
        if opt.gain < IV_UNVERIFIED_GAIN:
            return (
                "the instrumental-variable check cannot vouch for its signal and the "
                f"held-out gain is under {IV_UNVERIFIED_GAIN:.0%}"
            )
    elif not (opt.iv >= IV_MIN and opt.iv - IV_Z * iv_se > 0.0):
        return (
            f"instrumental-variable slope {opt.iv:.2f} +- {iv_se:.2f} (feedback bias; "
            f"needs >= {IV_MIN} and > {IV_Z:g} se above 0)"
        )
    return ""


def _bounds_and_trade(rp, sc, opt, current, new, cur_fit) -> str:
    short = next((w for w in (too_short(c, opt.fit.x[j]) for j, c in new) if w), "")
    if short:
        return short
    if any(fit_at_bound(rp, sc, opt.fit, j) for j, _ in new):
        return "at a bound"
    pushed = [c.name for j, c in enumerate(current) if fit_at_bound(rp, sc, opt.fit, j)]
    if pushed:  # the joint refit drives an accepted effect to its bound
        return f"it pushes the accepted {pushed[0]} to a bound"
    return "" if cur_fit is None else trade_off(cur_fit, [c.name for c in current], opt.fit)


def _folds(rp, sc, opt, new) -> str:
    for j, c in new:
        ok, detail = fold_agreement(
            c,
            opt.fit.x[j],
            [fx[j] for fx in opt.cv.fold_x],
            lambda xf, j=j: fit_bound_mask(rp, sc, opt.fit, j, xf),
        )
        opt.agreement[c.name] = detail
        if not ok:
            return f"{c.name}: the folds disagree ({detail})"
    return ""


def trade_off(before: Fit, names, after: Fit) -> str:
    """Why refitting the effects ``names`` of ``before`` together with new ones (``after``)
    would trade instead of add, or "".

    Each parameter's standard error from the fit's geometry alone (``sd / sqrt(s2)``, the
    Jacobian without the residual level) may grow by at most ``INFLATION`` (3x) when the new
    effects join: more, and the new effect and the old one move together along a direction
    the data cannot resolve (an efficiency falling on every rotor while a steady upward force
    carries the weight), so the joint fit is not evidence for the new effect."""
    for name in names:
        i = [c.name for c in before.candidates].index(name)
        j = [c.name for c in after.candidates].index(name)
        sd0 = np.asarray(before.sd[i], float) / np.sqrt(max(before.s2, 1e-300))
        sd1 = np.asarray(after.sd[j], float) / np.sqrt(max(after.s2, 1e-300))
        ratio = sd1 / np.maximum(sd0, 1e-300)
        k = int(np.argmax(ratio))
        if ratio[k] > INFLATION:
            c = before.candidates[i]
            return (
                f"{name} would become {ratio[k]:.0f}x less certain ({c.labels[k]}): the "
                "effects trade along a direction the data cannot resolve"
            )
    return ""


def select(
    rp: Replay,
    library: list[Candidate],
    sc,
    *,
    folds: int = 5,
    max_effects: int = 3,
    min_improvement: float = 0.05,
    bic_margin: float = 10.0,
    screen_top: int = 3,
    pair_top: int = PAIR_TOP,
    progress=None,
) -> Selection:
    """Forward selection (module docstring) with the fixed scoring ``sc``
    (:class:`~quadfault.diagnosis.scores.Scoring`)."""
    kw = {"bic_margin": bic_margin, "min_improvement": min_improvement}
    scale = sc.divisor
    fl = folds_of(rp.n_blocks, folds)
    baseline = cross_validate(rp, [], sc, [], fl)
    n = rp.measured.size
    current: list[Candidate] = []
    x_cur: list = []
    cur_cv = baseline
    cur_bic = n * np.log(float(np.sum((baseline.residual / scale) ** 2)) / n)  # in-sample
    steps, verdicts, alone, last_x = [], {}, {}, {}
    final = None
    screening = ()
    lacks = None
    testable = [c for c in library if c.testable(rp)]
    while len(current) < max_effects:
        chosen = {c.name for c in current}
        pool = [
            c
            for c in testable
            if c.name not in chosen
            and c.name not in verdicts_final(verdicts)
            and c.compatible(current)
        ]
        if not pool:
            break
        fixed = list(zip(current, x_cur))
        singles = []
        for c in pool:  # screening: the new effect alone on top of the current model
            # started from its last screening fit (the first round scans its start guesses)
            f = fit(rp, [c], scale, fixed=fixed, init=[last_x.get(c.name)])
            singles.append((f.bic(), c, f))
            last_x[c.name] = f.x[0]
            if not current:
                alone[c.name] = f
            if progress is not None:
                progress()
        singles.sort(key=lambda item: item[0])
        screening = tuple((c.name, b) for b, c, _ in singles)
        for b, c, f in singles:  # this round's reading, unless an option test says more
            verdicts[c.name] = Verdict(
                c, "rejected", _screen_reason(b, cur_bic, kw), f, f.x[0], f.sd[0]
            )
        cur_pred = predict(rp, x_terms(current, x_cur))
        options = []
        for _b, c, f in [s for s in singles if s[0] < cur_bic - bic_margin][:screen_top]:
            if current:  # joint refit of the candidate with the accepted effects
                f = fit(rp, current + [c], scale, init=x_cur + list(f.x))
            options.append(_Option(current + [c], f, f.bic()))
        if len(current) + 2 <= max_effects:
            for (ba, a, fa), (_, b, fb) in itertools.combinations(singles[:pair_top], 2):
                if not a.compatible([b]) or ba >= cur_bic - bic_margin:
                    continue  # (singles are in BIC order: the better one must lower BIC)
                f = fit(rp, current + [a, b], scale, init=x_cur + list(fa.x) + list(fb.x))
                options.append(_Option(current + [a, b], f, f.bic()))
        single_cv = {}

        def singles_cv(c):
            """Held-out result and fit of ``c`` alone on top of the accepted effects."""
            for o in options:
                if len(o.cands) == len(current) + 1 and o.cands[-1] is c:
                    if o.cv is None:
                        o.cv = cross_validate(rp, o.cands, sc, None, fl, full=o.fit)
                    return o.cv, o.fit
            if c.name not in single_cv:
                f = next(s[2] for s in singles if s[1] is c)
                if current:
                    f = fit(rp, current + [c], scale, init=x_cur + list(f.x))
                single_cv[c.name] = (cross_validate(rp, current + [c], sc, None, fl, full=f), f)
            return single_cv[c.name]

        timing = TimingCheck(
            rp,
            sc,
            fl,
            x_terms(current, x_cur),
            unresolved(singles, cur_bic, bic_margin),
            min_improvement,
        )
        for opt in options:
            _test(
                rp,
                sc,
                opt,
                current,
                x_cur,
                cur_cv,
                cur_bic,
                cur_pred,
                fl,
                kw,
                singles_cv,
                final,
                timing,
            )
        lacks = below_resolution(rp, sc, options, len(current), cur_cv, min_improvement)
        passed = []
        single_tested = set()
        for opt in sorted(options, key=lambda o: len(o.cands)):  # singles first
            new = opt.cands[len(current) :]
            for j, c in enumerate(opt.cands):
                if c not in new or c.name in verdicts_final(verdicts):
                    continue
                if opt.failed == "at a bound" and fit_at_bound(rp, sc, opt.fit, j):
                    verdicts[c.name] = _verdict(
                        c,
                        "suspect",
                        (
                            "improves the held-out fit only with a parameter at its bound: the data "
                            "asks for more than this effect allows; a missing effect is likely"
                        ),
                        opt,
                        j,
                    )
                elif opt.failed and (len(new) == 1 or c.name not in single_tested):
                    why = opt.failed
                    if why == "at a bound":
                        other = [o.name for o in new if o is not c]
                        why = f"fitted with {other[0]}, which sits at a bound"
                    elif len(new) == 2:
                        why = f"as a pair with {[o.name for o in new if o is not c][0]}: {why}"
                    verdicts[c.name] = _verdict(c, "rejected", why, opt, j)
                if len(new) == 1:
                    single_tested.add(c.name)
            if not opt.failed:
                passed.append(opt)
        if not passed:
            break
        one = [o for o in passed if len(o.cands) == len(current) + 1]
        two = [o for o in passed if len(o.cands) == len(current) + 2]
        best = min(one, key=lambda o: o.cv.sse) if one else None
        if two:
            pair = min(two, key=lambda o: o.cv.sse)
            if best is None or np.sqrt(pair.cv.sse / best.cv.sse) <= 1.0 - min_improvement:
                best = pair
        for o in passed:
            if o is not best:
                for j, c in enumerate(o.cands[len(current) :], start=len(current)):
                    if c not in best.cands:
                        verdicts[c.name] = _verdict(
                            c,
                            "rejected",
                            (
                                "passed the tests, but "
                                + " + ".join(x.name for x in best.cands[len(current) :])
                                + " fitted the held-out data better"
                            ),
                            o,
                            j,
                        )
        for _j, c in enumerate(best.cands[len(current) :], start=len(current)):
            rivals = {
                rc.name: rf.sse / max(best.fit.sse, 1e-300) for _, rc, rf in singles if rc is not c
            }
            steps.append(
                Step(
                    c,
                    best.fit,
                    best.cv,
                    float(best.gain),
                    rivals,
                    best.iv,
                    best.agreement.get(c.name, ""),
                )
            )
            verdicts.pop(c.name, None)
        current = list(best.cands)
        x_cur = list(best.fit.x)
        cur_cv, cur_bic, final = best.cv, best.bic, best.fit
        lacks = None  # judged against the model before this round's acceptance
    for c in testable:  # never screened (the search stopped) or still pending
        if (
            c.name not in verdicts
            and c.name not in {s.candidate.name for s in steps}
            and c.name in alone
        ):
            f = alone[c.name]
            verdicts[c.name] = Verdict(
                c, "rejected", "not reached: the search stopped", f, f.x[0], f.sd[0]
            )
    return Selection(baseline, tuple(steps), final, cur_cv, screening, alone, verdicts, lacks)


def verdicts_final(verdicts: dict) -> set:
    """Names that are out of the search for good (suspects)."""
    return {k for k, v in verdicts.items() if v.status == "suspect"}


def _verdict(c, status, reason, opt, j) -> Verdict:
    return Verdict(
        c,
        status,
        reason,
        opt.fit,
        np.asarray(opt.fit.x[j]),
        np.asarray(opt.fit.sd[j]),
        opt.cv,
        opt.gain if opt.cv is not None else None,
        opt.iv,
        opt.agreement.get(c.name, ""),
        opt.like,
    )


def _screen_reason(b, cur_bic, kw) -> str:
    if b >= cur_bic - kw["bic_margin"]:
        return f"BIC not lower by more than {kw['bic_margin']:g} on top of the accepted effects"
    return "ranked below the candidates cross-validated on top of the accepted effects"
