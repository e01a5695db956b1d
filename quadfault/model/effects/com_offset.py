"""``com_offset``: the centre of mass sits at ``r`` from the rotor-plane centre, so the rotors
act about it: ``M' = M + r x (0, 0, T)``; with a yaw trim ``k_z`` (a tilted motor, unequal
drag torques) also ``M_z' = M_z + k_z T``: the vehicle's own moment imbalance, proportional
to the thrust.

In near-hover this is the same moment as a per-rotor efficiency pattern with no common part
(two roll/pitch degrees of freedom and one yaw); the two differ only where the rotors'
commands vary relative to each other (:mod:`quadfault.diagnosis.rotors`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit
from quadfault.layout import fields
from quadfault.model.effects.base import Compiled, Identifiability, number, param, vector
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.physics import batch_of, rows_of
from quadfault.model.rotation import store3


@jit
def com_offset_moment3(thrust, rx, ry, kz=0.0):
    """Body moment [N m] of collective thrust ``thrust`` [N] with the CoM at ``(rx, ry)``
    [m] from the rotor-plane centre, ``r x (0, 0, T)``, and a yaw trim ``kz`` [m]
    (``M_z = kz T``)."""
    return (ry * thrust, -rx * thrust, kz * thrust)


#: the chain entry's parameters: (r_x, r_y), k_z
PARAMETERS = fields("ComOffsetParameters", ("offset", 2), "yaw_trim")


@jit(inline="always")
def wrench_term(x, q, f):
    """The step's numbers: the body moment (3) of the step's collective thrust."""
    thrust = 0.0
    for r in range(f.shape[0]):
        thrust += f[r]
    r0 = PARAMETERS.offset
    M = com_offset_moment3(thrust, x[r0], x[r0 + 1], x[PARAMETERS.yaw_trim])
    return M[0], M[1], M[2], 0.0, 0.0, 0.0


@jit(inline="always")
def wrench_stage(s, v, R, w):
    """The step's body moment, the same at every stage."""
    return (0.0, 0.0, 0.0), (s[1], s[2], s[3])


@jit
def _moment_rows(T, offset, kz, out):
    for i in range(T.shape[0]):
        store3(out[i], com_offset_moment3(T[i], offset[i, 0], offset[i, 1], kz[i]))


def com_offset_moment(thrust, offset, yaw_trim=0.0) -> np.ndarray:
    """Extra body moment [N m] of collective thrust ``thrust`` [N] when the CoM sits at
    ``offset`` = (r_x, r_y) [m] from the rotor-plane centre, ``r x (0, 0, T)``, with a yaw
    trim ``yaw_trim`` = k_z [m] (``M_z = k_z T``)."""
    batch = batch_of((thrust, ()), (offset, (2,)), (yaw_trim, ()))
    rT, ro, rk = rows_of(batch, (thrust, ()), (offset, (2,)), (yaw_trim, ()))
    out = np.zeros((int(np.prod(batch)), 3))
    _moment_rows(rT, ro, rk, out)
    return out.reshape(batch + (3,))


@dataclass(frozen=True)
class ComOffset(Compiled):
    """Centre of mass at ``offset`` = (r_x, r_y) [m] from the rotor-plane centre (body FRD):
    the rotors act about the CoM, ``M' = M + r x (0, 0, T)``; and a yaw trim ``yaw_trim`` =
    k_z [m] about the body z axis (FRD: positive turns the nose right), ``M_z' = M_z + k_z
    T`` (a tilted motor, unequal drag torques)."""

    offset: tuple = (0.0, 0.0)
    yaw_trim: float = 0.0
    name: ClassVar[str] = "com_offset"
    order: ClassVar[int] = 10
    identifiability: ClassVar[Identifiability] = Identifiability(
        scales_with=("mass", "inertia"),
        note="a thrust-proportional moment: hover needs an unequal rotor split",
    )
    explanation: ClassVar[str] = (
        "the centre of mass is offset from the rotor-plane centre "
        "(and a yaw trim): thrust makes a moment"
    )
    values: ClassVar[tuple] = (2, 3)
    syntax: ClassVar[str] = "RX,RY[,KZ] [m]"
    example: ClassVar[str] = "com_offset=0.01,-0.02"

    def __post_init__(self):
        off = vector(self.offset, 2, "com_offset")
        if max(abs(x) for x in off) > 1.0:
            raise ConfigError(f"com_offset must be within 1 m, got {off}")
        object.__setattr__(self, "offset", off)
        object.__setattr__(
            self, "yaw_trim", number(self.yaw_trim, "com_offset yaw_trim", -1.0, 1.0)
        )

    def params(self):
        return {"offset_m": list(self.offset), "yaw_trim_m": self.yaw_trim}

    @classmethod
    def from_params(cls, params):
        return cls(
            param(params, "offset_m", cls.name),
            params.get("yaw_trim_m", 0.0) if isinstance(params, dict) else 0.0,
        )

    @classmethod
    def from_values(cls, values, options):
        return cls(
            offset=tuple(values[:2]), yaw_trim=values[2] if len(values) > 2 else 0.0, **options
        )

    @classmethod
    def candidate(cls, ctx):
        """Bounds: 0.3 arm per axis, and 0.3 yaw-torque coefficients for the yaw trim."""
        arm, c = ctx.arm, ctx.c_yaw
        return ComOffsetCandidate(
            cls.name,
            ("rx [m]", "ry [m]", "kz [m]"),
            (-0.3 * arm,) * 2 + (-0.3 * c,),
            (0.3 * arm,) * 2 + (0.3 * c,),
            (0.0,) * 3,
            ((0.0,) * 3,),
            "wrench",
            affine=True,
            frames=(("offset_m", "body"),),
        )


@dataclass(frozen=True)
class ComOffsetCandidate(Candidate):
    uses_thrust: ClassVar[bool] = True
    keys: ClassVar[tuple] = (("offset_m", 0, 2), ("yaw_trim_m", 2, 3))

    def wrench(self, x, inp):
        return None, com_offset_moment(inp.thrust, x[:2], x[2])
