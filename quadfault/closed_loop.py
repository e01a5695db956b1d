"""The closed loop: the one definition of a physics step, for every user of the model.

Per physics step k (time ``t_k = t0 + k dt``) of one vehicle, :func:`fly_vehicle` runs::

    [reference integrator: the authors' Euler step, before the sensors]
    measure      sensors (quadfault.sensors.measure3): noisy p, v, R, Omega
    control      every ``decimation`` steps: geometric controller (eqs. 9, 10) on the
                 measurement and the nominal allocation inverse (eq. 12) -> rotor commands
                 (decimation 0: the caller sets the commands between calls)
    motors       saturation, efficiency, thrust noise (eqs. 11, 13) -> produced thrusts
                 [effects: rotor_thrust]
    plant step   allocation (eq. 12), RKMK4 (eqs. 1-4) [effects: wrench at every stage]
    accelerometer the specific force at the step's start, with its noise

Random numbers come from the vehicle's ``numpy.random.Generator`` in that order (sensors,
motors, accelerometer), drawn inside the kernel; so a flight is a function of its seed only.

Who calls it:

* :func:`quadfault.simulator.simulate` -- one vehicle, the controller in the loop, chunks of
  steps between progress-bar updates;
* the Gymnasium env -- one vehicle, one call per control step (the agent's action sets the
  commands, ``decimation = 0``); the vector env -- :func:`fly_batch`, the same kernel over N
  vehicles (``prange``), each with its own generator;
* :func:`agents.rollout.fly` -- one call per physics step between the estimator's updates.

A plant with effects (:mod:`quadfault.plant`) runs :func:`fly_vehicle` interpreted by Python
with the effects hook; results equal the compiled loop's where the effects are neutral.

State between calls lives in :class:`Vehicles` (arrays the kernel updates in place); the
functions of time (efficiency per step, controller references) in :class:`Tables`; what a
caller wants kept in :class:`Records`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from quadfault.controller import (
    ControllerConstants,
    controller_tuples,
    geometric_control,
    reference_row,
    rotor_commands,
)
from quadfault.dynamics import (
    reference_euler_step,
    reference_euler_store,
    rkmk4_step,
    specific_force3,
    translational_acceleration3,
)
from quadfault.errors import ConfigError
from quadfault.jit import jit, prange, python
from quadfault.motors import motor_thrust
from quadfault.rotation import mat3, store3, store33, vec3
from quadfault.sensors import accelerometer3, measure3


class LoopConstants(NamedTuple):
    """Everything fixed over a flight, as scalars and arrays (numba's parallel loops take no
    tuples inside a tuple; :func:`fly_vehicle` builds the kernels' tuples once per call)."""

    dt: float  # physics step [s]
    t0: float  # time of step 0 [s]
    reference: bool  # the authors' Euler step instead of RKMK4
    decimation: int  # controller every this many steps; 0: the caller sets the commands
    sensors: np.ndarray  # (6,) SensorNoise.constants (the last: 1.0 when any noise)
    record_accel: bool  # measure the accelerometer (its noise drawn only then)
    saturate: bool  # clip commands to [0, f_max] (else only at 0)
    f_max: float  # per-rotor thrust limit of the true plant [N]
    mass: float  # true plant [kg]
    gravity: float  # [m/s^2]
    inertia: np.ndarray  # (3, 3) true plant [kg m^2]
    inertia_inverse: np.ndarray  # (3, 3)
    allocation: np.ndarray  # (4, n) of the true plant


class Vehicles(NamedTuple):
    """The state of N vehicles carried from call to call (updated in place)."""

    p: np.ndarray  # (N, 3) true position [m]
    v: np.ndarray  # (N, 3) true velocity [m/s]
    R: np.ndarray  # (N, 3, 3) true attitude
    w: np.ndarray  # (N, 3) true body rate [rad/s]
    memory: np.ndarray  # (N, 4, 3) the reference integrator's stored a, W', T R e3, M
    mp: np.ndarray  # (N, 3) measurement of the current step: position
    mv: np.ndarray  # (N, 3) velocity
    mR: np.ndarray  # (N, 3, 3) attitude
    mw: np.ndarray  # (N, 3) body rate
    f_cmd: np.ndarray  # (N, n) rotor commands held [N]
    f: np.ndarray  # (N, n) thrusts produced over the last step [N]
    sigma: np.ndarray  # (N,) thrust noise sigma_f

    @classmethod
    def empty(cls, n_vehicles: int, n_rotors: int) -> "Vehicles":
        N = n_vehicles
        eye = np.broadcast_to(np.eye(3), (N, 3, 3))
        return cls(np.zeros((N, 3)), np.zeros((N, 3)), eye.copy(), np.zeros((N, 3)),
                   np.zeros((N, 4, 3)), np.zeros((N, 3)), np.zeros((N, 3)), eye.copy(),
                   np.zeros((N, 3)), np.zeros((N, n_rotors)), np.zeros((N, n_rotors)),
                   np.zeros(N))

    def set_state(self, rows, state) -> None:
        """Set the true state of ``rows`` (and clear the reference integrator's memory)."""
        for dst, src in zip((self.p, self.v, self.R, self.w), state):
            dst[rows] = src
        self.memory[rows] = 0.0

    def state(self, i: int = 0):
        """A copy of vehicle ``i``'s true state (a RigidBodyState)."""
        from quadfault.dynamics import RigidBodyState

        return RigidBodyState(self.p[i].copy(), self.v[i].copy(), self.R[i].copy(),
                              self.w[i].copy())

    def measurement(self, i: int = 0):
        """A copy of vehicle ``i``'s current measurement (a RigidBodyState)."""
        from quadfault.dynamics import RigidBodyState

        return RigidBodyState(self.mp[i].copy(), self.mv[i].copy(), self.mR[i].copy(),
                              self.mw[i].copy())


class Tables(NamedTuple):
    """Functions of time per vehicle: row ``k - first[i]`` belongs to step k."""

    first: np.ndarray  # (N,) int64: the step of row 0
    eta: np.ndarray  # (N, K, n) true efficiency
    refs: np.ndarray  # (N, K, 6, 3) controller references (K may be 0 without control)


class Records(NamedTuple):
    """Per-step outputs: step k of a call starting at k0 goes to row ``(k - k0) // stride``
    when ``(k - k0) % stride == 0`` (arrays with 0 rows are not written)."""

    stride: int
    p: np.ndarray  # (N, K, 3) measured position [m]
    v: np.ndarray  # (N, K, 3) measured velocity [m/s]
    R: np.ndarray  # (N, K, 3, 3) measured attitude
    w: np.ndarray  # (N, K, 3) measured body rate [rad/s]
    f_cmd: np.ndarray  # (N, K, n) commands held over the step [N]
    accel: np.ndarray  # (N, K, 3) accelerometer reading (body FRD) [m/s^2]

    @classmethod
    def none(cls, n_vehicles: int, n_rotors: int) -> "Records":
        return cls.empty(n_vehicles, 0, n_rotors)

    @classmethod
    def empty(cls, n_vehicles: int, rows: int, n_rotors: int, stride: int = 1,
              accel: bool = True) -> "Records":
        N, K = n_vehicles, rows
        return cls(int(stride), np.empty((N, K, 3)), np.empty((N, K, 3)),
                   np.empty((N, K, 3, 3)), np.empty((N, K, 3)), np.empty((N, K, n_rotors)),
                   np.empty((N, K if accel else 0, 3)))


@jit(inline="always")
def _finite(p, v, R, w):
    ok = True
    for k in range(3):
        ok = ok and np.isfinite(p[k]) and np.isfinite(v[k]) and np.isfinite(w[k])
    for k in range(9):
        ok = ok and np.isfinite(R[k])
    return ok


@jit(inline="always")
def _allocate(A, f):
    """Collective thrust [N] and moment [N m] of rotor thrusts ``f`` (eq. 12)."""
    T = m0 = m1 = m2 = 0.0
    for i in range(f.shape[0]):
        T += A[0, i] * f[i]
        m0 += A[1, i] * f[i]
        m1 += A[2, i] * f[i]
        m2 += A[3, i] * f[i]
    return T, (m0, m1, m2)


@jit(inline="always")
def _tuples(C):
    """The kernels' tuples of :class:`LoopConstants`: the true rigid body and the sensors."""
    rigid = (C.mass, C.gravity, mat3(C.inertia), mat3(C.inertia_inverse))
    s = C.sensors
    return rigid, (s[0], s[1], s[2], s[3], s[4], s[5] != 0.0)


@jit
def fly_vehicle(i, gen, k0, k1, measure_first, C, K, V, T, out, fx, memory=None):
    """Steps ``k0 .. k1-1`` of vehicle ``i`` (see the module docstring), drawing from
    ``gen``; ``C`` the :class:`LoopConstants`, ``K`` the controller's
    :class:`~quadfault.controller.ControllerConstants` of the controller in the loop (None: the
    caller sets ``V.f_cmd``), ``V`` the :class:`Vehicles` (updated), ``T``
    the :class:`Tables`, ``out`` the :class:`Records`, ``fx`` the effects hook (None: none).
    With ``measure_first`` False the first step uses the carried measurement ``V.m*[i]``.
    ``memory`` (``V.memory``) flies the authors' Euler step (``C.reference``), None RKMK4
    (the branch not taken is compiled out). Returns the number of steps run: it stops after
    the first step whose state is not finite."""
    p, v, R, w = vec3(V.p[i]), vec3(V.v[i]), mat3(V.R[i]), vec3(V.w[i])
    mp, mv, mR, mw = vec3(V.mp[i]), vec3(V.mv[i]), mat3(V.mR[i]), vec3(V.mw[i])
    f_cmd, f, sigma = V.f_cmd[i], V.f[i], V.sigma[i]
    eta, refs, first = T.eta[i], T.refs[i], T.first[i]
    rigid, sensors = _tuples(C)
    rec = out.p.shape[1] > 0
    rec_accel = out.accel.shape[1] > 0
    done = 0
    for k in range(k0, k1):
        row = k - first
        t = C.t0 + C.dt * k
        if memory is not None:
            p, v, R, w = reference_euler_step(p, v, R, w, memory[i], rigid, C.dt)
        if k > k0 or measure_first:
            mp, mv, mR, mw = measure3(p, v, R, w, sensors, gen)
        if K is not None:  # (compiled out without a controller in the loop)
            if k % C.decimation == 0:
                gains, nominal = controller_tuples(K)
                u = geometric_control(mp, mv, mR, mw, reference_row(refs, row), gains, nominal)
                rotor_commands(u[0], u[1], K.allocation_inverse, f_cmd)
        motor_thrust(f_cmd, eta, row, C.f_max, C.saturate, sigma, gen, f)
        if fx is not None:
            fx.rotor_thrust(f, t, C.dt, p, v, R, w)
        thrust, M = _allocate(C.allocation, f)
        if memory is not None:
            reference_euler_store(memory[i], thrust, M, R)
            p1, v1, R1, w1 = p, v, R, w
            a0 = translational_acceleration3(R, thrust, rigid)
        else:
            p1, v1, R1, w1, a0 = rkmk4_step(p, v, R, w, thrust, M, rigid, C.dt, fx, f, t)
        sf = a0
        if C.record_accel:
            sf = accelerometer3(specific_force3(R, a0, C.gravity), sensors, gen)
        j = k - k0
        if rec and j % out.stride == 0:
            r = j // out.stride
            store3(out.p[i, r], mp)
            store3(out.v[i, r], mv)
            store33(out.R[i, r], mR)
            store3(out.w[i, r], mw)
            for m in range(f_cmd.shape[0]):
                out.f_cmd[i, r, m] = f_cmd[m]
            if rec_accel and C.record_accel:
                store3(out.accel[i, r], sf)
        p, v, R, w = p1, v1, R1, w1
        done += 1
        if not _finite(p, v, R, w):
            break
    store3(V.p[i], p)
    store3(V.v[i], v)
    store33(V.R[i], R)
    store3(V.w[i], w)
    store3(V.mp[i], mp)
    store3(V.mv[i], mv)
    store33(V.mR[i], mR)
    store3(V.mw[i], mw)
    return done


@jit(parallel=True)
def _fly_parallel(gens, active, k0, n_steps, measure_first, C, K, V, T, out, done):
    for r in prange(active.shape[0]):
        i = np.int64(r)  # the same specialisation of fly_vehicle as the serial loop's
        if active[i]:
            done[i] = fly_vehicle(i, gens[i], k0[i], k0[i] + n_steps, measure_first, C, K, V,
                                  T, out, None)


@jit
def _fly_serial(gens, active, k0, n_steps, measure_first, C, K, V, T, out, done):
    for i in range(active.shape[0]):
        if active[i]:
            done[i] = fly_vehicle(i, gens[i], k0[i], k0[i] + n_steps, measure_first, C, K, V,
                                  T, out, None)


@jit
def sense_vehicle(i, gen, C, V):
    """Measure vehicle ``i``'s true state into its carried measurement (the sensors' draws)."""
    mp, mv, mR, mw = measure3(vec3(V.p[i]), vec3(V.v[i]), mat3(V.R[i]), vec3(V.w[i]),
                              _tuples(C)[1], gen)
    store3(V.mp[i], mp)
    store3(V.mv[i], mv)
    store33(V.mR[i], mR)
    store3(V.mw[i], mw)


@jit
def _sense_rows(gens, rows, C, V):
    for r in range(rows.shape[0]):
        sense_vehicle(rows[r], gens[rows[r]], C, V)


#: below this many vehicles the batch runs on the calling thread (a parallel launch costs
#: more than it saves for a handful of vehicles)
PARALLEL_MIN_VEHICLES = 64


@jit
def _fly_one(gens, i, k0, k1, measure_first, C, K, V, T, out, memory):
    return fly_vehicle(i, gens[i], k0, k1, measure_first, C, K, V, T, out, None, memory)


def fly(gens, k0: int, k1: int, measure_first: bool, C: LoopConstants, V: Vehicles, T: Tables,
        out: Records, hook=None, K: ControllerConstants | None = None, i: int = 0) -> int:
    """:func:`fly_vehicle` for vehicle ``i`` with its generator ``gens[i]`` (a
    :func:`generators` list, cheap to pass per call) or ``gens`` itself (a
    ``numpy.random.Generator``); ``K``: the controller in the loop, every ``C.decimation``
    steps (None: the commands in ``V.f_cmd`` are held). With an effects ``hook`` the loop
    runs interpreted by Python (see :mod:`quadfault.plant`)."""
    if K is not None and C.decimation < 1:
        raise ConfigError(f"a controller in the loop needs a decimation >= 1, got {C.decimation}")
    gen = gens if isinstance(gens, np.random.Generator) else None
    memory = V.memory if C.reference else None
    if hook is not None:
        gen = gens[i] if gen is None else gen
        return python(fly_vehicle)(i, gen, k0, k1, measure_first, C, K, V, T, out, hook, memory)
    if gen is not None:  # a Generator: ~10 us per call to pass (fine for long calls)
        return fly_vehicle(i, gen, k0, k1, measure_first, C, K, V, T, out, None, memory)
    return _fly_one(gens, i, k0, k1, measure_first, C, K, V, T, out, memory)


def fly_batch(gens, active: np.ndarray, k0: np.ndarray, n_steps: int, measure_first: bool,
              C: LoopConstants, V: Vehicles, T: Tables, out: Records,
              K: ControllerConstants | None = None) -> np.ndarray:
    """``n_steps`` steps of every active vehicle ``i`` from its step ``k0[i]``, each with its
    generator ``gens[i]`` (a :func:`generators` list), in parallel from
    :data:`PARALLEL_MIN_VEHICLES` on (``K``: a controller in the loop, as for :func:`fly`).
    Returns the steps each vehicle ran (N,). The reference integrator and effects are single-
    vehicle features (:func:`fly`)."""
    if C.reference:
        raise ConfigError("the reference integrator flies one vehicle at a time (fly)")
    if K is not None and C.decimation < 1:
        raise ConfigError(f"a controller in the loop needs a decimation >= 1, got {C.decimation}")
    done = np.zeros(len(active), dtype=np.int64)
    kernel = _fly_parallel if len(active) >= PARALLEL_MIN_VEHICLES else _fly_serial
    kernel(gens, active, k0, int(n_steps), bool(measure_first), C, K, V, T, out, done)
    return done


def sense(gens, C: LoopConstants, V: Vehicles, i: int = 0) -> None:
    """Measure vehicle ``i`` with its generator ``gens[i]`` (or ``gens``, a Generator;
    :func:`sense_vehicle`;
    noise-free sensors draw nothing and measure the state itself, copied here without a
    kernel call)."""
    if C.sensors[5] == 0.0:
        V.mp[i], V.mv[i], V.mR[i], V.mw[i] = V.p[i], V.v[i], V.R[i], V.w[i]
    elif isinstance(gens, np.random.Generator):
        sense_vehicle(i, gens, C, V)
    else:
        _sense_rows(gens, np.array([i], dtype=np.int64), C, V)


def sense_rows(gens, rows: np.ndarray, C: LoopConstants, V: Vehicles) -> None:
    """Measure the vehicles ``rows`` with their generators ``gens`` (on the calling thread:
    a few draws per vehicle cost less than a parallel launch); noise-free sensors measure
    the state itself (copied here; ``gens`` is then not used and may be None)."""
    rows = np.asarray(rows, dtype=np.int64)
    if C.sensors[5] == 0.0:
        for m, x in ((V.mp, V.p), (V.mv, V.v), (V.mR, V.R), (V.mw, V.w)):
            m[rows] = x[rows]
    else:
        _sense_rows(gens() if callable(gens) else gens, rows, C, V)


def generators(rngs):
    """The list of generators the loop takes: one ``numpy.random.Generator`` per vehicle (a
    numba typed list: a kernel draws from them directly; passing it costs a fraction of
    passing a Generator)."""
    from quadfault.jit import typed_list

    return typed_list(rngs)


def constants(plant, sensors, decimation: int = 0, record_accel: bool = True,
              t0: float = 0.0) -> LoopConstants:
    """The :class:`LoopConstants` of a flight of ``plant`` (a :class:`~quadfault.plant.Plant`)
    measured by ``sensors`` (a SensorNoise), with the controller in the loop every
    ``decimation`` steps (0: the caller sets the commands)."""
    veh = plant.vehicle
    arr = (lambda a: np.array(a, dtype=float, order="C"))  # writable: one specialisation
    return LoopConstants(
        float(plant.dt), float(t0), plant.integrator == "reference", int(decimation),
        arr(sensors.constants), bool(record_accel), bool(plant.motor.saturate),
        float(veh.rotor_max_thrust), float(veh.mass), float(veh.gravity), arr(veh.inertia),
        arr(veh.inertia_inverse), arr(veh.allocation))


__all__ = ["LoopConstants", "Vehicles", "Tables", "Records", "fly_vehicle", "fly", "fly_batch",
           "sense", "sense_rows", "sense_vehicle", "generators", "constants",
           "PARALLEL_MIN_VEHICLES"]
