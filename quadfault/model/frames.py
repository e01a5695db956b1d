"""Fixed frame changes of recordings: world ENU / body FLU <-> world NED / body FRD.

Both maps are involutions (their own inverse); the exact matrices are in
:mod:`quadfault.model.rotation`.
"""

from __future__ import annotations

import numpy as np

from quadfault.model.rotation import ENU_TO_NED, FLU_TO_FRD, quat_multiply, rot_to_quat
from quadfault.model.vehicle import Vehicle

# Quaternions of the fixed frame changes.
_Q_ENU_TO_NED = rot_to_quat(ENU_TO_NED)
_Q_FLU_TO_FRD = rot_to_quat(FLU_TO_FRD)


def _conj(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def enu_flu_to_ned_frd(position, velocity, quaternion, omega, accel):
    """Convert world ENU / body FLU quantities to world NED / body FRD (and back: the same
    map is its own inverse)."""
    P, B = ENU_TO_NED, FLU_TO_FRD
    pos = None if position is None else position @ P.T
    vel = None if velocity is None else velocity @ P.T
    quat = None
    if quaternion is not None:
        quat = quat_multiply(quat_multiply(_Q_ENU_TO_NED, quaternion), _conj(_Q_FLU_TO_FRD))
        quat = quat * np.where(quat[..., :1] < 0, -1.0, 1.0)
    om = None if omega is None else omega @ B.T
    acc = None if accel is None else accel @ B.T
    return pos, vel, quat, om, acc


def vehicle_flu_to_frd(mass, inertia, allocation, **kw) -> Vehicle:
    """A vehicle described in FLU body axes, expressed in FRD (the map is an involution)."""
    B = FLU_TO_FRD
    J = np.asarray(inertia, dtype=float)
    if J.shape == (3,):
        J = np.diag(J)
    A = np.asarray(allocation, dtype=float)
    T = np.diag([1.0, 1.0, -1.0, -1.0])  # [T, Mx, My, Mz]: moments transform with B
    return Vehicle(mass=mass, inertia=B @ J @ B, allocation=T @ A, **kw)
