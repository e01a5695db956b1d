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

When the search stops with such a time constant still asked for -- its fit passes every test
an effect meets before the resolution check (BIC, held-out gain, instrumental variables) and
beats the final model on held-out data by the bar of every effect (:func:`below_resolution`)
-- the model does not match the flight, though the log cannot say which time constant is
missing: the diagnosis reports it (:meth:`Unattributed.entry`) and its verdict is not
``consistent``, and the time constant is still not accepted.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from quadfault.diagnosis.crossval import Gain, gain_over, held_out
from quadfault.diagnosis.identifiability import TIMING_SAMPLES, too_short
from quadfault.model.effects.registry import EFFECT_NAMES, identifiability


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
        return (
            f"a {self.name} of {1000 * float(self.x[0]):.1f} ms, shorter than the "
            f"{TIMING_SAMPLES:g} command periods ({1000 * self.floor:.1f} ms) the log "
            "resolves"
        )


def is_timing(cand) -> bool:
    return identifiability(cand.name).timescale is not None


def _pct(v) -> str:
    return f"{round(v, 3) + 0.0:.1%}"  # no "-0.0%"


@dataclass(frozen=True, eq=False)
class Unattributed:
    """A time constant below the resolution that the final model lacks (module docstring).

    Attributes:
        unresolved: the time constant (its best timing candidate and fit).
        gain: its held-out :class:`~quadfault.diagnosis.crossval.Gain` over the final model.
    """

    unresolved: Unresolved
    gain: Gain

    def entry(self) -> dict:
        """The ``indistinguishable`` entry: every timing effect of the library, the best fit
        first, with the reason and the figures (``held_out``)."""
        un, g = self.unresolved, self.gain
        names = [un.name] + [
            n for n in EFFECT_NAMES if n != un.name and identifiability(n).timescale is not None
        ]
        rate = TIMING_SAMPLES / un.floor
        x = float(un.x[0])
        return {
            "names": names,
            "reason": (
                f"a time constant below the resolution ({1000 * x:.1f} ms as a "
                f"{un.name}; commands at {rate:.0f} Hz resolve "
                f"{1000 * un.floor:.1f} ms and up) explains {_pct(g.gain)} of the "
                f"held-out residual (best channel {_pct(g.best)}, 95% interval "
                f"from {_pct(g.lo)}): the model does not match the flight, but "
                f"this log cannot tell {' from '.join(names)} or measure it; "
                "faster commands or measured rotor speeds would tell which, and how long"
            ),
            "held_out": {
                "time_constant_s": x,
                "shortest_time_constant_s": un.floor,
                "command_rate_hz": rate,
                "improvement": g.gain,
                "best_channel": g.best,
                "ci95_low": g.lo,
            },
        }


def below_resolution(rp, sc, options, n_current: int, cur_cv, m: float) -> Unattributed | None:
    """Of one round's tested options, the single timing option that failed only because its
    fit is shorter than the floor (every test before that one passed) and beats the current
    model held out by the bar ``m`` of every effect (largest gain first); None otherwise."""
    best = None
    for opt in options:
        new = opt.cands[n_current:]
        if len(new) != 1 or not is_timing(new[0]) or opt.cv is None:
            continue
        x = np.asarray(opt.fit.x[n_current], dtype=float)
        if not opt.failed or opt.failed != too_short(new[0], x):
            continue
        g = gain_over(rp, sc, cur_cv, opt.cv, m)
        if g.passes and (best is None or g.gain > best.gain.gain):
            best = Unattributed(Unresolved(new[0], x, float(new[0].resolvable)), g)
    return best


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
            bounded = dataclasses.replace(
                c, lower=tuple(lower), upper=tuple(upper), starts=starts, resolvable=0.0
            )
            return Unresolved(
                bounded, np.clip(np.asarray(f.x[0], dtype=float), lower, upper), floor
            )
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
            self._base, _ = held_out(
                self.rp, self.sc, self.terms + [(un.candidate, un.x)], self.folds
            )
        cv, _ = held_out(self.rp, self.sc, list(opt.fit.terms) + [(un.candidate, un.x)], self.folds)
        g = gain_over(self.rp, self.sc, self._base, cv, self.m)
        if g.passes:
            return ""
        names = " + ".join(c.name for c in new)
        pct = _pct
        return (
            f"indistinguishable in this log from {un.describe()}: with that time "
            f"constant {names} improves the held-out fit by only {pct(g.gain)} (best "
            f"channel {pct(g.best)}, 95% interval from {pct(g.lo)}); a log with faster "
            "commands or measured rotor speeds could tell them apart"
        )
