"""The candidate library: physically named effects with bounded parameter vectors.

Every candidate (:mod:`quadfault.diagnosis.candidates`) predicts through
:mod:`quadfault.effects` (the same physics the simulator's plant runs) and
:mod:`quadfault.dynamics` (the same rigid-body equations). The model of a set of terms
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

from quadfault import effects as fx
import quadfault.diagnosis.candidates as cd
from quadfault.diagnosis.candidates import Candidate, PublicContext, WrenchInputs
from quadfault.diagnosis.residuals import Replay, model_channels
from quadfault.effects.model import frame_vectors

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


def _voltage_profile(rp: Replay) -> tuple:
    """``(v_start, v_end, duration)``: a straight line through the logged voltage."""
    t = 0.5 * (rp.t[:-1] + rp.t[1:])
    slope, icpt = np.polyfit(t - t[0], rp.vbat, 1)
    dur = float(rp.t[-1] - rp.t[0])
    return float(icpt), float(icpt + slope * dur), dur


def build_library(rp: Replay, names=None) -> list[Candidate]:
    """The candidates named in ``names`` (default: the default library), with bounds scaled to
    the nominal vehicle of ``rp``.

    ``thrust_curve`` is in the default library only for ``u``-command recordings (whose
    command-to-thrust curve is a declared, calibrated model); for thrust commands in newtons
    it is asked for by name: in closed loop its slope fits the same signal as an inertia or a
    payload (docs/effects.md, "What the data cannot tell apart")."""
    veh = rp.vehicle
    m, g, arm, n = veh.mass, veh.gravity, rp.arm, veh.n_rotors
    J = np.diag(veh.inertia)
    c_yaw = float(np.mean(np.abs(veh.allocation[3])))
    dt = float(np.median(rp.dt))
    tw = n * veh.rotor_max_thrust / (m * g)  # thrust-to-weight (inf without a limit)
    one4, one3, zero3 = (1.0,) * 4, (1.0,) * 3, (0.0,) * 3
    nominal = tuple(rp.thrust_curve) if rp.thrust_curve is not None else fx.thrust.IDENTITY_CURVE
    f_h = m * g / n
    u_h = float(fx.curve_command(nominal, f_h))
    lib = [
        cd.EfficiencyCandidate("motor_efficiency", ("eta1 [-]", "eta2 [-]", "eta3 [-]", "eta4 [-]"),
                               (0.2,) * 4, (1.5,) * 4, one4, (one4,), "thrust", 2, affine=True,
                               excludes=("thrust_scale",),
                               absolute=rp.has_rotor and rp.rotor_k_source == "sidecar"),
        cd.ScaleCandidate("thrust_scale", ("scale [-]",), (0.5,), (1.5,), (1.0,), ((1.0,),),
                          "thrust", 2, affine=True),
        cd.GroundEffectCandidate("ground_effect", ("rotor_radius^2 [m^2]",), (0.0,), (arm ** 2,),
                                 (0.0,), tuple(((k * arm) ** 2,) for k in (0.2, 0.45, 0.7, 0.95)),
                                 "thrust", 3, needs_pose=True),
        cd.DelayCandidate("delay", ("delay [s]",), (0.0,), (0.2,), (0.0,),
                          tuple((d,) for d in np.unique(np.r_[np.arange(0.0, 0.15, max(dt, 0.01)),
                                                              0.19])),
                          "thrust", 4, rotor_side=True),
        cd.LagCandidate("motor_lag", ("tau [s]",), (1e-4,), (0.3,), (1e-4,),
                        tuple((tau,) for tau in (0.005, 0.01, 0.02, 0.04, 0.07, 0.12, 0.2, 0.28)),
                        "thrust", 5, rotor_side=True),
        cd.DragCandidate("drag", ("kx [N s/m]", "ky [N s/m]", "kz [N s/m]"), zero3,
                         (3.0 * m, 3.0 * m, 5.0 * m), zero3, (zero3, (0.5 * m,) * 3), "wrench",
                         needs_pose=True, affine=True),
        cd.WindCandidate("wind", ("Fx [N]", "Fy [N]", "Fz [N]"), (-0.5 * m * g,) * 2 + (-0.25 * m * g,),
                         (0.5 * m * g,) * 2 + (0.25 * m * g,), zero3, (zero3,), "wrench",
                         needs_pose=True, affine=True,
                         frames=(("force_N", "world"), ("air_velocity_m_per_s", "world"))),
        cd.ComOffsetCandidate("com_offset", ("rx [m]", "ry [m]"), (-0.3 * arm,) * 2, (0.3 * arm,) * 2,
                              (0.0, 0.0), ((0.0, 0.0),), "wrench", affine=True,
                              frames=(("offset_m", "body"),)),
        cd.InertiaCandidate("inertia", ("sx [-]", "sy [-]", "sz [-]"), (0.5,) * 3, (2.0,) * 3, one3,
                            (one3,), "body"),
        cd.BladeFlappingCandidate("blade_flapping", ("k_force [s/m]", "k_moment [s]"),
                                  (0.0, -0.3 * arm), (0.3, 0.3 * arm), (0.0, 0.0), ((0.0, 0.0),),
                                  "wrench", needs_pose=True, affine=True),
        cd.RotorInertiaCandidate("rotor_inertia", ("kappa [m s]",), (0.0,), (1.5 * c_yaw,), (0.0,),
                                 ((0.0,),), "wrench", affine=True),
        cd.BatteryCandidate("battery_thrust", ("exponent [-]",), (-1.0,), (4.0,), (0.0,),
                            ((0.0,), (2.0,)), "thrust", 1, requires=("vbat",), rotor_side=True,
                            v_ref=float(np.median(rp.vbat)) if rp.vbat is not None else 1.0,
                            profile=_voltage_profile(rp) if rp.vbat is not None else (1.0,) * 3),
        cd.ThrustCurveCandidate("thrust_curve", ("d0 [-]", "d1 [-]", "d2 [-]"), (-0.5,) * 3,
                                (0.5,) * 3, zero3, (zero3,), "thrust", 0, affine=True,
                                default=rp.thrust_curve is not None,
                                excludes=("thrust_scale",), rotor_side=True, nominal=nominal,
                                f_hover=f_h, u_hover=u_h),
        cd.MassCandidate("mass", ("scale [-]",), (0.5,), (float(np.clip(0.8 * tw, 1.2, 2.0)),),
                         (1.0,), ((1.0,),), "body"),
        cd.RateDampingCandidate("rate_damping", tuple(f"D1{a} [N m s/rad]" for a in "xyz")
                                + tuple(f"D2{a} [N m s^2/rad^2]" for a in "xyz"), (0.0,) * 6,
                                tuple(J / 0.02) + tuple(J * 1.0), (0.0,) * 6, ((0.0,) * 6,),
                                "wrench", affine=True),
    ]
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
    stages = sorted(((c, np.asarray(x, dtype=float)) for c, x in terms if c.stage == "thrust"),
                    key=lambda t: t[0].order)
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


def predict_intervals(rp: Replay, terms) -> np.ndarray:
    """Model channels (M, C) per interval for the nominal model plus ``terms``: the six
    acceleration channels, then the accelerometer's, then (with measured rotor speeds) the
    rotor thrusts seen through only the effects before the rotor speed (``rotor_side``)."""
    terms = list(terms)
    rate = None
    if needs_rate(terms):
        f, f_end = thrust_series(rp, terms, ends=True)
        rate = fx.thrust_rate(f_end, rp.dt)
    else:
        f = thrust_series(rp, terms)
    W = rp.vehicle.wrench(f)
    T, M = W[:, 0], W[:, 1:]
    inp = WrenchInputs(rp.vehicle, rp.R, rp.v, rp.w, T, M, rate)
    F, Mx = external_wrench(terms, inp, rp)
    out = model_channels(rp, f, F, Mx, T, M, vehicle=body_vehicle(rp.vehicle, terms))
    if rp.has_rotor:
        out = np.hstack((out, thrust_series(rp, [t for t in terms if t[0].rotor_side])))
    return out


def predict(rp: Replay, terms) -> np.ndarray:
    """Block-mean model channels (B, C)."""
    return rp.block_mean(predict_intervals(rp, terms))


def public_params(cand: Candidate, x, sd, vehicle, selected: dict,
                  frame: str = "NED") -> tuple[dict, dict]:
    """``params`` and ``uncertainty`` (one sigma) as reported in the diagnosis JSON; direction
    parameters (world ``force_N``, ``air_velocity_m_per_s``; body ``offset_m``) in the
    recording's own frame (``"ENU"``: world ENU, body FLU)."""
    params, unc = cand.public(np.asarray(x, dtype=float), np.asarray(sd, dtype=float),
                              PublicContext(vehicle, selected, frame))
    return frame_vectors(params, frame), frame_vectors(unc, frame, magnitude=True)


