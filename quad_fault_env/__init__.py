"""Gymnasium environments for fault-tolerant quadrotor control.

``import quad_fault_env`` registers the ids below; ``gym.make("quad_fault_env:<id>")`` imports
this module itself. Episodes end by truncation after ``max_episode_steps`` control steps
(100 Hz) or by termination (crash, out of bounds, excessive tilt, non-finite state).

========================  =============================================================
id                        task
========================  =============================================================
``QuadFault-v0``          the paper's circle (radius 3 m, 0.1 Hz) for 20 s with battery
                          degradation and the four scheduled 50 % motor faults; the
                          observation carries the sliding-window IRLS estimate
``QuadFaultHover-v0``     hover at a set-point for 10 s with randomised faults (motor,
                          onset, severity, ramp), degradation rate, thrust noise and initial
                          state; the observation carries the IRLS estimate
========================  =============================================================

Every keyword of :class:`~quad_fault_env.envs.quad_fault.QuadFaultEnv` can be passed to
``gym.make`` (e.g. ``estimator="ekf"``, ``action_mode="motor"``, ``observation="dict"``).
"""

from gymnasium.envs.registration import register

from quad_fault_env.envs.config import InitialStateSpread
from quad_fault_env.estimation import make_estimator

ENTRY_POINT = "quad_fault_env.envs.quad_fault:QuadFaultEnv"

#: id -> (max_episode_steps, kwargs): the registration table
ENVIRONMENTS = {
    "QuadFault-v0": (2000, {"estimator": "irls", "scenario": "combined", "duration": 20.0}),
    "QuadFaultHover-v0": (1000, {
        "estimator": "irls", "scenario": "random", "random_trajectory": "hover",
        "duration": 10.0,
        "initial_spread": InitialStateSpread(position=0.3, velocity=0.2, attitude=0.1, rate=0.2),
    }),
}

for _id, (_steps, _kwargs) in ENVIRONMENTS.items():
    register(id=_id, entry_point=ENTRY_POINT, max_episode_steps=_steps, kwargs=_kwargs,
             vector_entry_point="quad_fault_env.vector:QuadFaultVectorEnv")

__all__ = ["ENVIRONMENTS", "make_estimator"]
