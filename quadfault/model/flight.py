"""One flight interface over the compiled closed loop: what the simulator, the environments,
the agents' rollouts and the diagnosis' replay fly.

A :class:`Flight` flies the vehicles of a :class:`~quadfault.model.plant.Plant` (one, or a batch of
N) through :mod:`quadfault.model.closed_loop`, measured by a
:class:`~quadfault.model.sensors.SensorNoise`::

    flight = Flight(plant, sensors)                 # the caller sets the commands
    flight.reset(seed=0, state=start)               # a generator per vehicle, the start
    flight.plan(n_steps, efficiency=schedule)       # the true efficiency of the coming steps
    out = flight.records(n_steps)                   # what to keep (optional)
    flight.step(commands, n_steps, record=out)      # commands held over the steps

or, with the geometric controller in the loop every ``control_every`` steps,
``Flight(plant, sensors, controller=ctrl, control_every=10)`` and ``flight.step(None, n)``.

What a caller needs to know: each vehicle has a step counter (:attr:`k`, 0 at its reset;
step k starts at ``t0 + k dt``), its own ``numpy.random.Generator`` (set by :meth:`reset`;
the loop draws the sensors, the motors' thrust noise and the accelerometer from it, in that
order, so a flight is a function of its seed), its held rotor commands (:attr:`commands`
[N]), its true state and its current measurement (:attr:`truth`, :attr:`measurement`, as
views: read them at once). The true efficiency reaches the loop one way: a table of the
coming steps, from a schedule (:meth:`plan`) or from a caller's window of rows refilled in
place (:meth:`use_efficiency`, the environments' time tables); without one the motors are
nominal. The loop's constants, tables and generator lists stay inside.
"""

from __future__ import annotations

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model import closed_loop
from quadfault.model.closed_loop import Records
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.scenarios import at_times
from quadfault.model.sensor_presets import as_sensor_noise
from quadfault.model.sensors import SensorNoise


def tabulate(schedule, times, n_rotors: int) -> np.ndarray:
    """The efficiency ``schedule`` (``t -> (n,)``; None: nominal) at ``times`` [s]:
    ``(len(times), n_rotors)``."""
    times = np.asarray(times, dtype=float)
    if schedule is None:
        return np.ones((len(times), n_rotors))
    eta = np.asarray(at_times(schedule, times), dtype=float)
    if eta.shape != (len(times), n_rotors):
        raise ConfigError(
            f"the efficiency schedule gave shape {eta.shape} for {len(times)} "
            f"times, expected ({len(times)}, {n_rotors})"
        )
    return np.ascontiguousarray(eta)


