"""Body-stage effects: the rigid body the plant flies differs from the nominal one.

They act through the plant's ``true_vehicle`` hook, once at reset: the plant integrates the
rigid-body equations (:mod:`quadfault.dynamics`, paper eqs. 2 and 4) with the true mass and
inertia, while the controller and the recording keep the nominal vehicle. The diagnosis
replays the same equations with the same modified vehicle
(:func:`~quadfault.effects.physics.vehicle_with`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from quadfault.effects.base import Effect, Identifiability, number, param, vector
from quadfault.effects.physics import vehicle_with
from quadfault.errors import ConfigError


@dataclass(frozen=True)
class Inertia(Effect):
    """True inertia ``D J D``, ``D = diag(sqrt(scale))`` (diagonal entries scaled by
    ``scale`` [-])."""

    scale: tuple = (1.0, 1.0, 1.0)
    name: ClassVar[str] = "inertia"
    identifiability: ClassVar[Identifiability] = Identifiability(
        excitation="angular manoeuvres",
        note="the angular response to the rotor moments is scaled")
    order: ClassVar[int] = 20

    def __post_init__(self):
        s = vector(self.scale, 3, "inertia scale")
        if not all(0.05 <= x <= 20 for x in s):
            raise ConfigError(f"inertia scale must be in [0.05, 20], got {s}")
        object.__setattr__(self, "scale", s)

    def true_vehicle(self, vehicle):
        return vehicle_with(vehicle, inertia_scale=self.scale)

    def params(self):
        return {"scale": list(self.scale)}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "scale", cls.name))


@dataclass(frozen=True)
class Mass(Effect):
    """True mass ``scale`` times the nominal one (a payload, or a wrong nominal mass); acts on
    translation only (combine with :class:`Inertia` for a payload that changes the inertia).
    The rotors' thrust limit is unchanged."""

    scale: float = 1.0
    name: ClassVar[str] = "mass"
    identifiability: ClassVar[Identifiability] = Identifiability(
        excitation="thrust changes and angular manoeuvres (the angular response separates "
                   "a payload from a thrust loss)",
        note="a payload acts on translation only; at hover it is a thrust_scale")
    order: ClassVar[int] = 20

    def __post_init__(self):
        number(self.scale, "mass scale", 0.05, 20.0)

    def true_vehicle(self, vehicle):
        return vehicle_with(vehicle, mass_scale=self.scale)

    def params(self):
        return {"scale": self.scale}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "scale", cls.name))
