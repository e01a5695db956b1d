"""``com_offset``: the centre of mass sits at ``r`` from the rotor-plane centre, so the rotors
act about it: ``M' = M + r x (0, 0, T)``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.effects.base import Compiled, Identifiability, param, vector
from quadfault.effects.candidate import Candidate
from quadfault.effects.physics import batch_of, rows_of
from quadfault.errors import ConfigError
from quadfault.jit import jit
from quadfault.rotation import store3


@jit
def com_offset_moment3(thrust, rx, ry):
    """Body moment [N m] of collective thrust ``thrust`` [N] with the CoM at ``(rx, ry)``
    [m] from the rotor-plane centre: ``r x (0, 0, T)``."""
    return (ry * thrust, -rx * thrust, 0.0)


@jit(inline="always")
def wrench_term(P, Q, i, a, m, f):
    """The step's numbers: the body moment (3) of the step's collective thrust (parameters
    r_x, r_y)."""
    thrust = 0.0
    for r in range(f.shape[0]):
        thrust += f[r]
    M = com_offset_moment3(thrust, P[i, a], P[i, a + 1])
    return M[0], M[1], M[2], 0.0, 0.0, 0.0


@jit(inline="always")
def wrench_stage(s, v, R, w):
    """The step's body moment, the same at every stage."""
    return (0.0, 0.0, 0.0), (s[1], s[2], s[3])


@jit
def _moment_rows(T, offset, out):
    for i in range(T.shape[0]):
        store3(out[i], com_offset_moment3(T[i], offset[i, 0], offset[i, 1]))


def com_offset_moment(thrust, offset) -> np.ndarray:
    """Extra body moment [N m] of collective thrust ``thrust`` [N] when the CoM sits at
    ``offset`` = (r_x, r_y) [m] from the rotor-plane centre: ``r x (0, 0, T)``."""
    batch = batch_of((thrust, ()), (offset, (2,)))
    rT, ro = rows_of(batch, (thrust, ()), (offset, (2,)))
    out = np.zeros((int(np.prod(batch)), 3))
    _moment_rows(rT, ro, out)
    return out.reshape(batch + (3,))


@dataclass(frozen=True)
class ComOffset(Compiled):
    """Centre of mass at ``offset`` = (r_x, r_y) [m] from the rotor-plane centre (body FRD):
    the rotors act about the CoM, ``M' = M + r x (0, 0, T)``."""

    offset: tuple = (0.0, 0.0)
    name: ClassVar[str] = "com_offset"
    order: ClassVar[int] = 10
    identifiability: ClassVar[Identifiability] = Identifiability(
        scales_with=("mass", "inertia"),
        note="a thrust-proportional moment: hover needs an unequal rotor split")
    explanation: ClassVar[str] = ("the centre of mass is offset from the rotor-plane centre: "
                                  "thrust makes a moment")
    values: ClassVar[tuple] = (2,)
    syntax: ClassVar[str] = "RX,RY [m]"
    example: ClassVar[str] = "com_offset=0.01,-0.02"

    def __post_init__(self):
        off = vector(self.offset, 2, "com_offset")
        if max(abs(x) for x in off) > 1.0:
            raise ConfigError(f"com_offset must be within 1 m, got {off}")
        object.__setattr__(self, "offset", off)

    def params(self):
        return {"offset_m": list(self.offset)}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "offset_m", cls.name))

    @classmethod
    def from_values(cls, values, options):
        return cls(offset=tuple(values), **options)

    def pack(self, n_rotors, dt, yaw_signs=None):
        return tuple(self.offset), 0

    @classmethod
    def candidate(cls, ctx):
        arm = ctx.arm
        return ComOffsetCandidate(cls.name, ("rx [m]", "ry [m]"), (-0.3 * arm,) * 2,
                                  (0.3 * arm,) * 2, (0.0, 0.0), ((0.0, 0.0),), "wrench",
                                  affine=True, frames=(("offset_m", "body"),))


@dataclass(frozen=True)
class ComOffsetCandidate(Candidate):
    uses_thrust: ClassVar[bool] = True
    keys: ClassVar[tuple] = (("offset_m", 0, 2),)

    def wrench(self, x, inp):
        return None, com_offset_moment(inp.thrust, x)


@dataclass(frozen=True)
class ImbalanceCandidate(Candidate):
    """The vehicle's own moment imbalance, proportional to the collective thrust: the centre
    of mass at ``(r_x, r_y)`` [m] (``r x (0, 0, T)``) and a yaw trim ``k_z`` [m] (``M_z = k_z
    T``: a tilted motor, unequal drag torques). In near-hover it spans the same moments as a
    per-rotor efficiency pattern (with a common thrust factor, the same four degrees of
    freedom); only rotor commands that vary relative to each other, or measured rotor speeds,
    tell the two apart. Not in the library: the diagnosis fits it only as the alternative to
    ``motor_efficiency`` (over a recording, the moment of the commanded thrust, so the model
    stays affine beside a thrust factor)."""

    keys: ClassVar[tuple] = (("offset_m", 0, 2), ("yaw_trim_m", 2, 3))

    @classmethod
    def of(cls, ctx) -> "ImbalanceCandidate":
        """Bounds as ``com_offset``'s (0.3 arm) and 0.3 yaw-torque coefficients."""
        b = (0.3 * ctx.arm,) * 2 + (0.3 * ctx.c_yaw,)
        return cls("imbalance", ("rx [m]", "ry [m]", "kz [m]"), tuple(-v for v in b), b,
                   (0.0,) * 3, ((0.0,) * 3,), "wrench", affine=True, default=False,
                   frames=(("offset_m", "body"),))

    def _moment(self, x, thrust):
        M = np.array(com_offset_moment(thrust, x[:2]), dtype=float)
        M[..., 2] += float(x[2]) * np.asarray(thrust, dtype=float)
        return M

    def wrench(self, x, inp):
        return None, self._moment(x, inp.thrust)

    def wrench_series(self, x, rp, inp):
        return None, self._moment(x, np.sum(rp.f, axis=1))
