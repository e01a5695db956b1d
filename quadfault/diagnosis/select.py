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
   than ``bic_margin``; significance by held-out likelihood over the flight: the held-out
   gain (5 contiguous folds, fixed weights) positive with its 95 % interval above 0; a
   held-out RMS lower by at least ``min_improvement`` relative to the current model, or by
   three times that in one channel the option acts on (its fitted signal above the noise);
   the instrumental-variable
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

The search stops when no option passes or ``max_effects`` are accepted. Rival explanations
of the accepted effects are then compared as whole sets (:mod:`~quadfault.diagnosis.rivals`). An effect that
contains another (``Candidate.excludes``: ``motor_efficiency`` and ``thrust_curve`` contain
``thrust_scale``) is never accepted with it. Every candidate that was
fitted and not accepted keeps the reason it last failed.
"""

from __future__ import annotations

import dataclasses
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
    gain_over,
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
    "ForwardSelection",
    "Selection",
    "SelectionSettings",
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
        iv: instrumental-variable slope (None if not tested); iv_se: its standard error.
        agreement: fold-agreement detail ("" if not tested).
        like: the time constant below the log's resolution it cannot be told from
            (:class:`~quadfault.diagnosis.resolution.Unresolved`), or None.
        trades_with: the accepted effect it trades with on this flight
            (:func:`trade_off`), or "".
        in_set: judged within a set fitted after the search (a rival explanation, the
            final model): its ``fit`` is reported, not its fit alone.
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
    trades_with: str = ""
    in_set: bool = False
    iv_se: float | None = None


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
    dropped: bool = False  # improvement_step: the gain over the final model without it


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


@dataclass(frozen=True)
class SelectionSettings:
    """The selection's thresholds (:class:`~quadfault.diagnosis.diagnose.DiagnosisConfig`
    documents each)."""

    folds: int = 5
    max_effects: int = 3
    min_improvement: float = 0.05
    bic_margin: float = 10.0
    screen_top: int = 3
    pair_top: int = PAIR_TOP


@dataclass(eq=False)
class _Option:
    """One effect (or pair) tried on top of the current model, and how its tests went."""

    cands: list
    fit: Fit
    bic: float
    cv: CrossValidation | None = None
    gain: float = 0.0
    iv: float | None = None
    iv_se: float | None = None
    failed: str = ""
    agreement: dict = field(default_factory=dict)
    like: Unresolved | None = None
    trades_with: str = ""


@dataclass(frozen=True, eq=False)
class _Model:
    """The model a round starts from: the accepted candidates, their values, the joint fit
    (None before the first acceptance), its held-out result, in-sample BIC and prediction."""

    cands: list
    x: list
    fit: Fit | None
    cv: CrossValidation
    bic: float
    prediction: np.ndarray

    @property
    def terms(self) -> list:
        return x_terms(self.cands, self.x)


class _Round:
    """One round of the search (module docstring, steps 1-4) on top of ``model``."""

    def __init__(self, search: ForwardSelection, model: _Model, singles: list):
        self.search, self.model, self.singles = search, model, singles
        self.options: list[_Option] = []
        self._single_cv: dict = {}

    # options --------------------------------------------------------------------------
    def build_options(self) -> None:
        """The best single candidates and the pairs among the best (module docstring)."""
        s, m = self.search.settings, self.model
        rp, scale = self.search.replay, self.search.scoring.divisor
        good = [b for b in self.singles if b[0] < m.bic - s.bic_margin][: s.screen_top]
        for _b, c, f in good:
            if m.cands:  # joint refit of the candidate with the accepted effects
                f = fit(rp, m.cands + [c], scale, init=m.x + list(f.x))
            self.options.append(_Option(m.cands + [c], f, f.bic()))
        if len(m.cands) + 2 <= s.max_effects:
            for (ba, a, fa), (_, b, fb) in itertools.combinations(self.singles[: s.pair_top], 2):
                if not a.compatible([b]) or ba >= m.bic - s.bic_margin:
                    continue  # (singles are in BIC order: the better one must lower BIC)
                f = fit(rp, m.cands + [a, b], scale, init=m.x + list(fa.x) + list(fb.x))
                self.options.append(_Option(m.cands + [a, b], f, f.bic()))

    def single_cv(self, c) -> tuple:
        """Held-out result and fit of ``c`` alone on top of the accepted effects."""
        m, sr = self.model, self.search
        for o in self.options:
            if len(o.cands) == len(m.cands) + 1 and o.cands[-1] is c:
                if o.cv is None:
                    o.cv = cross_validate(
                        sr.replay, o.cands, sr.scoring, None, sr.folds, full=o.fit
                    )
                return o.cv, o.fit
        if c.name not in self._single_cv:
            f = next(s[2] for s in self.singles if s[1] is c)
            if m.cands:
                f = fit(sr.replay, m.cands + [c], sr.scoring.divisor, init=m.x + list(f.x))
            cv = cross_validate(sr.replay, m.cands + [c], sr.scoring, None, sr.folds, full=f)
            self._single_cv[c.name] = (cv, f)
        return self._single_cv[c.name]

    # tests ----------------------------------------------------------------------------
    def test(self, opt: _Option, timing: TimingCheck) -> None:
        """Run the acceptance tests of one option in order (module docstring); fills
        ``opt.cv``, ``gain``, ``iv``, ``agreement`` and, on the first failure, ``failed``
        (and ``like`` when it is the time constant the log cannot resolve)."""
        sr, m, s = self.search, self.model, self.search.settings
        if opt.bic > m.bic - s.bic_margin:
            opt.failed = f"BIC not lower by more than {s.bic_margin:g}"
            return
        opt.cv = cross_validate(sr.replay, opt.cands, sr.scoring, None, sr.folds, full=opt.fit)
        opt.gain = 1.0 - np.sqrt(opt.cv.sse / m.cv.sse)
        signal = self.signal(opt)
        new = list(enumerate(opt.cands[len(m.cands) :], start=len(m.cands)))
        opt.failed = (
            self.held_out(opt, signal)
            or self.pair(opt, new)
            or self.feedback(opt, signal)
            or self.bounds_and_trade(opt, new)
            or self.folds_agree(opt, new)
            or rotors_differ(sr.replay, sr.scoring, opt, m.cands, sr.folds, s.min_improvement)
        )
        if not opt.failed:
            opt.failed = timing.why_not(opt, [c for _, c in new])
            opt.like = timing.un if opt.failed else None

    def signal(self, opt: _Option) -> np.ndarray:
        """RMS of the option's fitted signal per channel, in noise units."""
        m, sr = self.model, self.search
        terms = m.terms + list(opt.fit.terms)[len(m.cands) :]
        sig = (predict(sr.replay, terms) - m.prediction) / sr.scoring.noise
        return np.sqrt(np.mean(sig**2, axis=0))

    def held_out(self, opt: _Option, signal) -> str:
        """Significance by held-out likelihood over the flight: the option's held-out gain
        positive with its 95 % interval above 0; and large enough to matter: at least
        ``min_improvement`` overall or three times that in one channel it acts on (its
        fitted signal there above the noise)."""
        sr, bar = self.search, self.search.settings.min_improvement
        sc, cur_cv = sr.scoring, self.model.cv
        g = gain_over(sr.replay, sc, cur_cv, opt.cv, bar)
        if not (g.gain > 0.0 and g.lo > 0.0):
            return (
                f"no significant held-out gain: {g.gain:.1%} (95% interval from {g.lo:.1%}; "
                f"best channel {g.best:.1%})"
            )
        touched = signal >= 1.0  # the channels it acts on
        gain_touched = 0.0
        if touched.any():  # best held-out gain among the channels the option acts on
            before = sc.channel_sse(cur_cv.residual)[touched]
            after = sc.channel_sse(opt.cv.residual)[touched]
            gain_touched = float(np.max(1.0 - np.sqrt(after / np.maximum(before, 1e-300))))
        if opt.gain < bar and gain_touched < 3 * bar:
            return (
                f"held-out gain {opt.gain:.1%} (best channel it acts on {gain_touched:.1%}) "
                f"below {bar:.0%} ({3 * bar:.0%} in a channel it acts on)"
            )
        return ""

    def pair(self, opt: _Option, new) -> str:
        """A pair must beat each of its members alone, and add to their single fits."""
        if len(new) != 2:
            return ""
        bar = self.search.settings.min_improvement
        for _, c in new:
            one, fit_one = self.single_cv(c)
            if np.sqrt(opt.cv.sse / one.sse) > 1.0 - bar:
                return f"the pair is not better than {c.name} alone by {bar:.0%}"
            moved = trade_off(fit_one, [c.name], opt.fit)
            if moved:
                return moved
        return ""

    def feedback(self, opt: _Option, signal) -> str:
        """The instrumental-variable check on the channels the option acts on."""
        sr, m = self.search, self.model
        rp, sc = sr.replay, sr.scoring
        touched = signal >= 1.0
        channels = np.flatnonzero(touched) if touched.any() else np.flatnonzero(signal > 0)
        opt.iv, opt.iv_se = iv_slope(
            rp,
            m.terms,
            opt.fit.terms,
            sc.divisor,
            (rp.measured - m.prediction) / sc.divisor,
            channels,
        )
        iv_se = opt.iv_se
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

    def bounds_and_trade(self, opt: _Option, new) -> str:
        rp, sc, m = self.search.replay, self.search.scoring, self.model
        short = next((w for w in (too_short(c, opt.fit.x[j]) for j, c in new) if w), "")
        if short:
            return short
        if any(fit_at_bound(rp, sc, opt.fit, j) for j, _ in new):
            return "at a bound"
        pushed = [c.name for j, c in enumerate(m.cands) if fit_at_bound(rp, sc, opt.fit, j)]
        if pushed:  # the joint refit drives an accepted effect to its bound
            return f"it pushes the accepted {pushed[0]} to a bound"
        if m.fit is None:
            return ""
        for c in m.cands:
            why = trade_off(m.fit, [c.name], opt.fit)
            if why:
                opt.trades_with = c.name
                return why
        return ""

    def folds_agree(self, opt: _Option, new) -> str:
        rp, sc = self.search.replay, self.search.scoring
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

    # outcome --------------------------------------------------------------------------
    def record_failures(self, verdicts: dict) -> list:
        """Write the verdict of every candidate whose option failed (singles first); return
        the options that passed."""
        rp, sc, n = self.search.replay, self.search.scoring, len(self.model.cands)
        passed, single_tested = [], set()
        for opt in sorted(self.options, key=lambda o: len(o.cands)):  # singles first
            new = opt.cands[n:]
            for j, c in enumerate(opt.cands):
                if c not in new or c.name in verdicts_final(verdicts):
                    continue
                if opt.failed == "at a bound" and fit_at_bound(rp, sc, opt.fit, j):
                    verdicts[c.name] = _verdict(c, "suspect", AT_BOUND, opt, j)
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
        return passed

    def best(self, passed: list) -> _Option:
        """The option with the lowest held-out error; a pair only when it beats the best
        single by ``min_improvement``."""
        n, bar = len(self.model.cands), self.search.settings.min_improvement
        one = [o for o in passed if len(o.cands) == n + 1]
        two = [o for o in passed if len(o.cands) == n + 2]
        best = min(one, key=lambda o: o.cv.sse) if one else None
        if two:
            pair = min(two, key=lambda o: o.cv.sse)
            if best is None or np.sqrt(pair.cv.sse / best.cv.sse) <= 1.0 - bar:
                best = pair
        return best


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


