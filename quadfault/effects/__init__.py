"""Unmodelled physical effects: one model for the simulator's plant and the diagnosis.

Each effect is a small frozen dataclass of physical parameters; the physics are pure
functions (:mod:`quadfault.effects.physics`, batched over leading axes). The plant calls them
one step at a time through the effect protocol (``reset``, ``rotor_thrust``, ``wrench``,
``true_vehicle``; :class:`quadfault.effects.base.Effect`), and the mismatch diagnosis
(:mod:`quadfault.diagnosis.library`) calls the *same* functions over a whole recording.
Internal frames: world NED, body FRD. docs/effects.md gives every equation, parameter,
bound and ``--effect`` syntax.

==================  =======================================================================
name                model
==================  =======================================================================
thrust_curve        ``f' = a + b u + c u^2``, ``u`` the command the nominal curve maps to f
battery_thrust      ``f' = f (V / V_ref)^n`` (battery voltage V)
motor_efficiency    ``f_i' = eta_i f_i`` (per-rotor thrust loss, paper eq. 13)
thrust_scale        ``f_i' = s f_i`` (all rotors)
ground_effect       ``f_i' = f_i / (1 - (r / 4h)^2)`` (Cheeseman-Bennett), ``h`` = height above
                    the ground plane ``z = ground_z`` (NED), clipped to ``h >= r / 2``
delay               ``f'(t) = f(t - d)``; over a step the mean of the delayed zero-order hold
motor_lag           ``tau f'' = f - f'``, exact for a held command
drag                ``F = -R diag(k) R^T (v - v_air)`` [N] (body axes)
wind                air at ``v_air(t)`` (steady + Ornstein-Uhlenbeck gusts) seen through wind
                    drag ``k_w``: ``F = R diag(k_w) R^T v_air`` [N]
com_offset          ``M' = M + r x (0, 0, T)`` (CoM at ``r`` from the rotor-plane centre)
blade_flapping      ``F_b = -k_f T (v_bx, v_by, 0)``, ``M_b = k_m T (-v_by, v_bx, 0)``
rotor_inertia       ``M_z = kappa sum_i s_i df_i/dt``
rate_damping        ``M = -(D1 + D2 |w|) w`` per body axis
inertia             the plant flies ``J_t = D J D``, ``D = diag(sqrt(s))``
mass                the plant flies mass ``s m``
==================  =======================================================================

``parse_effect("drag=0.3")`` builds an effect from the ``quadfault simulate --effect``
syntax ``NAME=V1,V2,...[,key=value...]``; :func:`from_diagnosis` loads a fitted model.
"""

from quadfault.effects.base import Effect
from quadfault.effects.body import Inertia, Mass
from quadfault.effects.model import DiagnosedModel, FittedEffect, from_diagnosis
from quadfault.effects.physics import (
    battery_factor,
    blade_flapping_wrench,
    com_offset_moment,
    curve_command,
    curve_from_changes,
    curve_thrust,
    drag_force,
    ground_effect_factor,
    lag_gain,
    lag_series,
    rate_damping_moment,
    recurve,
    rotor_inertia_moment,
    scaled_inertia,
    thrust_rate,
    vehicle_with,
    zoh_cumulative,
    zoh_mean,
)
from quadfault.effects.spec import EFFECT_NAMES, EFFECTS, canonical_order, parse_effect
from quadfault.effects.thrust import (
    BatteryThrust,
    Delay,
    GroundEffect,
    MotorEfficiency,
    MotorLag,
    ThrustCurve,
    ThrustScale,
)
from quadfault.effects.wrench import BladeFlapping, ComOffset, Drag, RateDamping, RotorInertia, Wind

__all__ = [
    "EFFECTS", "EFFECT_NAMES", "BatteryThrust", "BladeFlapping", "ComOffset", "Delay",
    "DiagnosedModel", "Drag", "Effect", "FittedEffect", "GroundEffect", "Inertia", "Mass",
    "MotorEfficiency", "MotorLag", "RateDamping", "RotorInertia", "ThrustCurve", "ThrustScale",
    "Wind", "battery_factor", "blade_flapping_wrench", "canonical_order", "com_offset_moment",
    "curve_command", "curve_from_changes", "curve_thrust", "drag_force", "from_diagnosis", "ground_effect_factor",
    "lag_gain", "lag_series", "parse_effect", "rate_damping_moment", "recurve",
    "rotor_inertia_moment", "scaled_inertia", "thrust_rate", "vehicle_with", "zoh_cumulative",
    "zoh_mean",
]
