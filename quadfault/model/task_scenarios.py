"""Scenario generators of the tasks: random smooth tracking and an abrupt rotor loss.

Both draw everything from the caller's :class:`numpy.random.Generator` and scale with the
vehicle's size (Froude scaling): a task defined for the paper's F450 (arm
:data:`REFERENCE_ARM`) flies, on a vehicle of arm ``L``, lengths times ``s = L / REFERENCE_ARM``
and speeds times ``sqrt(s)``, so accelerations, tilt angles and the thrust margin they ask
for stay the same. A 30 g Crazyflie (arm 0.046 m) is then given metre-scale curves at about
0.5 m/s instead of the F450's 3 m circle.

* :class:`~quadfault.model.trajectory.SmoothTrack` -- per horizontal axis ``p_i(t) = c_i + s_i A_i (1 - cos(w_i t))``
  (it starts at rest at ``c``), heading turning at a constant rate. With peak axis speed
  ``v_i = A_i w_i`` and axis curvature ``kappa_i = 1 / A_i`` (the curvature of the path where
  the axis' speed peaks: when both axes share one frequency a quarter period apart the path
  is a circle of radius ``1 / kappa``), :func:`track_scenario` draws ``v`` and ``kappa`` from
  ranges and sets ``A = 1 / kappa``, ``w = v kappa``.
* :func:`rotor_loss_scenario` -- hover; one rotor drops abruptly to an efficiency in
  ``level`` (0: the rotor is lost) at an onset drawn from ``onset`` (fractions of the
  flight) and stays there.
"""

from __future__ import annotations

import math

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.scenarios import (
    N_MOTORS,
    AbruptFault,
    ConstantEfficiency,
    EfficiencySchedule,
    LinearVoltage,
    Scenario,
    VoltageDegradation,
)
from quadfault.model.trajectory import Hover, SmoothTrack

#: arm length of the paper's F450 [m]: the vehicle the tasks' default ranges are written for
REFERENCE_ARM = 0.225

#: default ranges of :func:`track_scenario` (for the reference arm; scaled by the vehicle)
TRACK_SPEED = (0.5, 2.0)  # peak speed of each horizontal axis [m/s]
TRACK_CURVATURE = (0.3, 1.0)  # inverse amplitude of each horizontal axis [1/m]
TRACK_YAW_RATE = (-0.3, 0.3)  # heading rate [rad/s]
ROTOR_LOSS_LEVEL = (0.0, 0.5)  # efficiency of the failed rotor after the loss
ROTOR_LOSS_ONSET = (0.3, 0.6)  # onset, fraction of the flight


def arm_length(allocation) -> float:
    """The rotors' largest lever arm about the roll and pitch axes [m] (rows 1-2 of the
    allocation ``[T; Mx; My; Mz]`` per unit thrust)."""
    A = np.asarray(allocation, dtype=float)
    return float(np.max(np.abs(A[1:3])))


def size_scale(vehicle) -> float:
    """Length scale of ``vehicle`` against the F450: ``arm / REFERENCE_ARM`` (1 for None)."""
    if vehicle is None:
        return 1.0
    return arm_length(vehicle.allocation) / REFERENCE_ARM


