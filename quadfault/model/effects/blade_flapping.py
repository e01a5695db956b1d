"""``blade_flapping``: rotor drag and blade flapping. With the air-relative body velocity
``v_b = R^T (v - v_air)`` and collective thrust ``T``: the in-plane force
``F_b = -k_f T (v_bx, v_by, 0)`` and the moment ``M_b = k_m T (-v_by, v_bx, 0)``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.jit import jit
from quadfault.layout import fields
from quadfault.model.effects.base import Compiled, Identifiability, number, param, vector
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.kernels import body_velocity3, world_vector3
from quadfault.model.effects.physics import batch_of, rows_of
from quadfault.model.rotation import mat3, store3, vec3


@jit
def blade_flapping3(R, v_air, thrust, k_force, k_moment):
    """Rotor drag and blade flapping: with ``v_b = R^T v_air``, the force
    ``F_b = -k_force T (v_bx, v_by, 0)`` (returned in world axes) [N] and the moment
    ``M_b = k_moment T (-v_by, v_bx, 0)`` [N m]."""
    vb = body_velocity3(R, v_air)
    kf = k_force * thrust
    F = world_vector3(R, (kf * vb[0], kf * vb[1], kf * 0.0))
    km = k_moment * thrust
    return (-F[0], -F[1], -F[2]), (km * -vb[1], km * vb[0], km * 0.0)


#: the chain entry's parameters
PARAMETERS = fields("BladeFlappingParameters", "k_force", "k_moment", ("air_velocity", 3))


@jit(inline="always")
def wrench_term(x, q, f):
    """The step's numbers: k_force, k_moment, the collective thrust, air velocity (3)."""
    thrust = 0.0
    for r in range(f.shape[0]):
        thrust += f[r]
    air = PARAMETERS.air_velocity
    return x[PARAMETERS.k_force], x[PARAMETERS.k_moment], thrust, x[air], x[air + 1], x[air + 2]


@jit(inline="always")
def wrench_stage(s, v, R, w):
    """Force (world) and moment (body) at a stage's state from the step's term ``s``."""
    va = (v[0] - s[4], v[1] - s[5], v[2] - s[6])
    return blade_flapping3(R, va, s[3], s[1], s[2])


@jit
def _flapping_rows(R, v, T, k_force, k_moment, out_F, out_M):
    for i in range(R.shape[0]):
        F, M = blade_flapping3(mat3(R[i]), vec3(v[i]), T[i], k_force, k_moment)
        store3(out_F[i], F)
        store3(out_M[i], M)


def blade_flapping_wrench(
    R: np.ndarray, v_air: np.ndarray, thrust, k_force: float, k_moment: float
) -> tuple[np.ndarray, np.ndarray]:
    """Rotor drag and blade flapping of rotors moving through the air in their plane.

    With the air-relative body velocity ``v_b = R^T v_air`` [m/s] and collective thrust ``T``
    [N]: the in-plane force ``F_b = -k_force T (v_bx, v_by, 0)`` [N] (``k_force`` [s/m]) and
    the moment ``M_b = k_moment T e3 x v_b = k_moment T (-v_by, v_bx, 0)`` [N m] (``k_moment``
    [s]; > 0: nose up when flying forward, as the flapped discs tilt back above the CoM).
    Returns ``(F_world, M_body)``.
    """
    batch = batch_of((R, (3, 3)), (v_air, (3,)), (thrust, ()))
    rR, rv, rT = rows_of(batch, (R, (3, 3)), (v_air, (3,)), (thrust, ()))
    n = int(np.prod(batch))
    F, M = np.zeros((n, 3)), np.zeros((n, 3))
    _flapping_rows(rR, rv, rT, float(k_force), float(k_moment), F, M)
    return F.reshape(batch + (3,)), M.reshape(batch + (3,))


@dataclass(frozen=True)
class BladeFlapping(Compiled):
    """Rotor drag and blade flapping proportional to thrust and in-plane airspeed
    (:func:`blade_flapping3`): force coefficient ``k_force`` [s/m], moment coefficient
    ``k_moment`` [s], still air by default."""

    k_force: float = 0.05
    k_moment: float = 0.002
    air_velocity: tuple = (0.0, 0.0, 0.0)
    name: ClassVar[str] = "blade_flapping"
    order: ClassVar[int] = 10
    identifiability: ClassVar[Identifiability] = Identifiability(
        scales_with=("mass", "inertia"),
        channels=("velocity", "attitude"),
        excitation="in-plane airspeed (forward flight)",
        note="force and moment grow with the in-plane airspeed",
    )
    explanation: ClassVar[str] = (
        "rotor drag and blade flapping: a force against and a moment "
        "from the in-plane airspeed, both proportional to thrust"
    )
    values: ClassVar[tuple] = (1, 2)
    syntax: ClassVar[str] = "K_FORCE[,K_MOMENT] [s/m, s]"
    example: ClassVar[str] = "blade_flapping=0.05,0.005"

    def __post_init__(self):
        number(self.k_force, "blade_flapping k_force [s/m]", 0.0, 10.0)
        number(self.k_moment, "blade_flapping k_moment [s]", -1.0, 1.0)
        object.__setattr__(
            self, "air_velocity", vector(self.air_velocity, 3, "blade_flapping air_velocity")
        )

    def params(self):
        return {"k_force_s_per_m": self.k_force, "k_moment_s": self.k_moment}

    @classmethod
    def from_params(cls, params):
        return cls(
            param(params, "k_force_s_per_m", cls.name), param(params, "k_moment_s", cls.name)
        )

    @classmethod
    def from_values(cls, values, options):
        return cls(k_force=values[0], k_moment=values[1] if len(values) > 1 else 0.0, **options)

    @classmethod
    def candidate(cls, ctx):
        arm = ctx.arm
        return BladeFlappingCandidate(
            cls.name,
            ("k_force [s/m]", "k_moment [s]"),
            (0.0, -0.3 * arm),
            (0.3, 0.3 * arm),
            (0.0, 0.0),
            ((0.0, 0.0),),
            "wrench",
            needs_pose=True,
            affine=True,
        )


@dataclass(frozen=True)
class BladeFlappingCandidate(Candidate):
    uses_thrust: ClassVar[bool] = True
    keys: ClassVar[tuple] = (("k_force_s_per_m", 0, 1), ("k_moment_s", 1, 2))

    def wrench(self, x, inp):
        return blade_flapping_wrench(inp.R, inp.v, inp.thrust, float(x[0]), float(x[1]))

    def public(self, x, sd, ctx):
        """Also the force's drag coefficient at hover thrust, ``k_force m g`` [N s/m] (what a
        drag fit of the same flight reads as its horizontal ``k``)."""
        params, unc = super().public(x, sd, ctx)
        params["drag_at_hover_N_s_per_m"] = float(x[0]) * ctx.vehicle.weight
        unc["drag_at_hover_N_s_per_m"] = float(sd[0]) * ctx.vehicle.weight
        return params, unc
