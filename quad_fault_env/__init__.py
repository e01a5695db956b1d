"""Gymnasium environments for fault-tolerant quadrotor control.

``import quad_fault_env`` registers the ids of :data:`quad_fault_env.tasks.TASKS`;
``gym.make("quad_fault_env:<id>")`` imports this module itself. Episodes end by truncation
when the scenario's ``duration`` is reached (``-v1``: nothing else; ``-v0`` also registers a
``max_episode_steps``) or by termination (crash, out of bounds, excessive tilt, non-finite
state).

=========================  =============================================================
id                         task
=========================  =============================================================
``QuadFault-v1``           the paper's circle (radius 3 m, 0.1 Hz) for 20 s with battery
                           degradation and the four scheduled 50 % motor faults; the
                           observation carries the sliding-window IRLS estimate
``QuadFaultHover-v1``      hover at a set-point for 10 s with randomised faults (motor,
                           onset, severity, ramp), degradation rate, thrust noise and initial
                           state; the observation carries the IRLS estimate
``QuadFaultTrack-v0``      follow a random smooth trajectory for 20 s (per horizontal axis
                           0.5-2 m/s peak speed, curvature 0.3-1 /m, heading rate within
                           0.3 rad/s; Froude-scaled to the vehicle), healthy motors
``QuadFaultRotorLoss-v0``  hover for 10 s; at 3-6 s one rotor drops abruptly to an
                           efficiency of 0-0.5 for good; survive and hold the set-point
``QuadFault-v0``,          deprecated: the same tasks with the first reward (no action
``QuadFaultHover-v0``      effort, no survival bonus, no termination penalty) and a
                           registered step limit (2,000 and 1,000 steps); kept unchanged for
                           reproducibility
=========================  =============================================================

Every keyword of :class:`~quad_fault_env.envs.quad_fault.QuadFaultEnv` can be passed to
``gym.make`` (e.g. ``estimator="ekf"``, ``action_mode="motor"``, ``observation="dict"``,
``duration=30``).
"""

from gymnasium.envs.registration import register

from quad_fault_env.estimation import make_estimator
from quad_fault_env.tasks import ENTRY_POINT, TASKS, VECTOR_ENTRY_POINT

#: id -> (max_episode_steps, kwargs): the registration table (from the tasks)
ENVIRONMENTS = {t.id: (t.max_episode_steps, t.kwargs()) for t in TASKS}

for _id, (_steps, _kwargs) in ENVIRONMENTS.items():
    register(
        id=_id,
        entry_point=ENTRY_POINT,
        max_episode_steps=_steps,
        kwargs=_kwargs,
        vector_entry_point=VECTOR_ENTRY_POINT,
    )

__all__ = ["ENVIRONMENTS", "TASKS", "make_estimator"]
