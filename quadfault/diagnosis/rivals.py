"""Rival explanations compared as whole sets, and the held-out support of every accepted effect.

Several effect sets explain nearly the same signal: a weak rotor and the vehicle's own
imbalance (a centre-of-mass offset with its yaw trim, and a thrust factor common to every
rotor), a mass change and a thrust scale, a motor lag and a delay, drag, wind and blade
flapping (:data:`RIVALS`), and any two effects the selection found trading along one direction
on this flight (:func:`~quadfault.diagnosis.select.trade_off`). Forward selection lets
whichever enters first win; so after it, for every accepted effect that has rivals, the
accepted set and the set with the rival **in its place** (not on top of it) are each fitted
jointly, from the same starts, and cross-validated on the same folds
(:class:`RivalComparison`):

* one set wins only when its held-out advantage over the other is significant: its gain
  at least ``MIN_ADVANTAGE`` (1 %) and the lower end of its 95 % interval (the segment
  bootstrap of :meth:`~quadfault.diagnosis.scores.Scoring.channel_table`) above 0; the model
  then holds the winner, and the loser is rejected with the figure. A weak rotor and the
  vehicle's imbalance -- the pair a healthy airframe confuses most -- are held to the bar
  every effect meets on top of a model (a gain of ``min_improvement`` overall or three times
  that in one channel, its interval above 0), and the imbalance is judged as fitted, even
  at a bound;
* otherwise the flight cannot tell them apart: both sets are reported together
  (``indistinguishable``, each with its fitted parameters and the figure that could not
  separate them, and what would separate them), and neither is named alone in ``effects``;
  the model holds the set with the lower held-out error.

Extra information decides where there is some: measured rotor speeds are channels of the
held-out score (the rotor side of a weak rotor, the lag against the delay), and with flights
of the healthy vehicle (``--baseline``) the weak rotor is measured against them, not against
the imbalance.

Then every accepted effect must earn its place held out (:func:`supported`), judged
conditional on the rest of the accepted set: the model without it, refitted, must be worse
on the same folds (gain positive, 95 % interval above 0). An effect that also improves the
held-out fit alone on the nominal model (at its values in the model fitted without each fold,
:func:`alone_at_folds`, or refitted alone) needs no more; one that does not -- another
unmodelled effect cancels its signal on the nominal model, as a weak rotor's moment can a
rate damping's -- must beat the model without it by the bar every effect meets on top of a
model (a gain of ``min_improvement``, or three times that in one channel, its interval above
0). An effect that fails is removed and the model refitted.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from quadfault.diagnosis.crossval import CrossValidation, Gain, fit_at_bound, gain_over, held_out
from quadfault.diagnosis.library import predict
from quadfault.diagnosis.select import Selection, Step, Verdict
from quadfault.model.effects.blade_flapping import BladeFlapping
from quadfault.model.effects.com_offset import ComOffset
from quadfault.model.effects.delay import Delay
from quadfault.model.effects.drag import Drag
from quadfault.model.effects.mass import Mass
from quadfault.model.effects.motor_efficiency import MotorEfficiency
from quadfault.model.effects.motor_lag import MotorLag
from quadfault.model.effects.thrust_scale import ThrustScale
from quadfault.model.effects.wind import Wind

#: rival explanations of one signal: each row lists alternative effect sets; the first member
#: of a set is its key (a set is in the model when its key is), and the sentence says what
#: would separate them
RIVALS = (
    (
        ((MotorEfficiency.name,), (ComOffset.name, ThrustScale.name)),
        "measured rotor speeds, a flight of the healthy vehicle (--baseline HEALTHY.json), or "
        "manoeuvres that load the rotors unequally (roll, pitch and yaw steps at several "
        "thrust levels)",
    ),
    (
        ((Mass.name,), (ThrustScale.name,)),
        "a weighed mass, or a flight at several thrust levels with angular manoeuvres (a "
        "thrust factor changes the moments, a mass does not)",
    ),
    (
        ((MotorLag.name,), (Delay.name,)),
        "measured rotor speeds, or sharp command steps logged fast",
    ),
    (
        ((Drag.name,), (Wind.name,), (BladeFlapping.name,)),
        "legs flown at several airspeeds and headings (drag grows with airspeed, a steady "
        "wind does not; blade flapping grows with thrust)",
    ),
)
#: what separates two effects that trade on this flight (a pair outside :data:`RIVALS`)
TRADING = "manoeuvres that excite the two differently, or a channel that sees one and not the other"


@dataclass(frozen=True, eq=False)
class RivalSet:
    """One explanation: its effects' fit and held-out result (the other accepted effects
    fitted with it)."""

    names: tuple
    fit: object
    cv: CrossValidation

    def terms_of(self, names) -> list:
        return [(c, x) for c, x in self.fit.terms if c.name in names]


@dataclass(frozen=True, eq=False)
class RivalComparison:
    """The accepted set against the same set with a rival in place of ``held``.

    Attributes:
        held, rival: the two explanations (:class:`RivalSet`), the held one as accepted.
        gain: held-out :class:`~quadfault.diagnosis.crossval.Gain` of the rival over the held;
            back: of the held over the rival.
        outcome: ``"held"``, ``"rival"`` (significantly better) or ``"tie"``.
        separate_by: what would separate them.
    """

    held: RivalSet
    rival: RivalSet
    gain: Gain
    back: Gain
    outcome: str
    separate_by: str

    def gain_of(self, second: RivalSet) -> Gain:
        """The held-out gain of ``second`` over the other set."""
        return self.gain if second is self.rival else self.back

    @property
    def sets(self) -> tuple:
        """The two explanations in a fixed order (the order of :data:`RIVALS`), so the
        report does not depend on which one the search met first."""
        a, b = self.held, self.rival
        return (a, b) if _rank(a.names) <= _rank(b.names) else (b, a)

    @property
    def winner(self) -> RivalSet:
        return self.rival if self.outcome == "rival" else self.held

    @property
    def loser(self) -> RivalSet:
        return self.held if self.outcome == "rival" else self.rival


def _rank(names) -> tuple:
    for i, (sets, _) in enumerate(RIVALS):
        for j, s in enumerate(sets):
            if tuple(names) == s:
                return (i, j)
    return (len(RIVALS), 0, tuple(names))


#: the least held-out gain of one rival set over the other that can decide between them
#: [-] (below it the segment bootstrap's interval is not to be trusted to its last digit)
MIN_ADVANTAGE = 0.01


def significant(g: Gain) -> bool:
    """A held-out advantage that is significant: positive with its 95 % interval above 0."""
    return g.gain > 0.0 and g.lo > 0.0


def decisive(g: Gain) -> bool:
    """A rival set's held-out advantage that decides: significant and at least
    ``MIN_ADVANTAGE``."""
    return significant(g) and g.gain >= MIN_ADVANTAGE


class Rivals:
    """The rival comparisons and the support check of one selection (module docstring) on a
    recording (``replay``, fixed ``scoring``, ``folds``) with its ``library`` (the candidates
    the rivals are drawn from), against the bar ``m``."""

    def __init__(self, replay, scoring, folds, library, m: float, allowed=None):
        """``library``: every candidate a rival may be drawn from (the whole library, also
        when the user restricted the search); ``allowed``: the names the model may hold
        (the user's library; None: all). A rival outside ``allowed`` that wins is not put
        in the model: the effect it beats is rejected."""
        self.replay, self.scoring, self.folds, self.m = replay, scoring, folds, m
        self.library = {c.name: c for c in library if c.testable(replay)}
        self.allowed = None if allowed is None else set(allowed)

    # rivals -----------------------------------------------------------------------------
    def rows(self, accepted: list, selection: Selection) -> list:
        """``[(held names, rival names, separate_by), ...]`` for the accepted names."""
        out = []
        for sets, why in RIVALS:
            held = next((s for s in sets if s[0] in accepted), None)
            if held is None:
                continue
            held = tuple(n for n in held if n in accepted)
            for s in sets:
                if s[0] in accepted or not all(n in self.library for n in s):
                    continue
                if self._baseline(s) or self._baseline(held):
                    continue  # the healthy flights measure the weak rotor
                out.append((held, s, why))
        for name, v in selection.verdicts.items():  # pairs that trade on this flight
            traded = getattr(v, "trades_with", "")
            if traded in accepted and name in self.library:
                pair = ((traded,), (name,))
                known = [{n for one in sets for n in one} for sets, _ in RIVALS]
                if not any({traded, name} <= names for names in known):
                    out.append((pair[0], pair[1], TRADING))
        return out

    def _baseline(self, names) -> bool:
        return any(getattr(self.library[n], "baseline", ()) for n in names if n in self.library)

    def _start(self, name, selection: Selection):
        f = selection.alone.get(name)
        c = self.library[name]
        return (c, np.asarray(f.x[0] if f is not None else c.starts[0], dtype=float))

    def fit_set(
        self, others: list, names, selection: Selection, any_bound: bool = True
    ) -> RivalSet | None:
        """``names`` fitted jointly with the terms ``others`` (started from their values; the
        new effects from their fits alone), cross-validated. Another effect the rival pushes
        to a bound is left out of the rival's model (the rival explains that part of the
        signal too). None when they cannot be in one model, or when the fit puts a parameter
        of ``names`` at a bound (not an alternative the data can hold)."""
        new = [self._start(n, selection) for n in names]
        cands = [c for c, _ in others]
        if any(not c.compatible(cands + [o for o, _ in new if o is not c]) for c, _ in new):
            return None
        others = list(others)
        while True:
            cv, f = held_out(self.replay, self.scoring, others + new, self.folds)
            at = [
                j for j in range(len(f.candidates)) if fit_at_bound(self.replay, self.scoring, f, j)
            ]
            if not at:
                return RivalSet(tuple(names), f, cv)
            if any(j >= len(others) for j in at):
                if not any_bound:  # judged as fitted: its bound is part of what it says
                    return RivalSet(tuple(names), f, cv)
                return None
            others = [t for j, t in enumerate(others) if j not in at]

    def compare(self, selection: Selection) -> tuple[Selection, list]:
        """``(selection with the winners in its model, [RivalComparison, ...])``."""
        comparisons = []
        done = set()
        while selection.final is not None:
            accepted = [s.candidate.name for s in selection.steps]
            rows = [
                r
                for r in self.rows(accepted, selection)
                if (frozenset(r[0]), frozenset(r[1])) not in done
            ]
            if not rows:
                break
            held_names, rival_names, why = rows[0]
            done.add((frozenset(held_names), frozenset(rival_names)))
            terms = list(selection.final.terms)
            others = [(c, x) for c, x in terms if c.name not in held_names]
            held_terms = [(c, x) for c, x in terms if c.name in held_names]
            cv_h, f_h = held_out(self.replay, self.scoring, others + held_terms, self.folds)
            held = RivalSet(held_names, f_h, cv_h)
            weak = MotorEfficiency.name in held_names + rival_names
            rival = self.fit_set(others, rival_names, selection, any_bound=not weak)
            if rival is None:
                continue
            g = gain_over(self.replay, self.scoring, held.cv, rival.cv, self.m)
            back = gain_over(self.replay, self.scoring, rival.cv, held.cv, self.m)
            wins = (lambda x: x.passes) if weak else decisive
            outcome = "rival" if wins(g) else "held" if wins(back) else "tie"
            comp = RivalComparison(held, rival, g, back, outcome, why)
            comparisons.append(comp)
            allowed = self.allowed is None or set(rival_names) <= self.allowed
            if outcome == "rival" and not allowed:  # the user left the winner out
                verdicts = dict(selection.verdicts)
                for c, _ in held.terms_of(held_names):
                    verdicts[c.name] = _rival_verdict(c, comp, rival)
                for c in [c for c, _ in held.terms_of(held_names)]:
                    selection = self._drop(selection, c, verdicts)
            elif allowed and (
                outcome == "rival" or (outcome == "tie" and rival.cv.sse < held.cv.sse)
            ):
                selection = self._swap(selection, comp, rival)
                done.add((frozenset(rival_names), frozenset(held_names)))
            if outcome == "held":
                verdicts = dict(selection.verdicts)
                for c, _ in rival.terms_of(rival.names):
                    verdicts[c.name] = _rival_verdict(c, comp, held)
                selection = dataclasses.replace(selection, verdicts=verdicts)
        return selection, comparisons

    def _swap(self, selection: Selection, comp: RivalComparison, into: RivalSet) -> Selection:
        """``selection`` with the model of ``into`` (the rival set in place of the held)."""
        out_names = set(comp.held.names if into is comp.rival else comp.rival.names)
        in_fit = {c.name for c in into.fit.candidates}
        verdicts = dict(selection.verdicts)
        for s in selection.steps:  # left out of the rival's model (at a bound)
            name = s.candidate.name
            if name not in out_names and name not in in_fit:
                f = selection.final
                j = [c.name for c in f.candidates].index(name)
                verdicts[name] = Verdict(
                    s.candidate,
                    "suspect",
                    f"at a bound beside {' + '.join(into.names)}, which explains the flight "
                    "better or as well: the data asks for more than this effect allows",
                    f,
                    np.asarray(f.x[j]),
                    np.asarray(f.sd[j]),
                    selection.final_cv,
                )
        steps = [
            s
            for s in selection.steps
            if s.candidate.name not in out_names and s.candidate.name in in_fit
        ]
        kept = {s.candidate.name for s in steps}
        g = comp.gain if into is comp.rival else None
        for c, _ in into.fit.terms:
            if c.name not in kept:
                steps.append(Step(c, into.fit, into.cv, float(g.gain if g else 0.0)))
        order = {c.name: i for i, (c, _) in enumerate(into.fit.terms)}
        steps.sort(key=lambda s: order[s.candidate.name])
        verdicts = {k: v for k, v in verdicts.items() if k not in order}
        if comp.outcome == "rival":
            for c, _ in comp.held.terms_of(comp.held.names):
                verdicts[c.name] = _rival_verdict(c, comp, into)
        return dataclasses.replace(
            selection, steps=tuple(steps), final=into.fit, final_cv=into.cv, verdicts=verdicts
        )

    # support ----------------------------------------------------------------------------
    def supported(self, selection: Selection, keep=()) -> Selection:
        """``selection`` without the accepted effects the held-out data does not support
        (module docstring); the names in ``keep`` are judged as one set (rivals the flight
        cannot tell apart: one of them is there)."""
        while selection.final is not None:
            terms = list(selection.final.terms)
            why, gains = "", {}
            for c, x in terms:
                if c.name in keep:
                    continue
                why, gains[c.name] = self._unsupported(c, x, terms, selection)
                if why:
                    break
            if not why:  # each kept effect's step: its gain over the model without it
                steps = tuple(
                    dataclasses.replace(st, improvement_step=gains[st.candidate.name], dropped=True)
                    if st.candidate.name in gains
                    else st
                    for st in selection.steps
                )
                return dataclasses.replace(selection, steps=steps)
            verdicts = dict(selection.verdicts)
            j = [o for o, _ in terms].index(c)
            verdicts[c.name] = Verdict(
                c,
                "rejected",
                why,
                selection.final,
                np.asarray(x),
                selection.final.sd[j],
                selection.final_cv,
                in_set=True,
            )
            selection = self._without(selection, c, verdicts)
        return selection

    def within_bounds(self, selection: Selection) -> Selection:
        """``selection`` without the accepted effects its final joint fit leaves at a bound
        that matters (:func:`~quadfault.diagnosis.crossval.fit_at_bound`): they become
        suspects (the data asks for more than the effect allows), and the model is
        refitted without them."""
        while selection.final is not None:
            f = selection.final
            j = next(
                (
                    j
                    for j in range(len(f.candidates))
                    if fit_at_bound(self.replay, self.scoring, f, j)
                ),
                None,
            )
            if j is None:
                return selection
            c = f.candidates[j]
            verdicts = dict(selection.verdicts)
            verdicts[c.name] = Verdict(
                c,
                "suspect",
                "at a bound in the final model (refitted with the other accepted effects): "
                "the data asks for more than this effect allows; a missing effect is likely",
                f,
                np.asarray(f.x[j]),
                np.asarray(f.sd[j]),
                selection.final_cv,
            )
            selection = self._without(selection, c, verdicts)
        return selection

    def _drop(self, selection: Selection, c, verdicts) -> Selection:
        if selection.final is None or c not in selection.final.candidates:
            return dataclasses.replace(selection, verdicts=verdicts)
        return self._without(selection, c, verdicts)

    def _without(self, selection: Selection, c, verdicts) -> Selection:
        """``selection`` with ``c`` out of the model (refitted) and the ``verdicts``."""
        rest = [(o, y) for o, y in selection.final.terms if o is not c]
        steps = [s for s in selection.steps if s.candidate is not c]
        if rest:
            cv, f = held_out(self.replay, self.scoring, rest, self.folds)
            order = {o.name: i for i, (o, _) in enumerate(rest)}
            steps = sorted(steps, key=lambda s: order[s.candidate.name])
        else:
            cv, f = selection.baseline, None
        return dataclasses.replace(
            selection, steps=tuple(steps), final=f, final_cv=cv, verdicts=verdicts
        )

    def _unsupported(self, c, x, terms, selection: Selection) -> tuple[str, float]:
        """``(why c is not supported or "", its held-out gain over the model without it)``."""
        rest = [(o, y) for o, y in terms if o is not c]
        if rest:
            cv, _ = held_out(self.replay, self.scoring, rest, self.folds)
        else:
            cv = selection.baseline
        g = gain_over(self.replay, self.scoring, cv, selection.final_cv, self.m)
        if not significant(g):
            return (
                f"not supported held out: the model without {c.name} (refitted) is as good "
                f"(gain of {c.name} {g.gain:.1%}, 95% interval from {g.lo:.1%})"
            ), g.gain
        j = [o for o, _ in terms].index(c)
        fold_x = [fx[j] for fx in selection.final_cv.fold_x]
        alone = [alone_at_folds(self.replay, self.scoring, self.folds, c, fold_x)]
        alone.append(held_out(self.replay, self.scoring, [(c, x)], self.folds)[0].sse)
        f = selection.alone.get(c.name)
        if f is not None:
            alone.append(held_out(self.replay, self.scoring, [(c, f.x[0])], self.folds)[0].sse)
        if min(alone) >= selection.baseline.sse and not g.passes:
            names = ", ".join(o.name for o, _ in rest)
            return (
                f"no held-out gain on its own: {c.name} alone does not improve the nominal "
                f"model held out, and beside {names} it adds {g.gain:.1%} (95% interval from "
                f"{g.lo:.1%}), under the bar an effect meets on top of a model"
            ), g.gain
        return "", g.gain


def alone_at_folds(replay, scoring, folds, c, fold_x) -> float:
    """Held-out SSE of the nominal model plus ``c`` alone at its values in a model fitted
    without each fold (``fold_x``: per fold, its parameter vector), each fold predicted
    with the values fitted without it."""
    res = np.array(replay.measured, dtype=float)
    for idx, x in zip(folds, fold_x):
        res[idx] = replay.measured[idx] - predict(replay, [(c, x)])[idx]
    return scoring.sse(res)


def _rival_verdict(c, comp: RivalComparison, winner: RivalSet) -> Verdict:
    loser = comp.held if winner is comp.rival else comp.rival
    f = loser.fit
    j = [o.name for o in f.candidates].index(c.name)
    g = comp.gain_of(winner)
    return Verdict(
        c,
        "rejected",
        rival_reason(c, f.x[j], winner.names, g, tie=False),
        f,
        np.asarray(f.x[j]),
        np.asarray(f.sd[j]),
        loser.cv,
        in_set=True,
    )


def tie_verdict(c, comp: RivalComparison) -> Verdict:
    """The ``rejected`` reading of an effect of a tied comparison (neither set accepted)."""
    own = comp.held if c.name in comp.held.names else comp.rival
    other = comp.rival if own is comp.held else comp.held
    j = [o.name for o in own.fit.candidates].index(c.name)
    g = comp.gain_of(other)
    return Verdict(
        c,
        "rejected",
        rival_reason(c, own.fit.x[j], other.names, g, tie=True),
        own.fit,
        np.asarray(own.fit.x[j]),
        np.asarray(own.fit.sd[j]),
        own.cv,
        in_set=True,
    )


#: what one flight cannot tell (the weak rotor's reason)
ONE_FLIGHT = (
    "one flight cannot tell a weak rotor from the vehicle's own imbalance (a centre-of-mass "
    "offset, a tilted motor); a flight of the healthy vehicle (--baseline HEALTHY.json) can"
)


def rival_reason(c, x, other, g: Gain, tie: bool) -> str:
    """Why ``c`` (fitted at ``x`` in its own set) is not accepted beside its rival set
    ``other``, whose held-out gain over it is ``g``."""
    names = " + ".join(other)
    figure = f"held-out gain {g.gain:.1%}, 95% interval from {g.lo:.1%}"
    if tie:
        text = (
            f"{names} in its place explains the held-out data as well ({figure} over it): "
            "indistinguishable on this flight (see indistinguishable)"
        )
    else:
        text = f"{names} in its place fits the held-out data significantly better ({figure})"
    if c.name == MotorEfficiency.name and ComOffset.name in other:
        rel = np.asarray(c.relative(np.asarray(x, dtype=float)), dtype=float)
        k = int(np.argmin(rel))
        return (
            f"vehicle imbalance: rotor {k + 1} looks weakest ({rel[k]:.2f} of the median "
            f"rotor), but {text}; {ONE_FLIGHT}"
        )
    return text
