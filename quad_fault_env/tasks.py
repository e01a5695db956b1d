"""The registered environments as tasks: what is flown, for how long, and how it is scored.

A :class:`Task` is one row of the registration table: the scenario generator (a named
scenario, or ``"random"`` with its trajectory and fault distribution), the episode length, the
initial-state spread, the estimator in the observation, the reward and the termination
limits -- keywords of :class:`~quad_fault_env.envs.quad_fault.QuadFaultEnv`, which
``gym.make`` passes on (a keyword given to ``gym.make`` overrides the task's). A new task is a
new row; a changed reward or episode rule is a new version of the id, and the old version
stays registered unchanged for reproducibility.

Episode length. ``-v1`` tasks end an episode by truncation when the scenario's ``duration``
[s] is reached, i.e. after ``round(duration * control_rate)`` control steps, whatever path
builds the environment (``gym.make``, ``gym.make_vec`` in every mode,
:func:`~quad_fault_env.sb3_vec.make_sb3_vec_env`, ``quadfault train``): they register no step
limit. The deprecated ``-v0`` tasks also register a ``max_episode_steps`` (``TimeLimit``,
counted in steps), which cuts a longer ``duration`` or a lower ``control_rate`` short.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import gymnasium as gym

from quad_fault_env.envs.config import InitialStateSpread, RewardConfig, TerminationLimits
from quadfault.errors import ConfigError
from quadfault.model.relaxed_hover import ROTOR_LOSS_EFFECTS, rotor_loss_vehicle
from quadfault.model.vehicle import Vehicle

#: the classes every id registers (``gym.make`` / ``gym.make_vec``)
ENTRY_POINT = "quad_fault_env.envs.quad_fault:QuadFaultEnv"
VECTOR_ENTRY_POINT = "quad_fault_env.vector:QuadFaultVectorEnv"

#: the reward of the -v0 ids: tracking and thrust effort only (no action effort, no survival
#: bonus, no termination penalty)
REWARD_V0 = RewardConfig(
    position_scale=1.0,
    velocity_weight=0.1,
    effort_weight=0.01,
    action_weight=0.0,
    survival_bonus=0.0,
    termination_penalty=0.0,
)
#: the reward of the -v1 ids (the defaults of :class:`RewardConfig`)
REWARD_V1 = RewardConfig()
#: the initial-state spread of the hover tasks
HOVER_SPREAD = InitialStateSpread(position=0.3, velocity=0.2, attitude=0.1, rate=0.2)


@dataclass(frozen=True)
class Task:
    """A registered environment.

    Attributes:
        id: the Gymnasium id (``Name-vN``).
        summary: one line for the docs and ``repr``.
        scenario: a name of :data:`quadfault.model.scenarios.SCENARIO_NAMES` or a generator
            (``"random"``, ``"track"``, ``"rotor_loss"``).
        duration: episode length [s].
        random_trajectory: trajectory of random scenarios.
        scenario_options: keywords of the ``track`` / ``rotor_loss`` generator (None: its
            defaults).
        initial_spread: spread of the initial state, or None (none).
        estimator: the estimator in the observation.
        reward: the reward.
        limits: the termination limits (None: the defaults).
        max_episode_steps: a step limit (``TimeLimit``) registered with the id, or None
            (the episode ends at ``duration``; every ``-v1`` id).
        deprecated_by: the id that replaces this one, or None.
        vehicle: the vehicle flown (None: the env's default, the paper's F450).
        effects: the plant's effects (``effects`` keyword of the env), or None.
        allocation: the base controller's allocation (None: the env's default, nominal).
    """

    id: str
    summary: str
    scenario: str
    duration: float
    random_trajectory: str = "random"
    scenario_options: dict | None = None
    initial_spread: InitialStateSpread | None = None
    estimator: str = "irls"
    reward: RewardConfig = field(default_factory=RewardConfig)
    limits: TerminationLimits | None = None
    max_episode_steps: int | None = None
    deprecated_by: str | None = None
    vehicle: Vehicle | None = None
    effects: tuple | None = None
    allocation: str | None = None

    def __post_init__(self):
        if not (math.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"task {self.id}: duration must be positive [s]")

    def kwargs(self) -> dict:
        """The environment keywords of the task (what the registration passes)."""
        out = {
            "estimator": self.estimator,
            "scenario": self.scenario,
            "duration": float(self.duration),
            "reward": self.reward,
        }
        if self.scenario == "random":
            out["random_trajectory"] = self.random_trajectory
        if self.scenario_options is not None:
            out["scenario_options"] = dict(self.scenario_options)
        if self.initial_spread is not None:
            out["initial_spread"] = self.initial_spread
        if self.limits is not None:
            out["limits"] = self.limits
        for key in ("vehicle", "effects", "allocation"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        return out


_CIRCLE = (
    "the paper's circle (radius 3 m, 0.1 Hz) for 20 s with battery degradation and the "
    "four scheduled 50 % motor faults; IRLS estimate in the observation"
)
_HOVER = (
    "hover at a set-point for 10 s with randomised faults, degradation, thrust noise and "
    "initial state; IRLS estimate in the observation"
)

_TRACK = (
    "follow a random smooth trajectory for 20 s (each horizontal axis 0.5-2 m/s peak "
    "speed, curvature 0.3-1 /m; heading rate within 0.3 rad/s; scaled to the vehicle's "
    "size), healthy motors; IRLS estimate in the observation"
)
_ROTOR_LOSS = (
    "hover for 10 s; between 3 and 6 s one rotor drops abruptly to an efficiency of "
    "0-0.5 and stays there; survive and hold the set-point; IRLS estimate in the "
    "observation"
)
_ROTOR_LOSS_COMPLETE = (
    "hover for 10 s on the complete-loss vehicle (thrust-to-weight 2.75, body rate damping, "
    "rotor inertia and gyroscopic moment); between 3 and 6 s one rotor stops (efficiency 0); "
    "hold the set-point spinning on three rotors (success: within 1 m from 2 s after the "
    "loss to the end); base: the relaxed-hover fallback on the IRLS estimate"
)
#: small initial-state spread of the new tasks
TASK_SPREAD = InitialStateSpread(position=0.1, velocity=0.1, attitude=0.05, rate=0.1)

TASKS = (
    Task("QuadFault-v1", _CIRCLE, "combined", 20.0),
    Task(
        "QuadFaultHover-v1",
        _HOVER,
        "random",
        10.0,
        random_trajectory="hover",
        initial_spread=HOVER_SPREAD,
    ),
    Task("QuadFaultTrack-v0", _TRACK, "track", 20.0, initial_spread=TASK_SPREAD),
    Task("QuadFaultRotorLoss-v0", _ROTOR_LOSS, "rotor_loss", 10.0, initial_spread=TASK_SPREAD),
    Task(
        "QuadFaultRotorLossComplete-v0",
        _ROTOR_LOSS_COMPLETE,
        "rotor_loss",
        10.0,
        scenario_options={"level": (0.0, 0.0)},
        initial_spread=TASK_SPREAD,
        vehicle=rotor_loss_vehicle(),
        effects=ROTOR_LOSS_EFFECTS,
        allocation="relaxed-hover",
    ),
    Task(
        "QuadFault-v0",
        _CIRCLE,
        "combined",
        20.0,
        reward=REWARD_V0,
        max_episode_steps=2000,
        deprecated_by="QuadFault-v1",
    ),
    Task(
        "QuadFaultHover-v0",
        _HOVER,
        "random",
        10.0,
        random_trajectory="hover",
        initial_spread=HOVER_SPREAD,
        reward=REWARD_V0,
        max_episode_steps=1000,
        deprecated_by="QuadFaultHover-v1",
    ),
)


def registered_kwargs(env_id: str, **overrides) -> dict:
    """The :class:`~quad_fault_env.vector.QuadFaultVectorEnv` keywords of a registered QuadFault id, as
    ``gym.make_vec`` passes them: the task's keywords, then ``overrides``, and the id's step
    limit as ``max_episode_steps`` when it registers one (``-v0``) and none is given."""
    try:
        spec = gym.spec(env_id)
    except gym.error.Error as exc:
        raise ConfigError(f"environment {env_id!r}: {exc}") from None
    if spec.vector_entry_point != VECTOR_ENTRY_POINT:
        raise ConfigError(
            f"{env_id!r} is not a QuadFault environment id (its vector entry "
            f"point is {spec.vector_entry_point!r})"
        )
    kwargs = dict(spec.kwargs, **overrides)
    if spec.max_episode_steps is not None:
        kwargs.setdefault("max_episode_steps", spec.max_episode_steps)
    return kwargs


def task(env_id: str) -> Task:
    """The task registered as ``env_id`` (``KeyError`` names the known ids)."""
    for t in TASKS:
        if t.id == env_id:
            return t
    raise KeyError(f"unknown task {env_id!r}; known: {', '.join(t.id for t in TASKS)}")


__all__ = [
    "HOVER_SPREAD",
    "TASK_SPREAD",
    "registered_kwargs",
    "REWARD_V0",
    "REWARD_V1",
    "TASKS",
    "Task",
    "task",
]
