"""The candidate library: physically named effects with bounded parameter vectors.

Every candidate (each effect's ``candidate``, built from the registry
:mod:`quadfault.model.effects.registry`; the protocol in :mod:`quadfault.model.effects.candidate`)
predicts through its effect's module (the same physics the simulator's plant runs) and
:mod:`quadfault.model.dynamics` (the same rigid-body equations). The model of a set of terms
``[(candidate, x), ...]`` is the plant's chain:

1. ``thrust`` stages in ``order``: command-to-thrust curve, battery voltage, efficiency or
   common scale, ground effect, delay, lag (on fast merged logs the curve and the timing
   effects act on the raw commands, the pointwise factors on the merged thrust);
2. ``wrench`` stages add a force (world) and a moment (body);
3. ``body`` stages change the rigid body the equations of motion use (mass, inertia).

Bounds are physically plausible for the vehicle class: they scale with the nominal vehicle
(mass m [kg], weight m g, rotor distance ``arm`` [m], inertia J, yaw coefficient c) and are
documented in docs/effects.md. A fit at a bound means the data asks for more than the effect
allows.
"""

from __future__ import annotations

import numpy as np

import quadfault.model.effects.registry as registry
from quadfault.diagnosis.residuals import Replay, model_parts
from quadfault.model.effects.candidate import Candidate, LibraryContext, PublicContext, WrenchInputs
from quadfault.model.effects.model import frame_vectors
from quadfault.model.effects.rotor_inertia import thrust_rate
from quadfault.model.effects.thrust_curve import IDENTITY_CURVE, curve_command

__all__ = [
    "EQUIVALENT",
    "EXPLANATIONS",
    "Candidate",
    "WrenchInputs",
    "body_vehicle",
    "build_library",
    "external_wrench",
    "predict",
    "predict_intervals",
    "public_bounds",
    "public_params",
    "thrust_series",
]


def context(rp: Replay) -> LibraryContext:
    """The scales of ``rp``'s nominal vehicle that the candidates' bounds are set in."""
    veh = rp.vehicle
    m, g, n = veh.mass, veh.gravity, veh.n_rotors
    nominal = tuple(rp.thrust_curve) if rp.thrust_curve is not None else IDENTITY_CURVE
    f_h = m * g / n
    return LibraryContext(
        rp=rp,
        mass=m,
        gravity=g,
        arm=rp.arm,
        n_rotors=n,
        inertia=np.diag(veh.inertia),
        c_yaw=float(np.mean(np.abs(veh.allocation[3]))),
        dt=float(np.median(rp.dt)),
        thrust_to_weight=n * veh.rotor_max_thrust / (m * g),
        nominal_curve=nominal,
        f_hover=f_h,
        u_hover=float(curve_command(nominal, f_h)),
        u_commands=rp.thrust_curve is not None,
    )


def build_library(rp: Replay, names=None) -> list[Candidate]:
    """The candidates named in ``names`` (default: the default library), with bounds scaled to
    the nominal vehicle of ``rp``, in the registry's order.

    ``thrust_curve`` is in the default library only for ``u``-command recordings (whose
    command-to-thrust curve is a declared, calibrated model); for thrust commands in newtons
    it is asked for by name: in closed loop its slope fits the same signal as an inertia or a
    payload (docs/effects.md, "What the data cannot tell apart")."""
    ctx = context(rp)
    lib = [cls.candidate(ctx) for cls in registry.TABLE]
    if names is None:
        return [c for c in lib if c.default]
    return [c for c in lib if c.name in names]


def thrust_series(rp: Replay, terms, ends: bool = False):
    """Produced rotor thrusts (M, n) [N] after the thrust-stage terms ``[(cand, x), ...]``.

    On merged (fast) logs (``rp.raw``) the stages that act on raw commands (curve, delay, lag)
    run on the raw rows, which are then merged; the pointwise factors (battery, efficiency,
    scale, ground effect) follow on the merged thrust -- exact for the constant factors, and
    for the others up to their variation within one internal step. With ``ends``, also the
    thrust held at the end of each interval (M, n) (its last raw row), for rates."""
    stages = sorted(
        ((c, np.asarray(x, dtype=float)) for c, x in terms if c.stage == "thrust"),
        key=lambda t: t[0].order,
    )
    f, f_end = rp.f, None
    raw = rp.raw
    if raw is not None and (ends or any(c.on_raw for c, _ in stages)):
        fr = raw["f"]
        for cand, x in (s for s in stages if s[0].on_raw):
            fr = cand.thrust(x, rp, fr, raw["t"], raw["dt"])
        f = np.asarray(raw["merge"] @ fr)
        f_end = fr[rp.knots[1:] - 1] if ends else None
        stages = [s for s in stages if not s[0].on_raw]
    for cand, x in stages:
        f = cand.thrust(x, rp, f, rp.t, rp.dt)
        if f_end is not None:
            f_end = cand.thrust(x, rp, f_end, rp.t, rp.dt)
    if ends:
        return f, (f if f_end is None else f_end)
    return f


