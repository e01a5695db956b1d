"""The configuration of :class:`~quad_fault_env.envs.quad_fault.QuadFaultEnv`: one frozen
dataclass whose fields are the env's keywords (``gym.make("QuadFault-v1", **keywords)``).

:class:`EnvConfig` checks every keyword when it is built (a one-line
:class:`~quadfault.errors.ConfigError` naming the keyword and what it takes) and holds the
checked values: the configuration dataclasses for ``None`` or a dict of their fields, the
nominal vehicle (the model's when ``model`` is given), the controller's configuration with the
paper's gains carried over to that vehicle. Derived values (physics substeps, periods, the
estimator's stride) are properties. The estimator itself is built by the env (it has state).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from quad_fault_env.envs.config import (
    ALLOCATIONS,
    ESTIMATOR_RATES,
    INFO_LEVELS,
    OBSERVATION_KINDS,
    RANDOM_TRAJECTORIES,
    ActionConfig,
    InitialStateSpread,
    RewardConfig,
    TerminationLimits,
    check_choice,
    check_keywords,
    check_random_faults,
    config_of,
    number_at_least,
)
from quad_fault_env.envs.scenario_source import GENERATORS, check_scenario_options
from quadfault.errors import ConfigError
from quadfault.model.controller import ControllerConfig, GeometricGains
from quadfault.model.effects.sampling import PhysicsDraws
from quadfault.model.scenarios import SCENARIO_NAMES, Scenario
from quadfault.model.sensor_presets import as_sensor_noise
from quadfault.model.sensors import SensorNoise
from quadfault.model.vehicle import Vehicle

#: the render modes of the single env (its ``metadata["render_modes"]``)
RENDER_MODES = ["human", "rgb_array"]


@dataclass(frozen=True)
class EnvConfig:
    """Every keyword of :class:`~quad_fault_env.envs.quad_fault.QuadFaultEnv`, checked (the
    env's docstring says what each one does).

    Fields given as ``None`` or a dict (``reward``, ``limits``, ``initial_spread``,
    ``sensor_noise``) hold their dataclass after construction; ``random_faults`` holds its checked
    dict, ``scenario_options`` its checked dict or None (the generator's defaults). Built from the env's keywords with
    :meth:`from_keywords` (an unknown keyword names the closest valid one).
    """

    estimator: object = "irls"
    scenario: str | Scenario = "combined"
    estimator_kwargs: dict | None = None
    random_trajectory: str = "random"
    random_faults: dict | None = None
    scenario_options: dict | None = None
    duration: float | None = None
    thrust_noise: float | None = None
    sensor_noise: SensorNoise | str | dict | None = None
    action_mode: str = "residual"
    residual_scale: float = 1.0
    moment_scale: tuple = (1.0, 1.0, 0.05)
    control_rate: float = 100.0
    physics_rate: float = 1000.0
    estimator_rate: str = "physics"
    compensate: bool = False
    allocation: str = "nominal"
    observation: str = "flat"
    reference_acceleration: bool = True
    reward: RewardConfig | dict | None = None
    limits: TerminationLimits | dict | None = None
    initial_spread: InitialStateSpread | dict | None = None
    vehicle: Vehicle | None = None
    controller: ControllerConfig | None = None
    render_mode: str | None = None
    effects: object = None
    model: object = None
    model_uncertainty: bool = False
    info: str = "light"
    #: the randomised physics of the episodes (None: the nominal physics)
    physics_draws: PhysicsDraws | None = field(init=False, repr=False, compare=False)
    #: the nominal vehicle: the controller's and the estimator's (``model``'s or ``vehicle``)
    nominal_vehicle: Vehicle = field(init=False, repr=False, compare=False)
    #: how actions become rotor commands
    action_config: ActionConfig = field(init=False, repr=False, compare=False)
    #: the baseline controller's configuration (``controller`` or the paper's gains scaled
    #: to the nominal vehicle)
    controller_config: ControllerConfig = field(init=False, repr=False, compare=False)

    @classmethod
    def from_keywords(cls, owner: str = "QuadFaultEnv", **keywords) -> EnvConfig:
        """The configuration of an env's keywords; an unknown one is a one-line error naming
        ``owner`` and the closest valid keyword."""
        check_keywords(keywords, KEYWORDS, owner)
        return cls(**keywords)

    def __post_init__(self):
        def put(name, value):
            object.__setattr__(self, name, value)

        check_choice("info", self.info, INFO_LEVELS)
        draws = PhysicsDraws.of(self.effects, self.model, self.model_uncertainty)
        put("physics_draws", draws)
        vehicle = self.vehicle
        if draws is not None and draws.vehicle is not None:
            if vehicle is not None:
                raise ConfigError("give either vehicle or model (the model brings its vehicle)")
            vehicle = draws.vehicle
        vehicle = vehicle or Vehicle()
        if not isinstance(vehicle, Vehicle) or vehicle.n_rotors != 4:
            raise ConfigError(
                "vehicle must be a quadfault Vehicle with 4 rotors (the scenarios "
                "and the observation have four motors)"
            )
        put("nominal_vehicle", vehicle)
        put("action_config", ActionConfig(self.action_mode, self.residual_scale, self.moment_scale))
        put("reward", config_of(self.reward, RewardConfig, "reward"))
        put("limits", config_of(self.limits, TerminationLimits, "limits"))
        put("initial_spread", config_of(self.initial_spread, InitialStateSpread, "initial_spread"))
        put("sensor_noise", as_sensor_noise(self.sensor_noise, "sensor_noise"))
        self._check_rates()
        self._check_scenario()
        self._check_allocation()
        # the paper's gains carried over to the vehicle's mass and inertia (any vehicle flies)
        put(
            "controller_config",
            self.controller or ControllerConfig(gains=GeometricGains().scaled(vehicle)),
        )
        if self.observation not in OBSERVATION_KINDS:
            raise ConfigError(
                f"observation must be one of {OBSERVATION_KINDS}, got {self.observation!r}"
            )
        if self.render_mode is not None and self.render_mode not in RENDER_MODES:
            raise ConfigError(
                f"render_mode must be one of {RENDER_MODES}, got {self.render_mode!r}"
            )

    def _check_rates(self) -> None:
        noise = self.thrust_noise
        if noise is not None and not number_at_least(noise, 0.0):
            raise ConfigError(f"thrust_noise must be a number >= 0, got {noise!r}")
        control, physics = self.control_rate, self.physics_rate
        if not (
            number_at_least(control, 0.0)
            and number_at_least(physics, 0.0)
            and control > 0
            and physics > 0
        ):
            raise ConfigError(
                f"control_rate and physics_rate must be positive [Hz], got "
                f"{control!r} and {physics!r}"
            )
        ratio = physics / control
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ConfigError(
                f"physics_rate ({physics} Hz) must be a whole multiple of "
                f"control_rate ({control} Hz)"
            )
        if self.estimator_rate not in ESTIMATOR_RATES:
            raise ConfigError(
                f"estimator_rate must be one of {ESTIMATOR_RATES}, got {self.estimator_rate!r}"
            )

    def _check_scenario(self) -> None:
        scenario = self.scenario
        if not (isinstance(scenario, (str, Scenario))):
            raise ConfigError(f"scenario must be a name, 'random' or a Scenario, got {scenario!r}")
        if isinstance(scenario, str) and scenario not in SCENARIO_NAMES + GENERATORS:
            raise ConfigError(
                f"unknown scenario {scenario!r}; choose from "
                f"{', '.join(SCENARIO_NAMES + GENERATORS)}"
            )
        if self.random_trajectory not in RANDOM_TRAJECTORIES:
            raise ConfigError(
                f"random_trajectory must be one of {RANDOM_TRAJECTORIES}, "
                f"got {self.random_trajectory!r}"
            )
        object.__setattr__(self, "random_faults", check_random_faults(self.random_faults))
        options = check_scenario_options(self.scenario_options, scenario)
        object.__setattr__(self, "scenario_options", options or None)  # None: the defaults
        duration = self.duration
        if duration is not None and not (number_at_least(duration, 0.0) and duration > 0):
            raise ConfigError(f"duration must be positive [s], got {duration!r}")

    def _check_allocation(self) -> None:
        allocation = self.allocation
        if allocation not in ALLOCATIONS:
            raise ConfigError(f"allocation must be one of {ALLOCATIONS}, got {allocation!r}")
        aware = allocation in ("estimate-aware", "relaxed-hover")
        if aware and self.action_config.mode == "motor":
            raise ConfigError(
                f"allocation={allocation!r} allocates a wrench (the controller's "
                "in residual mode, the agent's in wrench mode); motor mode has "
                "none"
            )
        if allocation == "relaxed-hover" and self.action_config.mode != "residual":
            raise ConfigError(
                "allocation='relaxed-hover' replaces the base controller: it needs "
                "action_mode='residual'"
            )
        if aware and self.compensate:
            raise ConfigError(
                "choose compensate=True (the nominal split divided by eta_hat) or "
                f"allocation={allocation!r} (which already uses eta_hat), not both"
            )

    # -- derived values ----------------------------------------------------------------------
    @property
    def substeps(self) -> int:
        """Physics steps per control step."""
        return int(round(self.physics_rate / self.control_rate))

    @property
    def dt(self) -> float:
        """Physics step [s]."""
        return 1.0 / self.physics_rate

    @property
    def control_period(self) -> float:
        """Control step [s]."""
        return 1.0 / self.control_rate

    @property
    def estimator_stride(self) -> int:
        """The estimator reads every ``estimator_stride``-th physics substep's sample."""
        return 1 if self.estimator_rate == "physics" else self.substeps


#: the keywords of the env (the fields given at construction)
KEYWORDS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(EnvConfig) if f.init)

__all__ = ["KEYWORDS", "RENDER_MODES", "EnvConfig"]
