"""When a per-rotor efficiency pattern is evidence of a weak rotor.

In near-hover a quadrotor's four rotor efficiencies have four degrees of freedom, and the
vehicle's own build explains each of them as well: one factor common to every rotor (a
thrust calibration, ``thrust_scale`` / ``thrust_curve``), two that trade roll and pitch
moment (a centre-of-mass offset ``r`` makes the moment ``r x T``) and one yaw-moment pattern
(a tilted motor, unequal drag torques: a yaw trim proportional to the thrust). The two
explanations give different moments only where the rotors' commands vary relative to each
other (``eta_i f_i`` against ``r x sum f``), or where measured rotor speeds separate them.

So ``motor_efficiency`` (:func:`rotors_differ`) must beat, on the same held-out folds, the
same model with one factor common to every rotor (``thrust_scale``) by ``min_improvement``:
else it is a calibration error, not per-rotor damage. Against the vehicle's own imbalance
(the common factor, a centre-of-mass offset and a yaw trim) it is compared as a whole set
after the selection (:mod:`~quadfault.diagnosis.rivals`): where one flight cannot tell them
apart, both are reported (``indistinguishable``).

With flights of the healthy vehicle (``EfficiencyCandidate.baseline``) the baseline holds
the vehicle's own imbalance, and the imbalance test is not needed: the efficiencies relative
to it are accepted when a rotor departs from it by more than ``BASELINE_TOLERANCE`` (5 %) and
by more than ``BASELINE_Z`` (3) times the healthy flights' flight-to-flight spread of that
rotor, and the rival comparison with the imbalance is not made (:func:`~quadfault.model.effects.motor_efficiency.healthy_pattern`; with one healthy flight
the spread is unknown and 5 % is the only test).
"""

from __future__ import annotations

import numpy as np

from quadfault.diagnosis.crossval import held_out
from quadfault.diagnosis.library import EQUIVALENT, build_library
from quadfault.model.effects.motor_efficiency import MotorEfficiency
from quadfault.model.effects.thrust_scale import ThrustScale

#: effects that already carry a thrust factor common to every rotor (the thrust class of
#: effects the data cannot tell apart, but the per-rotor one)
COMMON_THRUST = tuple(
    n
    for n, k in EQUIVALENT.items()
    if k == EQUIVALENT[MotorEfficiency.name] and n != MotorEfficiency.name
)


def rotors_differ(rp, sc, opt, current, fl, m) -> str:
    """Why the option ``opt`` (its candidates, joint ``fit`` and held-out ``cv``) may not
    accept ``motor_efficiency`` (module docstring), or ""."""
    new = [c for c in opt.cands[len(current) :] if c.name == MotorEfficiency.name]
    if not new:
        return ""
    eff = new[0]
    eta = np.asarray(opt.fit.x[list(opt.cands).index(eff)], dtype=float)
    if eff.baseline:
        rel, tol = eff.relative(eta), eff.tolerance()
        if np.all(np.abs(rel - 1.0) <= tol):
            n = eff.baseline_flights
            return (
                f"the rotors match the healthy vehicle ({n} flight{'s' * (n != 1)}) within "
                f"{_percent(tol)} (eta relative to it {np.round(rel, 3).tolist()})"
            )
    others = [(c, x) for c, x in zip(opt.cands, opt.fit.x) if c.name != MotorEfficiency.name]
    has_common = any(c.name in COMMON_THRUST for c, _ in others)
    common = (
        []
        if has_common
        else [(build_library(rp, (ThrustScale.name,))[0], np.array([float(np.mean(eta))]))]
    )
    if common:
        cv, f = held_out(rp, sc, others + common, fl)
        if np.sqrt(opt.cv.sse / max(cv.sse, 1e-300)) > 1.0 - m:
            return (
                "the rotors do not differ from each other: one thrust factor common to "
                f"every rotor (thrust_scale {float(f.x[-1][0]):.3g}) fits the held-out "
                f"data within {m:.0%}; that is a calibration or thrust-curve error, not "
                "per-rotor damage"
            )
    return ""


def _percent(tol) -> str:
    tol = np.round(100 * np.asarray(tol, dtype=float), 1)
    if np.all(tol == tol[0]):
        return f"{tol[0]:g}%"
    return "[" + ", ".join(f"{v:g}" for v in tol) + "] %"
