"""``thrust_curve``: the rotors follow another command-to-thrust curve than the nominal one.

The command is ``u = nominal^-1(f)`` (for the identity nominal curve the commanded thrust
``f`` [N] itself; for a ``u``-command recording, the sidecar's curve) and the produced thrust
``f' = a + b u + c u^2`` [N] with ``curve = (a, b, c)``. The diagnosis fits it relative to
hover (docs/effects.md): ``f' = f + f_h (d0 + d1 (x - 1) + d2 (x - 1)^2)``, ``x = u / u_h``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit
from quadfault.layout import fields
from quadfault.model.effects.base import Compiled, Identifiability, param, vector
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.kernels import replaced
from quadfault.model.effects.physics import rows_of, shaped
from quadfault.model.effects.thrust_scale import ThrustScale

IDENTITY_CURVE = (0.0, 1.0, 0.0)


# kernels ---------------------------------------------------------------------------------
@jit
def curve_thrust1(a, b, c, u):
    """Thrust [N] of command ``u`` through the curve ``f = a + b u + c u^2``."""
    return a + u * (b + c * u)


@jit
def curve_command1(a, b, c, f):
    """The command ``u >= 0`` the curve ``(a, b, c)`` maps to thrust ``f`` [N] (the larger
    root; 0 below the curve's value at 0)."""
    f = f - a
    if c == 0.0:
        return max(f / b, 0.0)
    disc = max(b * b + 4.0 * c * f, 0.0)
    return max((math.sqrt(disc) - b) / (2.0 * c), 0.0)


@jit
def recurve1(f, nominal, curve):
    """Thrust [N] through ``curve`` of the command the ``nominal`` curve maps to ``f`` [N]
    (never negative); both curves are 3-tuples ``(a, b, c)``."""
    u = curve_command1(nominal[0], nominal[1], nominal[2], f)
    return max(curve_thrust1(curve[0], curve[1], curve[2], u), 0.0)


#: the chain entry's parameters: (a, b, c) of the curve and of the nominal one
PARAMETERS = fields("ThrustCurveParameters", ("curve", 3), ("nominal", 3))


@jit(inline="always")
def thrust_step(x, q, f, t, dt, p, gen, streams, i):
    """The chain's entry: each thrust through the curve of the command the nominal curve
    maps to it."""
    c, n = PARAMETERS.curve, PARAMETERS.nominal
    curve = (x[c], x[c + 1], x[c + 2])
    nominal = (x[n], x[n + 1], x[n + 2])
    out = f
    for r in range(len(f)):
        out = replaced(out, r, recurve1(f[r], nominal, curve))
    return out


# over arrays -----------------------------------------------------------------------------
@jit
def _curve_rows(curve, x, inverse, out):
    a, b, c = curve[0], curve[1], curve[2]
    for i in range(x.shape[0]):
        out[i] = curve_command1(a, b, c, x[i]) if inverse else curve_thrust1(a, b, c, x[i])


def _curve(curve, x, inverse: bool):
    c = np.array([float(v) for v in curve])
    (xs,) = rows_of(np.shape(x), (x, ()))
    out = np.empty(len(xs))
    _curve_rows(c, xs, inverse, out)
    return shaped(out, np.shape(x))


def curve_thrust(curve, u) -> np.ndarray:
    """Rotor thrust [N] of the command ``u`` through the curve ``f = a + b u + c u^2``."""
    return _curve(curve, u, False)


def curve_command(curve, f) -> np.ndarray:
    """The command ``u >= 0`` that the curve ``(a, b, c)`` maps to thrust ``f`` [N] (the
    larger root; ``u = 0`` where ``f`` is below the curve's value at 0)."""
    return _curve(curve, f, True)


def curve_from_changes(nominal, f_hover: float, changes) -> np.ndarray:
    """The curve ``(a, b, c)`` whose thrust differs from the ``nominal`` curve's by
    ``f_h (d0 + d1 (x - 1) + d2 (x - 1)^2)``, ``x = u / u_h`` the command relative to the
    hover command ``u_h`` (the nominal curve's command for ``f_h`` [N]); ``changes`` =
    ``(d0, d1, d2)`` [-]: hover thrust, slope and curvature changes relative to hover."""
    d0, d1, d2 = (float(v) for v in changes)
    uh = float(curve_command(nominal, f_hover))
    return np.asarray(nominal, dtype=float) + f_hover * np.array(
        [d0 - d1 + d2, (d1 - 2 * d2) / uh, d2 / uh**2]
    )


@jit
def _recurve_rows(f, nominal, curve, out):
    nom = (nominal[0], nominal[1], nominal[2])
    cur = (curve[0], curve[1], curve[2])
    for i in range(f.shape[0]):
        out[i] = recurve1(f[i], nom, cur)


def recurve(f, nominal, curve) -> np.ndarray:
    """Thrust [N] produced through ``curve`` by the command that the ``nominal`` curve maps to
    the commanded thrust ``f`` [N] (never negative)."""
    (fs,) = rows_of(np.shape(f), (f, ()))
    out = np.empty(len(fs))
    _recurve_rows(fs, np.array(nominal, dtype=float), np.array(curve, dtype=float), out)
    return shaped(out, np.shape(f))


# the effect ------------------------------------------------------------------------------
def _curve3(value, what) -> tuple:
    c = vector(value, 3, what)
    if c[1] <= 0 and c[2] <= 0:
        raise ConfigError(
            f"{what} (a, b, c) needs b > 0 or c > 0 (thrust growing with the command), got {c}"
        )
    return c


@dataclass(frozen=True)
class ThrustCurve(Compiled):
    """The rotors follow another command-to-thrust curve than the nominal one.

    The command is ``u = nominal^-1(f)`` (for the default identity nominal curve, the commanded
    thrust ``f`` [N] itself; for a ``u``-command recording, the sidecar's curve) and the
    produced thrust ``f' = a + b u + c u^2`` [N] with ``curve = (a, b, c)``.
    """

    curve: tuple = IDENTITY_CURVE
    nominal: tuple = IDENTITY_CURVE
    name: ClassVar[str] = "thrust_curve"
    order: ClassVar[int] = 0
    identifiability: ClassVar[Identifiability] = Identifiability(
        scales_with=("mass",),
        direct=("rotor_speed",),
        excitation="commands spanning a range of thrust (climbs, descents, manoeuvres)",
        note="near hover a curve is a thrust scale; its slope and curvature need thrust changes",
    )
    explanation: ClassVar[str] = (
        "the command-to-thrust curve differs from the nominal one "
        "(f = a + b u + c u^2 in the recording's command units)"
    )
    equivalent: ClassVar[str] = "thrust"
    values: ClassVar[tuple] = (3,)
    syntax: ClassVar[str] = "A,B,C (f' = A + B f + C f^2) [N, -, 1/N]"
    example: ClassVar[str] = "thrust_curve=1.225,0.35,0.0816"

    def __post_init__(self):
        object.__setattr__(self, "curve", _curve3(self.curve, "thrust_curve curve"))
        object.__setattr__(self, "nominal", _curve3(self.nominal, "thrust_curve nominal"))

    def params(self):
        return {"curve": list(self.curve), "nominal_curve": list(self.nominal)}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "curve", cls.name), params.get("nominal_curve", IDENTITY_CURVE))

    @classmethod
    def from_values(cls, values, options):
        return cls(curve=tuple(values), **options)

    @classmethod
    def candidate(cls, ctx):
        """In the default library only for ``u``-command recordings (whose curve is a
        declared, calibrated model); for thrust commands its slope fits the same closed-loop
        signal as an inertia or a payload, so it is asked for by name."""
        zero3 = (0.0,) * 3
        return ThrustCurveCandidate(
            cls.name,
            ("d0 [-]", "d1 [-]", "d2 [-]"),
            (-0.5,) * 3,
            (0.5,) * 3,
            zero3,
            (zero3,),
            "thrust",
            cls.order,
            affine=True,
            default=ctx.u_commands,
            excludes=(ThrustScale.name,),
            rotor_side=True,
            nominal=ctx.nominal_curve,
            f_hover=ctx.f_hover,
            u_hover=ctx.u_hover,
        )


