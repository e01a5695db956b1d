"""``ground_effect``: thrust grows near the ground (Cheeseman-Bennett),
``f_i' = f_i / (1 - (r / 4h)^2)``, ``h`` the height above the ground plane ``z = ground_z``
(world NED) clipped to ``h >= r / 2``."""

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


@jit
def ground_effect_factor1(height, rotor_radius):
    """Cheeseman-Bennett ratio ``1 / (1 - (r / 4h)^2)``, ``h`` [m] clipped to ``r / 2``."""
    h = max(height, max(0.5 * rotor_radius, 1e-6))
    q = rotor_radius / (4.0 * h)
    return 1.0 / (1.0 - q * q)


#: the chain entry's parameters
PARAMETERS = fields("GroundEffectParameters", "rotor_radius", "ground_z")


@jit(inline="always")
def thrust_step(x, q, f, t, dt, p, gen, streams, i):
    """The chain's entry: the thrusts' gain at the height at the step's start."""
    height = x[PARAMETERS.ground_z] - p[2]
    return scaled(f, ground_effect_factor1(height, x[PARAMETERS.rotor_radius]))


@jit
def _factor_rows(x, rotor_radius, out):
    for i in range(x.shape[0]):
        out[i] = ground_effect_factor1(x[i], rotor_radius)


def ground_effect_factor(height, rotor_radius: float) -> np.ndarray:
    """Cheeseman-Bennett thrust ratio ``1 / (1 - (r / 4h)^2)`` for height ``h`` [m] above the
    ground and rotor radius ``r`` [m]; ``h`` is clipped to ``r / 2`` (ratio at most 4/3)."""
    (xs,) = rows_of(np.shape(height), (height, ()))
    out = np.empty(len(xs))
    _factor_rows(xs, float(rotor_radius), out)
    return shaped(out, np.shape(height))


@dataclass(frozen=True)
class GroundEffect(Compiled):
    """Cheeseman-Bennett ground effect: rotor radius [m], ground plane ``z = ground_z`` [m]
    (world NED; 0 = the height where the recording's z is 0)."""

    rotor_radius: float = 0.1
    ground_z: float = 0.0
    name: ClassVar[str] = "ground_effect"
    order: ClassVar[int] = 3
    identifiability: ClassVar[Identifiability] = Identifiability(
        channels=("position",),
        excitation="heights that vary within a few rotor radii of the ground",
        note="the gain depends on the height above the ground, z = 0",
    )
    explanation: ClassVar[str] = (
        "thrust grows near the ground (Cheeseman-Bennett, ground plane at z = 0)"
    )
    syntax: ClassVar[str] = "RADIUS [m]"
    example: ClassVar[str] = "ground_effect=0.3"
    options: ClassVar[dict] = {"ground_z": float}

    def __post_init__(self):
        number(self.rotor_radius, "ground_effect rotor radius [m]", 0.0, 2.0)
        number(self.ground_z, "ground_effect ground_z [m]")

    def params(self):
        return {"rotor_radius_m": self.rotor_radius, "ground_z_m": self.ground_z}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "rotor_radius_m", cls.name), params.get("ground_z_m", 0.0))

    @classmethod
    def from_values(cls, values, options):
        return cls(rotor_radius=values[0], **options)

    @classmethod
    def fit_note(cls, params, selected):
        return " Height above the ground is taken as -z of the recording (ground at z = 0)."

    @classmethod
    def candidate(cls, ctx):
        arm = ctx.arm
        return GroundEffectCandidate(
            cls.name,
            ("rotor_radius^2 [m^2]",),
            (0.0,),
            (arm**2,),
            (0.0,),
            tuple(((k * arm) ** 2,) for k in (0.2, 0.45, 0.7, 0.95)),
            "thrust",
            cls.order,
            needs_pose=True,
        )


@dataclass(frozen=True)
class GroundEffectCandidate(Candidate):
    """Parameter: the squared rotor radius [m^2] (smooth at 0); reported as the radius."""

    def thrust(self, x, rp, f, t, dt):
        r = float(np.sqrt(max(x[0], 0.0)))
        return f * ground_effect_factor(-rp.p[:, 2], r)[:, None]

    def public(self, x, sd, ctx):
        r = float(np.sqrt(max(x[0], 0.0)))
        sr = float(sd[0] / (2 * r)) if r > 0 else float(np.sqrt(sd[0]))
        return {"rotor_radius_m": r, "ground_z_m": 0.0}, {"rotor_radius_m": sr}

    def public_bounds(self, x=None):
        return {"rotor_radius_m": [float(np.sqrt(self.lower[0])), float(np.sqrt(self.upper[0]))]}

    def x_from_params(self, params):
        return np.array([float(params["rotor_radius_m"]) ** 2])
