"""The true vehicle ("plant"): rigid body + motors + efficiency schedule + unmodelled effects.

The plant is what the controller and the estimators do *not* know. Per physics step of
length ``dt`` it takes the rotor commands [N] (held constant over the step, zero-order hold),
applies saturation, efficiency and thrust noise (:func:`quadfault.motors.motor_thrust`), then
the effects, and integrates the rigid body (:func:`quadfault.dynamics.rkmk4_step`, or the
authors' Euler step). The loop that does this is :mod:`quadfault.closed_loop`; this module
says what a plant is and how effects act on it.

Effects (the hook)
------------------
An effect is any object with these methods (numpy form; :mod:`quadfault.effects` has the
built-in ones)::

    reset(n_rotors) -> None                    # start of a flight
    rotor_thrust(f, t, dt, state) -> f_new     # produced rotor thrusts [N] (n,) after the
                                               # motor model, for the step [t, t + dt); may
                                               # keep internal state (lag, delay)
    wrench(state, f, t) -> (F_world, M_body)   # extra force [N] (world) and moment [N m]
                                               # (body), evaluated at every RK stage's state
    true_vehicle(vehicle) -> Vehicle           # optional: the vehicle the plant flies (e.g.
                                               # another mass or inertia), applied at reset;
                                               # the controller and the recording keep the
                                               # nominal vehicle

``state`` is a :class:`~quadfault.dynamics.RigidBodyState` of numpy arrays (world NED, body
FRD) -- the state at the step's start for ``rotor_thrust``, the stage's state for ``wrench``.
Effects act in the order given: ``rotor_thrust`` chained, wrenches summed.

A plant with effects runs the same closed loop interpreted by Python
(:func:`quadfault.jit.python`), whose kernels call :class:`EffectsHook` at those two
points; without effects the loop is compiled and the hook is compiled out (``fx is None``).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from quadfault.closed_loop import Vehicles
from quadfault.dynamics import RigidBodyState
from quadfault.errors import ConfigError
from quadfault.motors import MotorModel
from quadfault.vehicle import Vehicle

INTEGRATORS = ("rk4", "reference")


class Effect(Protocol):
    """An unmodelled physical effect of the true plant (see the module docstring)."""

    def reset(self, n_rotors: int) -> None: ...

    def rotor_thrust(self, f: np.ndarray, t: float, dt: float, state: RigidBodyState) -> np.ndarray:
        """Transform the produced rotor thrusts [N] for the step starting at ``t``."""

    def wrench(self, state: RigidBodyState, f: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """External force (world) [N] and moment (body) [N m] at ``state``."""


def _state(p, v, R, w) -> RigidBodyState:
    """The kernels' tuples as a RigidBodyState of arrays."""
    return RigidBodyState(np.array(p, dtype=float), np.array(v, dtype=float),
                          np.array(R, dtype=float).reshape(3, 3), np.array(w, dtype=float))


def flown_vehicle(vehicle: Vehicle, effects) -> Vehicle:
    """The vehicle the plant flies: ``vehicle`` passed through every effect's optional
    ``true_vehicle`` hook, in order (the controller keeps the nominal one)."""
    n = vehicle.n_rotors
    for e in effects:
        hook = getattr(e, "true_vehicle", None)
        if callable(hook):
            vehicle = hook(vehicle)
            if not isinstance(vehicle, Vehicle) or vehicle.n_rotors != n:
                raise ConfigError(f"effect {type(e).__name__}.true_vehicle must return a "
                                  f"Vehicle with {n} rotors")
    return vehicle


class EffectsHook:
    """What the interpreted loop calls (``fx``): the effects in numpy form.

    ``rotor_thrust(f, t, dt, p, v, R, w)`` replaces the produced thrusts ``f`` (an array,
    in place) by the effects' chain; ``wrench(p, v, R, w, f, t)`` returns the summed
    external force and moment as 3-tuples.
    """

    def __init__(self, effects):
        self.effects = tuple(effects)

    def rotor_thrust(self, f, t, dt, p, v, R, w) -> None:
        state = _state(p, v, R, w)
        out = f.copy()
        for e in self.effects:
            out = e.rotor_thrust(out, t, dt, state)
        f[:] = out

    def wrench(self, p, v, R, w, f, t):
        state = _state(p, v, R, w)
        F, M = np.zeros(3), np.zeros(3)
        for e in self.effects:
            dF, dM = e.wrench(state, f, t)
            F = F + dF
            M = M + dM
        return (F[0], F[1], F[2]), (M[0], M[1], M[2])


class Plant:
    """The true multirotor(s): what the closed loop flies, and their state.

    Args:
        vehicle: the vehicle's parameters (the controller may hold different, nominal ones);
            effects with ``true_vehicle`` change it at :meth:`reset`.
        efficiency: callable ``t -> (n,)`` true motor efficiency (arrays of times give rows).
        motor: saturation and thrust noise (sigma_f of every vehicle; see ``vehicles.sigma``).
        effects: unmodelled effects applied in order (see the module docstring).
        integrator: ``"rk4"`` (default) or ``"reference"`` (the authors' Euler step).
        dt: physics step [s].
        n_vehicles: how many vehicles of these parameters (the vector env flies N).

    ``vehicles`` (:class:`~quadfault.closed_loop.Vehicles`) holds their state between calls
    of the loop; :attr:`state` is vehicle 0's.
    """

    def __init__(self, vehicle: Vehicle, efficiency=None, motor: MotorModel | None = None,
                 effects: tuple = (), integrator: str = "rk4", dt: float = 1e-3,
                 n_vehicles: int = 1):
        if integrator not in INTEGRATORS:
            raise ConfigError(f"integrator must be one of {INTEGRATORS}, got {integrator!r}")
        if not (dt > 0):
            raise ConfigError(f"dt must be positive [s], got {dt!r}")
        if integrator == "reference" and effects:
            raise ConfigError("the reference integrator does not support extra effects")
        self.nominal_vehicle = vehicle
        self.efficiency = efficiency
        self.motor = motor or MotorModel()
        self.effects = tuple(effects)
        self.vehicle = flown_vehicle(vehicle, self.effects)
        self.integrator = integrator
        self.dt = float(dt)
        self.vehicles = Vehicles.empty(int(n_vehicles), vehicle.n_rotors)
        self.vehicles.sigma[:] = self.motor.thrust_noise

    @property
    def state(self) -> RigidBodyState:
        """A copy of vehicle 0's true state."""
        return self.vehicles.state(0)

    def reset(self, state: RigidBodyState | None = None) -> None:
        """Start a flight (from ``state``, vehicle 0, when given): the effects' ``reset``
        and ``true_vehicle``."""
        if state is not None:
            self.vehicles.set_state(0, state)
        for e in self.effects:
            e.reset(self.nominal_vehicle.n_rotors)
        self.vehicle = flown_vehicle(self.nominal_vehicle, self.effects)

    @property
    def hook(self) -> EffectsHook | None:
        """The loop's effects hook (None without effects: the compiled loop)."""
        return EffectsHook(self.effects) if self.effects else None


__all__ = ["INTEGRATORS", "Effect", "EffectsHook", "Plant", "flown_vehicle"]