#: the reason of a suspect
AT_BOUND = (
    "improves the held-out fit only with a parameter at its bound: the data "
    "asks for more than this effect allows; a missing effect is likely"
)


class ForwardSelection:
    """Forward selection (module docstring) over the candidate ``library`` of one recording
    (its ``replay``), scored with its fixed ``scoring``
    (:class:`~quadfault.diagnosis.scores.Scoring`) under ``settings``.

    ``run()`` returns the :class:`Selection`; ``progress()`` is called after each screening
    fit."""

    def __init__(
        self,
        replay: Replay,
        library: list[Candidate],
        scoring,
        settings: SelectionSettings | None = None,
        progress=None,
    ):
        self.replay, self.scoring = replay, scoring
        self.settings = settings or SelectionSettings()
        self.library = list(library)
        self.progress = progress
        self.folds = folds_of(replay.n_blocks, self.settings.folds)

    def _model(self, cands, x, f, cv, bic) -> _Model:
        return _Model(list(cands), list(x), f, cv, bic, predict(self.replay, x_terms(cands, x)))

    def _screen(self, pool, model: _Model, last_x: dict, alone: dict) -> list:
        """Each candidate of ``pool`` fitted alone on top of ``model``, best BIC first;
        started from its last screening fit (the first round scans its start guesses)."""
        singles = []
        for c in pool:
            f = fit(
                self.replay,
                [c],
                self.scoring.divisor,
                fixed=model.terms,
                init=[last_x.get(c.name)],
            )
            singles.append((f.bic(), c, f))
            last_x[c.name] = f.x[0]
            if not model.cands:
                alone[c.name] = f
            if self.progress is not None:
                self.progress()
        singles.sort(key=lambda item: item[0])
        return singles

    def run(self) -> Selection:
        rp, sc, s = self.replay, self.scoring, self.settings
        baseline = cross_validate(rp, [], sc, [], self.folds)
        n = rp.measured.size
        bic0 = n * np.log(float(np.sum((baseline.residual / sc.divisor) ** 2)) / n)  # in-sample
        model = self._model([], [], None, baseline, bic0)
        steps, verdicts, alone, last_x = [], {}, {}, {}
        screening = ()
        lacks = None
        testable = [c for c in self.library if c.testable(rp)]
        while len(model.cands) < s.max_effects:
            chosen = {c.name for c in model.cands}
            pool = [
                c
                for c in testable
                if c.name not in chosen
                and c.name not in verdicts_final(verdicts)
                and c.compatible(model.cands)
            ]
            if not pool:
                break
            singles = self._screen(pool, model, last_x, alone)
            screening = tuple((c.name, b) for b, c, _ in singles)
            for b, c, f in singles:  # this round's reading, unless an option test says more
                verdicts[c.name] = Verdict(
                    c, "rejected", _screen_reason(b, model.bic, s), f, f.x[0], f.sd[0]
                )
            rnd = _Round(self, model, singles)
            rnd.build_options()
            timing = TimingCheck(
                rp,
                sc,
                self.folds,
                model.terms,
                unresolved(singles, model.bic, s.bic_margin),
                s.min_improvement,
            )
            for opt in rnd.options:
                rnd.test(opt, timing)
            lacks = below_resolution(
                rp, sc, rnd.options, len(model.cands), model.cv, s.min_improvement
            )
            passed = rnd.record_failures(verdicts)
            if not passed:
                break
            best = rnd.best(passed)
            n_cur = len(model.cands)
            for o in passed:
                if o is best:
                    continue
                for j, c in enumerate(o.cands[n_cur:], start=n_cur):
                    if c not in best.cands:
                        winners = " + ".join(x.name for x in best.cands[n_cur:])
                        verdicts[c.name] = _verdict(
                            c,
                            "rejected",
                            f"passed the tests, but {winners} fitted the held-out data better "
                            "and was accepted first",
                            o,
                            j,
                        )
            for c in best.cands[n_cur:]:
                rivals = {
                    rc.name: rf.sse / max(best.fit.sse, 1e-300)
                    for _, rc, rf in singles
                    if rc is not c
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
            model = self._model(best.cands, best.fit.x, best.fit, best.cv, best.bic)
            lacks = None  # judged against the model before this round's acceptance
        if len(model.cands) >= s.max_effects:  # not traded: the search had no room left
            for name, v in list(verdicts.items()):
                if v.reason.startswith("passed the tests"):
                    verdicts[name] = dataclasses.replace(
                        v, reason=f"{v.reason}; the search stopped at max_effects = {s.max_effects}"
                    )
        accepted = {st.candidate.name for st in steps}
        for c in testable:  # never screened (the search stopped) or still pending
            if c.name not in verdicts and c.name not in accepted and c.name in alone:
                f = alone[c.name]
                verdicts[c.name] = Verdict(
                    c, "rejected", "not reached: the search stopped", f, f.x[0], f.sd[0]
                )
        return Selection(
            baseline, tuple(steps), model.fit, model.cv, screening, alone, verdicts, lacks
        )


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
    """:class:`ForwardSelection` of ``library`` on ``rp`` with the fixed scoring ``sc``."""
    settings = SelectionSettings(
        folds, max_effects, min_improvement, bic_margin, screen_top, pair_top
    )
    return ForwardSelection(rp, library, sc, settings, progress).run()


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
        opt.trades_with,
        iv_se=opt.iv_se,
    )


def _screen_reason(b, cur_bic, settings: SelectionSettings) -> str:
    if b >= cur_bic - settings.bic_margin:
        return f"BIC not lower by more than {settings.bic_margin:g} on top of the accepted effects"
    return "ranked below the candidates cross-validated on top of the accepted effects"
