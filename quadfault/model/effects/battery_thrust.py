"""``battery_thrust``: thrust per command follows the battery voltage, ``f' = f (V / V_ref)^n``.

``n = 2`` for a motor whose speed is proportional to its voltage, ``n = 0`` for perfect
voltage compensation. The simulated voltage falls linearly; the diagnosis follows the logged
``vbat``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.jit import jit
from quadfault.layout import fields
from quadfault.model.effects.base import Compiled, Identifiability, number, param
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.kernels import scaled
from quadfault.model.effects.physics import rows_of, shaped


# kernels ---------------------------------------------------------------------------------
@jit
def battery_voltage1(t, v_start, v_end, duration):
    """Battery voltage [V] at ``t`` [s] falling linearly from ``v_start`` to ``v_end`` over
    ``duration`` [s] (then constant)."""
    frac = min(max(t / duration, 0.0), 1.0)
    return v_start + (v_end - v_start) * frac


@jit
def battery_factor1(voltage, v_ref, exponent):
    """Thrust ratio ``(V / V_ref)^n`` at battery voltage ``V`` [V]."""
    return (max(voltage, 1e-6) / v_ref) ** exponent


#: the chain entry's parameters
PARAMETERS = fields("BatteryThrustParameters", "exponent", "v_start", "v_end", "duration", "v_ref")


@jit(inline="always")
def thrust_step(x, q, f, t, dt, p, gen, streams, i):
    """The chain's entry: the thrusts' factor at the voltage of the step's middle."""
    X = PARAMETERS
    volts = battery_voltage1(t + 0.5 * dt, x[X.v_start], x[X.v_end], x[X.duration])
    return scaled(f, battery_factor1(volts, x[X.v_ref], x[X.exponent]))


# over arrays -----------------------------------------------------------------------------
@jit
def _factor_rows(x, v_ref, exponent, out):
    for i in range(x.shape[0]):
        out[i] = battery_factor1(x[i], v_ref, exponent)


def battery_factor(voltage, v_ref: float, exponent: float) -> np.ndarray:
    """Thrust ratio ``(V / V_ref)^n`` at battery voltage ``V`` [V] (``n`` = 2 for a motor whose
    speed is proportional to its voltage, 0 for perfect voltage compensation)."""
    (xs,) = rows_of(np.shape(voltage), (voltage, ()))
    out = np.empty(len(xs))
    _factor_rows(xs, float(v_ref), float(exponent), out)
    return shaped(out, np.shape(voltage))


# the effect ------------------------------------------------------------------------------
@dataclass(frozen=True)
class BatteryThrust(Compiled):
    """Thrust that follows the battery voltage: ``f' = f (V / v_ref)^exponent``.

    The voltage falls linearly from ``v_start`` to ``v_end`` [V] over ``duration`` [s] (then
    stays); ``v_ref`` [V] is the voltage at which the nominal curve holds (default: the
    middle of the discharge); over a physics step the thrust follows the voltage at the
    step's middle. ``quadfault simulate`` records the same voltage as ``vbat``.
    """

    exponent: float = 2.0
    v_start: float = 12.0
    v_end: float = 11.0
    duration: float = 80.0
    v_ref: float | None = None
    name: ClassVar[str] = "battery_thrust"
    order: ClassVar[int] = 1
    identifiability: ClassVar[Identifiability] = Identifiability(
        channels=("battery",),
        direct=("rotor_speed",),
        excitation="a battery voltage that changes over the log",
        note="the thrust follows the logged voltage; without vbat there is nothing to follow",
    )
    explanation: ClassVar[str] = "thrust per command follows the battery voltage, f ~ (V / V_ref)^n"
    syntax: ClassVar[str] = "EXPONENT [-]"
    example: ClassVar[str] = "battery_thrust=2,v_start=12,v_end=11,duration=8"
    options: ClassVar[dict] = {"v_start": float, "v_end": float, "duration": float, "v_ref": float}

    def __post_init__(self):
        number(self.exponent, "battery_thrust exponent", -5.0, 10.0)
        number(self.v_start, "battery_thrust v_start [V]", 0.0, 1e3, open_lo=True)
        number(self.v_end, "battery_thrust v_end [V]", 0.0, 1e3, open_lo=True)
        number(self.duration, "battery_thrust duration [s]", 0.0, 1e9, open_lo=True)
        if self.v_ref is None:
            object.__setattr__(self, "v_ref", 0.5 * (self.v_start + self.v_end))
        number(self.v_ref, "battery_thrust v_ref [V]", 0.0, 1e3, open_lo=True)

    def params(self):
        return {
            "exponent": self.exponent,
            "v_ref_V": self.v_ref,
            "v_start_V": self.v_start,
            "v_end_V": self.v_end,
            "duration_s": self.duration,
        }

    @classmethod
    def from_params(cls, params):
        kw = {
            k: params[p]
            for k, p in (
                ("v_start", "v_start_V"),
                ("v_end", "v_end_V"),
                ("duration", "duration_s"),
                ("v_ref", "v_ref_V"),
            )
            if p in params
        }
        return cls(param(params, "exponent", cls.name), **kw)

    @classmethod
    def from_values(cls, values, options):
        return cls(exponent=values[0], **options)

    @classmethod
    def candidate(cls, ctx):
        rp = ctx.rp
        has = rp.vbat is not None
        return BatteryCandidate(
            cls.name,
            ("exponent [-]",),
            (-1.0,),
            (4.0,),
            (0.0,),
            ((0.0,), (2.0,)),
            "thrust",
            cls.order,
            requires=("vbat",),
            rotor_side=True,
            v_ref=float(np.median(rp.vbat)) if has else 1.0,
            profile=_voltage_profile(rp) if has else (1.0,) * 3,
        )


def _voltage_profile(rp) -> tuple:
    """``(v_start, v_end, duration)``: a straight line through the logged voltage."""
    t = 0.5 * (rp.t[:-1] + rp.t[1:])
    slope, icpt = np.polyfit(t - t[0], rp.vbat, 1)
    dur = float(rp.t[-1] - rp.t[0])
    return float(icpt), float(icpt + slope * dur), dur


@dataclass(frozen=True)
class BatteryCandidate(Candidate):
    """``f' = f (V / V_ref)^n`` with the logged voltage ``V`` and ``V_ref`` its median."""

    v_ref: float = 1.0
    profile: tuple = (1.0, 1.0, 1.0)  # (v_start, v_end, duration): linear fit of the log
    keys: ClassVar[tuple] = (("exponent", 0, 1),)

    def thrust(self, x, rp, f, t, dt):
        return f * battery_factor(rp.vbat, self.v_ref, float(x[0]))[:, None]

    def public(self, x, sd, ctx):
        params, unc = super().public(x, sd, ctx)
        params.update(
            v_ref_V=self.v_ref,
            v_start_V=self.profile[0],
            v_end_V=self.profile[1],
            duration_s=self.profile[2],
        )
        return params, unc
