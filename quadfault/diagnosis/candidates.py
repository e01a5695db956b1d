"""The candidate effects of the diagnosis library, one small class each.

A candidate is a named effect with a bounded parameter vector ``x`` and one hook for the
stage of the model it acts at; every hook calls the pure functions of
:mod:`quadfault.effects.physics` that the simulator's plant calls step by step:

* ``thrust`` stage -- ``thrust(x, rp, f, t, dt)``: the produced rotor thrusts [N] from
  ``f`` (command-to-thrust curve, battery, efficiency, scale, ground effect, delay, lag);
* ``wrench`` stage -- ``wrench(x, inp)``: an external force (world) [N] and/or moment (body)
  [N m] from :class:`WrenchInputs` (drag, wind, CoM offset, blade flapping, rotor inertia,
  rate damping);
* ``body`` stage -- ``body(x, vehicle)``: the rigid body the equations of motion use
  (mass, inertia).

``public(x, sd, ctx)`` turns ``x`` and its one-sigma ``sd`` into the reported ``params`` and
``uncertainty`` (the keys of the plant effect's ``params()``); ``public_bounds()`` gives the
bounds in those keys.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import numpy as np

from quadfault import effects as fx


class WrenchInputs(NamedTuple):
    """What a wrench-stage candidate sees per interval (or per integration stage).

    Attributes: nominal ``vehicle``; ``R``, ``v`` (world) [m/s], ``w`` (body) [rad/s] (``R``
    and ``v`` None for an IMU-only log); collective ``thrust`` [N] and rotor ``moment``
    (body) [N m] of the produced thrusts; ``rate``: their mean rate of change per rotor
    [N/s] (None when no candidate needs it)."""

    vehicle: object
    R: np.ndarray | None
    v: np.ndarray | None
    w: np.ndarray
    thrust: np.ndarray
    moment: np.ndarray
    rate: np.ndarray | None = None


@dataclass(frozen=True)
class PublicContext:
    """What ``public`` needs beside ``x``: the nominal vehicle, the parameters of the other
    selected effects (``{name: x}``) and the recording's world frame."""

    vehicle: object
    selected: dict
    frame: str = "NED"


@dataclass(frozen=True)
class Candidate:
    """One named effect of the library.

    Attributes:
        name: canonical effect name (docs/formats.md).
        labels: name of each scalar parameter, with its unit.
        lower, upper: physically plausible bounds for the vehicle class; x0: neutral value
            (the nominal model).
        starts: initial guesses tried before the local fit (multi-modal effects).
        stage: ``"thrust"``, ``"wrench"`` or ``"body"``; order: position among thrust stages.
        needs_pose: needs position/velocity/attitude (not testable on IMU-only logs).
        requires: other recorded inputs it needs (``"vbat"``).
        affine: the model channels are affine in ``x`` with every other effect held fixed.
        on_raw: a thrust stage that acts on the unmerged commands of fast logs (timing
            effects, the command curve).
        uses_thrust: a wrench proportional to the produced thrust (jointly with a thrust gain
            the model is no longer affine).
        needs_rate: the wrench needs the thrusts' rate of change.
        default: in the default library (else only when asked for by name).
        excludes: effects this one contains (never accepted together with it).
        rotor_side: acts between the command and the rotor speed (the command curve, the
            battery, motor dynamics), so measured rotor speeds see it; effects after the
            rotor speed (propeller, aerodynamics, the body) leave them unchanged.
        frames: ``((param_key, "world" | "body"), ...)``: reported vector parameters in the
            world or body frame (reported in the recording's own frame).
        resolvable: the shortest time constant the recording's commands resolve [s] (timing
            effects; 0: no floor), set by :mod:`~quadfault.diagnosis.identifiability`.
    """

    name: str
    labels: tuple
    lower: tuple
    upper: tuple
    x0: tuple
    starts: tuple
    stage: str
    order: int = 0
    needs_pose: bool = False
    requires: tuple = ()
    affine: bool = False
    default: bool = True
    excludes: tuple = ()
    rotor_side: bool = False
    frames: tuple = ()
    resolvable: float = 0.0
    on_raw: ClassVar[bool] = False
    uses_thrust: ClassVar[bool] = False
    needs_rate: ClassVar[bool] = False
    #: public parameter key of each slice of ``x`` (``(key, start, stop)``)
    keys: ClassVar[tuple] = ()

    @property
    def size(self) -> int:
        return len(self.x0)

    def testable(self, rp) -> bool:
        """Whether the recording has what this effect needs."""
        return (rp.has_pose or not self.needs_pose) and all(
            getattr(rp, need, None) is not None for need in self.requires)

    def compatible(self, others) -> bool:
        """Whether this effect may be in one model with ``others`` (no one contains another,
        ``excludes``)."""
        names = {o.name for o in others}
        return not names & set(self.excludes) and not any(self.name in o.excludes for o in others)

    # hooks -------------------------------------------------------------------------------
    def thrust(self, x, rp, f, t, dt):
        raise TypeError(f"{self.name} is not a thrust-stage effect")

    def wrench(self, x, inp: WrenchInputs):
        raise TypeError(f"{self.name} is not a wrench-stage effect")

    def wrench_series(self, x, rp, inp: WrenchInputs):
        """The wrench over every interval of ``rp`` (a candidate may cache on ``rp``)."""
        return self.wrench(x, inp)

    def body(self, x, vehicle):
        raise TypeError(f"{self.name} is not a body-stage effect")

    def public(self, x, sd, ctx: PublicContext) -> tuple[dict, dict]:
        """``params`` and ``uncertainty`` (one sigma) as reported in the diagnosis JSON."""
        return self._split(x), self._split(sd)

    def public_bounds(self) -> dict:
        """``{"<param>": [lo, hi]}`` in the reported keys; for a vector parameter ``lo`` and
        ``hi`` are numbers when every element has the same bounds, else lists."""
        lo, hi = self._split(self.lower), self._split(self.upper)
        out = {}
        for k in lo:
            a, b = lo[k], hi[k]
            if isinstance(a, list) and len(set(a)) == 1 and len(set(b)) == 1:
                a, b = a[0], b[0]
            out[k] = [a, b]
        return out

    def x_from_params(self, params: dict) -> np.ndarray:
        """The parameter vector of reported (or plant-effect) ``params``: the inverse of
        :meth:`public` (used to score a known effect, e.g. a simulated truth)."""
        return np.concatenate([np.ravel(np.asarray(params[k], dtype=float))
                               for k, _, _ in self.keys])

    def _split(self, x) -> dict:
        x = np.asarray(x, dtype=float)
        return {k: (float(x[a]) if b - a == 1 else x[a:b].tolist()) for k, a, b in self.keys}


