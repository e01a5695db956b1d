"""Rigid-body dynamics of a multirotor (paper eqs. 1-4) and its integrators.

NED world frame, FRD body frame::

    x' = v                                   (1)
    m v' = m g e3 - T R e3 + F_ext           (2)
    R' = R [Omega]x                          (3)
    J Omega' + Omega x J Omega = M + M_ext   (4)

All functions accept a leading batch shape (``p`` is ``(..., 3)``, ``R`` is ``(..., 3, 3)``),
so the single-vehicle simulator and the vectorised environment run the same code.

Integrators:

* :func:`step_rk4` -- Runge-Kutta-Munthe-Kaas of order 4: ``p, v, Omega`` by classical RK4,
  the attitude on SO(3) through the exponential map, so ``R`` stays orthonormal to machine
  precision without re-projection.
* :class:`ReferenceEuler` -- the authors' MATLAB step (``dynamics.m``), reproduced exactly:
  the semi-implicit Euler order and the one-sample input lag (the derivative used from
  sample k to k+1 was computed at the end of the previous step, from the command applied at
  sample k-1 and the attitude R_{k-1}).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from quadfault.rotation import cross, dcm_orthonormalize_reference, expm_so3, hat
from quadfault.vehicle import Vehicle

E3 = np.array([0.0, 0.0, 1.0])


class RigidBodyState(NamedTuple):
    """Kinematic state; arrays may carry a leading batch shape.

    Attributes:
        p: position of the centre of mass, world NED [m].
        v: velocity, world NED [m/s].
        R: rotation body (FRD) -> world (NED).
        w: body angular rate Omega [rad/s].
    """

    p: np.ndarray
    v: np.ndarray
    R: np.ndarray
    w: np.ndarray

    @classmethod
    def at_rest(cls, position=(0.0, 0.0, 0.0), batch_shape: tuple = ()) -> "RigidBodyState":
        p = np.broadcast_to(np.asarray(position, dtype=float), batch_shape + (3,)).copy()
        return cls(p, np.zeros(batch_shape + (3,)),
                   np.broadcast_to(np.eye(3), batch_shape + (3, 3)).copy(),
                   np.zeros(batch_shape + (3,)))

    def copy(self) -> "RigidBodyState":
        return RigidBodyState(self.p.copy(), self.v.copy(), self.R.copy(), self.w.copy())

    def is_finite(self) -> np.ndarray:
        return (np.isfinite(self.p).all(-1) & np.isfinite(self.v).all(-1)
                & np.isfinite(self.R).all((-1, -2)) & np.isfinite(self.w).all(-1))


#: ``external(state) -> (F_world [N], M_body [N m])``, evaluated at every integrator stage.
ExternalWrench = Callable[[RigidBodyState], tuple]


def translational_acceleration(R: np.ndarray, thrust, vehicle: Vehicle,
                               force_world=None) -> np.ndarray:
    """v' of eq. (2) [m/s^2] for collective thrust ``thrust`` [N] (``(...,)``)."""
    acc = vehicle.gravity * E3 - (np.asarray(thrust)[..., None] / vehicle.mass) * R[..., :, 2]
    if force_world is not None:
        acc = acc + force_world / vehicle.mass
    return acc


def angular_acceleration(w: np.ndarray, moment: np.ndarray, vehicle: Vehicle,
                         moment_ext=None, inertia=None, inertia_inverse=None) -> np.ndarray:
    """Omega' of eq. (4) [rad/s^2]."""
    J = vehicle.inertia if inertia is None else inertia
    Jinv = vehicle.inertia_inverse if inertia_inverse is None else inertia_inverse
    m = moment - cross(w, w @ J.T)
    if moment_ext is not None:
        m = m + moment_ext
    return m @ Jinv.T


def specific_force_body(R: np.ndarray, acceleration_world: np.ndarray, gravity: float) -> np.ndarray:
    """Accelerometer reading in FRD: ``R^T (a - g e3)`` [m/s^2] ((0, 0, -g) at rest)."""
    f_world = acceleration_world - gravity * E3
    return np.einsum("...ji,...j->...i", R, f_world)