class Flight:
    """The vehicles of ``plant`` flown by the closed loop (see the module docstring).

    Args:
        plant: the true vehicle(s): parameters, motors, effects, state.
        sensors: the sensors of every vehicle (default noise-free): a
            :class:`~quadfault.model.sensors.SensorNoise` or what ``as_sensor_noise`` takes
            (a preset name such as ``"crazyflie"``).
        controller: a :class:`~quadfault.model.controller.GeometricController` in the loop (one
            vehicle; its references come from :meth:`plan`), or None: the caller sets the
            commands.
        control_every: the controller's period in physics steps.
        record_accel: measure the accelerometer (its noise is drawn only then).
        t0: time of step 0 [s].
    """

    def __init__(
        self,
        plant,
        sensors: SensorNoise | str | None = None,
        *,
        controller=None,
        control_every: int = 1,
        record_accel: bool = True,
        t0: float = 0.0,
    ):
        self.plant = plant
        self.sensors = as_sensor_noise(sensors, "sensors")
        self.controller = controller
        self._K = None if controller is None else controller.constants
        decimation = 0 if controller is None else int(control_every)
        self._C = closed_loop.constants(plant, self.sensors, decimation, record_accel, t0)
        V = plant.vehicles
        self.n_vehicles, self.n_rotors = V.f_cmd.shape
        N = self.n_vehicles
        #: each vehicle's next step
        self.k = np.zeros(N, dtype=np.int64)
        #: the steps each vehicle ran in the last :meth:`step` (it stops after a step whose
        #: state is not finite)
        self.steps_run = np.zeros(N, dtype=np.int64)
        self._nominal = True  # no efficiency table: the motors are nominal
        self._no_refs = np.zeros((N, 0, 6, 3))
        self._tables = closed_loop.Tables(
            np.zeros(N, dtype=np.int64), np.ones((N, 1, self.n_rotors)), self._no_refs
        )
        self._rngs: list = [None] * N
        self._gens = None  # the loop's list of the generators, built when needed
        self._none = Records.none(N, self.n_rotors)

    # -- time and physics ------------------------------------------------------------------
    @property
    def dt(self) -> float:
        """Physics step [s]."""
        return self._C.dt

    @property
    def t0(self) -> float:
        """Time of step 0 [s]."""
        return self._C.t0

    def time(self, i: int = 0) -> float:
        """Time of vehicle ``i``'s next step [s]."""
        return self._C.t0 + self._C.dt * int(self.k[i])

    @property
    def thrust_noise(self) -> np.ndarray:
        """Each vehicle's thrust noise sigma_f [N] (N,) (a view)."""
        return self.plant.vehicles.sigma

    def set_thrust_noise(self, rows, sigma) -> None:
        """Thrust noise sigma_f [N] of the vehicles ``rows`` (from their next step)."""
        self.plant.vehicles.sigma[rows] = sigma

    # -- starting flights --------------------------------------------------------------------
    def reset(self, seed=None, *, rows=None, state: RigidBodyState | None = None) -> None:
        """Start flights of the vehicles ``rows`` (default all): their generators, the true
        ``state`` (arrays with a leading axis of ``len(rows)``, or one vehicle's), step 0,
        zero commands, and a fresh measurement when ``state`` is given.

        ``seed``: an int or None (a new ``numpy.random.Generator``), a Generator (drawn from
        as it is: a caller that draws from it too shares its stream), or one of those per row.
        """
        rows = (
            np.arange(self.n_vehicles)
            if rows is None
            else np.atleast_1d(np.asarray(rows, dtype=np.int64))
        )
        seeds = seed if isinstance(seed, (list, tuple)) else [seed] * len(rows)
        if len(seeds) != len(rows):
            raise ConfigError(f"reset needs {len(rows)} seeds, got {len(seeds)}")
        self.seed(
            rows,
            [s if isinstance(s, np.random.Generator) else np.random.default_rng(s) for s in seeds],
        )
        self.restart(rows, state)

    def restart(self, rows, state: RigidBodyState | None = None) -> None:
        """Start new flights of the vehicles ``rows`` (an int array) drawing on from the
        generators they have: step 0, zero commands, new sensors, and the true ``state``
        (arrays with a leading axis of ``len(rows)``) measured when given. Vectorised: no
        Python per vehicle."""
        self.k[rows] = 0
        self.plant.vehicles.f_cmd[rows] = 0.0
        closed_loop.restart_sensors(self.plant.vehicles, rows)
        if state is not None:
            self.plant.vehicles.set_state(rows, state)
            self.sense(rows)

    def seed(self, rows, generators) -> None:
        """The vehicles ``rows`` draw from ``generators`` (one ``numpy.random.Generator``
        each) from now on, without restarting their flights."""
        rows = np.atleast_1d(np.asarray(rows, dtype=np.int64)).tolist()
        for i, g in zip(rows, generators):
            self._rngs[i] = g
        if self._gens is not None:
            if 4 * len(rows) > self.n_vehicles:
                self._gens = None  # rebuilt when needed: cheaper than many setitems
            else:
                self._gens.put(rows, [self._rngs[i] for i in rows])

    def generator(self, i: int = 0):
        """Vehicle ``i``'s generator."""
        return self._rngs[i]

    def generator_table(self):
        """The vehicles' generators as the table a compiled kernel draws from
        (:func:`quadfault.model.generator_table.generator_at`); take it again after a
        :meth:`reset` or :meth:`seed`."""
        return self._generators()

    def _generators(self):
        if self._gens is None:
            if any(g is None for g in self._rngs):
                raise ConfigError("reset the flight (its generators) before flying it")
            self._gens = closed_loop.generators(self._rngs)
        return self._gens

    def set_state(self, state: RigidBodyState, i: int = 0) -> None:
        """Put vehicle ``i`` at the true ``state`` (without measuring it)."""
        self.plant.vehicles.set_state(i, state)

    # -- functions of time -------------------------------------------------------------------
    def plan(self, n_steps: int, efficiency=None) -> np.ndarray:
        """Tabulate the coming ``n_steps`` of vehicle 0 (from its step :attr:`k`): the true
        efficiency ``efficiency`` (``t -> (n,)``; None: nominal) and, with a controller in
        the loop, its references. Returns the efficiency table ``(n_steps, n)``."""
        k0 = int(self.k[0])
        times = self._C.t0 + self._C.dt * (k0 + np.arange(int(n_steps)))
        eta = tabulate(efficiency, times, self.n_rotors)
        refs = (
            self._no_refs
            if self.controller is None
            else np.ascontiguousarray(self.controller.reference_rows(times)[None])
        )
        self._tables = closed_loop.Tables(np.full(1, k0, dtype=np.int64), eta[None], refs)
        self._nominal = False
        return eta

    def use_efficiency(self, eta: np.ndarray, first: np.ndarray) -> None:
        """Fly the efficiency table ``eta`` (N, K, n): row ``k - first[i]`` is vehicle i's
        at step k (``first`` (N,) int64, in physics steps). The arrays are held, not copied:
        a caller that refills them in place (a moving window) keeps the flight current."""
        if eta.ndim != 3 or eta.shape[0] != self.n_vehicles or eta.shape[2] != self.n_rotors:
            raise ConfigError(
                f"the efficiency table must be ({self.n_vehicles}, K, "
                f"{self.n_rotors}), got {eta.shape}"
            )
        self._tables = closed_loop.Tables(first, eta, self._no_refs)
        self._nominal = False

    def _nominal_tables(self, n: int) -> None:
        """Nominal efficiency for the coming ``n`` steps of every vehicle."""
        T = self._tables
        if T.eta.shape[1] < n:
            T = self._tables = T._replace(eta=np.ones((self.n_vehicles, n, self.n_rotors)))
        T.first[:] = self.k

    # -- flying ------------------------------------------------------------------------------
    def records(self, n_steps: int, stride: int = 1, accel: bool = True) -> Records:
        """Arrays for :meth:`step` to keep every ``stride``-th of ``n_steps`` steps: the
        measurement, the commands held and (``accel``) the accelerometer, ``(N, rows, ...)``."""
        return Records.empty(
            self.n_vehicles, -(-int(n_steps) // int(stride)), self.n_rotors, stride, accel
        )

    def step(
        self,
        commands=None,
        n: int = 1,
        *,
        record: Records | None = None,
        active: np.ndarray | None = None,
        measure_first: bool = False,
    ):
        """Fly ``n`` physics steps of every (``active``) vehicle with ``commands`` [N] held
        ((n,) or (N, n); None: the held ones, or the controller's in the loop).

        The first step uses the carried measurement (:meth:`sense`) unless
        ``measure_first``; ``record`` (:meth:`records`) keeps the steps' measurements,
        commands and accelerometer (rows of vehicles not flown hold their measurement).
        Returns ``record``; the steps each vehicle ran are in :attr:`steps_run`."""
        V = self.plant.vehicles
        if commands is not None:
            V.f_cmd[:] = commands
        if self._nominal:
            self._nominal_tables(n)
        out = self._none if record is None else record
        if self.n_vehicles == 1 and active is None:
            k0 = int(self.k[0])
            gens = self._gens if self._gens is not None else self._generators()
            self.steps_run[0] = closed_loop.fly(
                gens,
                k0,
                k0 + n,
                measure_first,
                self._C,
                V,
                self._tables,
                out,
                self.plant.hook,
                self._K,
            )
            self.k[0] = k0 + n
            return record
        if active is None:
            active = np.ones(self.n_vehicles, dtype=bool)
        elif record is not None and not active.all():
            idle = ~active
            for rec, m in zip(record[1:5], (V.mp, V.mv, V.mR, V.mw)):
                rec[idle] = m[idle, None]
        self.steps_run[:] = closed_loop.fly_batch(
            self._generators(),
            active,
            self.k,
            n,
            measure_first,
            self._C,
            V,
            self._tables,
            out,
            self._K,
            self.plant.hook,
        )
        self.k[active] += n
        return record

    def loop(self, record: Records | None = None) -> tuple:
        """The closed loop's arguments of this flight, for a caller whose compiled code calls
        :func:`~quadfault.model.closed_loop.fly_vehicle` per vehicle itself (the vector env's
        fused step): ``(generators, constants, vehicles, tables, records, effects)``, checked
        (:func:`~quadfault.model.closed_loop.check_batch`). The caller advances :attr:`k`;
        take them again after a :meth:`reset` or :meth:`seed` (the generators' table)."""
        V = self.plant.vehicles
        closed_loop.check_batch(self._C, V, None, self.plant.hook)
        out = self._none if record is None else record
        return self._generators(), self._C, V, self._tables, out, self.plant.hook

    def step_at(self, commands, t: float, dt: float) -> None:
        """One step of vehicle 0 of length ``dt`` [s] from time ``t`` [s] with ``commands``
        held (a recording's own clock; its step counter stays), measuring its start."""
        V = self.plant.vehicles
        V.f_cmd[0] = commands
        C = self._C._replace(dt=float(dt), t0=float(t))
        k = self.k.copy()
        self.k[:] = 0
        if self._nominal:
            self._nominal_tables(1)
        gens = self._gens if self._gens is not None else self._generators()
        closed_loop.fly(gens, 0, 1, True, C, V, self._tables, self._none, self.plant.hook, self._K)
        self.k[:] = k

    def sense(self, rows=None, *, noise: bool = True) -> None:
        """Measure the vehicles ``rows`` (default all) now, drawing the sensor noise from
        their generators; ``noise=False``: their measurement is their true state (no draw)."""
        V = self.plant.vehicles
        if not noise:
            for m, x in zip((V.mp, V.mv, V.mR, V.mw), (V.p, V.v, V.R, V.w)):
                m[rows] = x[rows]
        elif rows is None and self.n_vehicles == 1:
            gens = self._gens if self._gens is not None else self._generators()
            closed_loop.sense(gens, self._C, V)
        else:
            closed_loop.sense_rows(self._generators, rows, self._C, V)

    # -- what the vehicles are doing ---------------------------------------------------------
    @property
    def commands(self) -> np.ndarray:
        """Rotor commands held (N, n) [N] (a view)."""
        return self.plant.vehicles.f_cmd

    @property
    def truth(self) -> RigidBodyState:
        """True states (N, ...) -- views of the arrays the loop updates."""
        V = self.plant.vehicles
        return RigidBodyState(V.p, V.v, V.R, V.w)

    @property
    def measurement(self) -> RigidBodyState:
        """Current measurements (N, ...) -- views."""
        V = self.plant.vehicles
        return RigidBodyState(V.mp, V.mv, V.mR, V.mw)

    def views(self, i: int = 0) -> tuple[RigidBodyState, RigidBodyState]:
        """Vehicle ``i``'s true state and measurement as views that stay current (the loop
        writes them in place): take them once, read them when needed."""
        V = self.plant.vehicles
        return (
            RigidBodyState(V.p[i], V.v[i], V.R[i], V.w[i]),
            RigidBodyState(V.mp[i], V.mv[i], V.mR[i], V.mw[i]),
        )

    def state(self, i: int = 0) -> RigidBodyState:
        """A copy of vehicle ``i``'s true state."""
        return self.plant.vehicles.state(i)

    def measured(self, i: int = 0) -> RigidBodyState:
        """A copy of vehicle ``i``'s current measurement."""
        return self.plant.vehicles.measurement(i)


__all__ = ["Flight", "Records", "tabulate"]
