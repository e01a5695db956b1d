"""QuadFaultVectorEnv: N quadrotors stepped in one call (a gymnasium VectorEnv).

The physics is the core model's one closed loop over the sub-envs: one
:class:`quadfault.model.flight.Flight` of N vehicles runs the same per-vehicle kernel the single
:class:`~quad_fault_env.envs.quad_fault.QuadFaultEnv` runs, in parallel over the vehicles
(``prange``), one call per control step. The configuration is one: the keywords are those of
the single env, validated once (:attr:`QuadFaultVectorEnv.single_env`, never stepped); the
per-episode state is arrays over the rows. Resets are batched: per row only the seed, the
scenario (``QuadFaultEnv._make_scenario``) and the row's draws; the initial states come from
:func:`quad_fault_env.envs.episode_start.start_states` over all reset rows -- the function
the single env's reset calls with one row -- so both envs share one definition of an episode
start. The estimate comes from the batched estimators of :mod:`estimators.batched`, fed the
measurements the loop recorded at the estimator's substeps.

Seeds and random streams: sub-env i owns the generator its single twin would own --
``reset(seed=s)`` seeds sub-env i with ``s + i`` (as ``SyncVectorEnv``) -- and the loop draws
from it in the single env's order (per physics substep: sensors, motors, accelerometer; the
end-of-step measurement after the termination check). Hence N single envs reset with seeds
``s .. s+N-1`` and fed the same actions give the same trajectories (tested to 1e-9).

Differences from the single env: ``info`` holds the per-env arrays below (no per-substep
``samples`` / ``eta_true_samples`` / ``specific_force_samples``, no ``fault_events``); no
rendering; only the named estimators with a batched form (:mod:`estimators.registry`), the
nominal belief ``"none"`` and the oracle ``"truth"``.
"""

from __future__ import annotations

import os

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from estimators.base import STATUSES
from estimators.registry import estimator_names, estimator_spec, make_estimator
from quad_fault_env import vector_step
from quad_fault_env.envs.config import (
    INFO_LEVELS,
    REASONS,
    check_choice,
    check_keywords,
    keywords_of,
    light_info,
    validate_action,
)
from quad_fault_env.envs.env_config import KEYWORDS as ENV_KEYWORDS
from quad_fault_env.envs.episode_start import SPREAD_DRAWS, nominal_starts, start_states
from quad_fault_env.envs.quad_fault import QuadFaultEnv
from quad_fault_env.envs.scenario_source import GENERATORS
from quad_fault_env.estimation import NOMINAL_PRIOR_SD
from quad_fault_env.observation import SD_MAX
from quad_fault_env.time_tables import InternTable, RowTimeTables, window_steps
from quad_fault_env.vector_step import StepConstants, StepOut, StepRows
from quadfault import jit
from quadfault.errors import ConfigError
from quadfault.model.closed_loop import Records
from quadfault.model.controller import GeometricController
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.effects.sampling import describe
from quadfault.model.flight import Flight
from quadfault.model.motors import MotorModel
from quadfault.model.plant import Plant

#: batch size from which the vector env runs its step (and its batched estimator) on numba's
#: threads by default; below it, on the calling thread alone (measured on an idle 2-core
#: machine: ``benchmarks/numba_threads.py --task physics`` and ``--task study``,
#: docs/throughput.md "numba threads")
THREADS_MIN_BATCH = 1024
#: the estimators the vector env takes: those with a batched form, the nominal belief and the
#: oracle (both computed here)
VECTOR_ESTIMATORS = (
    estimator_names(batched=True) + estimator_names(role="nominal") + estimator_names(role="oracle")
)
AUTORESET_MODES = {"next_step": AutoresetMode.NEXT_STEP, "same_step": AutoresetMode.SAME_STEP}
#: estimator status -> its code (the env keeps codes; names only in the full ``info``)
_STATUS = {name: k for k, name in enumerate(STATUSES)}
#: ``max_episode_steps`` of an env without one
_NO_LIMIT = np.iinfo(np.int64).max // 4