# ----------------------------------------------------------------------------------------
# thrust stage
@dataclass(frozen=True)
class ThrustCurveCandidate(Candidate):
    """``f' = f + f_h (d0 + d1 (x - 1) + d2 (x - 1)^2)`` with ``x = u / u_h`` the command
    relative to the hover command: a new curve ``(a, b, c)`` in the recording's command
    units, through :func:`quadfault.effects.recurve`."""

    nominal: tuple = fx.thrust.IDENTITY_CURVE
    f_hover: float = 1.0
    u_hover: float = 1.0
    on_raw: ClassVar[bool] = True
    keys: ClassVar[tuple] = (("hover_thrust_change", 0, 1), ("slope_change", 1, 2),
                             ("curvature_change", 2, 3))

    def testable(self, rp) -> bool:
        """Also needs a nominal curve that reaches the hover thrust at a positive command."""
        return self.u_hover > 0 and super().testable(rp)

    def curve(self, x) -> np.ndarray:
        return fx.curve_from_changes(self.nominal, self.f_hover, x)

    def thrust(self, x, rp, f, t, dt):
        return fx.recurve(f, self.nominal, self.curve(x))

    def x_from_params(self, params):
        da, db, dc = np.asarray(params["curve"], dtype=float) - np.asarray(self.nominal)
        fh, uh = self.f_hover, self.u_hover
        d2 = dc * uh ** 2 / fh
        d1 = db * uh / fh + 2 * d2
        return np.array([da / fh + d1 - d2, d1, d2])

    def public(self, x, sd, ctx):
        params, unc = super().public(x, sd, ctx)
        J = np.array([[1.0, -1.0, 1.0], [0.0, 1 / self.u_hover, -2 / self.u_hover],
                      [0.0, 0.0, 1 / self.u_hover ** 2]]) * self.f_hover
        params.update(curve=self.curve(x).tolist(), nominal_curve=list(self.nominal))
        unc["curve"] = np.sqrt((J ** 2) @ np.square(np.asarray(sd, dtype=float))).tolist()
        return params, unc


