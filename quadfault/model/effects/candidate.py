"""What the diagnosis fits: the candidate protocol each effect's module implements.

A candidate is a named effect with a bounded parameter vector ``x`` and one hook for the
stage of the model it acts at; every hook calls the kernels of the effect's own module that
the simulator's closed loop runs step by step (each effect's module has its candidate class
and a ``candidate(ctx)`` class method on the effect that builds it for a recording,
:class:`LibraryContext`):

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


class LibraryContext(NamedTuple):
    """What an effect's ``candidate(ctx)`` builds its candidate from: the recording's replay
    (``rp``: its nominal ``vehicle``, ``t``, ``dt``, ``vbat``, ``thrust_curve``...) and the
    scales of the nominal vehicle the bounds are set in.

    Attributes: ``mass`` [kg], ``gravity`` [m/s^2], ``arm`` (largest rotor distance) [m],
    ``n_rotors``, ``inertia`` (diagonal) [kg m^2], ``c_yaw`` (mean yaw-torque coefficient)
    [m], ``dt`` (median interval) [s], ``thrust_to_weight`` (inf without a thrust limit),
    ``nominal_curve`` (the ``(a, b, c)`` command-to-thrust curve; identity for thrust
    commands), ``f_hover`` (hover thrust per rotor) [N], ``u_hover`` (its command),
    ``u_commands`` (the recording's commands are ``u``, not thrusts)."""

    rp: object
    mass: float
    gravity: float
    arm: float
    n_rotors: int
    inertia: np.ndarray
    c_yaw: float
    dt: float
    thrust_to_weight: float
    nominal_curve: tuple
    f_hover: float
    u_hover: float
    u_commands: bool


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
        pinned: ``(x, sd)`` when the parameters come from direct evidence (a motor lag from
            command to measured rotor speed): the bounds then hold ``x`` and the reported
            one-sigma is ``sd``; ``()`` otherwise.
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
    pinned: tuple = ()
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
        return not self.untestable_reason(rp)

    def untestable_reason(self, rp) -> str:
        """What the recording lacks for this effect ("" when it has it all)."""
        if self.needs_pose and not rp.has_pose:
            return "no position, velocity and attitude in the log"
        missing = [need for need in self.requires if getattr(rp, need, None) is None]
        if "vbat" in missing and getattr(rp, "vbat_unusable", ""):
            return rp.vbat_unusable
        if missing:
            names = {"vbat": "battery voltage"}
            return "no " + ", ".join(names.get(m, m) for m in missing) + " in the log"
        return ""

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
        return self._split(x), self._split(self.pinned[1] if self.pinned else sd)

    def public_bounds(self, x=None) -> dict:
        """``{"<param>": [lo, hi]}`` in the reported keys and units (of the fit ``x`` where a
        reported value is relative to the fit, e.g. eta relative to the median rotor); for a
        vector parameter ``lo`` and ``hi`` are numbers when every element has the same
        bounds, else lists."""
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
        return np.concatenate(
            [np.ravel(np.asarray(params[k], dtype=float)) for k, _, _ in self.keys]
        )

    def _split(self, x) -> dict:
        x = np.asarray(x, dtype=float)
        return {k: (float(x[a]) if b - a == 1 else x[a:b].tolist()) for k, a, b in self.keys}