def usable_cores() -> int:
    """The CPUs this process may run on (its affinity: ``taskset``, a container's cpuset),
    at most numba's thread count."""
    import numba

    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # (no affinity on this platform)
        cpus = os.cpu_count() or 1
    return max(1, min(cpus, numba.config.NUMBA_NUM_THREADS))


def default_threads(num_envs: int) -> int | None:
    """The numba thread count a vector env of ``num_envs`` sub-envs steps with by default: 1
    below :data:`THREADS_MIN_BATCH`, else the CPUs this process may use
    (:func:`usable_cores`); None (the caller's count) when the user set
    ``NUMBA_NUM_THREADS``: their choice is kept."""
    if os.environ.get("NUMBA_NUM_THREADS"):
        return None
    return 1 if num_envs < THREADS_MIN_BATCH else usable_cores()


class QuadFaultVectorEnv(VectorEnv):
    """N :class:`~quad_fault_env.envs.quad_fault.QuadFaultEnv` episodes stepped as arrays.

    Args:
        num_envs: N.
        estimator: one of :data:`VECTOR_ESTIMATORS` (``"irls" | "ekf" | "truth" | "none"``;
            batched: :mod:`estimators.batched`).
        estimator_kwargs: ``config=`` of the estimator.
        max_episode_steps: truncation after this many control steps (the registration's
            value through ``gym.make_vec``), like ``TimeLimit`` on the single env.
        autoreset_mode: ``"next_step"`` (gymnasium's default: the step after an episode's end
            returns the reset observation, reward 0) or ``"same_step"`` (the reset observation
            is returned at once; the last one is in ``info["final_obs"]``).
        numba_threads: threads of numba's parallel kernels (the physics over the vehicles,
            the batched estimator) during this env's ``reset`` and ``step``: ``"auto"``
            (:func:`default_threads`: one below :data:`THREADS_MIN_BATCH` sub-envs, the CPUs
            the process may use from there on and never more than the calling thread's
            count, ``numba.set_num_threads``; numba's count whenever ``NUMBA_NUM_THREADS``
            is set), an
            integer, or None (the caller's count). Set on the calling thread for the call only
            (``quadfault.jit.threads``): nothing else in the process changes, and the flights
            are the same for every count.
        **kwargs: every other keyword of ``QuadFaultEnv`` (scenario, action_mode, rates, ...);
            ``render_mode`` is not supported. An unknown keyword raises a ``ConfigError``
            naming the closest valid one.

        info: what ``info`` holds: ``"light"`` (default: ``termination_reason`` alone, cheap
            at any N) or ``"full"`` (every diagnostic below; its copies cost about as much as
            the physics at one substep per step). The flights are the same either way.

    ``info`` (arrays over the sub-envs, with gymnasium's ``"_<key>"`` masks): with
    ``info="light"`` ``termination_reason`` (a name, or None while the episode goes on; the
    single env's light ``info``, :func:`~quad_fault_env.envs.config.light_info`);
    with ``info="full"`` also ``t`` [s],
    ``eta_true``, ``eta_hat``, ``eta_sd`` (10 = none, as in the observation),
    ``estimator_status``,
    ``position_error`` [m], ``tracking_error`` [m], ``motor_command`` [N],
    ``termination_reason``, ``scenario``; with ``effects`` / ``model``, ``effects`` (each
    sub-env's drawn effects, as the single env reports them).
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 1,
        estimator: str = "irls",
        scenario="combined",
        *,
        estimator_kwargs=None,
        max_episode_steps: int | None = None,
        autoreset_mode: str = "next_step",
        numba_threads="auto",
        info: str = "light",
        **kwargs,
    ):
        check_keywords(
            kwargs,
            keywords_of(QuadFaultVectorEnv.__init__) + ENV_KEYWORDS,
            type(self).__name__,
        )
        if (
            isinstance(num_envs, bool)
            or not isinstance(num_envs, (int, np.integer))
            or num_envs < 1
        ):
            raise ConfigError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if kwargs.get("render_mode") is not None:
            raise ConfigError("QuadFaultVectorEnv does not render; use QuadFaultEnv")
        if not isinstance(estimator, str) or estimator not in VECTOR_ESTIMATORS:
            raise ConfigError(
                f"estimator must be one of {', '.join(VECTOR_ESTIMATORS)} in the "
                f"vector env, got {estimator!r}"
            )
        if autoreset_mode not in AUTORESET_MODES:
            raise ConfigError(
                f"autoreset_mode must be one of {sorted(AUTORESET_MODES)}, got {autoreset_mode!r}"
            )
        #: what ``info`` holds: ``"light"`` (the termination reasons) or ``"full"``
        self.info_level = check_choice("info", info, INFO_LEVELS)
        if max_episode_steps is not None and not (
            isinstance(max_episode_steps, int) and max_episode_steps >= 1
        ):
            raise ConfigError(
                f"max_episode_steps must be an integer >= 1, got {max_episode_steps!r}"
            )
        if (
            numba_threads != "auto"
            and numba_threads is not None
            and (
                isinstance(numba_threads, bool)
                or not isinstance(numba_threads, (int, np.integer))
                or numba_threads < 1
            )
        ):
            raise ConfigError(
                f"numba_threads must be 'auto', None or an integer >= 1, got {numba_threads!r}"
            )
        self.num_envs = N = int(num_envs)
        self.max_episode_steps = max_episode_steps
        self.metadata = dict(self.metadata, autoreset_mode=AUTORESET_MODES[autoreset_mode])
        # one configuration for every sub-env: the single env's keywords, validated once
        #: the single env holding the configuration of every sub-env (never reset or stepped)
        self.single_env = e0 = QuadFaultEnv("none", scenario, **kwargs)
        self.vehicle, self.layout = e0.vehicle, e0.layout
        self.substeps, self.dt = e0.substeps, e0.dt
        self.estimator_stride = e0.estimator_stride
        self.estimator_name = estimator
        self.single_observation_space = e0.observation_space
        self.single_action_space = e0.action_space
        self.observation_space = batch_space(self.single_observation_space, N)
        self.action_space = batch_space(self.single_action_space, N)
        self.estimator = None
        if estimator_spec(estimator).batched is not None:
            self.estimator = make_estimator(
                estimator, self.vehicle, num=N, **(estimator_kwargs or {})
            )
        #: "auto": never more threads than the calling thread's count at the call (a user's
        #: ``numba.set_num_threads`` limit)
        self._auto_threads = numba_threads == "auto"
        if numba_threads == "auto":
            numba_threads = default_threads(N)
        #: numba threads of this env's steps and resets (None: the caller's count)
        self.numba_threads = None if numba_threads is None else int(numba_threads)
        # the single env's plant (MotorModel(thrust_noise): its default saturation), N of it
        self.plant = Plant(self.vehicle, MotorModel(), dt=self.dt, n_vehicles=N)
        self.flight = Flight(self.plant, e0.sensor_noise)
        self._trajectories, self._schedules = InternTable(), InternTable()
        # the geometric controller's gains and options (shared by every row; references given)
        self._controller = GeometricController(self.vehicle, None, e0.controller_config)
        #: the geometric controller runs in the step (residual actions)
        self._uses_controller = e0.action_config.mode == "residual"
        #: control steps per window of the time tables
        self._window = window_steps(self.substeps)
        self._tables = RowTimeTables(
            N,
            self.substeps,
            self.dt,
            self.vehicle,
            e0.controller_config,
            feedforward=self._uses_controller,
            window=self._window,
        )
        self.flight.use_efficiency(self._tables.eta, self._tables.first)
        n = self.vehicle.n_rotors
        self.eta_hat, self.eta_sd = np.ones((N, n)), np.full((N, n), np.nan)
        self._status = np.full(N, _STATUS["warmup"], dtype=np.int64)
        self.steps = np.zeros(N, dtype=np.int64)
        self.max_steps = np.zeros(N, dtype=np.int64)
        self._traj_key = np.zeros(N, dtype=np.int64)
        self._sched_key = np.zeros(N, dtype=np.int64)
        self._rngs: list = [None] * N  # each sub-env's generator (set by its reset)
        self._nominal = (None, None)  # a shared trajectory and its nominal_starts
        self._seeded = False  # every sub-env has its generator
        #: each sub-env's scenario of the current episode
        self.scenarios = np.full(N, None, dtype=object)
        self._scenario_names = np.full(N, None, dtype=object)
        self.physics_draws = e0.physics_draws  # per-vehicle physics drawn at each reset
        self._effects = np.full(N, None, dtype=object)
        #: the relaxed-hover base's per-row switches (allocation="relaxed-hover")
        self._relaxed = None if e0.relaxed is None else e0.relaxed.batch(N)
        self._started = False
        self._compile_step()

    def _compile_step(self) -> None:
        """The arrays and constants of the compiled step (:mod:`quad_fault_env.vector_step`):
        what is fixed, the rows it reads and updates, the estimator's records."""
        N, e0, S = self.num_envs, self.single_env, self.substeps
        stride = self.estimator_stride
        n_records = len(range(0, S, stride)) if self.estimator is not None else 0
        #: the estimator's samples of a step (every ``estimator_stride``-th substep), with
        #: the accelerometer (zeros until measured: a row that flies nothing keeps them finite)
        self._records = (
            self.flight.records(S, stride) if n_records else Records.none(N, self.vehicle.n_rotors)
        )
        self._records.accel[:] = 0.0
        cfg = e0.action_config
        # the compiled step maps the actions unless an estimate-aware allocator or the
        # relaxed-hover base (per-row state in Python) does
        direct = (e0.allocator is None or cfg.mode == "motor") and self._relaxed is None
        mode, compensate, residual_scale, ms = cfg.params(e0.compensate)
        at, low, high, fill = self.layout.bounds()
        self._step_constants = StepConstants(
            int(S),
            int(mode) if direct else -1,
            bool(compensate),
            float(residual_scale),
            np.array(ms, dtype=float),
            float(self.vehicle.rotor_max_thrust),
            np.ascontiguousarray(self.vehicle.allocation_inverse, dtype=float),
            np.array(e0.reward_config.params(), dtype=float),
            np.array(e0.limits.params(), dtype=float),
            at,
            low,
            high,
            fill,
            vector_step.ESTIMATE_TRUTH
            if self.estimator_name == "truth"
            else vector_step.ESTIMATE_KEPT,
            int(((S - 1) // stride) * stride),
            _NO_LIMIT if self.max_episode_steps is None else int(self.max_episode_steps),
            self._window,
            self.estimator is None,
            self.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP,
        )
        T = self._tables
        self._rows = StepRows(
            np.zeros((N, 4)),
            self.steps,
            self.max_steps,
            np.zeros(N, dtype=bool),
            T.k0,
            T.by_step,
            T.eta,
            self.eta_hat,
            self.eta_sd,
            np.zeros((N, max(n_records, 1))),
        )
        #: the controller in the step (residual actions with the nominal allocation)
        self._K = self._controller.constants if (self._uses_controller and direct) else None
        self._stale = True  # some row's window needs a refill before the next step
        self._n_ended = 0  # sub-envs that ended at the last step

    @property
    def status(self) -> np.ndarray:
        """Each sub-env's estimator status (names, an object array)."""
        return np.asarray(STATUSES, dtype=object)[self._status]

    @property
    def _needs_reset(self) -> np.ndarray:
        """The sub-envs that ended at the last step (next-step autoreset: reset at the next)."""
        return self._rows.resetting

    # -- the vehicles' arrays (views of the flight's state) ----------------------------------
    @property
    def state(self) -> RigidBodyState:
        """True states (N,) -- views of the arrays the loop updates."""
        return self.flight.truth

    @property
    def meas(self) -> RigidBodyState:
        """The measurements the agents see (N,) -- views."""
        return self.flight.measurement

    @property
    def f_cmd(self) -> np.ndarray:
        """Rotor commands held over the current step (N, n) [N]."""
        return self.flight.commands

    @property
    def eta_true(self) -> np.ndarray:
        """Each sub-env's true efficiency (N, n) now: at the end of its last step, at t = 0
        after its reset (a copy, read from the time tables when asked)."""
        if not self._started:
            return np.ones((self.num_envs, self.vehicle.n_rotors))
        return self._tables.efficiency_at(self.steps - 1, self.substeps)

    @property
    def sigma(self) -> np.ndarray:
        """Each sub-env's thrust noise sigma_f (N,)."""
        return self.flight.thrust_noise

    # -- resets ------------------------------------------------------------------------------
    def _reset_rows(self, rows, seeds=None, options=None):
        """Start new episodes in ``rows``: the single env's reset, batched.

        Per row, in the single env's order on the row's generator: the seed (if given), the
        scenario (``QuadFaultEnv._make_scenario``), the 12 uniform draws of the initial
        spread. Then, over all the rows at once, the initial states
        (``episode_start.start_states``: each distinct trajectory evaluated once), the
        measurement (the loop's sensors, each row's normals from its generator) and the true
        efficiency at t = 0 (each distinct schedule once). Deterministic scenarios (a name or
        a Scenario object) are built once per call. Returns the rows' reference at t = 0
        (position, velocity, acceleration; (len(rows), 3) each), or None for no rows.
        """
        rows = np.asarray(rows, dtype=np.int64).reshape(-1)
        if not len(rows):
            return None
        e0 = self.single_env
        spec = e0._scenario_option(options)
        drawn = isinstance(spec, str) and spec in GENERATORS  # a new scenario per row
        shared = None if drawn else e0._make_scenario(spec)
        u = np.empty((len(rows), SPREAD_DRAWS))
        if self._seed_rows(rows, seeds):
            self.flight.seed(rows, [self._rngs[i] for i in rows.tolist()])
        if drawn or self.physics_draws is not None:  # draws per row, in the single env's order
            sigma = np.empty(len(rows))
            for k, i in enumerate(rows.tolist()):
                rng = self._rngs[i]
                sc = shared if shared is not None else e0._make_scenario(spec, rng)
                self.scenarios[i] = sc
                if self.physics_draws is not None:  # the single env's draw, at the same point
                    effects = self.physics_draws.draw(rng)
                    self.plant.assign(i, effects)
                    self._effects[i] = describe(effects)
                u[k] = rng.uniform(-1.0, 1.0, SPREAD_DRAWS)
                self._scenario_names[i] = sc.name
                self._traj_key[i] = self._trajectories.key(sc.trajectory)
                self._sched_key[i] = self._schedules.key(sc.efficiency)
                sigma[k] = sc.thrust_noise
                self.max_steps[i] = int(round(sc.duration / e0.control_period))
        else:  # one scenario for every row: its draws alone, compiled
            vector_step.spread_draws(self.flight.generator_table(), rows, u)
            box = np.empty((), dtype=object)
            box[()] = shared  # (the scenario itself into each row, never its fields)
            self.scenarios[rows] = box
            self._scenario_names[rows] = shared.name
            self._traj_key[rows] = self._trajectories.key(shared.trajectory)
            self._sched_key[rows] = self._schedules.key(shared.efficiency)
            sigma = shared.thrust_noise
            self.max_steps[rows] = int(round(shared.duration / e0.control_period))
        self.flight.set_thrust_noise(rows, sigma)
        keys, inv = np.unique(self._traj_key[rows], return_inverse=True)
        items = [self._trajectories.items[int(key)] for key in keys]
        nominal = None
        if not drawn:  # one trajectory: its unperturbed start kept from reset to reset
            if self._nominal[0] is not items[0]:
                self._nominal = (
                    items[0],
                    nominal_starts(items, self.vehicle, e0.controller_config),
                )
            nominal = self._nominal[1]
        start, ref0 = start_states(
            items, inv.ravel(), self.vehicle, e0.controller_config, e0.initial_spread, u, nominal
        )
        # the rows' flights: their generators, initial states, measurements, zero commands
        self.flight.restart(rows, start)
        self.steps[rows] = 0
        if self._relaxed is not None:
            self._relaxed.reset(rows)
        self._tables.invalidate(rows)
        self._ensure_tables(self.steps, self._window - 1)  # the rows' windows from t = 0
        self.eta_hat[rows], self.eta_sd[rows], self._status[rows] = 1.0, np.nan, _STATUS["warmup"]
        if self.estimator_name == "truth":  # the efficiency at t = 0: the windows' first
            self.eta_hat[rows], self.eta_sd[rows] = self._tables.eta[rows, 0], 0.0
            self._status[rows] = _STATUS["ok"]
        elif self.estimator_name == "none":
            self.eta_sd[rows], self._status[rows] = NOMINAL_PRIOR_SD, _STATUS["ok"]
        if self.estimator is not None:
            mask = np.zeros(self.num_envs, dtype=bool)
            mask[rows] = True
            self.estimator.reset(mask)
        self._stale = False  # every row's window holds its next step (_ensure_tables)
        if len(self._trajectories.items) > 8 * self.num_envs + 64:
            self._compact_tables()
        self.episodes_started(rows)
        return ref0.position, ref0.velocity, ref0.acceleration

    def _seed_rows(self, rows: np.ndarray, seeds) -> bool:
        """New generators for the ``rows`` given a seed (``seeds``: one per row, or None) and
        for those without one yet, as gymnasium's ``Env.reset``; whether any row got one."""
        if seeds is None and self._seeded:
            return False
        seeded = False
        for k, i in enumerate(rows.tolist()):
            seed = None if seeds is None else seeds[k]
            if seed is not None or self._rngs[i] is None:
                self._rngs[i] = seeding.np_random(seed)[0]
                seeded = True
        self._seeded = all(g is not None for g in self._rngs)
        return seeded

    def _compact_tables(self) -> None:
        """Forget trajectories / schedules no sub-env uses any more."""
        for attr, keys in (("_trajectories", self._traj_key), ("_schedules", self._sched_key)):
            old = getattr(self, attr)
            new = InternTable()
            remap = {int(k): new.key(old.items[int(k)]) for k in np.unique(keys)}
            keys[:] = [remap[int(k)] for k in keys]
            setattr(self, attr, new)

    def reset(self, *, seed=None, options=None):
        """Reset every sub-env; ``seed`` an int (sub-env i gets ``seed + i``) or a list."""
        N = self.num_envs
        if seed is None:
            seeds = [None] * N
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seeds = [int(seed) + i for i in range(N)]
        else:
            seeds = list(seed)
            if len(seeds) != N:
                raise ConfigError(f"reset needs {N} seeds, got {len(seeds)}")
        self._trajectories, self._schedules = InternTable(), InternTable()
        self._needs_reset[:] = False
        with jit.threads(self._call_threads()):
            refs = self._reset_rows(np.arange(N), seeds, options)  # every row at t = 0
        self._n_ended = 0
        self._started = True
        obs = np.empty((N, self.layout.size), dtype=np.float32)
        vector_step.observe(self._step_constants, self._rows, self.plant.vehicles, obs, None, 1)
        return self._observations(obs), self._infos(refs, np.zeros(N, dtype=np.int64))

    # -- functions of time: per-row windows (quad_fault_env.time_tables) ---------------------
    def _ensure_tables(self, k: np.ndarray, last: int) -> None:
        self._tables.ensure(
            k,
            self._traj_key,
            self._sched_key,
            self._trajectories.items,
            self._schedules.items,
            last,
            # (rows reset for the next step stay put at it)
            self._rows.resetting if self._step_constants.next_step else None,
        )

    def _references_now(self):
        """Reference position, velocity, acceleration (N, 3) at each row's current time."""
        self._ensure_tables(self.steps, self._window)
        ref = self._tables.references(self.steps, 3)
        return ref[:, 0], ref[:, 1], ref[:, 2]

    def _check_actions(self, actions) -> np.ndarray:
        """The actions, checked (``validate_action``: finite, inside [-1, 1] up to 1e-6,
        clipped), in the step's action rows."""
        a = actions if isinstance(actions, np.ndarray) else np.asarray(actions)
        out = self._rows.action
        if a.shape != out.shape or a.dtype.kind != "f" or vector_step.copy_actions(a, out) >= 0:
            out[:] = validate_action(actions, self.action_space.shape, "actions")
        return out

    def _given_commands(self, a: np.ndarray) -> None:
        """Rotor commands of actions the compiled step does not map (an estimate-aware
        allocator, the relaxed-hover base: ``ActionConfig.commands`` with the controller's
        commands at the step's start), set before the step."""
        e0 = self.single_env
        cfg = e0.action_config
        f_ctrl = None
        if self._uses_controller:
            m = self.meas
            f_ctrl = self._controller.commands(
                m.p, m.v, m.R, m.w, self._tables.references(self.steps)
            )
        f = cfg.commands(a, self.vehicle, f_ctrl, self.eta_hat, e0.compensate, e0.allocator)
        if self._relaxed is not None:  # rows whose estimate isolated a lost rotor
            t = self.steps * self.substeps * self.dt
            lost = self._relaxed.update(t, self.eta_hat)
            if (lost >= 0).any():
                m, refs = self.meas, self._tables.references(self.steps)
                for i in np.flatnonzero(lost >= 0).tolist():
                    fr = self._relaxed.commands(
                        int(lost[i]), m.p[i], m.v[i], m.R[i], m.w[i], refs[i]
                    )
                    f[i] = cfg.commands(a[i], self.vehicle, fr)
        self.f_cmd[:] = f

    def _call_threads(self) -> int | None:
        """The numba threads of a call: :attr:`numba_threads`; with ``"auto"`` at most the
        calling thread's count (``numba.set_num_threads`` before the call lowers it)."""
        n = self.numba_threads
        if n is not None and n > 1 and self._auto_threads:
            n = min(n, jit.set_threads(None))
        return n

    def _threads(self) -> int:
        return jit.set_threads(None)

    # -- step --------------------------------------------------------------------------------
    def step(self, actions):
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = self._check_actions(actions)
        with (
            np.errstate(invalid="ignore", over="ignore", divide="ignore"),
            jit.threads(self._call_threads()),
        ):
            return self._step(a)

    def _step(self, a: np.ndarray):
        """One compiled call over the sub-envs (``vector_step.step``); a second for the
        batched estimator's update (and the observations it changes); Python only for the
        sub-envs that reset and the windows of the functions of time that need a refill."""
        N, S = self.num_envs, self._step_constants
        resetting = self._rows.resetting
        n_resetting = self._n_ended if S.next_step else 0
        rows = np.flatnonzero(resetting) if n_resetting else None
        if n_resetting:
            self._reset_rows(rows)
        if self._stale:
            self._ensure_tables(self.steps, self._window - 1)
        if S.mode < 0:
            self._given_commands(a)
        threads = self._threads()
        out = StepOut(
            np.empty(N, dtype=np.int64),
            np.empty(N, dtype=bool),
            np.empty(N, dtype=bool),
            np.empty(N),
            np.empty((N, self.layout.size), dtype=np.float32),
        )
        views = self.plant.vehicles
        stale, ended = vector_step.step(
            S,
            self._rows,
            out,
            self._K,
            self.flight.loop(self._records),
            self.flight.k,
            self.dt,
            threads,
        )
        self._stale, self._n_ended = stale > 0, ended
        if self.estimator is not None:
            self._update_estimator(rows)
            vector_step.observe(S, self._rows, views, out.obs, None, threads)
        code = out.code
        infos = self._infos(None, code)
        obs = out.obs
        if not S.next_step and ended:
            done = out.terminated | out.truncated
            ended_rows = np.flatnonzero(done)
            final_obs, final_infos = self._observations(obs), infos
            self._reset_rows(ended_rows)
            if self._stale:
                self._ensure_tables(self.steps, self._window - 1)
            obs = obs.copy()
            vector_step.observe(S, self._rows, views, obs, ended_rows, 1)
            infos = self._infos(None, np.where(done, 0, code))
            infos["final_obs"] = final_obs
            infos["final_info"] = final_infos
            infos["_final_obs"] = infos["_final_info"] = done.copy()
        return self._observations(obs), out.reward, out.terminated, out.truncated, infos

    # -- hooks: a subclass keeping per-row state beside the env's (an estimate it observes) --
    def episodes_started(self, rows: np.ndarray) -> None:
        """Called when the sub-envs ``rows`` (an int64 array) have started new episodes (their
        state, tables and the env's estimate at t = 0 set; their observation not yet
        written). Does nothing here."""

    def estimate_updated(self, restarted_rows: np.ndarray | None) -> None:
        """Called at each step after the batched estimator's update (``estimator`` not None),
        with the rows whose estimator then restarted (reset at this step; None: no row).
        Does nothing here. :meth:`estimate_on_records` feeds another batched estimator the
        same records."""

    def estimate_on_records(self, estimator):
        """``estimator`` (a batched one) updated with every record of this step, in order;
        its last result."""
        rec, times = self._records, self._rows.times
        res = None
        for r in range(rec.p.shape[1]):
            res = estimator.update(
                times[:, r],
                rec.p[:, r],
                rec.v[:, r],
                rec.R[:, r],
                rec.w[:, r],
                self.f_cmd,
                accel=rec.accel[:, r],
            )
        return res

    def _update_estimator(self, resetting_rows) -> None:
        """The batched estimator's updates on the step's records (every
        ``estimator_stride``-th substep); the estimate does not act on the physics within a
        step. Sub-envs reset at this step start their estimator afresh."""
        res = self.estimate_on_records(self.estimator)
        self.eta_hat[:], self.eta_sd[:], self._status[:] = res.eta, res.sd, res.status
        if resetting_rows is not None:
            mask = np.zeros(self.num_envs, dtype=bool)
            mask[resetting_rows] = True
            self.estimator.reset(mask)
            self.eta_hat[resetting_rows], self.eta_sd[resetting_rows] = 1.0, np.nan
            self._status[resetting_rows] = _STATUS["warmup"]
        self.estimate_updated(resetting_rows)

    # -- observation and info ----------------------------------------------------------------
    def _observations(self, flat):
        """The flat observations as the env gives them (a dict of slots for ``"dict"``)."""
        return self.layout.split(flat) if self.single_env.observation_kind == "dict" else flat

    def _infos(self, refs, code) -> dict:
        """The step's ``info``; ``code`` the rows' termination codes (``REASONS``; 0: none)."""
        N = self.num_envs
        reasons = np.empty(N, dtype=object)  # None (an object array's fill); the ended rows'
        ended = np.flatnonzero(code)  # names alone (REASONS[code] costs ~10 ns per row)
        if len(ended):
            reasons[ended] = REASONS[code[ended]]
        light = light_info(reasons)
        if self.info_level == "light":
            return light | {"_" + key: np.ones(N, dtype=bool) for key in light}
        refs = self._references_now() if refs is None else refs
        err = self.state.p - refs[0]
        info = light | {
            "t": self.steps * self.substeps * self.dt,
            "eta_true": self.eta_true,
            "eta_hat": self.eta_hat.copy(),
            "eta_sd": np.where(np.isnan(self.eta_sd), SD_MAX, self.eta_sd),
            "estimator_status": self.status,
            "position_error": err,
            "tracking_error": np.linalg.norm(err, axis=-1),
            "motor_command": self.f_cmd.copy(),
            "scenario": self._scenario_names.copy(),
        }
        if self.physics_draws is not None:
            info["effects"] = self._effects.copy()
        for key in list(info):
            info["_" + key] = np.ones(N, dtype=bool)
        return info

    def close_extras(self, **kwargs):
        self.single_env.close()


__all__ = [
    "AUTORESET_MODES",
    "INFO_LEVELS",
    "THREADS_MIN_BATCH",
    "QuadFaultVectorEnv",
    "default_threads",
]
