"""The closed loop: the one definition of a physics step, for every user of the model.

Per physics step k (time ``t_k = t0 + k dt``) of one vehicle, :func:`fly_vehicle` runs::

    [reference integrator: the authors' Euler step, before the sensors]
    measure      sensors (quadfault.model.sensors: measure3, or measure_model with coloured
                 noise, bias, rate and latency): the measured p, v, R, Omega
    control      every ``decimation`` steps: geometric controller (eqs. 9, 10) on the
                 measurement and the nominal allocation inverse (eq. 12) -> rotor commands
                 (decimation 0: the caller sets the commands between calls)
    motors       saturation, efficiency, thrust noise (eqs. 11, 13) -> produced thrusts
                 [effects: rotor_thrust]
    plant step   allocation (eq. 12), RKMK4 (eqs. 1-4) [effects: wrench at every stage]
    accelerometer the specific force at the step's start, with its noise (accelerometer3 or
                 accelerometer_model)

Random numbers come from the vehicle's ``numpy.random.Generator`` in that order (sensors,
motors, accelerometer), drawn inside the kernel; so a flight is a function of its seed only.

Who calls it:

* :func:`quadfault.sim.simulator.simulate` -- one vehicle, the controller in the loop, chunks of
  steps between progress-bar updates;
* the Gymnasium env -- one vehicle, one call per control step (the agent's action sets the
  commands, ``decimation = 0``); the vector env -- :func:`fly_batch`, the same kernel over N
  vehicles (``prange``), each with its own generator;
* :func:`agents.rollout.fly` -- one call per physics step between the estimator's updates.

Effects (``fx``): the built-in effects of :mod:`quadfault.model.effects` run compiled, each vehicle
its own (:class:`~quadfault.model.effects.chain.EffectRows`: parameters per vehicle, memory per
vehicle; :func:`~quadfault.model.effects.chain.step_effects` after the motors applies the thrust
stage and gives the step's wrench terms, :func:`~quadfault.model.effects.chain.effects_wrench`
adds them at every RK stage); a plant with effects
written in Python runs :func:`fly_vehicle` interpreted with its
:class:`~quadfault.model.plant.EffectsHook` at the same two points (one vehicle at a time).

State between calls lives in :class:`Vehicles` (arrays the kernel updates in place), with
each vehicle's physical parameters (mass, inertia, rotor thrust limit, thrust noise: they
may differ from vehicle to vehicle); the functions of time (efficiency per step, controller
references) in :class:`Tables`; what a caller wants kept in :class:`Records`; the constants
of the batch -- and each vehicle's sensor noise -- in :class:`LoopConstants`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit, prange, python
from quadfault.model.controller import (
    ControllerConstants,
    controller_tuples,
    geometric_control,
    reference_row,
    rotor_commands,
)
from quadfault.model.dynamics import (
    RigidBodyState,
    call_wrench,
    reference_euler_step,
    reference_euler_store,
    rkmk4_step,
    rotor_wrench,
    specific_force3,
    translational_acceleration3,
)
from quadfault.model.effects.chain import EffectRows, has_wrench, step_effects
from quadfault.model.generator_table import generator_at, generator_at_python, generator_table
from quadfault.model.motors import motor_thrust
from quadfault.model.rotation import mat3, store3, store33, vec3
from quadfault.model.sensors import (
    ROW_WIDTH,
    accelerometer3,
    accelerometer_model,
    measure3,
    measure_model,
    state_width,
)


class LoopConstants(NamedTuple):
    """What is fixed over a flight, as scalars and arrays (numba's parallel loops take no
    tuples inside a tuple; :func:`fly_vehicle` builds the kernels' tuples once per call).
    ``sensors`` has a row per vehicle (set a row to give that vehicle other noise)."""

    dt: float  # physics step [s]
    t0: float  # time of step 0 [s]
    reference: bool  # the authors' Euler step instead of RKMK4
    decimation: int  # controller every this many steps; 0: the caller sets the commands
    sensors: np.ndarray  # (N, ROW_WIDTH) SensorNoise.row per vehicle (column 5: any noise,
    # column 6: the full model)
    record_accel: bool  # measure the accelerometer (its noise drawn only then)
    saturate: bool  # clip commands to [0, f_max] (else only at 0)
    gravity: float  # [m/s^2]
    allocation: np.ndarray  # (4, n) of the true plant


class Vehicles(NamedTuple):
    """The N true vehicles: their state carried from call to call (updated in place) and
    each one's physical parameters (the flown vehicle; :meth:`set_body`)."""

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
    mass: np.ndarray  # (N,) true mass [kg]
    inertia: np.ndarray  # (N, 3, 3) true inertia [kg m^2]
    inertia_inverse: np.ndarray  # (N, 3, 3)
    f_max: np.ndarray  # (N,) per-rotor thrust limit [N]
    sensor_state: np.ndarray  # (N, S) the sensors' full model (S = 0 without it)

    @classmethod
    def empty(cls, n_vehicles: int, n_rotors: int, vehicle=None) -> Vehicles:
        """N vehicles at the origin, at rest; all of ``vehicle``'s parameters when given."""
        N = n_vehicles
        eye = np.broadcast_to(np.eye(3), (N, 3, 3))
        out = cls(
            np.zeros((N, 3)),
            np.zeros((N, 3)),
            eye.copy(),
            np.zeros((N, 3)),
            np.zeros((N, 4, 3)),
            np.zeros((N, 3)),
            np.zeros((N, 3)),
            eye.copy(),
            np.zeros((N, 3)),
            np.zeros((N, n_rotors)),
            np.zeros((N, n_rotors)),
            np.zeros(N),
            np.ones(N),
            eye.copy(),
            eye.copy(),
            np.full(N, np.inf),
            np.zeros((N, 0)),
        )
        if vehicle is not None:
            out.set_body(slice(None), vehicle)
        return out

    def set_body(self, rows, vehicle) -> None:
        """Vehicles ``rows`` fly ``vehicle``'s mass, inertia and rotor thrust limit (its
        allocation must be the batch's, :attr:`LoopConstants.allocation`)."""
        self.mass[rows] = vehicle.mass
        self.inertia[rows] = vehicle.inertia
        self.inertia_inverse[rows] = vehicle.inertia_inverse
        self.f_max[rows] = vehicle.rotor_max_thrust

    def set_state(self, rows, state) -> None:
        """Set the true state of ``rows`` (and clear the reference integrator's memory)."""
        for dst, src in zip((self.p, self.v, self.R, self.w), state):
            dst[rows] = src
        self.memory[rows] = 0.0

    def state(self, i: int = 0):
        """A copy of vehicle ``i``'s true state (a RigidBodyState)."""
        return RigidBodyState(
            self.p[i].copy(), self.v[i].copy(), self.R[i].copy(), self.w[i].copy()
        )

    def measurement(self, i: int = 0):
        """A copy of vehicle ``i``'s current measurement (a RigidBodyState)."""
        return RigidBodyState(
            self.mp[i].copy(), self.mv[i].copy(), self.mR[i].copy(), self.mw[i].copy()
        )


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
    def none(cls, n_vehicles: int, n_rotors: int) -> Records:
        return cls.empty(n_vehicles, 0, n_rotors)

    @classmethod
    def empty(
        cls, n_vehicles: int, rows: int, n_rotors: int, stride: int = 1, accel: bool = True
    ) -> Records:
        N, K = n_vehicles, rows
        return cls(
            int(stride),
            np.empty((N, K, 3)),
            np.empty((N, K, 3)),
            np.empty((N, K, 3, 3)),
            np.empty((N, K, 3)),
            np.empty((N, K, n_rotors)),
            np.empty((N, K if accel else 0, 3)),
        )


@jit(inline="always")
def _finite(p, v, R, w):
    ok = True
    for k in range(3):
        ok = ok and np.isfinite(p[k]) and np.isfinite(v[k]) and np.isfinite(w[k])
    for k in range(9):
        ok = ok and np.isfinite(R[k])
    return ok


@jit(inline="always")
def _tuples(C, V, i):
    """The kernels' tuples of vehicle ``i``: its true rigid body and its sensors."""
    rigid = (V.mass[i], C.gravity, mat3(V.inertia[i]), mat3(V.inertia_inverse[i]))
    s = C.sensors
    return rigid, (s[i, 0], s[i, 1], s[i, 2], s[i, 3], s[i, 4], s[i, 5] != 0.0)


@jit(inline="always")
def _measure(p, v, R, w, sensors, C, V, i, gen):
    """Vehicle ``i``'s measurement: the full model when its row asks for it, else white."""
    if C.sensors[i, 6] != 0.0:
        return measure_model(p, v, R, w, C.sensors[i], V.sensor_state[i], C.dt, gen)
    return measure3(p, v, R, w, sensors, gen)


@jit(inline="always")
def _accelerometer(sf, sensors, C, V, i, gen):
    if C.sensors[i, 6] != 0.0:
        return accelerometer_model(sf, C.sensors[i], V.sensor_state[i], C.dt, gen)
    return accelerometer3(sf, sensors, gen)


@jit(inline="always")
def fly_vehicle(i, gens, k0, k1, measure_first, C, K, V, T, out, fx, memory):
    """Steps ``k0 .. k1-1`` of vehicle ``i`` (see the module docstring), drawing from its
    generator ``gens[i]`` (a :func:`generators` table); ``C`` the :class:`LoopConstants`, ``K`` the controller's
    :class:`~quadfault.model.controller.ControllerConstants` of the controller in the loop (None: the
    caller sets ``V.f_cmd``), ``V`` the :class:`Vehicles` (updated), ``T``
    the :class:`Tables`, ``out`` the :class:`Records`, ``fx`` the effects (None: none; the
    :class:`~quadfault.model.effects.chain.EffectRows`, or in the interpreted loop the hook).
    With ``measure_first`` False the first step uses the carried measurement ``V.m*[i]``.
    ``memory`` (``V.memory``) flies the authors' Euler step (``C.reference``), None RKMK4
    (the branch not taken is compiled out). Returns the number of steps run: it stops after
    the first step whose state is not finite.

    The one entry point of the loop: :func:`fly` calls it, and the batch's loops call it with
    the same argument types, so that one vehicle and a batch share its compiled form."""
    gen = generator_at(gens, i)
    p, v, R, w = vec3(V.p[i]), vec3(V.v[i]), mat3(V.R[i]), vec3(V.w[i])
    mp, mv, mR, mw = vec3(V.mp[i]), vec3(V.mv[i]), mat3(V.mR[i]), vec3(V.mw[i])
    f_cmd, f, sigma, f_max = V.f_cmd[i], V.f[i], V.sigma[i], V.f_max[i]
    eta, refs, first = T.eta[i], T.refs[i], T.first[i]
    rigid, sensors = _tuples(C, V, i)
    rec = out.p.shape[1] > 0
    rec_accel = out.accel.shape[1] > 0
    done = 0
    for k in range(k0, k1):
        row = k - first
        t = C.t0 + C.dt * k
        if memory is not None:
            p, v, R, w = reference_euler_step(p, v, R, w, memory[i], rigid, C.dt)
        if k > k0 or measure_first:
            mp, mv, mR, mw = _measure(p, v, R, w, sensors, C, V, i, gen)
        if K is not None:  # (compiled out without a controller in the loop)
            if k % C.decimation == 0:
                gains, nominal = controller_tuples(K)
                u = geometric_control(mp, mv, mR, mw, reference_row(refs, row), gains, nominal)
                f_hi = f_max if C.saturate else math.inf  # the mixer's upper bound
                rotor_commands(u[0], u[1], K.allocation_inverse, f_cmd, K.yaw_release, f_hi)
        motor_thrust(f_cmd, eta, row, f_max, C.saturate, sigma, gen, f)
        # the thrust stage, and the step's wrench terms the RK stages take (numbers; the
        # chain compiled for the rows' effects alone, nothing without effects)
        W = step_effects(fx, i, f, t, C.dt, p, v, R, w, gen)
        thrust, M = rotor_wrench(C.allocation, f)
        if memory is not None:
            reference_euler_store(memory[i], thrust, M, R)
            p1, v1, R1, w1 = p, v, R, w
            a0 = translational_acceleration3(R, thrust, rigid)
        elif fx is None or not has_wrench(W):  # the stages add no wrench: none to call
            p1, v1, R1, w1, a0 = rkmk4_step(p, v, R, w, thrust, M, rigid, C.dt)
        else:
            p1, v1, R1, w1, a0 = rkmk4_step(p, v, R, w, thrust, M, rigid, C.dt, W)
        sf = a0
        if C.record_accel:
            sf = _accelerometer(specific_force3(R, a0, C.gravity), sensors, C, V, i, gen)
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


@jit(_nrt=False)
def _fly_rows(lo, hi, gens, active, k0, n_steps, measure_first, C, K, V, T, out, fx, done):
    """:func:`fly_vehicle` for the active vehicles ``lo .. hi-1``, in order, compiled without
    numba's reference counts (``_nrt=False``: the loop allocates nothing and the caller holds
    every array; with them, a loop whose body branches takes and drops a count of every
    array of its tuples at every vehicle)."""
    for i in range(lo, hi):
        if active[i]:
            done[i] = fly_vehicle(
                i, gens, k0[i], k0[i] + n_steps, measure_first, C, K, V, T, out, fx, None
            )


@jit(parallel=True)
def _fly_parallel(gens, active, k0, n_steps, measure_first, C, K, V, T, out, fx, done, chunk):
    N = active.shape[0]
    for c in prange((N + chunk - 1) // chunk):
        lo = np.int64(c) * chunk
        _fly_rows(
            lo,
            min(lo + chunk, N),
            gens,
            active,
            k0,
            n_steps,
            measure_first,
            C,
            K,
            V,
            T,
            out,
            fx,
            done,
        )


@jit(inline="always")
def measure_vehicle(i, gen, C, V):
    """Measure vehicle ``i``'s true state into its carried measurement (the sensors' draws);
    inlined where it is called (a kernel looping over vehicles takes the arrays' reference
    counts once, not once per vehicle)."""
    mp, mv, mR, mw = _measure(
        vec3(V.p[i]), vec3(V.v[i]), mat3(V.R[i]), vec3(V.w[i]), _tuples(C, V, i)[1], C, V, i, gen
    )
    store3(V.mp[i], mp)
    store3(V.mv[i], mv)
    store33(V.mR[i], mR)
    store3(V.mw[i], mw)


@jit
def sense_vehicle(i, gen, C, V):
    """:func:`measure_vehicle`, called on its own."""
    measure_vehicle(i, gen, C, V)


@jit(_nrt=False)
def _sense_rows(gens, rows, C, V):
    for r in range(rows.shape[0]):
        measure_vehicle(rows[r], generator_at(gens, rows[r]), C, V)


#: below this many vehicles the batch runs on the calling thread (a parallel launch costs
#: more than it saves for a handful of vehicles)
PARALLEL_MIN_VEHICLES = 64
#: vehicles per task of the parallel loop
CHUNK = 64


def _call_step(fx, i, f, t, dt, p, v, R, w, gen):
    """The interpreted loop's step of the chain: the hook's thrust stage, then its wrench
    with the step's thrusts and time (:class:`_StepHook`)."""
    fx.rotor_thrust(f, t, dt, p, v, R, w, gen)
    return _StepHook(fx, i, f, t)


class _StepHook:
    """The interpreted loop's wrench terms: the hook with the step's thrusts and time."""

    def __init__(self, hook, i, f, t):
        self.hook, self.f, self.t = hook, f, t

    def wrench(self, p, v, R, w, f, t):
        return self.hook.wrench(p, v, R, w, self.f, self.t)

    def has_wrench(self) -> bool:
        return True  # (a hook's wrench is called at every stage)


#: the interpreted loop's calls at the chain's two points: the hook's methods
HOOK_CALLS = {
    "step_effects": _call_step,
    "has_wrench": _StepHook.has_wrench,
    "effects_wrench": call_wrench,
    "generator_at": generator_at_python,
}


def _interpreted():
    """:func:`fly_vehicle` run by Python, calling an effects hook (an object with
    ``rotor_thrust(f, t, dt, p, v, R, w, gen)`` -- ``f`` replaced in place -- and ``wrench(p,
    v, R, w, f, t)``, :class:`quadfault.model.plant.EffectsHook`) at the chain's two points."""
    return python(fly_vehicle, HOOK_CALLS)


def _check_rotors(fx, V: Vehicles) -> None:
    """A one-line error when compiled effects ``fx`` were built for another rotor count."""
    if fx is not None and fx.layout.n_rotors != V.f.shape[1]:
        raise ConfigError(
            f"the effects were built for {fx.layout.n_rotors} rotors, the "
            f"vehicles have {V.f.shape[1]}"
        )


def fly(
    gens,
    k0: int,
    k1: int,
    measure_first: bool,
    C: LoopConstants,
    V: Vehicles,
    T: Tables,
    out: Records,
    hook=None,
    K: ControllerConstants | None = None,
    i: int = 0,
) -> int:
    """:func:`fly_vehicle` for vehicle ``i`` with its generator ``gens[i]`` (a
    :func:`generators` table, cheap to pass per call) or ``gens`` itself (a
    ``numpy.random.Generator``, put in such a list on each call); ``K``: the controller in the loop, every ``C.decimation``
    steps (None: the commands in ``V.f_cmd`` are held). ``hook``: the plant's effects
    (:attr:`quadfault.model.plant.Plant.hook`) -- compiled rows, or a hook of effects written in
    Python, with which the loop runs interpreted (see :mod:`quadfault.model.plant`)."""
    interpreted = hook is not None and not isinstance(hook, EffectRows)
    if not interpreted:
        _check_rotors(hook, V)
    if K is not None and C.decimation < 1:
        raise ConfigError(f"a controller in the loop needs a decimation >= 1, got {C.decimation}")
    memory = V.memory if C.reference else None
    if isinstance(gens, np.random.Generator):  # vehicle i's own: in the list the loop takes
        gens = generators([gens] * (i + 1))
    kernel = _interpreted() if interpreted else fly_vehicle
    return kernel(i, gens, k0, k1, measure_first, C, K, V, T, out, hook, memory)


def check_batch(C: LoopConstants, V: Vehicles, K=None, fx=None) -> None:
    """A one-line error when the batch's loop (:func:`fly_vehicle` over vehicles, compiled)
    cannot fly these vehicles: the reference integrator and effects written in Python fly
    one vehicle at a time (:func:`fly`)."""
    if C.reference:
        raise ConfigError("the reference integrator flies one vehicle at a time (fly)")
    if K is not None and C.decimation < 1:
        raise ConfigError(f"a controller in the loop needs a decimation >= 1, got {C.decimation}")
    if fx is not None and not isinstance(fx, EffectRows):
        raise ConfigError(
            "effects written in Python fly one vehicle at a time (fly); a batch "
            "flies the built-in effects of quadfault.model.effects"
        )
    _check_rotors(fx, V)


def fly_batch(
    gens,
    active: np.ndarray,
    k0: np.ndarray,
    n_steps: int,
    measure_first: bool,
    C: LoopConstants,
    V: Vehicles,
    T: Tables,
    out: Records,
    K: ControllerConstants | None = None,
    fx: EffectRows | None = None,
) -> np.ndarray:
    """``n_steps`` steps of every active vehicle ``i`` from its step ``k0[i]``, each with its
    generator ``gens[i]`` (a :func:`generators` table), in parallel from
    :data:`PARALLEL_MIN_VEHICLES` on (``K``: a controller in the loop, as for :func:`fly`;
    ``fx``: the vehicles' compiled effects, :attr:`quadfault.model.plant.Plant.hook`). Returns the
    steps each vehicle ran (N,). The reference integrator and effects written in Python fly
    one vehicle at a time (:func:`fly`)."""
    check_batch(C, V, K, fx)
    N = len(active)
    done = np.zeros(N, dtype=np.int64)
    if N >= PARALLEL_MIN_VEHICLES:
        _fly_parallel(
            gens, active, k0, int(n_steps), bool(measure_first), C, K, V, T, out, fx, done, CHUNK
        )
    else:
        _fly_rows(
            0, N, gens, active, k0, int(n_steps), bool(measure_first), C, K, V, T, out, fx, done
        )
    return done


def sense(gens, C: LoopConstants, V: Vehicles, i: int = 0) -> None:
    """Measure vehicle ``i`` with its generator ``gens[i]`` (or ``gens``, a Generator;
    :func:`sense_vehicle`;
    noise-free sensors draw nothing and measure the state itself, copied here without a
    kernel call)."""
    if C.sensors[i, 5] == 0.0:
        V.mp[i], V.mv[i], V.mR[i], V.mw[i] = V.p[i], V.v[i], V.R[i], V.w[i]
    elif isinstance(gens, np.random.Generator):
        sense_vehicle(i, gens, C, V)
    else:
        _sense_rows(gens, np.array([i], dtype=np.int64), C, V)


def sense_rows(gens, rows: np.ndarray | None, C: LoopConstants, V: Vehicles) -> None:
    """Measure the vehicles ``rows`` (None: all) with their generators ``gens`` (on the
    calling thread: a few draws per vehicle cost less than a parallel launch); noise-free
    sensors measure the state itself (copied here; ``gens`` is then not used and may be
    None)."""
    every = rows is None
    rows = np.arange(len(V.p)) if every else np.asarray(rows, dtype=np.int64)
    if not C.sensors[rows, 5].any():
        for m, x in ((V.mp, V.p), (V.mv, V.v), (V.mR, V.R), (V.mw, V.w)):
            if every:
                m[...] = x
            else:
                m[rows] = x[rows]
    else:
        _sense_rows(gens() if callable(gens) else gens, rows, C, V)


def sensor_state(V: Vehicles, rows: np.ndarray, dt: float) -> Vehicles:
    """``V`` with a sensor state wide enough for sensor ``rows`` (N, ROW_WIDTH) at physics step
    ``dt`` [s] (its own array when it already is; zeroed: each flight starts at its first
    measurement)."""
    width = state_width(rows, dt)
    if V.sensor_state.shape[1] >= width:
        return V
    return V._replace(sensor_state=np.zeros((len(V.p), width)))


def restart_sensors(V: Vehicles, rows=None) -> None:
    """The sensors of vehicles ``rows`` (None: all) start a new flight at their next
    measurement (new biases, coloured noise from its stationary law, no history)."""
    if V.sensor_state.shape[1]:
        V.sensor_state[slice(None) if rows is None else rows, 0] = 0.0


def generators(rngs):
    """The generators the loop takes: one ``numpy.random.Generator`` per vehicle, as a
    :class:`~quadfault.model.generator_table.GeneratorTable` (a kernel draws from them directly,
    without the reference counts of a typed list; passing it costs a fraction of passing a
    Generator)."""
    return generator_table(rngs)


def constants(
    plant, sensors, decimation: int = 0, record_accel: bool = True, t0: float = 0.0
) -> LoopConstants:
    """The :class:`LoopConstants` of a flight of ``plant`` (a :class:`~quadfault.model.plant.Plant`;
    its vehicles' physical parameters are in ``plant.vehicles``) measured by ``sensors`` (a
    SensorNoise, for every vehicle), with the controller in the loop every ``decimation``
    steps (0: the caller sets the commands). The vehicles get the sensor state the full model
    needs (:func:`sensor_state`)."""
    veh = plant.vehicle
    N = len(plant.vehicles.p)
    sensor_rows = np.array(np.broadcast_to(sensors.row, (N, ROW_WIDTH)))
    plant.vehicles = sensor_state(plant.vehicles, sensor_rows, plant.dt)
    return LoopConstants(
        float(plant.dt),
        float(t0),
        plant.integrator == "reference",
        int(decimation),
        sensor_rows,
        bool(record_accel),
        bool(plant.motor.saturate),
        float(veh.gravity),
        np.array(veh.allocation, dtype=float, order="C"),
    )


__all__ = [
    "LoopConstants",
    "Vehicles",
    "Tables",
    "Records",
    "fly_vehicle",
    "fly",
    "fly_batch",
    "check_batch",
    "sense",
    "sense_rows",
    "sense_vehicle",
    "measure_vehicle",
    "generators",
    "constants",
    "restart_sensors",
    "sensor_state",
    "PARALLEL_MIN_VEHICLES",
]