def body_vehicle(vehicle, terms):
    """The rigid body of the model: ``vehicle`` through the body-stage terms."""
    for cand, x in terms:
        if cand.stage == "body":
            vehicle = cand.body(np.asarray(x, dtype=float), vehicle)
    return vehicle


def external_wrench(terms, inp: WrenchInputs, rp: Replay | None = None):
    """Summed external force (world) [N] and moment (body) [N m] of the wrench-stage terms
    (either None when no term gives one); over the intervals of ``rp`` when given."""
    F = Mx = None
    for cand, x in terms:
        if cand.stage != "wrench":
            continue
        x = np.asarray(x, dtype=float)
        dF, dM = cand.wrench(x, inp) if rp is None else cand.wrench_series(x, rp, inp)
        if dF is not None:
            F = dF if F is None else F + dF
        if dM is not None:
            Mx = dM if Mx is None else Mx + dM
    return F, Mx


def needs_rate(terms) -> bool:
    return any(c.needs_rate for c, _ in terms)


def _interval_parts(rp: Replay, terms) -> list:
    """The interval channels of :func:`predict_intervals` as column groups (M, k)."""
    terms = list(terms)
    rate = None
    if needs_rate(terms):
        f, f_end = thrust_series(rp, terms, ends=True)
        rate = thrust_rate(f_end, rp.dt)
    else:
        f = thrust_series(rp, terms)
    W = rp.vehicle.wrench(f)
    T, M = W[:, 0], W[:, 1:]
    inp = WrenchInputs(rp.vehicle, rp.R, rp.v, rp.w, T, M, rate)
    F, Mx = external_wrench(terms, inp, rp)
    parts = model_parts(rp, f, F, Mx, T, M, vehicle=body_vehicle(rp.vehicle, terms))
    if rp.has_rotor:
        rotor = [t for t in terms if t[0].rotor_side]
        same = rate is None and all(c.rotor_side for c, _ in terms if c.stage == "thrust")
        parts.append(f if same else thrust_series(rp, rotor))  # same stages: the same f
    return parts


def predict_intervals(rp: Replay, terms) -> np.ndarray:
    """Model channels (M, C) per interval for the nominal model plus ``terms``: the six
    acceleration channels, then the accelerometer's, then (with measured rotor speeds) the
    rotor thrusts seen through only the effects before the rotor speed (``rotor_side``)."""
    return np.hstack(_interval_parts(rp, terms))


def predict(rp: Replay, terms) -> np.ndarray:
    """Block-mean model channels (B, C) (each column group averaged before stacking: the
    same numbers as averaging the stacked intervals, without copying them)."""
    return np.hstack([rp.block_mean(p) for p in _interval_parts(rp, terms)])


def public_params(
    cand: Candidate, x, sd, vehicle, selected: dict, frame: str = "NED"
) -> tuple[dict, dict]:
    """``params`` and ``uncertainty`` (one sigma) as reported in the diagnosis JSON; direction
    parameters (world ``force_N``, ``air_velocity_m_per_s``; body ``offset_m``) in the
    recording's own frame (``"ENU"``: world ENU, body FLU)."""
    params, unc = cand.public(
        np.asarray(x, dtype=float),
        np.asarray(sd, dtype=float),
        PublicContext(vehicle, selected, frame),
    )
    return frame_vectors(params, frame), frame_vectors(unc, frame, magnitude=True)


def public_bounds(cand: Candidate, x=None) -> dict:
    """``{"<param>": [lo, hi]}`` of the reported parameters, in their reported units (of the
    fit ``x``: eta relative to the median rotor); ``lo``, ``hi`` are lists for vector
    parameters; symmetric for direction parameters, so the same in every frame."""
    return cand.public_bounds(x)


#: effect name -> the one line the diagnosis reports (each effect's ``explanation``)
EXPLANATIONS = {cls.name: cls.explanation for cls in registry.TABLE}

#: Effects the data cannot always tell apart; counted as one class in the blinded study.
#: "thrust": the same translational response (a thrust gain, a curve, or a mass change); only
#: the angular response separates them, which closed-loop feedback biases. "timing": both
#: low-pass the command. docs/effects.md explains each.
EQUIVALENT = registry.equivalence_classes()