def _derivatives(state: RigidBodyState, thrust, moment, vehicle: Vehicle,
                 external: ExternalWrench | None):
    if external is None:
        F = Mx = None
    else:
        F, Mx = external(state)
    vdot = translational_acceleration(state.R, thrust, vehicle, F)
    wdot = angular_acceleration(state.w, moment, vehicle, Mx)
    return state.v, vdot, wdot


def _dexpinv(theta: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Inverse right-trivialised differential of exp, to 4th order: theta' given Omega."""
    tw = cross(theta, w)
    return w + 0.5 * tw + cross(theta, tw) / 12.0


def step_rk4(state: RigidBodyState, thrust, moment, vehicle: Vehicle, dt: float,
             external: ExternalWrench | None = None) -> RigidBodyState:
    """One RKMK4 step of length ``dt`` [s] with thrust [N] and moment [N m] held constant.

    ``R(t) = R0 exp([theta(t)]x)``, ``theta' = dexp^-1_{-theta}(Omega)``; order 4 in ``dt``.
    """
    p0, v0, R0, w0 = state
    h = 0.5 * dt
    k1p, k1v, k1w = _derivatives(state, thrust, moment, vehicle, external)
    th1 = w0
    s2 = RigidBodyState(p0 + h * k1p, v0 + h * k1v, R0 @ expm_so3(h * th1), w0 + h * k1w)
    k2p, k2v, k2w = _derivatives(s2, thrust, moment, vehicle, external)
    th2 = _dexpinv(h * th1, s2.w)
    s3 = RigidBodyState(p0 + h * k2p, v0 + h * k2v, R0 @ expm_so3(h * th2), w0 + h * k2w)
    k3p, k3v, k3w = _derivatives(s3, thrust, moment, vehicle, external)
    th3 = _dexpinv(h * th2, s3.w)
    s4 = RigidBodyState(p0 + dt * k3p, v0 + dt * k3v, R0 @ expm_so3(dt * th3), w0 + dt * k3w)
    k4p, k4v, k4w = _derivatives(s4, thrust, moment, vehicle, external)
    th4 = _dexpinv(dt * th3, s4.w)
    c = dt / 6.0
    return RigidBodyState(
        p0 + c * (k1p + 2 * k2p + 2 * k3p + k4p),
        v0 + c * (k1v + 2 * k2v + 2 * k3v + k4v),
        R0 @ expm_so3(c * (th1 + 2 * th2 + 2 * th3 + th4)),
        w0 + c * (k1w + 2 * k2w + 2 * k3w + k4w),
    )


class ReferenceEuler:
    """The authors' MATLAB integrator (``dynamics.m``), single vehicle, reproduced exactly.

    Per sample: ``W += W' dt; v += a dt; R <- orth(R (I + [W dt]x)); x += v dt``; only then
    are ``a`` and ``W'`` recomputed from the force and moment currently stored. The controller
    stores the new command *after* the step, so the transition k -> k+1 uses the command
    applied at sample k-1 with the attitude R_{k-1}, and position picks up ``a dt^2``.
    """

    def __init__(self, vehicle: Vehicle, dt: float):
        self.vehicle = vehicle
        self.dt = float(dt)
        self.a = np.zeros(3)
        self.w_dot = np.zeros(3)
        self.force_world = np.zeros(3)  # thrust vector T R e3 stored by the controller [N]
        self.moment = np.zeros(3)

    def step(self, state: RigidBodyState) -> RigidBodyState:
        dt, veh = self.dt, self.vehicle
        w = state.w + self.w_dot * dt
        v = state.v + self.a * dt
        R = dcm_orthonormalize_reference(state.R @ (np.eye(3) + hat(w * dt)))
        p = state.p + v * dt
        self.a = veh.gravity * E3 - self.force_world / veh.mass
        self.w_dot = veh.inertia_inverse @ (self.moment - np.cross(w, veh.inertia @ w))
        return RigidBodyState(p, v, R, w)

    def apply(self, thrust: float, moment: np.ndarray, R: np.ndarray) -> None:
        """Store the applied wrench (the reference's ``uav_dynamics.f`` and ``.M``)."""
        self.force_world = float(thrust) * R[:, 2]
        self.moment = np.asarray(moment, dtype=float).copy()