def public_bounds(cand: Candidate) -> dict:
    """``{"<param>": [lo, hi]}`` of the reported parameters (``lo``, ``hi`` are lists for
    vector parameters; symmetric for direction parameters, so the same in every frame)."""
    return cand.public_bounds()


EXPLANATIONS = {
    "motor_efficiency": "rotor thrusts are eta_i times the commanded ones (per-rotor thrust loss)",
    "thrust_scale": "all rotors produce a common factor of the commanded thrust",
    "ground_effect": "thrust grows near the ground (Cheeseman-Bennett, ground plane at z = 0)",
    "delay": "the rotor thrust follows the command after a pure delay",
    "motor_lag": "the rotor thrust follows the command through first-order dynamics",
    "drag": "a force opposes the velocity through the air, F = -R diag(k) R^T v",
    "wind": "a steady external force pushes the vehicle (moving air)",
    "com_offset": "the centre of mass is offset from the rotor-plane centre: thrust makes a moment",
    "inertia": "the inertia differs from the nominal value (angular response scaled)",
    "blade_flapping": "rotor drag and blade flapping: a force against and a moment from the "
                      "in-plane airspeed, both proportional to thrust",
    "rotor_inertia": "the rotors' inertia: changing rotor speeds kick the body in yaw",
    "battery_thrust": "thrust per command follows the battery voltage, f ~ (V / V_ref)^n",
    "thrust_curve": "the command-to-thrust curve differs from the nominal one "
                    "(f = a + b u + c u^2 in the recording's command units)",
    "mass": "the mass differs from the nominal value (a payload): translation responds less",
    "rate_damping": "the body rates are damped, M = -(D1 + D2 |w|) w per body axis",
}

#: Effects the data cannot always tell apart; counted as one class in the blinded study.
#: "thrust": the same translational response (a thrust gain, a curve, or a mass change); only
#: the angular response separates them, which closed-loop feedback biases. "timing": both
#: low-pass the command. docs/effects.md explains each.
EQUIVALENT = {"thrust_scale": "thrust", "motor_efficiency": "thrust", "thrust_curve": "thrust",
              "mass": "thrust", "delay": "timing", "motor_lag": "timing"}
