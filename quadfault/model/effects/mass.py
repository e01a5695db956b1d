"""``mass``: the body flies with mass ``s m`` (a payload, or a wrong nominal mass).

It acts through the plant's ``true_vehicle`` hook, once at reset: the plant integrates the
rigid-body equations (:mod:`quadfault.model.dynamics`, paper eq. 2) with the true mass, while the
controller and the recording keep the nominal vehicle. The diagnosis replays the same
equations with the same modified vehicle (:func:`~quadfault.model.effects.physics.vehicle_with`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.model.effects.base import Effect, Identifiability, number
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.physics import vehicle_with


@dataclass(frozen=True)
class Mass(Effect):
    """True mass ``scale`` times the nominal one (a payload, or a wrong nominal mass); acts on
    translation only (combine with :class:`~quadfault.model.effects.inertia.Inertia` for a payload
    that changes the inertia). The rotors' thrust limit is unchanged."""

    scale: float = 1.0
    name: ClassVar[str] = "mass"
    order: ClassVar[int] = 20
    identifiability: ClassVar[Identifiability] = Identifiability(
        scales_with=("mass",),
        excitation="thrust changes and angular manoeuvres (the angular response separates "
        "a payload from a thrust loss)",
        note="a payload acts on translation only; at hover it is a thrust_scale",
    )
    explanation: ClassVar[str] = (
        "the mass differs from the nominal value (a payload): translation responds less"
    )
    equivalent: ClassVar[str] = "thrust"
    syntax: ClassVar[str] = "SCALE [-]"
    example: ClassVar[str] = "mass=1.15"
    parameter: ClassVar[tuple] = ("scale", "scale")

    def __post_init__(self):
        number(self.scale, "mass scale", 0.05, 20.0)

    def true_vehicle(self, vehicle):
        return vehicle_with(vehicle, mass_scale=self.scale)

    @classmethod
    def candidate(cls, ctx):
        """Bounds: a payload that leaves some thrust margin."""
        return MassCandidate(
            cls.name,
            ("scale [-]",),
            (0.5,),
            (float(np.clip(0.8 * ctx.thrust_to_weight, 1.2, 2.0)),),
            (1.0,),
            ((1.0,),),
            "body",
        )


@dataclass(frozen=True)
class MassCandidate(Candidate):
    keys: ClassVar[tuple] = (("scale", 0, 1),)

    def body(self, x, vehicle):
        return vehicle_with(vehicle, mass_scale=float(x[0]))

    def public(self, x, sd, ctx):
        params, unc = super().public(x, sd, ctx)
        params["mass_kg"] = float(x[0]) * ctx.vehicle.mass
        unc["mass_kg"] = float(sd[0]) * ctx.vehicle.mass
        return params, unc
