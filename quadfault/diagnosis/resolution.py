"""When an effect is evidence, and not a time constant the log cannot resolve.

A motor lag or a delay shorter than two command periods is below what a recording resolves
(:mod:`~quadfault.diagnosis.identifiability`): its fit is rejected. Its signal is still in
the residual, though, and another effect can take part of it up. In closed loop the
commanded rotor moments carry the controller's fast reactions; a lag of a few milliseconds
attenuates and delays them, and an inertia scaled up (a frequency-independent gain below 1
on the angular response) fits the attenuated part -- a fraction of what the lag explains, but
enough, held out, to be accepted without this check.

So when, in a round of the selection, a timing candidate's fit on top of the accepted
effects is shorter than its floor and lowers BIC by more than the margin (the data asks for
a time constant the log cannot resolve, :func:`unresolved`), every option without a timing
effect must add to that time constant held at most at the floor (:func:`beats_unresolved`):
on the same held-out folds, the option with the time constant must beat the accepted effects
with the time constant alone by the bar every effect meets on top of a model (a held-out
gain of ``min_improvement`` overall or three times that in one channel, its 95 % interval
above 0). Else the log cannot tell the option's effect from the time constant, and the
diagnosis names both (``indistinguishable``) instead of one.

An effect that is there besides the lag (a true inertia error: a gain at every frequency,
which no lag of a few milliseconds gives) adds to it and passes; the same test in the other
direction is the identifiability rule itself (a time constant shorter than the floor is
never accepted).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from quadfault.diagnosis.crossval import gain_over, held_out
from quadfault.diagnosis.identifiability import TIMING_SAMPLES, too_short
from quadfault.effects.registry import identifiability


@dataclass(frozen=True, eq=False)
class Unresolved:
    """A time constant the data asks for below what the log resolves.

    Attributes:
        candidate: the timing candidate (``motor_lag`` or ``delay``) bounded above by the
            floor (its parameter at most ``floor``).
        x: its fitted value on top of the accepted effects [s].
        floor: the shortest time constant the log's commands resolve [s].
    """

    candidate: object
    x: np.ndarray
    floor: float

    @property
    def name(self) -> str:
        return self.candidate.name

    def describe(self) -> str:
        return (f"a {self.name} of {1000 * float(self.x[0]):.1f} ms, shorter than the "
                f"{TIMING_SAMPLES:g} command periods ({1000 * self.floor:.1f} ms) the log "
                "resolves")


def is_timing(cand) -> bool:
    return identifiability(cand.name).timescale is not None


def unresolved(singles, cur_bic: float, margin: float) -> Unresolved | None:
    """From one round's screening fits ``[(bic, candidate, fit), ...]`` (best BIC first), the
    best timing candidate when it lowers BIC by more than ``margin`` with a fit shorter than
    its floor; None otherwise (also when the best time constant is one the log resolves)."""
    for b, c, f in singles:
        if b >= cur_bic - margin:
            break
        if not is_timing(c):
            continue
        if too_short(c, f.x[0]):
            floor = float(c.resolvable)
            upper = np.minimum(np.asarray(c.upper, dtype=float), floor)
            lower = np.minimum(np.asarray(c.lower, dtype=float), upper)
            starts = tuple(tuple(np.clip(s, lower, upper)) for s in c.starts)
            bounded = dataclasses.replace(c, lower=tuple(lower), upper=tuple(upper),
                                          starts=starts, resolvable=0.0)
            return Unresolved(bounded, np.clip(np.asarray(f.x[0], dtype=float), lower, upper),
                              floor)
        return None
    return None


class TimingCheck:
    """The check of one selection round (module docstring): its base model -- the accepted
    effects with the unresolved time constant -- is fitted and cross-validated once, when
    the first option needs it."""

    def __init__(self, rp, sc, folds, terms, un: Unresolved | None, m: float):
        self.rp, self.sc, self.folds, self.terms, self.un, self.m = rp, sc, folds, terms, un, m
        self._base = None

    def why_not(self, opt, new) -> str:
        """Why the option ``opt`` (joint ``fit``; its new candidates ``new``) adds nothing
        to the unresolved time constant, or ""."""
        un = self.un
        if un is None or not new or any(is_timing(c) for c in new):
            return ""
        if self._base is None:
            self._base, _ = held_out(self.rp, self.sc, self.terms + [(un.candidate, un.x)],
                                     self.folds)
        cv, _ = held_out(self.rp, self.sc, list(opt.fit.terms) + [(un.candidate, un.x)],
                         self.folds)
        g = gain_over(self.rp, self.sc, self._base, cv, self.m)
        if g.passes:
            return ""
        names = " + ".join(c.name for c in new)

        def pct(v):
            return f"{round(v, 3) + 0.0:.1%}"  # no "-0.0%"

        return (f"indistinguishable in this log from {un.describe()}: with that time "
                f"constant {names} improves the held-out fit by only {pct(g.gain)} (best "
                f"channel {pct(g.best)}, 95% interval from {pct(g.lo)}); a log with faster "
                "commands or measured rotor speeds could tell them apart")