def _range(name: str, value, low: float | None = None, high: float | None = None) -> tuple:
    """A checked ``(a, b)`` range with ``a <= b`` (inside ``[low, high]`` when given)."""
    try:
        a, b = (float(x) for x in value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a (low, high) pair, got {value!r}") from None
    if not (math.isfinite(a) and math.isfinite(b) and a <= b):
        raise ConfigError(f"{name} must be finite with low <= high, got {value!r}")
    if (low is not None and a < low) or (high is not None and b > high):
        raise ConfigError(f"{name} must lie in [{low}, {high}], got {value!r}")
    return a, b


def _duration(duration) -> float:
    T = float(duration)
    if not (math.isfinite(T) and T > 0):
        raise ConfigError(f"duration must be positive [s], got {duration!r}")
    return T


def track_scenario(
    rng: np.random.Generator,
    duration: float = 20.0,
    *,
    speed: tuple = TRACK_SPEED,
    curvature: tuple = TRACK_CURVATURE,
    yaw_rate: tuple = TRACK_YAW_RATE,
    altitude: float = 1.0,
    degradation: tuple | None = None,
    level: tuple | None = None,
    onset: tuple = ROTOR_LOSS_ONSET,
    thrust_noise: float = 0.07,
    vehicle=None,
) -> Scenario:
    """A random smooth trajectory (:class:`SmoothTrack`); all motors healthy by default, or
    degrading gradually and/or losing one rotor abruptly.

    Args:
        rng: the generator every draw comes from.
        duration: flight time [s].
        speed: range of each horizontal axis' peak speed [m/s] (for the F450; times
            ``sqrt(size_scale(vehicle))``).
        curvature: range of each horizontal axis' curvature ``1 / amplitude`` [1/m] (for the
            F450; divided by ``size_scale(vehicle)``).
        yaw_rate: range of the heading rate [rad/s].
        altitude: height of the start above the origin [m] (times the size scale).
        degradation: None (no degradation) or the range of every motor's efficiency at the
            end of the flight, reached by a battery voltage falling linearly over the flight
            (:class:`~quadfault.model.scenarios.VoltageDegradation`, ``xi`` 0.25 /V).
        level: None (no fault) or the range of the efficiency one rotor (drawn uniformly)
            drops to abruptly, as in :func:`rotor_loss_scenario`, at a time drawn from
            ``onset`` (fractions of the flight); the other rotors keep degrading.
        vehicle: the flown vehicle (sets the size scale; None: the F450).

    The draws of the trajectory come first and are those of the healthy task; the
    degradation and the fault are drawn after them, only when asked for.
    """
    T = _duration(duration)
    deg = None if degradation is None else _range("degradation", degradation, 0.05, 1.0)
    lv = None if level is None else _range("level", level, 0.0, 1.0)
    on = _range("onset", onset, 0.0, 1.0)
    v_lo, v_hi = _range("speed", speed, 0.0)
    k_lo, k_hi = _range("curvature", curvature, 0.0)
    if k_lo <= 0:
        raise ConfigError(f"curvature must be > 0 [1/m], got {curvature!r}")
    r_lo, r_hi = _range("yaw_rate", yaw_rate)
    s = size_scale(vehicle)
    A, w = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    for i in range(2):
        v = float(rng.uniform(v_lo, v_hi)) * math.sqrt(s)
        kappa = float(rng.uniform(k_lo, k_hi)) / s
        sign = 1.0 if rng.random() < 0.5 else -1.0
        A[i], w[i] = sign / kappa, v * kappa
    traj = SmoothTrack(
        (0.0, 0.0, -altitude * s),
        tuple(A),
        tuple(w),
        float(rng.uniform(-math.pi, math.pi)),
        float(rng.uniform(r_lo, r_hi)),
    )
    base, faults = ConstantEfficiency(), ()
    if deg is not None:  # eta_end = exp(xi (V_end - V_start))
        xi = VoltageDegradation.xi
        v_end = LinearVoltage.v_start + math.log(float(rng.uniform(*deg))) / xi
        base = VoltageDegradation(LinearVoltage(v_end=v_end, duration=T), xi=xi)
    if lv is not None:
        motor = int(rng.integers(1, N_MOTORS + 1))
        t0 = float(rng.uniform(*on)) * T
        faults = (AbruptFault(motor=motor, onset=t0, level=float(rng.uniform(*lv))),)
    return Scenario("track", T, EfficiencySchedule(base, faults), traj, thrust_noise=thrust_noise)


def rotor_loss_scenario(
    rng: np.random.Generator,
    duration: float = 10.0,
    *,
    level: tuple = ROTOR_LOSS_LEVEL,
    onset: tuple = ROTOR_LOSS_ONSET,
    altitude: float = 1.0,
    thrust_noise: float = 0.07,
    vehicle=None,
) -> Scenario:
    """Hover; one rotor (drawn uniformly) drops abruptly to an efficiency drawn from
    ``level`` at a time drawn from ``onset`` (fractions of ``duration``) and stays there.

    Args:
        level: range of the failed rotor's efficiency after the loss (0 = rotor lost).
        onset: range of the onset as fractions of the flight, inside [0, 1].
        altitude: hover height [m] (times the vehicle's size scale).
    """
    T = _duration(duration)
    lv = _range("level", level, 0.0, 1.0)
    on = _range("onset", onset, 0.0, 1.0)
    s = size_scale(vehicle)
    motor = int(rng.integers(1, N_MOTORS + 1))
    t0 = float(rng.uniform(*on)) * T
    eta = float(rng.uniform(*lv))
    fault = AbruptFault(motor=motor, onset=t0, level=eta)
    return Scenario(
        "rotor_loss",
        T,
        EfficiencySchedule(ConstantEfficiency(), (fault,)),
        Hover((0.0, 0.0, -altitude * s)),
        thrust_noise=thrust_noise,
    )
