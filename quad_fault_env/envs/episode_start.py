"""The start of an episode over a batch axis: one definition for the single and the vector env.

An episode of :class:`~quad_fault_env.envs.quad_fault.QuadFaultEnv` starts from the core's
:func:`quadfault.sim.simulator.initial_state` (the geometric controller's feed-forward attitude
``R_d`` and rate ``Omega_d`` at t = 0 on the reference's position and velocity), perturbed by
:class:`~quad_fault_env.envs.config.InitialStateSpread` with 12 uniform draws of the episode's
generator (position, velocity, attitude, rate; 3 each). :func:`start_states` computes that for
N episodes at once: each distinct trajectory is evaluated once (with the same calls as for a
single episode), and the controller arithmetic runs over the batch axis -- the single env
calls it with N = 1, the vector env's reset with all the rows it resets.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from quadfault.model.controller import ControllerConfig, GeometricController
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.rotation import expm_so3
from quadfault.model.scenarios import at_times
from quadfault.model.trajectory import FlatOutput
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import initial_state

#: uniform draws in [-1, 1] per episode start: position, velocity, attitude, rate (3 each)
SPREAD_DRAWS = 12


def _as_shape(x, shape: tuple) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return x if x.shape == shape else np.broadcast_to(x, shape)


class RowTrajectories:
    """N reference trajectories as one callable: row i follows ``items[keys[i]]``.

    ``self(t)`` returns a :class:`~quadfault.model.trajectory.FlatOutput` of arrays
    ``(N,) + shape(t) + (3,)``; each distinct trajectory is evaluated once on the times
    (:func:`quadfault.model.scenarios.at_times`: one call when it takes arrays).
    """

    def __init__(self, items, keys: np.ndarray):
        self.items = list(items)
        self.keys = np.asarray(keys, dtype=np.int64)
        self._memo: dict = {}  # times -> FlatOutput (initial_state asks for t = 0 twice)

    def __call__(self, t) -> FlatOutput:
        t_key = (np.shape(t), np.asarray(t, dtype=float).tobytes())
        if t_key not in self._memo:
            self._memo[t_key] = self._scalar_from_memo(t)
        if self._memo[t_key] is None:
            shape = np.shape(t) + (3,)
            flat = np.asarray(t, dtype=float).reshape(-1)
            outs = [at_times(traj, flat) for traj in self.items]
            self._memo[t_key] = FlatOutput(
                *(
                    np.stack([_as_shape(np.reshape(o[f], shape), shape) for o in outs])[self.keys]
                    for f in range(4)
                )
            )
        return FlatOutput(*(x.copy() for x in self._memo[t_key]))

    def _scalar_from_memo(self, t):
        """A scalar time already evaluated inside a 1-D array of times, or None."""
        if np.ndim(t) != 0:
            return None
        for (shape, raw), ref in self._memo.items():
            if len(shape) == 1 and ref is not None:
                hit = np.flatnonzero(np.frombuffer(raw) == float(t))
                if len(hit):
                    return FlatOutput(*(x[:, hit[0]] for x in ref))
        return None


def nominal_starts(items, vehicle: Vehicle, controller: ControllerConfig):
    """The unperturbed episode start of each trajectory of ``items``: the states
    :func:`start_states` perturbs and the reference at t = 0, arrays with a leading axis of
    ``len(items)`` (a caller starting many episodes on the same trajectories keeps them)."""
    traj = RowTrajectories(items, np.arange(len(items)))
    if controller.angular_feedforward:  # one evaluation per trajectory: the feed-forward's
        h = controller.ff_step  # times (as feedforward_rates forms them) hold t = 0
        traj(np.stack((0.0 - h, 0.0, 0.0 + h), axis=-1))
    s = initial_state(
        SimpleNamespace(trajectory=traj), 0.0, GeometricController(vehicle, traj, controller)
    )
    return s, traj(0.0)


def start_states(
    items,
    keys,
    vehicle: Vehicle,
    controller: ControllerConfig,
    spread,
    u: np.ndarray,
    nominal=None,
) -> tuple[RigidBodyState, FlatOutput]:
    """Initial true states (N,) of N episodes.

    Args:
        items, keys: the distinct trajectories and each row's index into them (N,).
        vehicle, controller: the nominal vehicle and the controller configuration.
        spread: the :class:`~quad_fault_env.envs.config.InitialStateSpread` half-widths.
        u: (N, 12) uniform draws in [-1, 1] (each row's generator: ``uniform(-1, 1, 12)``,
            the same numbers as four draws of 3).
        nominal: :func:`nominal_starts` of ``items`` when the caller kept it (None: computed).

    Returns the states and the reference at t = 0 (rows (N, 3)).
    """
    keys = np.asarray(keys, dtype=np.int64)
    s, ref0 = nominal_starts(items, vehicle, controller) if nominal is None else nominal
    s = RigidBodyState(*(np.asarray(x)[keys] for x in s))
    pos, vel, att, rate = (u[:, 3 * k : 3 * k + 3] for k in range(4))
    R = s.R if spread.attitude == 0 else s.R @ expm_so3(spread.attitude * att)  # R I == R
    state = RigidBodyState(
        s.p + spread.position * pos, s.v + spread.velocity * vel, R, s.w + spread.rate * rate
    )
    return state, FlatOutput(*(np.asarray(x)[keys] for x in ref0))


__all__ = ["SPREAD_DRAWS", "RowTrajectories", "nominal_starts", "start_states"]