@dataclass(frozen=True)
class BatteryCandidate(Candidate):
    """``f' = f (V / V_ref)^n`` with the logged voltage ``V`` and ``V_ref`` its median."""

    v_ref: float = 1.0
    profile: tuple = (1.0, 1.0, 1.0)  # (v_start, v_end, duration): linear fit of the log
    keys: ClassVar[tuple] = (("exponent", 0, 1),)

    def thrust(self, x, rp, f, t, dt):
        return f * fx.battery_factor(rp.vbat, self.v_ref, float(x[0]))[:, None]

    def public(self, x, sd, ctx):
        params, unc = super().public(x, sd, ctx)
        params.update(v_ref_V=self.v_ref, v_start_V=self.profile[0], v_end_V=self.profile[1],
                      duration_s=self.profile[2])
        return params, unc


@dataclass(frozen=True)
class EfficiencyCandidate(Candidate):
    """Per-rotor thrust factors ``eta``, reported relative to the median rotor: a factor
    common to every rotor is a calibration (``thrust_scale``, ``thrust_curve``), not damage.
    With ``absolute`` (thrust calibrated independently, e.g. measured rotor speeds with a
    known thrust coefficient) the fitted factors are also given as ``eta_absolute``."""

    absolute: bool = False
    baseline: tuple = ()
    keys: ClassVar[tuple] = (("eta", 0, 4),)

    def thrust(self, x, rp, f, t, dt):
        return f * np.asarray(x, dtype=float)[None, :]

    def relative(self, x) -> np.ndarray:
        """``eta`` as reported: relative to the median rotor, and with a ``baseline`` (a
        healthy flight's relative eta) relative to it."""
        x = np.asarray(x, dtype=float)
        if self.baseline:
            x = x / np.asarray(self.baseline, dtype=float)
        return x / max(float(np.median(x)), 1e-9)

    def public(self, x, sd, ctx):
        x, sd = np.asarray(x, dtype=float), np.asarray(sd, dtype=float)
        rel = self.relative(x)
        params, unc = {"eta": rel.tolist()}, {"eta": (sd * rel / np.maximum(x, 1e-9)).tolist()}
        if self.baseline:
            flight = x / max(float(np.median(x)), 1e-9)
            params["eta_flight"], unc["eta_flight"] = flight.tolist(), (sd * flight / x).tolist()
            params["baseline_eta"] = list(self.baseline)
        if self.absolute:
            params["eta_absolute"], unc["eta_absolute"] = x.tolist(), sd.tolist()
        return params, unc


@dataclass(frozen=True)
class ScaleCandidate(Candidate):
    keys: ClassVar[tuple] = (("scale", 0, 1),)

    def thrust(self, x, rp, f, t, dt):
        return f * float(x[0])


@dataclass(frozen=True)
class GroundEffectCandidate(Candidate):
    """Parameter: the squared rotor radius [m^2] (smooth at 0); reported as the radius."""

    def thrust(self, x, rp, f, t, dt):
        r = float(np.sqrt(max(x[0], 0.0)))
        return f * fx.ground_effect_factor(-rp.p[:, 2], r)[:, None]

    def public(self, x, sd, ctx):
        r = float(np.sqrt(max(x[0], 0.0)))
        sr = float(sd[0] / (2 * r)) if r > 0 else float(np.sqrt(sd[0]))
        return {"rotor_radius_m": r, "ground_z_m": 0.0}, {"rotor_radius_m": sr}

    def public_bounds(self):
        return {"rotor_radius_m": [float(np.sqrt(self.lower[0])), float(np.sqrt(self.upper[0]))]}

    def x_from_params(self, params):
        return np.array([float(params["rotor_radius_m"]) ** 2])


@dataclass(frozen=True)
class DelayCandidate(Candidate):
    on_raw: ClassVar[bool] = True
    keys: ClassVar[tuple] = (("delay_s", 0, 1),)

    def thrust(self, x, rp, f, t, dt):
        tk = t[:-1]
        return fx.zoh_mean(tk, f, fx.zoh_cumulative(tk, f), tk - x[0], t[1:] - x[0])


@dataclass(frozen=True)
class LagCandidate(Candidate):
    on_raw: ClassVar[bool] = True
    keys: ClassVar[tuple] = (("tau_s", 0, 1),)

    def thrust(self, x, rp, f, t, dt):
        return fx.lag_series(f, dt, float(x[0]))


