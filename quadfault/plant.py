"""The true vehicle ("plant"): rigid body + motors + efficiency schedule + unmodelled effects.

The plant is what the controller and the estimators do *not* know. Per physics step of
length ``dt`` it takes the rotor commands [N] (held constant over the step, zero-order hold),
applies saturation, efficiency and thrust noise (:class:`~quadfault.motors.MotorModel`), then
any effects (motor lag, delay, drag, wind, ...), and integrates the rigid body.

Effects follow the small :class:`Effect` protocol, so the mismatch diagnosis can model the
same physics with the same code.
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np

from quadfault.dynamics import ReferenceEuler, RigidBodyState, specific_force_body, step_rk4
from quadfault.dynamics import translational_acceleration
from quadfault.errors import ConfigError
from quadfault.motors import MotorModel
from quadfault.vehicle import Vehicle

INTEGRATORS = ("rk4", "reference")


class Effect(Protocol):
    """An unmodelled physical effect of the true plant (see ``quadfault.effects``)."""

    def reset(self, n_rotors: int) -> None: ...

    def rotor_thrust(self, f: np.ndarray, t: float, dt: float, state: RigidBodyState) -> np.ndarray:
        """Transform the produced rotor thrusts [N] for the step starting at ``t``."""

    def wrench(self, state: RigidBodyState, f: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """External force (world) [N] and moment (body) [N m] at ``state``."""

    # optional: ``true_vehicle(vehicle) -> Vehicle``, the rigid body the plant flies (another
    # mass or inertia), applied once at reset; the controller keeps the nominal vehicle.


def flown_vehicle(vehicle: Vehicle, effects) -> Vehicle:
    """The vehicle the plant flies: ``vehicle`` passed through every effect's optional
    ``true_vehicle`` hook, in order."""
    for e in effects:
        hook = getattr(e, "true_vehicle", None)
        if hook is not None:
            vehicle = hook(vehicle)
    return vehicle


class PlantStep(NamedTuple):
    rotor_thrust: np.ndarray  # thrust each rotor produced over the step [N]
    eta: np.ndarray  # true efficiency used [-]
    specific_force: np.ndarray  # accelerometer truth at the step start, body FRD [m/s^2]


class Plant:
    """The true multirotor.

    Args:
        vehicle: true vehicle parameters (the controller may hold different, nominal ones);
            effects with a ``true_vehicle`` hook modify it at every reset (``self.vehicle`` is
            the one flown, ``self.nominal_vehicle`` the one given).
        efficiency: callable ``t -> (4,)`` true motor efficiency.
        motor: saturation and thrust noise.
        effects: unmodelled effects applied in order.
        integrator: ``"rk4"`` (default) or ``"reference"`` (the authors' Euler step).
        dt: physics step [s].
        rng: the plant's random generator (thrust noise).
    """

    def __init__(self, vehicle: Vehicle, efficiency, motor: MotorModel | None = None,
                 effects: tuple = (), integrator: str = "rk4", dt: float = 1e-3,
                 rng: np.random.Generator | None = None):
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
        self.rng = rng if rng is not None else np.random.default_rng()
        self.state = RigidBodyState.at_rest()
        self._reference = ReferenceEuler(vehicle, dt) if integrator == "reference" else None

    def reset(self, state: RigidBodyState) -> None:
        self.state = state.copy()
        for e in self.effects:
            e.reset(self.nominal_vehicle.n_rotors)
        self.vehicle = flown_vehicle(self.nominal_vehicle, self.effects)
        if self._reference is not None:
            self._reference = ReferenceEuler(self.vehicle, self.dt)

    def _external(self, f_rotor, t):
        if not self.effects:
            return None

        def external(state):
            F = np.zeros(state.p.shape)
            M = np.zeros(state.w.shape)
            for e in self.effects:
                dF, dM = e.wrench(state, f_rotor, t)
                F = F + dF
                M = M + dM
            return F, M

        return external

    def produced_thrust(self, f_cmd: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Rotor thrusts [N] actually produced for commands ``f_cmd`` at time ``t``."""
        eta = np.asarray(self.efficiency(t), dtype=float)
        f = self.motor.apply(f_cmd, eta, self.vehicle.rotor_max_thrust, self.rng)
        for e in self.effects:
            f = e.rotor_thrust(f, t, self.dt, self.state)
        return f, eta

    def step(self, f_cmd: np.ndarray, t: float) -> PlantStep:
        """Advance one physics step from time ``t`` with rotor commands ``f_cmd`` [N]."""
        f, eta = self.produced_thrust(f_cmd, t)
        wrench = self.vehicle.wrench(f)
        thrust, moment = wrench[..., 0], wrench[..., 1:]
        external = self._external(f, t)
        F_ext = None if external is None else external(self.state)[0]
        acc = translational_acceleration(self.state.R, thrust, self.vehicle, F_ext)
        sf = specific_force_body(self.state.R, acc, self.vehicle.gravity)
        if self._reference is None:
            self.state = step_rk4(self.state, thrust, moment, self.vehicle, self.dt, external)
        else:
            # The reference stores the wrench after its (lagged) step: see ReferenceEuler.
            self._reference.apply(thrust, moment, self.state.R)
        return PlantStep(f, eta, sf)

    def advance_reference(self) -> RigidBodyState:
        """Reference mode only: the authors' step, run *before* the controller each sample."""
        self.state = self._reference.step(self.state)
        return self.state
