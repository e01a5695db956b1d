"""``inertia``: the body flies with inertia ``J_t = D J D``, ``D = diag(sqrt(s))``.

It acts through the plant's ``true_vehicle`` hook, once at reset (paper eq. 4 with the true
inertia); the controller and the recording keep the nominal vehicle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.effects.base import Effect, Identifiability, vector
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.physics import vehicle_with


@dataclass(frozen=True)
class Inertia(Effect):
    """True inertia ``D J D``, ``D = diag(sqrt(scale))`` (diagonal entries scaled by
    ``scale`` [-])."""

    scale: tuple = (1.0, 1.0, 1.0)
    name: ClassVar[str] = "inertia"
    order: ClassVar[int] = 20
    identifiability: ClassVar[Identifiability] = Identifiability(
        scales_with=("inertia", "geometry", "torque_coefficient"),
        excitation="angular manoeuvres",
        note="the angular response to the rotor moments is scaled",
    )
    explanation: ClassVar[str] = (
        "the inertia differs from the nominal value (angular response scaled)"
    )
    values: ClassVar[tuple] = (1, 3)
    syntax: ClassVar[str] = "S or SX,SY,SZ [-]"
    example: ClassVar[str] = "inertia=1.6,1.6,1"
    parameter: ClassVar[tuple] = ("scale", "scale")

    def __post_init__(self):
        s = vector(self.scale, 3, "inertia scale")
        if not all(0.05 <= x <= 20 for x in s):
            raise ConfigError(f"inertia scale must be in [0.05, 20], got {s}")
        object.__setattr__(self, "scale", s)

    def true_vehicle(self, vehicle):
        return vehicle_with(vehicle, inertia_scale=self.scale)

    @classmethod
    def candidate(cls, ctx):
        one3 = (1.0,) * 3
        return InertiaCandidate(
            cls.name, ("sx [-]", "sy [-]", "sz [-]"), (0.5,) * 3, (2.0,) * 3, one3, (one3,), "body"
        )


@dataclass(frozen=True)
class InertiaCandidate(Candidate):
    keys: ClassVar[tuple] = (("scale", 0, 3),)

    def body(self, x, vehicle):
        return vehicle_with(vehicle, inertia_scale=x)

    def public(self, x, sd, ctx):
        params, unc = super().public(x, sd, ctx)
        params["inertia_diag_kg_m2"] = (np.diag(ctx.vehicle.inertia) * np.asarray(x)).tolist()
        return params, unc
