"""QuadFaultVectorEnv: N quadrotors stepped in one array operation (a gymnasium VectorEnv).

The physics is the core model over a leading batch axis -- the same code the single
:class:`~quad_fault_env.envs.quad_fault.QuadFaultEnv` runs, not a copy:
:class:`quadfault.motors.MotorModel` (saturation, efficiency, thrust noise, eqs. 11, 13),
:meth:`quadfault.vehicle.Vehicle.wrench`, :func:`quadfault.dynamics.step_rk4` (eqs. 1-4),
:class:`quadfault.controller.GeometricController` (eqs. 5-10) and
:meth:`quadfault.simulator.SensorNoise.measure`. Resets are batched: per row only the seed,
the scenario (``QuadFaultEnv._make_scenario``) and the row's draws; the initial states come
from :func:`quad_fault_env.envs.episode_start.start_states` over all reset rows -- the function
the single env's reset calls with one row -- so both envs share one definition of an episode
start. The estimate comes from the batched estimators of
:mod:`estimators.batched`. With ``physics="numba"`` (the default when numba is importable) the
substeps run in the compiled twin of the same functions, ``quadfault._sim_numba.step_batch``
(one call per control step without an estimator, one per run of substeps between estimator
updates), and the controller in ``_sim_numba.controller_batch``.

Seeds and random streams: sub-env i owns the generator its single twin would own --
``reset(seed=s)`` seeds sub-env i with ``s + i`` (as ``SyncVectorEnv``) -- and draws from it in
the single env's order (per physics substep: sensor noise, then thrust noise, then
accelerometer noise; the end-of-step measurement after the termination check). Standard
normal draws of a ``numpy.random.Generator`` are sequential, so one block draw per sub-env and
control step equals the single env's sequence of small draws. Hence N single envs reset with
seeds ``s .. s+N-1`` and fed the same actions give the same trajectories (tested to 1e-9).

Differences from the single env: ``info`` holds the per-env arrays below (no per-substep
``samples`` / ``eta_true_samples`` / ``specific_force_samples``, no ``fault_events``); no
rendering; only the named estimators (``"irls" | "ekf" | "truth" | "none"``).
"""

from __future__ import annotations

import copy

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from quad_fault_env.envs.config import RewardConfig, TerminationLimits, validate_action
from quad_fault_env.envs.episode_start import SPREAD_DRAWS, start_states
from quad_fault_env.envs.quad_fault import QuadFaultEnv
from quad_fault_env.estimation import NOMINAL_PRIOR_SD
from quad_fault_env.observation import SD_MAX
from quad_fault_env.time_tables import WINDOW, RowTimeTables
from quadfault.controller import GeometricController
from quadfault.dynamics import RigidBodyState, step_rk4
from quadfault.errors import ConfigError
from quadfault.motors import MotorModel
from quadfault.trajectory import FlatOutput

PHYSICS_BACKENDS = ("auto", "numpy", "numba")
NOISE_STREAMS = ("per_env", "shared")
AUTORESET_MODES = {"next_step": AutoresetMode.NEXT_STEP, "same_step": AutoresetMode.SAME_STEP}
_BIG = float(np.finfo(np.float32).max / 2)


class _Draws:
    """A stand-in generator that hands out pre-drawn standard normals, column block by block,
    so the core's ``measure`` / ``apply`` consume exactly the single env's draws."""

    def __init__(self, z: np.ndarray):
        self.z = z

    def standard_normal(self, shape):
        return self.z.reshape(shape)


def _groups(keys: np.ndarray):
    """``[(key, rows), ...]`` of an integer key array (rows sorted)."""
    order = np.argsort(keys, kind="stable")
    sk = keys[order]
    cuts = np.flatnonzero(np.diff(sk)) + 1
    return [(int(keys[idx[0]]), idx) for idx in np.split(order, cuts)]


