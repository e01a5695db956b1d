"""``drag``: a force against the velocity through the air, ``F = -R diag(k) R^T (v - v_air)``
[N] (``k`` per body axis [N s/m])."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit
from quadfault.layout import fields
from quadfault.model.effects.base import Compiled, Identifiability, vector
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.kernels import body_velocity3, world_vector3
from quadfault.model.effects.physics import batch_of, rows_of
from quadfault.model.rotation import mat3, store3, vec3


@jit
def drag_force3(R, v_air, k):
    """``-R diag(k) R^T v_air`` [N] for air-relative velocity ``v_air`` (world) [m/s] and
    drag ``k`` [N s/m] per body axis; ``-k v_air`` when the three are equal (``R R^T = I``:
    the same force without the two rotations, which the RK stages would wait for)."""
    if k[0] == k[1] and k[1] == k[2]:
        return (-(k[0] * v_air[0]), -(k[0] * v_air[1]), -(k[0] * v_air[2]))
    vb = body_velocity3(R, v_air)
    F = world_vector3(R, (vb[0] * k[0], vb[1] * k[1], vb[2] * k[2]))
    return (-F[0], -F[1], -F[2])


#: the chain entry's parameters
PARAMETERS = fields("DragParameters", ("k", 3), ("air_velocity", 3))


@jit(inline="always")
def wrench_term(x, q, f):
    """The step's numbers: k (3), air velocity (3)."""
    k, air = PARAMETERS.k, PARAMETERS.air_velocity
    return x[k], x[k + 1], x[k + 2], x[air], x[air + 1], x[air + 2]


@jit(inline="always")
def wrench_stage(s, v, R, w):
    """Force (world) and moment (body) at a stage's state from the step's term ``s``."""
    va = (v[0] - s[4], v[1] - s[5], v[2] - s[6])
    return drag_force3(R, va, (s[1], s[2], s[3])), (0.0, 0.0, 0.0)


@jit
def _drag_rows(R, v, k, out):
    for i in range(R.shape[0]):
        store3(out[i], drag_force3(mat3(R[i]), vec3(v[i]), vec3(k[i])))


def drag_force(R: np.ndarray, v_air: np.ndarray, k) -> np.ndarray:
    """``-R diag(k) R^T v_air`` [N] for air-relative velocity ``v_air`` (world) [m/s]."""
    k = np.asarray(k, dtype=float)
    k = np.broadcast_to(k, k.shape[:-1] + (3,)) if k.ndim else np.full(3, float(k))
    batch = batch_of((R, (3, 3)), (v_air, (3,)), (k, (3,)))
    rR, rv, rk = rows_of(batch, (R, (3, 3)), (v_air, (3,)), (k, (3,)))
    out = np.zeros((int(np.prod(batch)), 3))
    _drag_rows(rR, rv, rk, out)
    return out.reshape(batch + (3,))


@dataclass(frozen=True)
class Drag(Compiled):
    """Linear (rotor) drag ``k`` [N s/m] per body axis, opposing the air-relative velocity;
    ``air_velocity`` [m/s] (world) is the steady air motion it sees (default still air)."""

    k: tuple = (0.3, 0.3, 0.3)
    air_velocity: tuple = (0.0, 0.0, 0.0)
    name: ClassVar[str] = "drag"
    order: ClassVar[int] = 10
    identifiability: ClassVar[Identifiability] = Identifiability(
        scales_with=("mass",),
        channels=("velocity", "attitude"),
        excitation="speeds through the air of about 1 m/s or more",
        note="the force opposes the velocity through the air: no valid velocity, no drag",
    )
    explanation: ClassVar[str] = (
        "a force opposes the velocity through the air, F = -R diag(k) R^T v"
    )
    values: ClassVar[tuple] = (1, 3)
    syntax: ClassVar[str] = "K or KX,KY,KZ [N s/m]"
    example: ClassVar[str] = "drag=0.3"
    parameter: ClassVar[tuple] = ("k", "k_N_s_per_m")

    def __post_init__(self):
        k = vector(self.k, 3, "drag k")
        if min(k) < 0:
            raise ConfigError(f"drag coefficients must be >= 0 [N s/m], got {k}")
        object.__setattr__(self, "k", k)
        object.__setattr__(self, "air_velocity", vector(self.air_velocity, 3, "drag air_velocity"))

    @classmethod
    def candidate(cls, ctx):
        m, zero3 = ctx.mass, (0.0,) * 3
        return DragCandidate(
            cls.name,
            ("kx [N s/m]", "ky [N s/m]", "kz [N s/m]"),
            zero3,
            (3.0 * m, 3.0 * m, 5.0 * m),
            zero3,
            (zero3, (0.5 * m,) * 3),
            "wrench",
            needs_pose=True,
            affine=True,
        )


@dataclass(frozen=True)
class DragCandidate(Candidate):
    keys: ClassVar[tuple] = (("k_N_s_per_m", 0, 3),)

    def wrench(self, x, inp):
        return drag_force(inp.R, inp.v, x), None

    def wrench_series(self, x, rp, inp):
        """The same force from its linear basis, cached on ``rp``: column i is the force of
        ``k = e_i`` at every interval."""
        D = rp.__dict__.get("_drag_basis")
        if D is None:
            D = np.stack([drag_force(rp.R, rp.v, e) for e in np.eye(3)], axis=-1)
            object.__setattr__(rp, "_drag_basis", D)
        return D @ np.asarray(x, dtype=float), None
