"""``rate_damping``: the body rates decay on their own, ``M = -(D1 + D2 |w|) w`` per body
axis (linear: the rotors' inflow change; quadratic: the frame's drag)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit
from quadfault.layout import fields
from quadfault.model.effects.base import Compiled, Identifiability, param, vector
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.physics import batch_of, rows_of
from quadfault.model.rotation import store3, vec3


@jit
def rate_damping3(w, linear, quadratic):
    """``M = -(D1 + D2 |w|) w`` per body axis [N m] for body rate ``w`` [rad/s]."""
    return (
        -(linear[0] + quadratic[0] * abs(w[0])) * w[0],
        -(linear[1] + quadratic[1] * abs(w[1])) * w[1],
        -(linear[2] + quadratic[2] * abs(w[2])) * w[2],
    )


#: the chain entry's parameters
PARAMETERS = fields("RateDampingParameters", ("linear", 3), ("quadratic", 3))


@jit(inline="always")
def wrench_term(x, q, f):
    """The step's numbers: D1 (3), D2 (3)."""
    d1, d2 = PARAMETERS.linear, PARAMETERS.quadratic
    return x[d1], x[d1 + 1], x[d1 + 2], x[d2], x[d2 + 1], x[d2 + 2]


@jit(inline="always")
def wrench_stage(s, v, R, w):
    """Force (world) and moment (body) at a stage's state from the step's term ``s``."""
    return (0.0, 0.0, 0.0), rate_damping3(w, (s[1], s[2], s[3]), (s[4], s[5], s[6]))


@jit
def _moment_rows(w, linear, quadratic, out):
    for i in range(w.shape[0]):
        store3(out[i], rate_damping3(vec3(w[i]), vec3(linear[i]), vec3(quadratic[i])))


def rate_damping_moment(w: np.ndarray, linear, quadratic) -> np.ndarray:
    """Aerodynamic damping of the body rate ``w`` [rad/s]:
    ``M = -(D1 + D2 |w|) w`` per body axis [N m] (``linear`` D1 [N m s/rad], ``quadratic``
    D2 [N m s^2/rad^2])."""
    batch = batch_of((w, (3,)), (linear, (3,)), (quadratic, (3,)))
    rw, rl, rq = rows_of(batch, (w, (3,)), (linear, (3,)), (quadratic, (3,)))
    out = np.zeros((int(np.prod(batch)), 3))
    _moment_rows(rw, rl, rq, out)
    return out.reshape(batch + (3,))


@dataclass(frozen=True)
class RateDamping(Compiled):
    """Aerodynamic damping of the body rate, ``M = -(D1 + D2 |w|) w`` per body axis:
    ``linear`` D1 [N m s/rad] and ``quadratic`` D2 [N m s^2/rad^2] (3 values each)."""

    linear: tuple = (0.0, 0.0, 0.0)
    quadratic: tuple = (0.0, 0.0, 0.0)
    name: ClassVar[str] = "rate_damping"
    order: ClassVar[int] = 10
    identifiability: ClassVar[Identifiability] = Identifiability(
        scales_with=("inertia",),
        excitation="body rotation (roll, pitch or yaw rates)",
        note="the moment grows with the body rate",
    )
    explanation: ClassVar[str] = "the body rates are damped, M = -(D1 + D2 |w|) w per body axis"
    values: ClassVar[tuple] = (1, 2, 3, 6)
    syntax: ClassVar[str] = (
        "D1 | D1,D2 | D1X,D1Y,D1Z | D1X,D1Y,D1Z,D2X,D2Y,D2Z [N m s/rad, N m s^2/rad^2]"
    )
    example: ClassVar[str] = "rate_damping=0.07,0.07,0.14"

    def __post_init__(self):
        for key in ("linear", "quadratic"):
            d = vector(getattr(self, key), 3, f"rate_damping {key}")
            if min(d) < 0:
                raise ConfigError(f"rate_damping {key} must be >= 0, got {d}")
            object.__setattr__(self, key, d)

    def params(self):
        return {
            "linear_N_m_s_per_rad": list(self.linear),
            "quadratic_N_m_s2_per_rad2": list(self.quadratic),
        }

    @classmethod
    def from_params(cls, params):
        return cls(
            param(params, "linear_N_m_s_per_rad", cls.name),
            params.get("quadratic_N_m_s2_per_rad2", (0.0, 0.0, 0.0)),
        )

    @classmethod
    def from_values(cls, values, options):
        if len(values) in (1, 3):
            return cls(linear=tuple(values), **options)
        if len(values) == 2:
            return cls(linear=values[0], quadratic=values[1], **options)
        return cls(linear=tuple(values[:3]), quadratic=tuple(values[3:]), **options)

    @classmethod
    def candidate(cls, ctx):
        J = ctx.inertia
        return RateDampingCandidate(
            cls.name,
            tuple(f"D1{a} [N m s/rad]" for a in "xyz")
            + tuple(f"D2{a} [N m s^2/rad^2]" for a in "xyz"),
            (0.0,) * 6,
            tuple(J / 0.02) + tuple(J * 1.0),
            (0.0,) * 6,
            ((0.0,) * 6,),
            "wrench",
            affine=True,
        )


@dataclass(frozen=True)
class RateDampingCandidate(Candidate):
    keys: ClassVar[tuple] = (("linear_N_m_s_per_rad", 0, 3), ("quadratic_N_m_s2_per_rad2", 3, 6))

    def wrench(self, x, inp):
        x = np.asarray(x, dtype=float)
        return None, rate_damping_moment(inp.w, x[:3], x[3:])