class _Table:
    """Interned hashable objects (trajectories, efficiency schedules): object -> small int."""

    def __init__(self):
        self.items: list = []
        self.index: dict = {}

    def key(self, obj) -> int:
        try:
            k = self.index.get(obj)
        except TypeError:  # unhashable: one entry per object
            k = None
        if k is None:
            k = len(self.items)
            self.items.append(obj)
            try:
                self.index[obj] = k
            except TypeError:
                pass
        return k


def batched_reward(cfg: RewardConfig, pos_err, vel_err, f_cmd, f_max: float, terminated):
    """:class:`RewardConfig` over a batch (the same formula, rows (N, 3)); (N,) float64."""
    track = np.linalg.norm(pos_err, axis=-1) + cfg.velocity_weight * np.linalg.norm(vel_err,
                                                                                    axis=-1)
    effort = np.mean((np.asarray(f_cmd) / f_max) ** 2, axis=-1)
    r = np.exp(-track / cfg.position_scale) - cfg.effort_weight * effort
    r = r - np.where(terminated, cfg.termination_penalty, 0.0)
    return np.where(np.isfinite(r), r, 0.0)


def batched_termination(limits: TerminationLimits, p, R, p_ref) -> np.ndarray:
    """:meth:`TerminationLimits.reason` over a batch: object array of reasons or None."""
    reason = np.full(len(p), None, dtype=object)
    finite = np.isfinite(p).all(-1) & np.isfinite(R).all((-1, -2))
    tilt = np.arccos(np.clip(np.nan_to_num(R[:, 2, 2]), -1.0, 1.0)) > limits.max_tilt
    checks = (("excessive_tilt", tilt),
              ("out_of_bounds", np.linalg.norm(p - p_ref, axis=-1) > limits.max_position_error),
              ("crash", -p[:, 2] < limits.ground_altitude), ("non_finite", ~finite))
    for name, hit in checks:  # last assignment wins: the single env's order of precedence
        reason[hit] = name
    return reason