# ----------------------------------------------------------------------------------------
# wrench stage
@dataclass(frozen=True)
class DragCandidate(Candidate):
    keys: ClassVar[tuple] = (("k_N_s_per_m", 0, 3),)

    def wrench(self, x, inp):
        return fx.drag_force(inp.R, inp.v, x), None

    def wrench_series(self, x, rp, inp):
        """The same force from its linear basis, cached on ``rp``: column i is the force of
        ``k = e_i`` at every interval."""
        D = rp.__dict__.get("_drag_basis")
        if D is None:
            D = np.stack([fx.drag_force(rp.R, rp.v, e) for e in np.eye(3)], axis=-1)
            object.__setattr__(rp, "_drag_basis", D)
        return D @ np.asarray(x, dtype=float), None


@dataclass(frozen=True)
class WindCandidate(Candidate):
    """A steady world force; the air velocity when drag is selected too."""

    keys: ClassVar[tuple] = (("force_N", 0, 3),)

    def wrench(self, x, inp):
        return np.broadcast_to(np.asarray(x, dtype=float), inp.v.shape), None

    def public(self, x, sd, ctx):
        x, sd = np.asarray(x, dtype=float), np.asarray(sd, dtype=float)
        params, unc = {"force_N": x.tolist()}, {"force_N": sd.tolist()}
        if "drag" in ctx.selected:
            k = np.asarray(ctx.selected["drag"], dtype=float)
            kk = np.maximum(np.array([0.5 * (k[0] + k[1])] * 2 + [k[2]]), 1e-9)
            params["air_velocity_m_per_s"] = (x / kk).tolist()
            unc["air_velocity_m_per_s"] = (sd / kk).tolist()
        return params, unc


@dataclass(frozen=True)
class ComOffsetCandidate(Candidate):
    uses_thrust: ClassVar[bool] = True
    keys: ClassVar[tuple] = (("offset_m", 0, 2),)

    def wrench(self, x, inp):
        return None, fx.com_offset_moment(inp.thrust, x)


@dataclass(frozen=True)
class BladeFlappingCandidate(Candidate):
    uses_thrust: ClassVar[bool] = True
    keys: ClassVar[tuple] = (("k_force_s_per_m", 0, 1), ("k_moment_s", 1, 2))

    def wrench(self, x, inp):
        return fx.blade_flapping_wrench(inp.R, inp.v, inp.thrust, float(x[0]), float(x[1]))

    def public(self, x, sd, ctx):
        """Also the force's drag coefficient at hover thrust, ``k_force m g`` [N s/m] (what a
        ``drag`` fit of the same flight reads as its horizontal ``k``)."""
        params, unc = super().public(x, sd, ctx)
        params["drag_at_hover_N_s_per_m"] = float(x[0]) * ctx.vehicle.weight
        unc["drag_at_hover_N_s_per_m"] = float(sd[0]) * ctx.vehicle.weight
        return params, unc


@dataclass(frozen=True)
class RotorInertiaCandidate(Candidate):
    uses_thrust: ClassVar[bool] = True
    needs_rate: ClassVar[bool] = True
    keys: ClassVar[tuple] = (("kappa_m_s", 0, 1),)

    def wrench(self, x, inp):
        signs = np.sign(inp.vehicle.allocation[3])
        return None, fx.rotor_inertia_moment(inp.rate, signs, float(x[0]))


@dataclass(frozen=True)
class RateDampingCandidate(Candidate):
    keys: ClassVar[tuple] = (("linear_N_m_s_per_rad", 0, 3), ("quadratic_N_m_s2_per_rad2", 3, 6))

    def wrench(self, x, inp):
        x = np.asarray(x, dtype=float)
        return None, fx.rate_damping_moment(inp.w, x[:3], x[3:])


# ----------------------------------------------------------------------------------------
# body stage
@dataclass(frozen=True)
class InertiaCandidate(Candidate):
    keys: ClassVar[tuple] = (("scale", 0, 3),)

    def body(self, x, vehicle):
        return fx.vehicle_with(vehicle, inertia_scale=x)

    def public(self, x, sd, ctx):
        params, unc = super().public(x, sd, ctx)
        params["inertia_diag_kg_m2"] = (np.diag(ctx.vehicle.inertia) * np.asarray(x)).tolist()
        return params, unc


@dataclass(frozen=True)
class MassCandidate(Candidate):
    keys: ClassVar[tuple] = (("scale", 0, 1),)

    def body(self, x, vehicle):
        return fx.vehicle_with(vehicle, mass_scale=float(x[0]))

    def public(self, x, sd, ctx):
        params, unc = super().public(x, sd, ctx)
        params["mass_kg"] = float(x[0]) * ctx.vehicle.mass
        unc["mass_kg"] = float(sd[0]) * ctx.vehicle.mass
        return params, unc
