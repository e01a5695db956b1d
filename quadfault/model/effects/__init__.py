"""Unmodelled physical effects: one model for the simulator's plant and the diagnosis.

Each effect lives in one module of this package (``quadfault/model/effects/<name>.py``): a small
frozen dataclass of physical parameters, its kernels (the physics the closed loop runs step
by step and the diagnosis runs over whole recordings), its packing into the compiled chain,
its diagnosis candidate and what a recording needs to reveal it. The registry
(:mod:`quadfault.model.effects.registry`) names them all. The plant calls them through the effect
protocol (``reset``, ``rotor_thrust``, ``wrench``, ``true_vehicle``;
:class:`quadfault.model.effects.base.Effect`). Internal frames: world NED, body FRD.
docs/effects.md gives every equation, parameter, bound and ``--effect`` syntax, and how to
write a new effect.

``parse_effect("drag=0.3")`` builds an effect from the ``quadfault simulate --effect``
syntax ``NAME=V1,V2,...[,key=value...]``; :func:`from_diagnosis` loads a fitted model.
"""

from quadfault.model.effects.base import Effect, Identifiability
from quadfault.model.effects.battery_thrust import BatteryThrust, battery_factor
from quadfault.model.effects.blade_flapping import BladeFlapping, blade_flapping_wrench
from quadfault.model.effects.com_offset import ComOffset, com_offset_moment
from quadfault.model.effects.delay import Delay, zoh_cumulative, zoh_mean
from quadfault.model.effects.drag import Drag, drag_force
from quadfault.model.effects.ground_effect import GroundEffect, ground_effect_factor
from quadfault.model.effects.inertia import Inertia
from quadfault.model.effects.mass import Mass
from quadfault.model.effects.model import DiagnosedModel, FittedEffect, from_diagnosis
from quadfault.model.effects.motor_efficiency import MotorEfficiency
from quadfault.model.effects.motor_lag import MotorLag, lag_gain, lag_series
from quadfault.model.effects.physics import scaled_inertia, vehicle_with
from quadfault.model.effects.rate_damping import RateDamping, rate_damping_moment
from quadfault.model.effects.registry import EFFECT_NAMES, EFFECTS
from quadfault.model.effects.rotor_inertia import (
    RotorInertia,
    gyroscopic_moment,
    rotor_inertia_moment,
    rotor_momentum,
    thrust_rate,
)
from quadfault.model.effects.spec import canonical_order, parse_effect
from quadfault.model.effects.thrust_curve import (
    ThrustCurve,
    curve_command,
    curve_from_changes,
    curve_thrust,
    recurve,
)
from quadfault.model.effects.thrust_scale import ThrustScale
from quadfault.model.effects.wind import Wind

__all__ = [
    "EFFECTS",
    "EFFECT_NAMES",
    "BatteryThrust",
    "BladeFlapping",
    "ComOffset",
    "Delay",
    "DiagnosedModel",
    "Drag",
    "Effect",
    "FittedEffect",
    "GroundEffect",
    "Identifiability",
    "Inertia",
    "Mass",
    "MotorEfficiency",
    "MotorLag",
    "RateDamping",
    "RotorInertia",
    "ThrustCurve",
    "ThrustScale",
    "Wind",
    "battery_factor",
    "blade_flapping_wrench",
    "canonical_order",
    "com_offset_moment",
    "curve_command",
    "curve_from_changes",
    "curve_thrust",
    "drag_force",
    "from_diagnosis",
    "ground_effect_factor",
    "lag_gain",
    "lag_series",
    "parse_effect",
    "rate_damping_moment",
    "recurve",
    "rotor_inertia_moment",
    "rotor_momentum",
    "gyroscopic_moment",
    "scaled_inertia",
    "thrust_rate",
    "vehicle_with",
    "zoh_cumulative",
    "zoh_mean",
]
