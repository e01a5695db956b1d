"""QuadFaultEnv: a quadrotor with degrading / failing motors and an efficiency estimate in the
observation.

Data flow per control step (100 Hz by default)::

    action -> rotor commands (held) -> 10 x [sensors -> Sample; Plant.step] (1 kHz)
           -> estimator.update(samples) -> observation (+ truth only in info)

The physics is the core :class:`quadfault.plant.Plant` (rigid body, motor saturation,
efficiency, thrust noise drawn per physics substep) and the baseline controller is the core
:class:`quadfault.controller.GeometricController` on the *nominal* vehicle: a fault reaches the
controller only through the estimator (``compensate=True``) or through the agent.
"""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np

from estimators.base import Estimate, Sample
from quad_fault_env.envs.config import (
    ESTIMATOR_RATES,
    OBSERVATION_KINDS,
    ActionConfig,
    InitialStateSpread,
    RewardConfig,
    TerminationLimits,
    validate_action,
)
from quad_fault_env.envs.episode_start import SPREAD_DRAWS, start_states
from quad_fault_env.estimation import (
    NOMINAL_PRIOR_SD,
    NominalBelief,
    TruthOracle,
    diagnostics_dict,
    estimate_sd,
    make_estimator,
)
from quad_fault_env.observation import SD_MAX, ObservationLayout
from quadfault.controller import ControllerConfig, GeometricController
from quadfault.dynamics import RigidBodyState
from quadfault.errors import ConfigError
from quadfault.motors import MotorModel
from quadfault.plant import Plant
from quadfault.scenarios import SCENARIO_NAMES, Scenario, named_scenario, random_scenario
from quadfault.simulator import SensorNoise
from quadfault.vehicle import Vehicle

DEFAULT_DURATION = 20.0  # [s] episode length for named and random scenarios
#: a fault event at time t_k belongs to the step whose interval [t0, t1) holds it (same
#: tolerance as the fault windows of quadfault.scenarios) [s]
EVENT_TOL = 1e-9
#: trajectories of random scenarios (``quadfault.scenarios.random_scenario``)
RANDOM_TRAJECTORIES = ("random", "circle", "hover", "lissajous")


def _number_at_least(value, low: float) -> bool:
    """Whether ``value`` is a finite real number >= ``low``."""
    return (isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
            and math.isfinite(value) and value >= low)


#: keywords of ``random_faults``: (low, high) ranges and probabilities of ``random_scenario``
_RANGE_KEYS = ("n_faults", "severity", "xi_range", "thrust_noise")
_PROB_KEYS = ("degradation_prob", "ramp_prob")


def _check_random_faults(spec) -> dict:
    """Validate ``random_faults`` (None: the defaults of ``random_scenario``)."""
    if spec is None:
        return {}
    if not isinstance(spec, dict):
        raise ConfigError(f"random_faults must be a dict of random_scenario keywords, got {spec!r}")
    out = {}
    for key, value in spec.items():
        if key in _PROB_KEYS:
            if not (_number_at_least(value, 0.0) and value <= 1.0):
                raise ConfigError(f"random_faults[{key!r}] must be a probability in [0, 1], "
                                  f"got {value!r}")
            out[key] = float(value)
        elif key in _RANGE_KEYS:
            try:
                low, high = (float(v) for v in value)
            except (TypeError, ValueError):
                raise ConfigError(f"random_faults[{key!r}] must be a (low, high) pair, "
                                  f"got {value!r}") from None
            if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low <= high):
                raise ConfigError(f"random_faults[{key!r}] must satisfy 0 <= low <= high, "
                                  f"got {value!r}")
            if key == "n_faults":
                if low != int(low) or high != int(high):
                    raise ConfigError(f"random_faults['n_faults'] must be whole numbers, "
                                      f"got {value!r}")
                out[key] = (int(low), int(high))
            elif key == "severity" and high > 1.0:
                raise ConfigError(f"random_faults['severity'] levels are efficiencies in "
                                  f"[0, 1], got {value!r}")
            else:
                out[key] = (low, high)
        else:
            raise ConfigError(f"random_faults has unknown key {key!r}; choose from "
                              f"{', '.join(_RANGE_KEYS + _PROB_KEYS)}")
    return out


def _numba_available() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


#: ``physics`` values: the plant's substeps in numpy or on the compiled plant step
PHYSICS_BACKENDS = ("auto", "numpy", "numba")


