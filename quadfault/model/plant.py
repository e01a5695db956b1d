"""The true vehicle ("plant"): rigid body + motors + unmodelled effects.

The plant is what the controller and the estimators do *not* know. Per physics step of
length ``dt`` it takes the rotor commands [N] (held constant over the step, zero-order hold),
applies saturation, efficiency and thrust noise (:func:`quadfault.model.motors.motor_thrust`), then
the effects, and integrates the rigid body (:func:`quadfault.model.dynamics.rkmk4_step`, or the
authors' Euler step). The loop that does this is :mod:`quadfault.model.closed_loop`, flown through
:class:`quadfault.model.flight.Flight` (which also takes the true efficiency over time); this module
says what a plant is and how effects act on it.

Effects
-------
An effect is any object with these methods (:class:`quadfault.model.effects.base.Effect`, the
one effect type, gives their no-op defaults; :mod:`quadfault.model.effects` has the built-in
effects)::

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

``state`` is a :class:`~quadfault.model.dynamics.RigidBodyState` of numpy arrays (world NED, body
FRD) -- the state at the step's start for ``rotor_thrust``, the stage's state for ``wrench``.
Effects act in the order given: ``rotor_thrust`` chained, wrenches summed.

The built-in effects (the classes of ``quadfault.model.effects.EFFECTS``) always run compiled: their
parameters become each vehicle's row of the compiled effect chain
(:class:`~quadfault.model.effects.chain.EffectRows`, :attr:`Plant.hook`), their memory lives in the
plant, and mass and inertia effects set the vehicles' physical parameters. A plant with an
effect written in Python (any other object of the protocol) runs the same closed loop
interpreted by Python (:func:`quadfault.jit.python`), calling :class:`EffectsHook` at the same
two points for every effect (the built-in ones through their compiled entries); it flies one
vehicle at a time. Without effects the hook is compiled out (``fx is None``).

Per-vehicle physics: a plant of N vehicles flies them all alike; :meth:`Plant.assign` gives
vehicles their own built-in effects, vehicle parameters (mass, inertia, rotor thrust limit)
and thrust noise, e.g. drawn per episode (:mod:`quadfault.model.effects.sampling`).
"""

from __future__ import annotations

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.closed_loop import Vehicles
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.effects import rows as fx_rows
from quadfault.model.effects.base import Effect
from quadfault.model.effects.registry import EFFECTS
from quadfault.model.motors import MotorModel
from quadfault.model.vehicle import Vehicle

INTEGRATORS = ("rk4", "reference")


def _state(p, v, R, w) -> RigidBodyState:
    """The kernels' tuples as a RigidBodyState of arrays."""
    return RigidBodyState(
        np.array(p, dtype=float),
        np.array(v, dtype=float),
        np.array(R, dtype=float).reshape(3, 3),
        np.array(w, dtype=float),
    )


def flown_vehicle(vehicle: Vehicle, effects) -> Vehicle:
    """The vehicle the plant flies: ``vehicle`` passed through every effect's optional
    ``true_vehicle`` hook, in order (the controller keeps the nominal one)."""
    n = vehicle.n_rotors
    for e in effects:
        hook = getattr(e, "true_vehicle", None)
        if callable(hook):
            vehicle = hook(vehicle)
            if not isinstance(vehicle, Vehicle) or vehicle.n_rotors != n:
                raise ConfigError(
                    f"effect {type(e).__name__}.true_vehicle must return a Vehicle with {n} rotors"
                )
    return vehicle


def compiled(effect) -> bool:
    """Whether ``effect`` is a built-in effect (runs compiled; not a subclass)."""
    return type(effect) is EFFECTS.get(getattr(effect, "name", None))


def entries(effects, vehicle: Vehicle, dt: float) -> list:
    """The compiled chain's entries of the built-in ``effects`` on the flown ``vehicle``."""
    signs = np.sign(vehicle.allocation[3])
    out = [fx_rows.entry(e, vehicle.n_rotors, dt, signs) for e in effects]
    return [e for e in out if e is not None]