@dataclass(frozen=True)
class ThrustCurveCandidate(Candidate):
    """``f' = f + f_h (d0 + d1 (x - 1) + d2 (x - 1)^2)`` with ``x = u / u_h`` the command
    relative to the hover command: a new curve ``(a, b, c)`` in the recording's command
    units, through :func:`recurve`."""

    nominal: tuple = IDENTITY_CURVE
    f_hover: float = 1.0
    u_hover: float = 1.0
    on_raw: ClassVar[bool] = True
    keys: ClassVar[tuple] = (
        ("hover_thrust_change", 0, 1),
        ("slope_change", 1, 2),
        ("curvature_change", 2, 3),
    )

    def untestable_reason(self, rp) -> str:
        """Also needs a nominal curve that reaches the hover thrust at a positive command."""
        if not self.u_hover > 0:
            return "the command curve does not reach the hover thrust at a positive command"
        return super().untestable_reason(rp)

    def curve(self, x) -> np.ndarray:
        return curve_from_changes(self.nominal, self.f_hover, x)

    def thrust(self, x, rp, f, t, dt):
        return recurve(f, self.nominal, self.curve(x))

    def x_from_params(self, params):
        da, db, dc = np.asarray(params["curve"], dtype=float) - np.asarray(self.nominal)
        fh, uh = self.f_hover, self.u_hover
        d2 = dc * uh**2 / fh
        d1 = db * uh / fh + 2 * d2
        return np.array([da / fh + d1 - d2, d1, d2])

    def public(self, x, sd, ctx):
        params, unc = super().public(x, sd, ctx)
        J = (
            np.array(
                [
                    [1.0, -1.0, 1.0],
                    [0.0, 1 / self.u_hover, -2 / self.u_hover],
                    [0.0, 0.0, 1 / self.u_hover**2],
                ]
            )
            * self.f_hover
        )
        params.update(curve=self.curve(x).tolist(), nominal_curve=list(self.nominal))
        unc["curve"] = np.sqrt((J**2) @ np.square(np.asarray(sd, dtype=float))).tolist()
        return params, unc