def _compiled_physics_available() -> bool:
    from quadfault import _numba_kernels

    return _numba_kernels.AVAILABLE


_SLOW_ESTIMATOR_WARNED = False


def _warn_slow_estimator_once() -> None:
    """Tell a user without numba once that the 1 kHz estimator runs in pure numpy."""
    global _SLOW_ESTIMATOR_WARNED
    if not _SLOW_ESTIMATOR_WARNED:
        _SLOW_ESTIMATOR_WARNED = True
        warnings.warn("QuadFaultEnv: the estimator runs at the physics rate in pure numpy "
                      "(numba not installed), which is several times slower; install "
                      "'quadfault[fast]' or pass estimator_rate='control' for a decimated "
                      "100 Hz stream", RuntimeWarning, stacklevel=3)


def _fault_dict(f) -> dict:
    return {"motor": f.motor, "onset": f.onset, "end": f.end, "level": f.level, "ramp": f.ramp}


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

    ``info`` (truth lives here, never in the observation unless ``estimator="truth"``):
    ``t`` [s]; ``eta_true`` at ``t``; ``eta_hat``, ``eta_sd`` (None if not reported),
    ``estimator``, ``estimator_status``, ``estimator_diagnostics`` of the newest estimate;
    ``position_error`` (true, world NED [m]) and its norm ``tracking_error``;
    ``motor_command`` [N] held over the step; ``fault_events`` (faults whose onset or end lies
    in the step's interval [t0, t1): dicts ``motor, onset, end, level, ramp, kind, t``);
    ``faults`` (all faults of the episode); ``scenario``; ``thrust_noise``; ``samples`` (the step's measurement stream:
    one :class:`estimators.base.Sample` per physics substep, the command held over it; the
    env's estimator reads every ``estimator_stride``-th one); ``eta_true_samples`` and
    ``specific_force_samples`` (accelerometer, body FRD [m/s^2]) aligned with ``samples``;
    ``termination_reason``.

    Keyword arguments:
        estimator: ``"irls" | "ekf" | "truth" | "none"`` or an estimator object.
        estimator_kwargs: passed to the estimator's constructor.
        scenario: a name of :data:`quadfault.scenarios.SCENARIO_NAMES`, a
            :class:`~quadfault.scenarios.Scenario`, or ``"random"``
            (:func:`~quadfault.scenarios.random_scenario` with ``self.np_random``).
        random_trajectory: trajectory of random scenarios (``"random"``, ``"hover"``, ...).
        random_faults: keyword arguments of :func:`~quadfault.scenarios.random_scenario` for
            random scenarios (``n_faults``, ``severity``, ``degradation_prob``, ``xi_range``,
            ``thrust_noise``, ``ramp_prob``), e.g. ``{"n_faults": (1, 1), "severity": (0.5,
            0.8)}`` for one fault a controller can counter; None keeps its defaults.
        duration: episode length [s] of named and random scenarios (default 20 s); a
            Scenario object brings its own ``duration``.
        thrust_noise: sigma_f overriding the scenario's (None keeps it).
        sensor_noise: a :class:`~quadfault.simulator.SensorNoise` (default noise-free).
        action_mode, residual_scale, moment_scale: see ``ActionConfig``.
        control_rate: agent / controller rate [Hz] (100). physics_rate: plant rate [Hz] (1000).
        estimator_rate: ``"physics"`` (every substep; the default, whether or not numba is
            installed, so observations do not depend on the install) or ``"control"`` (the
            first substep of each control step only).
        compensate: divide the geometric controller's commands by eta_hat (fault-tolerant
            allocation through the estimate).
        observation: ``"flat"`` or ``"dict"``. reference_acceleration: add the ``ref_acc`` slot.
        reward, limits, initial_spread: ``RewardConfig``, ``TerminationLimits``,
            ``InitialStateSpread``.
        vehicle: the vehicle (nominal for the controller and the estimator; the plant flies it
            with the scenario's efficiency).
        controller: ``ControllerConfig`` of the baseline controller.
        render_mode: ``"rgb_array"`` or ``"human"``.
        physics: ``"auto"`` (default: ``"numba"`` when numba is importable, else
            ``"numpy"``), ``"numpy"`` (the core :class:`~quadfault.plant.Plant`, one call
            per substep) or ``"numba"`` (the substeps of a control step in one compiled call
            on the same plant step as the simulator and the vector env,
            ``quadfault._numba_kernels.plant_step``, and the compiled twin of the geometric
            controller). Both give the same observations, rewards and infos to rounding
            (tested to 1e-9) and draw the same random numbers.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 25}

    def __init__(self, estimator="irls", scenario="combined", *, estimator_kwargs=None,
                 random_trajectory: str = "random", random_faults: dict | None = None,
                 duration: float | None = None,
                 thrust_noise: float | None = None, sensor_noise: SensorNoise | None = None,
                 action_mode: str = "residual", residual_scale: float = 1.0,
                 moment_scale: tuple = (1.0, 1.0, 0.05), control_rate: float = 100.0,
                 physics_rate: float = 1000.0, estimator_rate: str = "physics",
                 compensate: bool = False, observation: str = "flat",
                 reference_acceleration: bool = True, reward: RewardConfig | None = None,
                 limits: TerminationLimits | None = None,
                 initial_spread: InitialStateSpread | None = None,
                 vehicle: Vehicle | None = None, controller: ControllerConfig | None = None,
                 render_mode: str | None = None, physics: str = "auto"):
        self.vehicle = vehicle or Vehicle()
        if not isinstance(self.vehicle, Vehicle) or self.vehicle.n_rotors != 4:
            raise ConfigError("vehicle must be a quadfault Vehicle with 4 rotors (the scenarios "
                              "and the observation have four motors)")
        self.action_config = ActionConfig(action_mode, residual_scale, moment_scale)
        self.reward_config = reward or RewardConfig()
        self.limits = limits or TerminationLimits()
        self.initial_spread = initial_spread or InitialStateSpread()
        self.sensor_noise = sensor_noise or SensorNoise()
        if not isinstance(self.sensor_noise, SensorNoise):
            raise ConfigError(f"sensor_noise must be a SensorNoise, got {sensor_noise!r}")
        if thrust_noise is not None and not _number_at_least(thrust_noise, 0.0):
            raise ConfigError(f"thrust_noise must be a number >= 0, got {thrust_noise!r}")
        self.thrust_noise = thrust_noise
        if not (_number_at_least(control_rate, 0.0) and _number_at_least(physics_rate, 0.0)
                and control_rate > 0 and physics_rate > 0):
            raise ConfigError(f"control_rate and physics_rate must be positive [Hz], got "
                              f"{control_rate!r} and {physics_rate!r}")
        ratio = physics_rate / control_rate
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ConfigError(f"physics_rate ({physics_rate} Hz) must be a whole multiple of "
                              f"control_rate ({control_rate} Hz)")
        self.substeps = int(round(ratio))
        self.dt = 1.0 / physics_rate
        self.control_period = 1.0 / control_rate
        self.metadata = {**self.metadata, "render_fps": control_rate}  # a frame per step
        if estimator_rate not in ESTIMATOR_RATES:
            raise ConfigError(f"estimator_rate must be one of {ESTIMATOR_RATES}, "
                              f"got {estimator_rate!r}")
        self.estimator_rate = estimator_rate
        #: take every ``estimator_stride``-th substep sample of ``info["samples"]``
        self.estimator_stride = 1 if estimator_rate == "physics" else self.substeps
        if not (isinstance(scenario, (str, Scenario))):
            raise ConfigError(f"scenario must be a name, 'random' or a Scenario, got {scenario!r}")
        if isinstance(scenario, str) and scenario not in SCENARIO_NAMES + ("random",):
            raise ConfigError(f"unknown scenario {scenario!r}; choose from "
                              f"{', '.join(SCENARIO_NAMES + ('random',))}")
        self.scenario_spec = scenario
        if random_trajectory not in RANDOM_TRAJECTORIES:
            raise ConfigError(f"random_trajectory must be one of {RANDOM_TRAJECTORIES}, "
                              f"got {random_trajectory!r}")
        self.random_trajectory = random_trajectory
        self.random_faults = _check_random_faults(random_faults)
        if duration is not None and not (_number_at_least(duration, 0.0) and duration > 0):
            raise ConfigError(f"duration must be positive [s], got {duration!r}")
        self.duration = duration
        self.estimator = make_estimator(estimator, self.vehicle, **(estimator_kwargs or {}))
        if estimator_rate == "physics" and estimator in ("irls", "ekf") and not _numba_available():
            _warn_slow_estimator_once()
        self.compensate = bool(compensate)
        self.controller_config = controller or ControllerConfig()
        if observation not in OBSERVATION_KINDS:
            raise ConfigError(f"observation must be one of {OBSERVATION_KINDS}, "
                              f"got {observation!r}")
        self.observation_kind = observation
        self.layout = ObservationLayout(reference_acceleration)
        self.observation_space = (self.layout.flat_space() if observation == "flat"
                                  else self.layout.dict_space())
        # per element of the flat layout: lower and upper bound, NaN fill (see _observation)
        self._obs_bounds = tuple(np.concatenate([np.full(s.size, x(s), dtype=float)
                                                 for s in self.layout.slots])
                                 for x in (lambda s: s.low, lambda s: s.high,
                                           lambda s: SD_MAX if s.name == "eta_sd" else 0.0))
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(self.vehicle.n_rotors,),
                                           dtype=np.float32)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(f"render_mode must be one of {self.metadata['render_modes']}, "
                              f"got {render_mode!r}")
        self.render_mode = render_mode
        if not isinstance(physics, str) or physics not in PHYSICS_BACKENDS:
            raise ConfigError(f"physics must be one of {PHYSICS_BACKENDS}, got {physics!r}")
        if physics == "numba" and not _compiled_physics_available():
            raise ConfigError("physics='numba' needs numba (install the 'fast' extra)")
        if physics == "auto":
            physics = "numba" if _compiled_physics_available() else "numpy"
        #: ``"numpy"`` or ``"numba"``: how the plant's substeps run (``physics`` resolved)
        self.physics = physics
        self._compiled = None
        self._renderer = None
        self.scenario: Scenario | None = None
        self.plant: Plant | None = None

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
    def _make_scenario(self, spec) -> Scenario:
        if isinstance(spec, Scenario):
            sc = spec  # a Scenario object brings its own duration
        elif spec == "random":
            sc = random_scenario(self.np_random, self.duration or DEFAULT_DURATION,
                                 trajectory=self.random_trajectory, **self.random_faults)
        elif isinstance(spec, str) and spec in SCENARIO_NAMES:
            sc = named_scenario(spec, self.duration or DEFAULT_DURATION, self.dt)
        else:
            raise ConfigError(f"options['scenario'] must be a scenario name, 'random' or a "
                              f"Scenario, got {spec!r}")
        if self.thrust_noise is not None:
            sc = sc.replace(thrust_noise=self.thrust_noise)
        return sc

    def _scenario_option(self, options):
        """The scenario spec of a reset (``options["scenario"]`` or the env's)."""
        options = options or {}
        unknown = set(options) - {"scenario"}
        if unknown:
            raise ConfigError(f"unknown reset option(s) {sorted(unknown)}; only 'scenario'")
        return options.get("scenario", self.scenario_spec)

    def _initial_state(self) -> RigidBodyState:
        """The episode's true initial state (``episode_start.start_states`` with N = 1)."""
        u = self.np_random.uniform(-1.0, 1.0, SPREAD_DRAWS)[None]
        s, _ = start_states([self.scenario.trajectory], np.zeros(1, dtype=np.int64),
                            self.vehicle, self.controller_config, self.initial_spread, u)
        return RigidBodyState(*(x[0].copy() for x in s))

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.scenario = self._make_scenario(self._scenario_option(options))
        self.controller = GeometricController(self.vehicle, self.scenario.trajectory,
                                              self.controller_config)
        self.plant = Plant(self.vehicle, self.scenario.efficiency,
                           MotorModel(self.scenario.thrust_noise), dt=self.dt,
                           rng=self.np_random)
        self.plant.reset(self._initial_state())
        self.max_steps = int(round(self.scenario.duration / self.control_period))
        self._compiled = None  # the compiled path's CompiledStep, built at the first step
        self._step_count = 0
        self._f_cmd = np.zeros(self.vehicle.n_rotors)
        self._terminal = False
        if isinstance(self.estimator, TruthOracle):
            self.estimator.bind(self.scenario.efficiency)
        self.estimator.reset()
        #: the estimate depends only on the newest sample (the oracle, the nominal belief)
        self._stateless_estimator = type(self.estimator) in (TruthOracle, NominalBelief)
        n = self.vehicle.n_rotors
        if isinstance(self.estimator, TruthOracle):
            self._estimate = self.estimator.update(self._sample(0.0, self.plant.state))
        elif isinstance(self.estimator, NominalBelief):
            self._estimate = Estimate(0.0, np.ones(n), np.full(n, NOMINAL_PRIOR_SD))
        else:
            self._estimate = Estimate(0.0, np.ones(n), None, "warmup")
        self._meas = self._measure(self.plant.state)
        self.history = [self.plant.state.p.copy()]
        events = [dict(_fault_dict(f), kind="onset", t=f.onset)
                  for f in self.scenario.efficiency.faults if f.onset < -EVENT_TOL]
        ref = self.scenario.trajectory(0.0)
        info = self._info([], [], [], events, None, ref)
        if self.render_mode == "human":
            self.render()
        return self._observation(ref), info

    # -- step --------------------------------------------------------------------------------
    def _check_action(self, action) -> np.ndarray:
        return validate_action(action, self.action_space.shape)

    def _measure(self, state: RigidBodyState) -> RigidBodyState:
        return self.sensor_noise.measure(state, None, self.np_random)[0]

    def _sample(self, t: float, meas: RigidBodyState) -> Sample:
        return Sample(t, meas.p.copy(), meas.v.copy(), meas.R.copy(), meas.w.copy(),
                      self._f_cmd.copy())

    def motor_commands(self, action: np.ndarray, t: float, meas: RigidBodyState) -> np.ndarray:
        """Rotor thrust commands [N] for a checked ``action`` (see ``ActionConfig``)."""
        cfg, f_max = self.action_config, self.f_max
        if cfg.mode == "motor":
            f = 0.5 * (action + 1.0) * f_max
        elif cfg.mode == "wrench":
            thrust = 0.5 * (action[0] + 1.0) * self.vehicle.n_rotors * f_max
            moment = action[1:] * np.asarray(cfg.moment_scale)
            f = self.vehicle.rotor_thrust(np.concatenate(([thrust], moment)))
        else:
            f_ctrl = self._controller_commands(t, meas)
            if self.compensate:
                f_ctrl = f_ctrl / np.clip(self._estimate.eta, 0.1, None)
            f = f_ctrl + cfg.residual_scale * action
        return np.clip(f, 0.0, f_max)

    def _controller_commands(self, t: float, meas: RigidBodyState) -> np.ndarray:
        """The geometric controller's rotor commands [N] (eqs. 5-10, nominal allocation)."""
        if self._compiled is not None and t == self._step_count * self.substeps * self.dt:
            return self._compiled.controller_commands(self._step_count, meas)
        return self.controller.motor_commands(t, meas.p, meas.v, meas.R, meas.w)[0]

    def _substeps_numpy(self, k0: int):
        """The control step's physics substeps through the core ``Plant`` (numpy)."""
        samples, eta_true, sf = [], [], []
        meas = self._meas
        for j in range(self.substeps):
            t = (k0 + j) * self.dt
            if j > 0:
                meas = self._measure(self.plant.state)
            samples.append(self._sample(t, meas))
            out = self.plant.step(self._f_cmd, t)
            eta_true.append(out.eta)
            if self.sensor_noise.accel:
                sf.append(out.specific_force + self.sensor_noise.accel
                          * self.np_random.standard_normal(3))
            else:
                sf.append(out.specific_force)
            if not self.plant.state.is_finite():
                break
        n = self.vehicle.n_rotors
        return samples, np.array(eta_true).reshape(-1, n), np.array(sf).reshape(-1, 3), None

    def step(self, action):
        if self.plant is None or self._terminal:
            raise gym.error.ResetNeeded("call reset() before step() (the episode has ended)")
        a = self._check_action(action)
        k0 = self._step_count * self.substeps
        t0 = k0 * self.dt
        if self.physics == "numba" and self._compiled is None:
            from quad_fault_env.envs.compiled_substeps import CompiledStep

            self._compiled = CompiledStep(self)
        self._f_cmd = self.motor_commands(a, t0, self._meas)
        if self._compiled is not None:
            samples, eta_true, sf, eta_t1 = self._compiled.substeps(self._step_count,
                                                                    self._f_cmd, self.np_random)
        else:
            samples, eta_true, sf, eta_t1 = self._substeps_numpy(k0)
        self._step_count += 1
        t1 = self.time
        if self._stateless_estimator:  # a pure function of the sample: the last one decides
            if samples[::self.estimator_stride]:
                self._estimate = self.estimator.update(samples[::self.estimator_stride][-1])
        else:
            for s in samples[::self.estimator_stride]:
                self._estimate = self.estimator.update(s)
        state = self.plant.state
        ref = (self.scenario.trajectory(t1) if self._compiled is None
               else self._compiled.reference(self._step_count))
        reason = self.limits.reason(state.p, state.R, ref.position)
        terminated = reason is not None
        self._terminal = terminated
        truncated = (not terminated) and self._step_count >= self.max_steps
        self._meas = self._measure(state) if not terminated else state
        self.history.append(np.array(state.p, dtype=float))
        reward = self.reward_config(state.p - ref.position, state.v - ref.velocity,
                                    self._f_cmd, self.f_max, terminated)
        events = []
        for f in self.scenario.efficiency.faults:
            for kind, tk in (("onset", f.onset), ("end", f.end)):
                if t0 - EVENT_TOL <= tk < t1 - EVENT_TOL:
                    events.append(dict(_fault_dict(f), kind=kind, t=tk))
        info = self._info(samples, eta_true, sf, events, reason, ref, eta_t1)
        if self.render_mode == "human":
            self.render()
        return self._observation(ref), (0.0 if not math.isfinite(reward) else reward), \
            terminated, truncated, info

    # -- observation and info ----------------------------------------------------------------
    def _observation(self, ref):
        """The observation at the end of the step; ``ref`` is the reference at that time.

        The numbers of ``ObservationLayout.values`` (NaN -> the slot's fill, clipped into the
        slot's bounds, float32) in one vector operation over the flat layout."""
        m, n = self._meas, self.vehicle.n_rotors
        sd = estimate_sd(self._estimate, n)
        lo, hi, fill = self._obs_bounds
        raw = {"pos_err": m.p - ref.position, "vel_err": m.v - ref.velocity,
               "rot6": (m.R[:, 0], m.R[:, 1]), "omega": m.w,
               "eta_hat": np.broadcast_to(np.asarray(self._estimate.eta, dtype=float), (n,)),
               "eta_sd": np.full(n, SD_MAX) if sd is None else sd, "ref_acc": ref.acceleration}
        x = np.concatenate([a for s in self.layout.slots
                            for a in (raw[s.name] if s.name == "rot6" else (raw[s.name],))])
        x = np.where(np.isnan(x), fill, x)
        flat = np.clip(x, lo, hi).astype(np.float32)
        if self.observation_kind == "flat":
            return flat
        return {s.name: flat[self.layout.slice(s.name)].copy() for s in self.layout.slots}

    def _info(self, samples, eta_true, sf, events, reason, ref, eta_t=None) -> dict:
        t = self.time
        state = self.plant.state
        est = self._estimate
        return {
            "t": t,
            "eta_true": (np.asarray(self.scenario.efficiency(t), dtype=float) if eta_t is None
                         else eta_t),
            "eta_hat": np.asarray(est.eta, dtype=float),
            "eta_sd": estimate_sd(est, self.vehicle.n_rotors),
            "estimator": getattr(self.estimator, "name", type(self.estimator).__name__),
            "estimator_status": est.status,
            "estimator_diagnostics": diagnostics_dict(est.diagnostics),
            "position_error": state.p - ref.position,
            "tracking_error": float(np.linalg.norm(state.p - ref.position)),
            "motor_command": self._f_cmd.copy(),
            "fault_events": events,
            "faults": [_fault_dict(f) for f in self.scenario.efficiency.faults],
            "scenario": self.scenario.name,
            "thrust_noise": self.scenario.thrust_noise,
            "samples": samples,
            "eta_true_samples": np.array(eta_true).reshape(-1, self.vehicle.n_rotors),
            "specific_force_samples": np.array(sf).reshape(-1, 3),
            "termination_reason": reason,
        }

    # -- rendering ---------------------------------------------------------------------------
    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode= to make")
            return None
        if self.plant is None:
            return None
        if self._renderer is None:
            from quad_fault_env.rendering import FlightRenderer

            self._renderer = FlightRenderer(self.vehicle, human=self.render_mode == "human")
        frame = self._renderer.draw(self)
        return frame if self.render_mode == "rgb_array" else None

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