class QuadFaultVectorEnv(VectorEnv):
    """N :class:`~quad_fault_env.envs.quad_fault.QuadFaultEnv` episodes stepped as arrays.

    Args:
        num_envs: N.
        estimator: ``"irls" | "ekf" | "truth" | "none"`` (batched: :mod:`estimators.batched`).
        estimator_kwargs: ``config=`` of the estimator.
        max_episode_steps: truncation after this many control steps (the registration's
            value through ``gym.make_vec``), like ``TimeLimit`` on the single env.
        physics: ``"auto"`` (default: numba when importable, else numpy), ``"numpy"`` (the
            core functions over the batch axis) or ``"numba"`` (the compiled batched kernel
            ``quadfault._sim_numba.step_batch`` -- motors, RKMK4 -- and ``controller_batch``,
            parallel over the sub-envs, the per-env draws in one compiled loop; the same
            results to rounding, tested to 1e-9 against the single env).
        noise_streams: ``"per_env"`` (default: each sub-env draws from its own generator in
            the single env's order, so it equals its single twin) or ``"shared"`` (the
            sub-envs' noise comes from one generator seeded at ``reset(seed=...)`` in one
            array draw per step: faster at large N, but not the single env's numbers).
        autoreset_mode: ``"next_step"`` (gymnasium's default: the step after an episode's end
            returns the reset observation, reward 0) or ``"same_step"`` (the reset observation
            is returned at once; the last one is in ``info["final_obs"]``).
        **kwargs: every other keyword of ``QuadFaultEnv`` (scenario, action_mode, rates, ...);
            ``render_mode`` is not supported.

    ``info`` (arrays over the sub-envs, with gymnasium's ``"_<key>"`` masks): ``t`` [s],
    ``eta_true``, ``eta_hat``, ``eta_sd`` (NaN = none), ``estimator_status``,
    ``position_error`` [m], ``tracking_error`` [m], ``motor_command`` [N],
    ``termination_reason``, ``scenario``.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 1, estimator: str = "irls", scenario="combined", *,
                 estimator_kwargs=None, max_episode_steps: int | None = None,
                 autoreset_mode: str = "next_step", physics: str = "auto",
                 noise_streams: str = "per_env", **kwargs):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) \
                or num_envs < 1:
            raise ConfigError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if kwargs.get("render_mode") is not None:
            raise ConfigError("QuadFaultVectorEnv does not render; use QuadFaultEnv")
        if not isinstance(estimator, str) or estimator not in ("irls", "ekf", "truth", "none"):
            raise ConfigError(f"estimator must be 'irls', 'ekf', 'truth' or 'none' in the vector "
                              f"env, got {estimator!r}")
        if autoreset_mode not in AUTORESET_MODES:
            raise ConfigError(f"autoreset_mode must be one of {sorted(AUTORESET_MODES)}, "
                              f"got {autoreset_mode!r}")
        if max_episode_steps is not None and not (isinstance(max_episode_steps, int)
                                                  and max_episode_steps >= 1):
            raise ConfigError(f"max_episode_steps must be an integer >= 1, "
                              f"got {max_episode_steps!r}")
        if physics not in PHYSICS_BACKENDS:
            raise ConfigError(f"physics must be one of {PHYSICS_BACKENDS}, got {physics!r}")
        if physics == "numba" and not _physics_numba_available():
            raise ConfigError("physics='numba' needs numba (install the 'fast' extra)")
        if physics == "auto":
            physics = "numba" if _physics_numba_available() else "numpy"
        self.physics = physics
        if noise_streams not in NOISE_STREAMS:
            raise ConfigError(f"noise_streams must be one of {NOISE_STREAMS}, "
                              f"got {noise_streams!r}")
        self.noise_streams = noise_streams
        self._shared_rng = np.random.default_rng()
        self.num_envs = N = int(num_envs)
        self.max_episode_steps = max_episode_steps
        self.metadata = dict(self.metadata, autoreset_mode=AUTORESET_MODES[autoreset_mode])
        # one single env per sub-env: scenarios, controllers, resets, generators. The first is
        # built (and validates the keywords); the others are shallow copies of it made before
        # any reset, so they share only immutable configuration (every per-episode attribute,
        # the generator included, is assigned anew by reset) -- O(1) each instead of a build.
        e0 = QuadFaultEnv("none", scenario, **kwargs)
        self.envs = [e0] + [copy.copy(e0) for _ in range(N - 1)]
        self.vehicle, self.layout = e0.vehicle, e0.layout
        self.substeps, self.dt = e0.substeps, e0.dt
        self.estimator_stride = e0.estimator_stride
        self.estimator_name = estimator
        self.single_observation_space = e0.observation_space
        self.single_action_space = e0.action_space
        self.observation_space = batch_space(self.single_observation_space, N)
        self.action_space = batch_space(self.single_action_space, N)
        self.estimator = None
        if estimator in ("irls", "ekf"):
            from estimators.batched import make_batched_estimator

            self.estimator = make_batched_estimator(estimator, self.vehicle, N,
                                                    **(estimator_kwargs or {}))
        # the single env's plant: MotorModel(thrust_noise) with its default saturation
        self._saturate = bool(MotorModel().saturate)
        noise = e0.sensor_noise
        self._meas_draws = (9 + (3 if noise.attitude else 0)) if noise.any else 0
        self._accel_draws = 3 if noise.accel else 0
        self._trajectories, self._schedules = _Table(), _Table()
        self._controllers: dict = {}
        # the geometric controller's gains and options (shared by every row; references given)
        self._controller = GeometricController(self.vehicle, None, e0.controller_config)
        self._tables = RowTimeTables(N, self.substeps, self.dt, self.vehicle,
                                     e0.controller_config)
        if self.physics == "numba":
            from quadfault._sim_numba import body_of, gains_of

            self._body = body_of(self.vehicle)
            self._gains = gains_of(self._controller)
        n = self.vehicle.n_rotors
        self.state = RigidBodyState.at_rest(batch_shape=(N,))
        self.meas = RigidBodyState.at_rest(batch_shape=(N,))
        self.f_cmd = np.zeros((N, n))
        self.eta_hat, self.eta_sd = np.ones((N, n)), np.full((N, n), np.nan)
        self.status = np.full(N, "warmup", dtype=object)
        self.eta_true = np.ones((N, n))
        self.sigma = np.zeros(N)
        self.steps = np.zeros(N, dtype=np.int64)
        self.max_steps = np.zeros(N, dtype=np.int64)
        self._traj_key = np.zeros(N, dtype=np.int64)
        self._sched_key = np.zeros(N, dtype=np.int64)
        self._needs_reset = np.zeros(N, dtype=bool)
        self._rngs: list = [None] * N  # each sub-env's generator (set by its reset)
        self._rng_list = None  # the same as a numba typed List (numba physics), built lazily
        self._scenario_names = np.full(N, None, dtype=object)
        self._started = False

    # -- resets ------------------------------------------------------------------------------
    def _reset_rows(self, rows, seeds=None, options=None):
        """Start new episodes in ``rows``: the single env's reset, batched.

        Per row, in the single env's order on the row's generator: the seed (if given), the
        scenario (``QuadFaultEnv._make_scenario``), the 12 uniform draws of the initial
        spread and the initial measurement's normals. Then, over all the rows at once, the
        initial states (``episode_start.start_states``: each distinct trajectory evaluated
        once), the measurement (``SensorNoise.measure``) and the true efficiency at t = 0 (each
        distinct schedule once). Deterministic scenarios (a name or a Scenario object) are
        built once per call. Returns the rows' reference at t = 0 (position, velocity,
        acceleration; (len(rows), 3) each), or None for no rows.
        """
        rows = np.asarray(rows, dtype=np.int64).reshape(-1)
        if not len(rows):
            return None
        e0, n = self.envs[0], self.vehicle.n_rotors
        spec = e0._scenario_option(options)
        shared = None if (isinstance(spec, str) and spec == "random") else e0._make_scenario(spec)
        u = np.empty((len(rows), SPREAD_DRAWS))
        z = np.zeros((len(rows), max(self._meas_draws, 1)))
        for k, i in enumerate(rows.tolist()):
            env = self.envs[i]
            gym.Env.reset(env, seed=None if seeds is None else seeds[k])
            rng = env.np_random
            sc = shared if shared is not None else env._make_scenario(spec)
            env.scenario = sc
            u[k] = rng.uniform(-1.0, 1.0, SPREAD_DRAWS)
            if self._meas_draws:
                rng.standard_normal(out=z[k, :self._meas_draws])
            self._rngs[i] = rng
            self._scenario_names[i] = sc.name
            self._traj_key[i] = self._trajectories.key(sc.trajectory)
            self._sched_key[i] = self._schedules.key(sc.efficiency)
            self.sigma[i] = sc.thrust_noise
            self.max_steps[i] = int(round(sc.duration / e0.control_period))
        if self._rng_list is not None:  # the compiled draws' typed list of the generators
            if 4 * len(rows) > self.num_envs:
                self._rng_list = None  # rebuilt at the next draw: cheaper than many setitems
            else:
                for i in rows.tolist():
                    self._rng_list[i] = self._rngs[i]
        keys, inv = np.unique(self._traj_key[rows], return_inverse=True)
        items = [self._trajectories.items[int(key)] for key in keys]
        for key, traj in zip(keys.tolist(), items):
            if key not in self._controllers:
                self._controllers[key] = GeometricController(self.vehicle, traj,
                                                             e0.controller_config)
        for i, key in zip(rows.tolist(), self._traj_key[rows].tolist()):
            self.envs[i].controller = self._controllers[key]
        start, ref0 = start_states(items, inv.ravel(), self.vehicle, e0.controller_config,
                                   e0.initial_spread, u)
        meas = self._measure(start, z)
        for arr, s_new, m_arr, m_new in zip(self.state, start, self.meas, meas):
            arr[rows] = s_new
            m_arr[rows] = m_new
        keys, inv = np.unique(self._sched_key[rows], return_inverse=True)
        eta0 = np.array([np.broadcast_to(np.asarray(self._schedules.items[key](0.0), float), (n,))
                         for key in keys.tolist()])
        self.eta_true[rows] = eta0[inv.ravel()]
        self.f_cmd[rows] = 0.0
        self.steps[rows] = 0
        self._tables.invalidate(rows)
        self.eta_hat[rows], self.eta_sd[rows], self.status[rows] = 1.0, np.nan, "warmup"
        if self.estimator_name == "truth":
            self.eta_hat[rows], self.eta_sd[rows], self.status[rows] = self.eta_true[rows], 0.0, "ok"
        elif self.estimator_name == "none":
            self.eta_sd[rows], self.status[rows] = NOMINAL_PRIOR_SD, "ok"
        if self.estimator is not None:
            mask = np.zeros(self.num_envs, dtype=bool)
            mask[rows] = True
            self.estimator.reset(mask)
        if len(self._trajectories.items) > 8 * self.num_envs + 64:
            self._compact_tables()
        return ref0.position, ref0.velocity, ref0.acceleration

    def _compact_tables(self) -> None:
        """Forget trajectories / schedules no sub-env uses any more."""
        for attr, keys in (("_trajectories", self._traj_key), ("_schedules", self._sched_key)):
            old = getattr(self, attr)
            new = _Table()
            remap = {int(k): new.key(old.items[int(k)]) for k in np.unique(keys)}
            keys[:] = [remap[int(k)] for k in keys]
            setattr(self, attr, new)
        self._controllers = {int(self._traj_key[i]): env.controller
                             for i, env in enumerate(self.envs)}

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
        self._trajectories, self._schedules, self._controllers = _Table(), _Table(), {}
        self._rng_list = None
        if seed is not None:
            self._shared_rng = np.random.default_rng(seeds)
        refs = self._reset_rows(np.arange(N), seeds, options)  # every row at t = 0
        self._needs_reset[:] = False
        self._started = True
        return self._observations(refs), self._infos(refs, np.full(N, None, dtype=object))

    # -- functions of time: per-row windows (quad_fault_env.time_tables) ---------------------
    def _ensure_tables(self, k: np.ndarray, last: int) -> None:
        self._tables.ensure(k, self._traj_key, self._sched_key, self._trajectories.items,
                            self._schedules.items, last)

    def _references_now(self):
        """Reference position, velocity, acceleration (N, 3) at each row's current time."""
        self._ensure_tables(self.steps, WINDOW)
        ref = self._tables.references(self.steps)
        return ref[:, 0], ref[:, 1], ref[:, 2]

    def _check_actions(self, actions) -> np.ndarray:
        return validate_action(actions, self.action_space.shape, "actions")

    def _motor_commands(self, a: np.ndarray, t: np.ndarray, refs: np.ndarray) -> np.ndarray:
        """``QuadFaultEnv.motor_commands`` over the batch (rows share the same formulas);
        ``refs`` (N, 6, 3) the controller's reference rows at ``t`` (see ``time_tables``)."""
        e0 = self.envs[0]
        cfg, f_max, veh = e0.action_config, e0.f_max, self.vehicle
        if cfg.mode == "motor":
            f = 0.5 * (a + 1.0) * f_max
        elif cfg.mode == "wrench":
            thrust = 0.5 * (a[:, :1] + 1.0) * veh.n_rotors * f_max
            f = veh.rotor_thrust(np.concatenate((thrust, a[:, 1:] * np.asarray(cfg.moment_scale)),
                                                axis=1))
        else:
            m = self.meas
            if self.physics == "numba":  # the compiled twin of the same controller
                from quadfault import _sim_numba

                f_ctrl = np.empty_like(a)
                _sim_numba.controller_batch(*(np.ascontiguousarray(x) for x in m),
                                            np.ascontiguousarray(refs), self._gains, self._body,
                                            f_ctrl)
            else:  # the controller's trajectory is not used: the references are given
                ctrl = self._controller
                ff = (refs[:, 4], refs[:, 5]) if ctrl.config.angular_feedforward else None
                f_ctrl, _ = ctrl.motor_commands(t, m.p, m.v, m.R, m.w,
                                                FlatOutput(*(refs[:, r] for r in range(4))), ff)
            if e0.compensate:
                f_ctrl = f_ctrl / np.clip(self.eta_hat, 0.1, None)
            f = f_ctrl + cfg.residual_scale * a
        return np.clip(f, 0.0, f_max)

    def _draw(self, sizes: np.ndarray, rows) -> np.ndarray:
        """Standard normals (N, max size + pad) from each sub-env's own generator."""
        width = int(sizes.max(initial=0)) + 16
        if self.noise_streams == "shared":
            return self._shared_rng.standard_normal((self.num_envs, width))
        z = np.zeros((self.num_envs, width))
        if self.physics == "numba":  # the same draws, in one compiled loop
            from numba.typed import List

            from quadfault._sim_numba import draw_normals

            if self._rng_list is None:
                self._rng_list = List(self._rngs)
            draw_normals(self._rng_list, np.asarray(rows, dtype=np.int64),
                         np.asarray(sizes, dtype=np.int64), z)
            return z
        rngs = self._rngs
        for i, s in zip(np.asarray(rows).tolist(), np.asarray(sizes)[rows].tolist()):
            if s:
                rngs[i].standard_normal(out=z[i, :s])
        return z

    def _measure(self, state: RigidBodyState, z: np.ndarray) -> RigidBodyState:
        """``SensorNoise.measure`` over the batch with pre-drawn normals ``z`` (N, k)."""
        noise = self.envs[0].sensor_noise
        if not noise.any:
            return state
        blocks = iter(np.split(z[:, :self._meas_draws], self._meas_draws // 3, axis=1))

        class _Seq:
            def standard_normal(self, shape):
                return next(blocks).reshape(shape)

        return noise.measure(state, None, _Seq())[0]

    def _estimate(self, j: int, t: np.ndarray, meas: RigidBodyState) -> None:
        """The batched estimator's update at substep ``j`` (every ``estimator_stride``)."""
        out = self.estimator.update(t, meas.p, meas.v, meas.R, meas.w, self.f_cmd)
        self.eta_hat, self.eta_sd = out.eta, out.sd
        self.status = out.status_names

    def _substeps_numpy(self, eta, z, has_thrust, ts) -> RigidBodyState:
        """The control step's physics substeps with the core functions over the batch axis."""
        N, n = self.num_envs, self.vehicle.n_rotors
        motor = MotorModel(1.0, self._saturate)
        f_max = self.vehicle.rotor_max_thrust
        state = self.state
        off = np.zeros(N, dtype=np.int64)
        rows_idx = np.arange(N)[:, None]
        for j in range(self.substeps):
            if j > 0 and self._meas_draws:
                zm = z[rows_idx, off[:, None] + np.arange(self._meas_draws)]
                meas = self._measure(state, zm)
                off = off + self._meas_draws
            elif j > 0:
                meas = state
            else:
                meas = self.meas
            if j % self.estimator_stride == 0 and self.estimator is not None:
                self._estimate(j, ts[:, j], meas)
            if has_thrust.any():
                zraw = z[rows_idx, off[:, None] + np.arange(n)] * has_thrust[:, None]
                off = off + n * has_thrust
            else:
                zraw = np.zeros((N, n))
            off = off + self._accel_draws
            # eqs. 11, 13: saturation, efficiency, exp(sigma_f eps) with the sub-env's draws
            f = motor.apply(self.f_cmd, eta[:, j], f_max, _Draws(zraw * self.sigma[:, None]))
            wrench = self.vehicle.wrench(f)
            state = step_rk4(state, wrench[:, 0], wrench[:, 1:], self.vehicle, self.dt)
        return state

    def _substeps_numba(self, eta, z, has_thrust, ts) -> RigidBodyState:
        """The same substeps with the compiled kernel ``quadfault._sim_numba.step_batch``:
        one call for the whole control step without an estimator, else one call per run of
        substeps between two estimator updates (the measurement for the estimator in numpy).

        Each sub-env's draws for substep j sit at ``j * per_substep`` in its row of ``z``
        (substep 0 has no measurement draws): the thrust normals there, the measurement ones
        ``meas_draws`` before.
        """
        from quadfault import _sim_numba

        N, S, n = self.num_envs, self.substeps, self.vehicle.n_rotors
        state = self.state.copy()  # the kernel works in place; self.meas may alias the state
        per_sub = self._meas_draws + n * has_thrust + self._accel_draws
        z_off = np.ascontiguousarray(np.arange(S)[None, :] * per_sub[:, None])
        z = np.ascontiguousarray(z, dtype=float)
        sigma = np.where(has_thrust, self.sigma, 0.0)  # no draws: nothing read from z
        stride = S if self.estimator is None else self.estimator_stride
        saturate = self._saturate
        for j0 in range(0, S, stride):
            j1 = min(S, j0 + stride)
            if self.estimator is not None:
                if j0 == 0:
                    meas = self.meas
                elif self._meas_draws:
                    cols = (z_off[:, j0] - self._meas_draws)[:, None] + np.arange(self._meas_draws)
                    meas = self._measure(state, z[np.arange(N)[:, None], cols])
                else:
                    meas = state
                self._estimate(j0, ts[:, j0], meas)
            _sim_numba.step_batch(state.p, state.v, state.R, state.w, self.f_cmd,
                                  np.ascontiguousarray(eta[:, j0:j1]), sigma, z,
                                  np.ascontiguousarray(z_off[:, j0:j1]), saturate,
                                  self._body, self.dt)
        return state

    # -- step --------------------------------------------------------------------------------
    def step(self, actions):
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = self._check_actions(actions)
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            return self._step(a)

    def _step(self, a: np.ndarray):
        N, S, n = self.num_envs, self.substeps, self.vehicle.n_rotors
        resetting = self._needs_reset.copy()
        live = np.flatnonzero(~resetting)
        k0 = self.steps * S
        t0 = k0 * self.dt
        self._ensure_tables(self.steps, WINDOW - 1)
        self.f_cmd = self._motor_commands(a, t0, self._tables.references(self.steps))
        ts = (k0[:, None] + np.arange(S)[None, :]) * self.dt
        eta_all = self._tables.efficiency(self.steps)  # S substeps, then the step's end
        eta = eta_all[:, :S]
        has_thrust = self.sigma > 0
        per_sub = self._meas_draws + n * has_thrust + self._accel_draws
        sizes = np.where(resetting, 0, S * per_sub - self._meas_draws)
        z = self._draw(sizes, live) if sizes.any() else np.zeros((N, 16 + S * 20))
        f_max, stride = self.vehicle.rotor_max_thrust, self.estimator_stride
        if self.physics == "numba":
            state = self._substeps_numba(eta, z, has_thrust & ~resetting, ts)
        else:
            state = self._substeps_numpy(eta, z, has_thrust, ts)
        if self.estimator_name == "truth":
            j_last = ((S - 1) // stride) * stride
            self.eta_hat, self.eta_sd = eta[:, j_last].copy(), np.zeros((N, n))
        self.state = state
        self.steps = self.steps + 1
        ref1 = self._tables.references(self.steps)  # k - k0 <= WINDOW: still in the window
        refs = ref1[:, 0], ref1[:, 1], ref1[:, 2]
        reason = batched_termination(self.envs[0].limits, state.p, state.R, refs[0])
        reason[resetting] = None
        terminated = np.not_equal(reason, None) & ~resetting
        truncated = ~terminated & (self.steps >= self.max_steps)
        if self.max_episode_steps is not None:
            truncated |= self.steps >= self.max_episode_steps
        truncated &= ~resetting
        # the end-of-step measurement of sub-envs that go on (after the termination check)
        sizes = np.where(terminated | resetting, 0, self._meas_draws)
        if sizes.any():
            self.meas = self._measure(state, self._draw(sizes, np.flatnonzero(sizes)))
            self.meas = RigidBodyState(*(np.where(_expand(terminated, x), s, x)
                                         for s, x in zip(state, self.meas)))
        else:
            self.meas = state.copy()
        self.eta_true = eta_all[:, S].copy()
        reward = batched_reward(self.envs[0].reward_config, state.p - refs[0],
                                state.v - refs[1], self.f_cmd, f_max, terminated)
        done = terminated | truncated
        mode = self.metadata["autoreset_mode"]
        if resetting.any():
            self._reset_rows(np.flatnonzero(resetting))
            reward[resetting] = 0.0
            refs = self._references_now()
        obs = self._observations(refs)
        infos = self._infos(refs, reason)
        if mode == AutoresetMode.SAME_STEP and done.any():
            rows = np.flatnonzero(done)
            final_obs, final_infos = obs, infos
            self._reset_rows(rows)
            refs = self._references_now()
            obs = self._observations(refs)
            infos = self._infos(refs, np.where(done, None, reason))
            infos["final_obs"] = final_obs
            infos["final_info"] = final_infos
            infos["_final_obs"] = infos["_final_info"] = done.copy()
        else:
            self._needs_reset = done
        return obs, reward, terminated, truncated, infos

    # -- observation and info ----------------------------------------------------------------
    def _observations(self, refs):
        """``ObservationLayout.values`` over the batch (same slots, clipping and NaN fills)."""
        m, (pos, vel, acc) = self.meas, refs
        raw = {"pos_err": m.p - pos, "vel_err": m.v - vel,
               "rot6": np.concatenate((m.R[:, :, 0], m.R[:, :, 1]), axis=1), "omega": m.w,
               "eta_hat": self.eta_hat, "eta_sd": self.eta_sd, "ref_acc": acc}
        out = {}
        for s in self.layout.slots:
            fill = SD_MAX if s.name == "eta_sd" else 0.0
            value = np.nan_to_num(raw[s.name], nan=fill, posinf=_BIG, neginf=-_BIG)
            out[s.name] = np.clip(value, max(s.low, -_BIG), min(s.high, _BIG)).astype(np.float32)
        if self.envs[0].observation_kind == "dict":
            return out
        return np.concatenate([out[s.name] for s in self.layout.slots], axis=1)

    def _infos(self, refs, reason) -> dict:
        N = self.num_envs
        err = self.state.p - refs[0]
        info = {
            "t": self.steps * self.substeps * self.dt,
            "eta_true": self.eta_true.copy(),
            "eta_hat": self.eta_hat.copy(),
            "eta_sd": self.eta_sd.copy(),
            "estimator_status": np.asarray(self.status, dtype=object).copy(),
            "position_error": err,
            "tracking_error": np.linalg.norm(err, axis=-1),
            "motor_command": self.f_cmd.copy(),
            "termination_reason": np.asarray(reason, dtype=object),
            "scenario": self._scenario_names.copy(),
        }
        for key in list(info):
            info["_" + key] = np.ones(N, dtype=bool)
        return info

    def close_extras(self, **kwargs):
        for env in self.envs:
            env.close()


def _physics_numba_available() -> bool:
    from quadfault import _sim_numba

    return _sim_numba.AVAILABLE


def _expand(mask: np.ndarray, like: np.ndarray) -> np.ndarray:
    return mask.reshape(mask.shape + (1,) * (like.ndim - 1))


__all__ = ["AUTORESET_MODES", "QuadFaultVectorEnv", "batched_reward", "batched_termination"]
