"""QuadFaultEnv: a quadrotor with degrading / failing motors and an efficiency estimate in the
observation.

Data flow per control step (100 Hz by default)::

    action -> rotor commands (held) -> the closed loop over the physics substeps (1 kHz)
           -> samples -> estimator.update(samples) -> observation (+ truth only in info)

The physics is the core model's one closed loop (:class:`quadfault.model.flight.Flight`: motor
saturation, efficiency and thrust noise, RKMK4, the sensors and the accelerometer, the random
numbers drawn from ``self.np_random`` in loop order), one call per control step, and the
baseline controller is the core :class:`quadfault.model.controller.GeometricController` on the
*nominal* vehicle: a fault reaches the controller only through the estimator
(``compensate=True``, ``allocation="estimate-aware"``) or through the agent.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from estimators.base import Estimate, Sample
from quad_fault_env.envs.config import light_info, validate_action
from quad_fault_env.envs.env_config import RENDER_MODES, EnvConfig
from quad_fault_env.envs.episode_start import SPREAD_DRAWS, start_states
from quad_fault_env.envs.scenario_source import fault_dict, make_scenario
from quad_fault_env.estimation import (
    diagnostics_template,
    estimate_info,
    estimate_sd,
    is_stateless,
    make_estimator,
    reads_truth,
)
from quad_fault_env.observation import ObservationLayout
from quad_fault_env.relaxed_base import RelaxedHoverBase
from quad_fault_env.rendering import FlightRenderer
from quad_fault_env.time_tables import EpisodeTables
from quadfault.errors import ConfigError
from quadfault.model.allocation import EstimateAwareAllocator
from quadfault.model.controller import GeometricController
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.effects.sampling import describe
from quadfault.model.flight import Flight
from quadfault.model.motors import MotorModel
from quadfault.model.plant import Plant
from quadfault.model.relaxed_hover_control import RotorLossDetector
from quadfault.model.scenarios import Scenario
from quadfault.model.trajectory import FlatOutput

#: gymnasium's ``np_random`` property (its getter and setter), extended by the env's
_NP_RANDOM = vars(gym.Env)["np_random"]
DEFAULT_DURATION = 20.0  # [s] episode length for named and random scenarios
#: a fault event at time t_k belongs to the step whose interval [t0, t1) holds it (same
#: tolerance as the fault windows of quadfault.model.scenarios) [s]
EVENT_TOL = 1e-9


class QuadFaultEnv(gym.Env):
    """Quadrotor tracking with motor faults; the observation carries an efficiency estimate.

    Observation (``observation="flat"``: float32 Box; ``"dict"``: one Box per slot), names in
    ``env.unwrapped.observation_names``:

    =========== ====  =========================================================
    slot        size  meaning
    =========== ====  =========================================================
    pos_err     3     p - p_ref, world NED [m] (measured), clipped to [-10, 10]
    vel_err     3     v - v_ref, world NED [m/s], clipped to [-50, 50]
    rot6        6     R[:, 0], R[:, 1] of body (FRD) -> world (NED)
    omega       3     body rate [rad/s], clipped to [-50, 50]
    eta_hat     4     estimated efficiency, clipped to [0, 2]
    eta_sd      4     its one-sigma uncertainty, clipped to [0, 10] (10 = none given)
    ref_acc     3     reference acceleration [m/s^2], in [-50, 50] (optional)
    =========== ====  =========================================================

    Action: Box [-1, 1]^4, see :class:`~quad_fault_env.envs.config.ActionConfig`. A wrong
    shape, NaN/inf or a value outside [-1, 1] (beyond 1e-6) raises ``ValueError``.

    Reward: :class:`~quad_fault_env.envs.config.RewardConfig` (bounded, tracking and effort).
    Termination: :class:`~quad_fault_env.envs.config.TerminationLimits`, with the reason in
    ``info["termination_reason"]`` (``crash``, ``out_of_bounds``, ``excessive_tilt``,
    ``non_finite``; None otherwise). Truncation when the scenario's duration is reached (and
    through ``max_episode_steps`` of the registration).

    ``info`` (truth lives here, never in the observation unless ``estimator="truth"``): with
    ``info="light"`` (the default) ``termination_reason`` alone
    (:func:`~quad_fault_env.envs.config.light_info`, the vector env's light ``info`` too);
    with ``info="full"`` also ``t`` [s]; ``eta_true`` at ``t``; ``eta_hat``, ``eta_sd`` (None
    if not reported), ``estimator``, ``estimator_status``, ``estimator_diagnostics`` of the
    newest estimate; ``position_error`` (true, world NED [m]) and its norm
    ``tracking_error``; ``motor_command`` [N] held over the step; ``fault_events`` (faults
    whose onset or end lies in the step's interval [t0, t1): dicts ``motor, onset, end,
    level, ramp, kind, t``); ``faults`` (all faults of the episode); ``scenario``;
    ``thrust_noise``; ``samples`` (the step's measurement stream: one
    :class:`estimators.base.Sample` per physics substep, the command held over it; the env's
    estimator reads every ``estimator_stride``-th one); ``eta_true_samples`` and
    ``specific_force_samples`` (accelerometer, body FRD [m/s^2]) aligned with ``samples``;
    with ``effects`` / ``model``, ``effects``.

    Keyword arguments:
        estimator: ``"irls" | "ekf" | "truth" | "none"`` or an estimator object.
        estimator_kwargs: passed to the estimator's constructor.
        scenario: a name of :data:`quadfault.model.scenarios.SCENARIO_NAMES`, a
            :class:`~quadfault.model.scenarios.Scenario`, or a generator drawn from at every reset
            with ``self.np_random``: ``"random"``
            (:func:`~quadfault.model.scenarios.random_scenario`), ``"track"``
            (:func:`~quadfault.model.task_scenarios.track_scenario`: a random smooth trajectory) or
            ``"rotor_loss"`` (:func:`~quadfault.model.task_scenarios.rotor_loss_scenario`: hover,
            one rotor drops abruptly); the last two scale with the vehicle's size.
        scenario_options: keyword arguments of the ``"track"`` or ``"rotor_loss"`` generator
            (e.g. ``{"speed": (0.5, 1.0), "curvature": (0.5, 1.0), "yaw_rate": (0, 0)}`` or
            ``{"level": (0.1, 0.3)}``); None keeps its defaults.
        random_trajectory: trajectory of random scenarios (``"random"``, ``"hover"``, ...).
        random_faults: keyword arguments of :func:`~quadfault.model.scenarios.random_scenario` for
            random scenarios (``n_faults``, ``severity``, ``degradation_prob``, ``xi_range``,
            ``thrust_noise``, ``ramp_prob``), e.g. ``{"n_faults": (1, 1), "severity": (0.5,
            0.8)}`` for one fault a controller can counter; None keeps its defaults.
        duration: episode length [s] of named and random scenarios (default 20 s); a
            Scenario object brings its own ``duration``.
        thrust_noise: sigma_f overriding the scenario's (None keeps it).
        sensor_noise: the sensors: a preset name measured on real logs (``"crazyflie"``,
            ``"px4"``, ...: docs/sensors.md), a :class:`~quadfault.model.sensors.SensorNoise`,
            a dict of its fields (``{"position": 0.01, "gyro": 0.005}``, ``{"preset": "px4",
            "gyro": 0.01}``) or ``"P,V,A,G[,ACC]"`` (white noise); default noise-free.
        action_mode, residual_scale, moment_scale: see ``ActionConfig``.
        control_rate: agent / controller rate [Hz] (100). physics_rate: plant rate [Hz] (1000).
        estimator_rate: ``"physics"`` (every substep, the default) or ``"control"`` (the
            first substep of each control step only).
        compensate: divide the geometric controller's commands by eta_hat (fault-tolerant
            allocation through the estimate).
        allocation: how the base controller's wrench (residual mode) or the agent's (wrench
            mode) becomes rotor commands: ``"nominal"`` (the allocation inverse, eq. 12) or
            ``"estimate-aware"`` (:mod:`quadfault.model.allocation`: ``A diag(eta_hat) f = w``
            within the rotor limits, giving up yaw first to keep thrust, roll and pitch; fed
            by the observation's estimate, never the truth unless ``estimator="truth"``), or
            ``"relaxed-hover"`` (residual mode: the estimate-aware allocation until the
            estimate isolates a rotor below 0.15, then the relaxed-hover controller on the
            other three, :mod:`quad_fault_env.relaxed_base`; the switch latches for the
            episode; the complete-loss task, ``QuadFaultRotorLossComplete-v0``, flies it).
        observation: ``"flat"`` or ``"dict"``. reference_acceleration: add the ``ref_acc`` slot.
        reward, limits, initial_spread: ``RewardConfig``, ``TerminationLimits``,
            ``InitialStateSpread``.
        vehicle: the vehicle (nominal for the controller and the estimator; the plant flies it
            with the scenario's efficiency).
        controller: ``ControllerConfig`` of the baseline controller.
        render_mode: ``"rgb_array"`` or ``"human"``.
        effects: domain randomisation: ``quadfault simulate --effect`` specs, values or
            ranges ``a:b`` drawn from ``self.np_random`` at each reset (e.g.
            ``["mass=0.8:1.2", "drag=0.1:0.5", "wind=-2:2,-2:2,0"]``); ``info["effects"]``
            says what was drawn (:mod:`quadfault.model.effects.sampling`).
        model: a diagnosis JSON (path or parsed object; ``quadfault.model.effects.from_diagnosis``):
            fly its nominal vehicle (instead of ``vehicle``) and its accepted effects.
        model_uncertainty: draw the model's fitted parameters from their reported
            uncertainty at each reset.
        info: what ``info`` holds: ``"light"`` (the termination reason alone; cheap to build
            and to copy) or ``"full"`` (every diagnostic above, the measurement stream the
            wrappers of :mod:`quad_fault_env.wrappers` read included). The flights are the
            same either way.

    The keywords are the fields of :class:`~quad_fault_env.envs.env_config.EnvConfig`, checked
    when it is built; ``config=EnvConfig(...)`` gives them all at once (alone). An unknown
    keyword raises a :class:`~quadfault.errors.ConfigError` naming the closest valid one.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": 25}

    def __init__(
        self,
        estimator="irls",
        scenario="combined",
        *,
        config: EnvConfig | None = None,
        **keywords,
    ):
        if config is None:
            config = EnvConfig.from_keywords(
                type(self).__name__, estimator=estimator, scenario=scenario, **keywords
            )
        elif not isinstance(config, EnvConfig) or keywords:
            raise ConfigError("config must be an EnvConfig, given alone (no other keywords)")
        #: the checked keywords (:class:`~quad_fault_env.envs.env_config.EnvConfig`)
        self.config = c = config
        #: what ``info`` holds: ``"light"`` (the termination reason) or ``"full"``
        self.info_level = c.info
        self.physics_draws = c.physics_draws
        self.vehicle = c.nominal_vehicle
        self.action_config = c.action_config
        self.reward_config, self.limits = c.reward, c.limits
        self.initial_spread, self.sensor_noise = c.initial_spread, c.sensor_noise
        self.thrust_noise, self.duration = c.thrust_noise, c.duration
        self.substeps, self.dt, self.control_period = c.substeps, c.dt, c.control_period
        self.metadata = {**self.metadata, "render_fps": c.control_rate}  # a frame per step
        self.estimator_rate = c.estimator_rate
        #: take every ``estimator_stride``-th substep sample of ``info["samples"]``
        self.estimator_stride = c.estimator_stride
        self.scenario_spec = c.scenario
        self.random_trajectory = c.random_trajectory
        self.random_faults, self.scenario_options = c.random_faults, c.scenario_options or {}
        self.estimator = make_estimator(c.estimator, self.vehicle, **(c.estimator_kwargs or {}))
        self._diagnostics_template = diagnostics_template(self.estimator)
        #: the estimate depends only on the newest sample (the registry's nominal belief and
        #: oracle)
        self._stateless_estimator = is_stateless(self.estimator)
        self.compensate, self.allocation = bool(c.compensate), c.allocation
        aware = c.allocation in ("estimate-aware", "relaxed-hover")
        #: the estimate-aware allocation (None: the nominal allocation inverse)
        self.allocator = EstimateAwareAllocator(self.vehicle) if aware else None
        #: the relaxed-hover base (None unless allocation="relaxed-hover")
        self.relaxed = (
            RelaxedHoverBase(
                self.vehicle,
                c.effects,
                c.control_period,
                detector=RotorLossDetector.for_sensors(self.sensor_noise),
            )
            if c.allocation == "relaxed-hover"
            else None
        )
        self.controller_config = c.controller_config
        self.observation_kind = c.observation
        self.layout = ObservationLayout(c.reference_acceleration)
        self.observation_space = (
            self.layout.flat_space() if c.observation == "flat" else self.layout.dict_space()
        )
        self.action_space = gym.spaces.Box(
            -1.0, 1.0, shape=(self.vehicle.n_rotors,), dtype=np.float32
        )
        self.render_mode = c.render_mode
        self._renderer = None
        #: the episode's scenario and plant (None before the first reset)
        self.scenario: Scenario | None = None
        self.plant: Plant | None = None
        #: the episode's flight and time tables (made by reset)
        self.flight: Flight
        self._tables: EpisodeTables

    # -- public helpers ----------------------------------------------------------------------
    @property
    def observation_names(self) -> list[str]:
        """One name per element of the flat observation (e.g. ``"eta_hat_1"``)."""
        return self.layout.names

    @property
    def f_max(self) -> float:
        return self.vehicle.rotor_max_thrust

    @property
    def time(self) -> float:
        """Simulation time at the end of the last step [s]."""
        return self._step_count * self.substeps * self.dt

    # -- scenario and reset ------------------------------------------------------------------
    def _make_scenario(self, spec, rng: np.random.Generator | None = None) -> Scenario:
        """The scenario of ``spec`` (drawn from ``rng``, default ``self.np_random``)."""
        return make_scenario(
            spec,
            rng or self.np_random,
            duration=self.duration or DEFAULT_DURATION,
            dt=self.dt,
            vehicle=self.vehicle,
            random_trajectory=self.random_trajectory,
            random_faults=self.random_faults or {},
            scenario_options=self.scenario_options or {},
            thrust_noise=self.thrust_noise,
        )

    def _scenario_option(self, options):
        """The scenario spec of a reset (``options["scenario"]`` or the env's)."""
        options = options or {}
        unknown = set(options) - {"scenario"}
        if unknown:
            raise ConfigError(f"unknown reset option(s) {sorted(unknown)}; only 'scenario'")
        return options.get("scenario", self.scenario_spec)

    def _initial_state(self, scenario: Scenario) -> RigidBodyState:
        """The true initial state of an episode of ``scenario`` (``episode_start.start_states``
        with N = 1)."""
        u = self.np_random.uniform(-1.0, 1.0, SPREAD_DRAWS)[None]
        s, _ = start_states(
            [scenario.trajectory],
            np.zeros(1, dtype=np.int64),
            self.vehicle,
            self.controller_config,
            self.initial_spread,
            u,
        )
        return RigidBodyState(*(x[0].copy() for x in s))

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.scenario = sc = self._make_scenario(self._scenario_option(options))
        self.controller = GeometricController(self.vehicle, sc.trajectory, self.controller_config)
        self.effects = self.physics_draws.draw(self.np_random) if self.physics_draws else ()
        self.plant = Plant(
            self.vehicle, MotorModel(sc.thrust_noise), effects=self.effects, dt=self.dt
        )
        self.plant.reset(self._initial_state(sc))
        self.flight = Flight(self.plant, self.sensor_noise)
        self.flight.reset(self.np_random)  # the loop draws from the env's generator
        self._views = self.flight.views(0)
        self._tables = EpisodeTables(
            sc, self.substeps, self.dt, self.vehicle, self.controller_config
        )
        self._tables.attach(self.flight)
        self.max_steps = int(round(sc.duration / self.control_period))
        self._step_count = 0
        self._f_cmd = np.zeros(self.vehicle.n_rotors)
        self._terminal = False
        if self.relaxed is not None:
            self.relaxed.reset()
        if reads_truth(self.estimator):  # the labelled oracle
            self.estimator.bind(sc.efficiency)
        self.estimator.reset()
        self._estimate = (
            self.estimator.update(self._sample(0.0, self._state))
            if self._stateless_estimator
            else Estimate(0.0, np.ones(self.vehicle.n_rotors), None, "warmup")
        )
        self.flight.sense()
        self.history = [self.plant.state.p.copy()]
        ref = sc.trajectory(0.0)
        events = (
            self._fault_events(-np.inf, 0.0, ("onset",)) if self.info_level == "full" else None
        )  # the faults under way from the start
        info = self._info([], [], [], events, None, ref)
        if self.render_mode == "human":
            self.render()
        return self._observation(ref), info

    # -- step --------------------------------------------------------------------------------
    @property
    def np_random(self) -> np.random.Generator:
        """The env's one generator (scenarios, initial states, and the flight's noise)."""
        return _NP_RANDOM.fget(self)

    @np_random.setter
    def np_random(self, value: np.random.Generator) -> None:
        _NP_RANDOM.fset(self, value)
        flight = getattr(self, "flight", None)
        if flight is not None:  # the loop draws from it
            flight.seed(0, [value])

    @property
    def _state(self) -> RigidBodyState:
        """The true state now (views of the flight's arrays: read them at once)."""
        return self._views[0]

    @property
    def _meas(self) -> RigidBodyState:
        """The measurement the agent and the controller see now (end of the last step;
        views of the flight's arrays)."""
        return self._views[1]

    @property
    def _episode_scenario(self) -> Scenario:
        """The episode's scenario (after a reset)."""
        if self.scenario is None:
            raise gym.error.ResetNeeded("call reset() first")
        return self.scenario

    def _check_action(self, action) -> np.ndarray:
        return validate_action(action, (self.vehicle.n_rotors,))

    def _sample(self, t: float, meas: RigidBodyState) -> Sample:
        return Sample(
            t, meas.p.copy(), meas.v.copy(), meas.R.copy(), meas.w.copy(), self._f_cmd.copy()
        )

    def motor_commands(self, action: np.ndarray, t: float, meas: RigidBodyState) -> np.ndarray:
        """Rotor thrust commands [N] for a checked ``action`` (see ``ActionConfig``)."""
        cfg = self.action_config
        if self.relaxed is not None:
            lost = int(self.relaxed.update(t, self._estimate.eta)[0])
            if lost >= 0:  # the relaxed hover replaces the base controller
                refs = self._tables.at(self._step_count).start
                f_ctrl = self.relaxed.commands(lost, meas.p, meas.v, meas.R, meas.w, refs)
                return cfg.commands(action, self.vehicle, f_ctrl)
        f_base: np.ndarray | None = (
            self._controller_commands(t, meas) if cfg.mode == "residual" else None
        )
        return cfg.commands(
            action, self.vehicle, f_base, self._estimate.eta, self.compensate, self.allocator
        )

    def _controller_commands(self, t: float, meas: RigidBodyState) -> np.ndarray:
        """The geometric controller's rotor commands [N] (eqs. 5-10, nominal allocation); at
        a control step's start the reference comes from the time tables."""
        k = self._step_count
        if t == k * self.substeps * self.dt:
            refs = self._tables.at(k).start
            return self.controller.commands(meas.p, meas.v, meas.R, meas.w, refs)
        return self.controller.motor_commands(t, meas.p, meas.v, meas.R, meas.w)[0]

    def _substeps(self, k: int):
        """Control step ``k``'s physics substeps through the closed loop: the samples of the
        ``info`` (every substep's with the full ``info``, none with the light one), the
        samples the estimator reads (every ``estimator_stride``-th; the last of those alone
        for an estimator that depends on the newest sample only), the true efficiency and
        accelerometer reading of each substep, and the efficiency at the end."""
        S = self.substeps
        tab = self._tables.at(k)
        out = self.flight.step(self._f_cmd, S, record=self.flight.records(S))
        done = int(self.flight.steps_run[0])
        t = ((k * S + np.arange(done)) * self.dt).tolist()

        def sample(j: int) -> Sample:
            return Sample(
                t[j],
                out.p[0, j],
                out.v[0, j],
                out.R[0, j],
                out.w[0, j],
                self._f_cmd.copy(),
                out.accel[0, j],
            )

        rows = range(0, done, self.estimator_stride)
        if self._stateless_estimator:  # a pure function of the sample: the last one decides
            rows = rows[-1:]
        if self.info_level == "full":
            samples = [sample(j) for j in range(done)]
            fed = [samples[j] for j in rows]
        else:
            samples, fed = [], [sample(j) for j in rows]
        eta = tab.eta
        return samples, fed, eta[:done].copy(), out.accel[0, :done], eta[S].copy()

    def step(self, action):
        if self.plant is None or self._terminal:
            raise gym.error.ResetNeeded("call reset() before step() (the episode has ended)")
        a = self._check_action(action)
        k = self._step_count
        t0 = k * self.substeps * self.dt
        self._f_cmd = self.motor_commands(a, t0, self._meas)
        samples, fed, eta_true, sf, eta_t1 = self._substeps(k)
        self._step_count += 1
        t1 = self.time
        for s in fed:
            self._estimate = self.estimator.update(s)
        state = self._state
        refs = self._tables.at(k).end
        ref = FlatOutput(refs[0].copy(), refs[1].copy(), refs[2].copy(), refs[3].copy())
        reason = self.limits.reason(state.p, state.R, ref.position)
        terminated = reason is not None
        self._terminal = terminated
        truncated = (not terminated) and self._step_count >= self.max_steps
        # the agent sees the true state of a terminated episode: no measurement is drawn
        self.flight.sense(noise=not terminated)
        self.history.append(np.array(state.p, dtype=float))
        reward = self.reward_config(
            state.p - ref.position, state.v - ref.velocity, self._f_cmd, self.f_max, terminated, a
        )
        full = self.info_level == "full"
        events = self._fault_events(t0, t1, ("onset", "end")) if full else None
        info = self._info(samples, eta_true, sf, events, reason, ref, eta_t1)
        if self.render_mode == "human":
            self.render()
        return self._observation(ref), reward, terminated, truncated, info

    # -- observation and info ----------------------------------------------------------------
    def _observation(self, ref):
        """The observation at the end of the step (``ObservationLayout.flat``); ``ref`` is
        the reference at that time."""
        m, n = self._meas, self.vehicle.n_rotors
        flat = self.layout.flat(
            pos_err=m.p - ref.position,
            vel_err=m.v - ref.velocity,
            R=m.R,
            omega=m.w,
            eta_hat=self._estimate.eta,
            eta_sd=estimate_sd(self._estimate, n),
            ref_acc=ref.acceleration,
        )
        return flat if self.observation_kind == "flat" else self.layout.split(flat)

    def _fault_events(self, t0: float, t1: float, kinds: tuple) -> list[dict]:
        """The ``info["fault_events"]`` of the interval [t0, t1): the faults' events of
        ``kinds`` (``"onset"``, ``"end"``) at a time within it."""
        return [
            dict(fault_dict(f), kind=kind, t=tk)
            for f in self._episode_scenario.efficiency.faults
            for kind, tk in (("onset", f.onset), ("end", f.end))
            if kind in kinds and t0 - EVENT_TOL <= tk < t1 - EVENT_TOL
        ]

    def _info(self, samples, eta_true, sf, events, reason, ref, eta_t=None) -> dict:
        """The step's (or the reset's) ``info``: light
        (:func:`~quad_fault_env.envs.config.light_info`) or full, with the same keys, types
        and shapes every time (``gym.make_vec`` batches them); per-substep rows that were not
        flown are NaN."""
        if self.info_level == "light":
            return light_info(reason)
        t = self.time
        state, sc = self._state, self._episode_scenario
        S, n = self.substeps, self.vehicle.n_rotors
        eta_rows, sf_rows = np.full((S, n), np.nan), np.full((S, 3), np.nan)
        eta_rows[: len(samples)] = np.reshape(eta_true, (-1, n))
        sf_rows[: len(samples)] = np.reshape(sf, (-1, 3))
        return (
            light_info(reason)
            | {
                "t": float(t),
                "eta_true": (np.asarray(sc.efficiency(t), dtype=float) if eta_t is None else eta_t),
                **estimate_info(self._estimate, self.estimator, n, self._diagnostics_template),
                "position_error": state.p - ref.position,
                "tracking_error": float(np.linalg.norm(state.p - ref.position)),
                "motor_command": self._f_cmd.copy(),
                "fault_events": events,
                "faults": [fault_dict(f) for f in sc.efficiency.faults],
                "scenario": sc.name,
                "thrust_noise": float(sc.thrust_noise),
                "samples": samples,
                "eta_true_samples": eta_rows,
                "specific_force_samples": sf_rows,
            }
            | ({"effects": describe(self.effects)} if self.physics_draws else {})
        )

    # -- rendering ---------------------------------------------------------------------------
    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode= to make")
            return None
        if self.plant is None:
            return None
        if self._renderer is None:
            self._renderer = FlightRenderer(self.vehicle, human=self.render_mode == "human")
        frame = self._renderer.draw(self)
        return frame if self.render_mode == "rgb_array" else None

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