class EffectsHook:
    """What the interpreted loop calls (``fx``): every effect through its protocol.

    ``rotor_thrust(f, t, dt, p, v, R, w, gen)`` replaces the produced thrusts ``f`` (an array,
    in place) by the effects' chain (a built-in effect runs its compiled entry, a wind without
    a seed drawing from the vehicle's generator ``gen``); ``wrench(p, v, R, w, f, t)`` returns
    the summed external force and moment as 3-tuples.
    """

    def __init__(self, effects):
        self.effects = tuple(effects)

    def rotor_thrust(self, f, t, dt, p, v, R, w, gen) -> None:
        state = _state(p, v, R, w)
        out = f.copy()
        for e in self.effects:
            if compiled(e):
                out = e.rotor_thrust(out, t, dt, state, gen)
            else:
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
        motor: saturation and thrust noise (sigma_f of every vehicle; see ``vehicles.sigma``).
        effects: unmodelled effects applied in order (see the module docstring).
        integrator: ``"rk4"`` (default) or ``"reference"`` (the authors' Euler step).
        dt: physics step [s].
        n_vehicles: how many vehicles of these parameters (the vector env flies N).

    ``vehicles`` (:class:`~quadfault.model.closed_loop.Vehicles`) holds their state between calls
    of the loop; :attr:`state` is vehicle 0's.
    """

    def __init__(
        self,
        vehicle: Vehicle,
        motor: MotorModel | None = None,
        effects: tuple = (),
        integrator: str = "rk4",
        dt: float = 1e-3,
        n_vehicles: int = 1,
    ):
        if (motor is not None and not isinstance(motor, MotorModel)) or isinstance(
            effects, MotorModel
        ):
            raise ConfigError(
                f"Plant(vehicle, motor, effects, ...) takes a MotorModel and a "
                f"tuple of effects, got {type(motor).__name__} and "
                f"{type(effects).__name__} (the true efficiency over time is "
                f"the flight's: quadfault.model.flight.Flight)"
            )
        if integrator not in INTEGRATORS:
            raise ConfigError(f"integrator must be one of {INTEGRATORS}, got {integrator!r}")
        if not (dt > 0):
            raise ConfigError(f"dt must be positive [s], got {dt!r}")
        if integrator == "reference" and effects:
            raise ConfigError("the reference integrator does not support extra effects")
        self.nominal_vehicle = vehicle
        self.motor = motor or MotorModel()
        self.effects = tuple(effects)
        self.vehicle = flown_vehicle(vehicle, self.effects)
        self.integrator = integrator
        self.dt = float(dt)
        N = int(n_vehicles)
        self.vehicles = Vehicles.empty(N, vehicle.n_rotors, self.vehicle)
        self.vehicles.sigma[:] = self.motor.thrust_noise
        self._python = not all(compiled(e) for e in self.effects)
        self._rows = None
        built = [] if self._python else entries(self.effects, self.vehicle, self.dt)
        if built:
            self._rows = fx_rows.build([built] * N, vehicle.n_rotors)

    @property
    def state(self) -> RigidBodyState:
        """A copy of vehicle 0's true state."""
        return self.vehicles.state(0)

    def reset(self, state: RigidBodyState | None = None) -> None:
        """Start a flight of every vehicle (from ``state``, vehicle 0, when given): the
        effects' ``reset`` and ``true_vehicle``, the compiled effects' memory cleared."""
        if state is not None:
            self.vehicles.set_state(0, state)
        for e in self.effects:
            e.reset(self.nominal_vehicle.n_rotors)
        self.vehicle = flown_vehicle(self.nominal_vehicle, self.effects)
        self.vehicles.set_body(slice(None), self.vehicle)
        if self._rows is not None:
            fx_rows.reset(self._rows, np.arange(len(self._rows.slot)))

    def assign(
        self,
        rows,
        effects=None,
        *,
        vehicle: Vehicle | None = None,
        thrust_noise: float | None = None,
    ) -> None:
        """Vehicles ``rows`` start a flight with their own physics: the built-in ``effects``
        (default: the plant's) on ``vehicle`` (default: the nominal one; the same rotor
        layout) -- the flown vehicle's mass, inertia and rotor thrust limit, the effects'
        parameters with their memory cleared -- and thrust noise ``thrust_noise`` (sigma_f;
        default: unchanged). Their state is the caller's to set."""
        effects = self.effects if effects is None else tuple(effects)
        bad = [e for e in effects if not compiled(e)]
        if bad:
            raise ConfigError(
                f"per-vehicle effects must be built-in effects of "
                f"quadfault.model.effects, got {type(bad[0]).__name__}"
            )
        base = self.nominal_vehicle if vehicle is None else vehicle
        if base.n_rotors != self.nominal_vehicle.n_rotors or not np.allclose(
            base.allocation, self.vehicle.allocation
        ):
            raise ConfigError(
                "a vehicle of the batch must keep the plant's rotor layout (allocation)"
            )
        flown = flown_vehicle(base, effects)
        chain = entries(effects, flown, self.dt)
        if self._rows is None and chain:
            self._rows = fx_rows.empty(len(self.vehicles.p), 0, 0, n_rotors=base.n_rotors)
        if self._rows is not None:
            self._rows = fx_rows.grown(self._rows, chain)
        for i in np.atleast_1d(np.arange(len(self.vehicles.p))[rows]):
            if self._rows is not None:
                fx_rows.write(self._rows, i, chain)
            self.vehicles.set_body(i, flown)
            if thrust_noise is not None:
                self.vehicles.sigma[i] = float(thrust_noise)

    @property
    def hook(self):
        """The loop's effects: None without effects (the compiled loop pays nothing), the
        compiled :class:`~quadfault.model.effects.chain.EffectRows` of the built-in effects, or an
        :class:`EffectsHook` (the interpreted loop) when an effect is written in Python."""
        if self._python:
            return EffectsHook(self.effects)
        return self._rows

    def check_effects(self) -> None:
        """A one-line error when a vehicle's delay effect lost a knot it needed (steps much
        shorter than ``dt``; see :func:`quadfault.model.effects.rows.delay_capacity`)."""
        if self._rows is not None and fx_rows.lost(self._rows).any():
            raise ConfigError(
                f"delay effect: physics steps much shorter than the plant's "
                f"dt = {self.dt:g} s dropped history it needed; build the plant "
                "with the shortest step"
            )


__all__ = ["INTEGRATORS", "Effect", "EffectsHook", "Plant", "compiled", "entries", "flown_vehicle"]
