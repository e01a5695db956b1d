"""Rigid-body dynamics of a multirotor (paper eqs. 1-4) and its integrators.

NED world frame, FRD body frame::

    x' = v                                   (1)
    m v' = m g e3 - T R e3 + F_ext           (2)
    R' = R [Omega]x                          (3)
    J Omega' + Omega x J Omega = M + M_ext   (4)

Kernels (one vehicle; vectors are 3-tuples, ``R`` a row-major 9-tuple, the vehicle's rigid
body the tuple ``rigid = (m, g, J, J^-1)`` of :func:`rigid_body`):

* :func:`rotor_wrench` -- the thrust allocation (eq. 12): ``[T; M] = A diag(eta) f``;
* :func:`translational_acceleration3` (eq. 2), :func:`angular_acceleration3` (eq. 4),
  :func:`specific_force3` (the accelerometer's reading ``R^T (v' - g e3)``);
* :func:`rkmk4_step` -- Runge-Kutta-Munthe-Kaas of order 4: ``p, v, Omega`` by classical RK4,
  the attitude on SO(3) through the exponential map, so ``R`` stays orthonormal to machine
  precision without re-projection. An external wrench enters through the effects hook
  ``fx`` (see :mod:`quadfault.model.plant`), evaluated at every stage's state;
* :func:`reference_euler_step` / :func:`reference_euler_store` -- the authors' MATLAB step
  (``dynamics.m``), reproduced exactly: the semi-implicit Euler order and the one-sample
  input lag (the derivative used from sample k to k+1 was computed at the end of the previous
  step, from the command applied at sample k-1 and the attitude R_{k-1}).

Array functions over a leading batch shape (``p`` is ``(..., 3)``, ``R`` is ``(..., 3, 3)``)
for the code that works on whole recordings: :func:`translational_acceleration`,
:func:`angular_acceleration`, :func:`specific_force_body` and :func:`step_rk4` are compiled
loops over the kernels; ``step_rk4`` with a Python ``external`` wrench runs the RKMK4 kernel
interpreted over the whole batch at once (numpy arrays in place of its floats), calling
``external`` once per stage.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from quadfault.jit import jit, python
from quadfault.model.effects.chain import effects_wrench
from quadfault.model.rotation import (
    axpy3,
    cross3,
    dcm_renormalize3,
    expm3,
    expm_so3,
    hat3,
    mat3,
    matmul3,
    matvec3,
    scale3,
    store3,
    store33,
    vec3,
)
from quadfault.model.vehicle import Vehicle

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
    def at_rest(cls, position=(0.0, 0.0, 0.0), batch_shape: tuple = ()) -> RigidBodyState:
        p = np.broadcast_to(np.asarray(position, dtype=float), batch_shape + (3,)).copy()
        return cls(
            p,
            np.zeros(batch_shape + (3,)),
            np.broadcast_to(np.eye(3), batch_shape + (3, 3)).copy(),
            np.zeros(batch_shape + (3,)),
        )

    def copy(self) -> RigidBodyState:
        return RigidBodyState(self.p.copy(), self.v.copy(), self.R.copy(), self.w.copy())

    def is_finite(self) -> np.ndarray:
        return (
            np.isfinite(self.p).all(-1)
            & np.isfinite(self.v).all(-1)
            & np.isfinite(self.R).all((-1, -2))
            & np.isfinite(self.w).all(-1)
        )


#: ``external(state) -> (F_world [N], M_body [N m])``, evaluated at every integrator stage.
ExternalWrench = Callable[[RigidBodyState], tuple]


def rigid_body(vehicle: Vehicle, inertia=None, inertia_inverse=None) -> tuple:
    """The kernels' rigid-body constants ``(m [kg], g [m/s^2], J, J^-1)`` of ``vehicle``
    (``J`` [kg m^2] and its inverse as row-major 9-tuples; ``inertia`` overrides ``J``)."""
    J = np.asarray(vehicle.inertia if inertia is None else inertia, dtype=float)
    if inertia_inverse is not None:
        Jinv = inertia_inverse
    else:
        Jinv = vehicle.inertia_inverse if inertia is None else np.linalg.inv(J)
    return (
        float(vehicle.mass),
        float(vehicle.gravity),
        tuple(J.ravel().tolist()),
        tuple(np.asarray(Jinv, dtype=float).ravel().tolist()),
    )


# --- kernels -------------------------------------------------------------------------------
@jit(inline="always")
def rotor_wrench(A, f, eta=None):
    """The thrust allocation (eq. 12): collective thrust ``T`` [N] and body moment ``M``
    [N m] (a 3-tuple) of rotor thrusts ``f`` (n,) [N] through the allocation ``A`` (4, n),
    ``[T; M] = A diag(eta) f``; ``eta`` (n,) the rotors' efficiencies (None: all 1). The one
    allocation of the project: the closed loop, the IRLS residuals and the EKF use it."""
    T = m0 = m1 = m2 = 0.0
    for j in range(f.shape[0]):
        if eta is None:
            fj = f[j]
        else:
            fj = eta[j] * f[j]
        T += A[0, j] * fj
        m0 += A[1, j] * fj
        m1 += A[2, j] * fj
        m2 += A[3, j] * fj
    return T, (m0, m1, m2)


@jit(inner=True)
def translational_acceleration3(R, thrust, rigid, F=None):
    """v' of eq. (2) [m/s^2] for collective thrust ``thrust`` [N] and an optional external
    force ``F`` (world) [N]."""
    mass = rigid[0]
    s = thrust / mass
    a = (0.0 - s * R[2], 0.0 - s * R[5], rigid[1] - s * R[8])
    if F is None:
        return a
    return (a[0] + F[0] / mass, a[1] + F[1] / mass, a[2] + F[2] / mass)


@jit(inner=True)
def angular_acceleration3(w, moment, rigid, moment_ext=None):
    """Omega' of eq. (4) [rad/s^2]: ``J^-1 (M - Omega x J Omega + M_ext)``."""
    c = cross3(w, matvec3(rigid[2], w))
    m = (moment[0] - c[0], moment[1] - c[1], moment[2] - c[2])
    if moment_ext is not None:
        m = (m[0] + moment_ext[0], m[1] + moment_ext[1], m[2] + moment_ext[2])
    return matvec3(rigid[3], m)


@jit(inner=True)
def specific_force3(R, acc, gravity):
    """Accelerometer reading in FRD: ``R^T (a - g e3)`` [m/s^2] ((0, 0, -g) at rest)."""
    f2 = acc[2] - gravity
    return (
        R[0] * acc[0] + R[3] * acc[1] + R[6] * f2,
        R[1] * acc[0] + R[4] * acc[1] + R[7] * f2,
        R[2] * acc[0] + R[5] * acc[1] + R[8] * f2,
    )


@jit(inner=True)
def dexpinv3(theta, w):
    """Inverse right-trivialised differential of exp, to 4th order: theta' given Omega."""
    tw = cross3(theta, w)
    ttw = cross3(theta, tw)
    return (
        w[0] + 0.5 * tw[0] + ttw[0] / 12.0,
        w[1] + 0.5 * tw[1] + ttw[1] / 12.0,
        w[2] + 0.5 * tw[2] + ttw[2] / 12.0,
    )


@jit(inline="always")
def _accelerations(p, v, R, w, thrust, moment, rigid, fx, f, t):
    """(v', Omega') of eqs. 2 and 4 at one stage's state; the effects ``fx`` (None: none)
    add their external wrench at that state. Inlined into the four stages of
    :func:`rkmk4_step` by numba: as a compiled call LLVM inlines it without effects but not
    with a wrench, and the four calls (some 50 arguments each) cost a vehicle-step more than
    a drag's physics; typing the effect chain four times costs a flight with effects about
    1 CPU-s of its first compile."""
    if fx is None:
        return (
            translational_acceleration3(R, thrust, rigid),
            angular_acceleration3(w, moment, rigid),
        )
    F, Mx = effects_wrench(fx, p, v, R, w, f, t)
    return (
        translational_acceleration3(R, thrust, rigid, F),
        angular_acceleration3(w, moment, rigid, Mx),
    )


@jit(inner=True)
def _rk_sum(x0, c, k1, k2, k3, k4):
    """``x0 + c (k1 + 2 k2 + 2 k3 + k4)``."""
    return (
        x0[0] + c * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0]),
        x0[1] + c * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1]),
        x0[2] + c * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2]),
    )


@jit(inner=True)
def rkmk4_step(p0, v0, R0, w0, thrust, moment, rigid, dt, fx=None, f=None, t=0.0):
    """One RKMK4 step of length ``dt`` [s] with thrust [N] and moment [N m] held constant:
    ``R(t) = R0 exp([theta(t)]x)``, ``theta' = dexp^-1_{-theta}(Omega)``; order 4 in ``dt``.

    ``fx`` (the effects, None for none: a vehicle's compiled effects over the step,
    :func:`quadfault.model.effects.chain.wrench_terms`, or in the interpreted kernel any object
    with a ``wrench`` method) gives the external wrench at each stage for the produced rotor
    thrusts ``f`` and the step's start time ``t`` [s]. Returns
    ``(p, v, R, w, a0)``: the new state and eq. 2's acceleration at the start (what the
    accelerometer measures, :func:`specific_force3`).
    """
    h = 0.5 * dt
    k1v, k1w = _accelerations(p0, v0, R0, w0, thrust, moment, rigid, fx, f, t)
    k1p, th1 = v0, w0
    p2, v2 = axpy3(p0, h, k1p), axpy3(v0, h, k1v)
    R2, w2 = matmul3(R0, expm3(scale3(h, th1))), axpy3(w0, h, k1w)
    k2v, k2w = _accelerations(p2, v2, R2, w2, thrust, moment, rigid, fx, f, t)
    k2p, th2 = v2, dexpinv3(scale3(h, th1), w2)
    p3, v3 = axpy3(p0, h, k2p), axpy3(v0, h, k2v)
    R3, w3 = matmul3(R0, expm3(scale3(h, th2))), axpy3(w0, h, k2w)
    k3v, k3w = _accelerations(p3, v3, R3, w3, thrust, moment, rigid, fx, f, t)
    k3p, th3 = v3, dexpinv3(scale3(h, th2), w3)
    p4, v4 = axpy3(p0, dt, k3p), axpy3(v0, dt, k3v)
    R4, w4 = matmul3(R0, expm3(scale3(dt, th3))), axpy3(w0, dt, k3w)
    k4v, k4w = _accelerations(p4, v4, R4, w4, thrust, moment, rigid, fx, f, t)
    k4p, th4 = v4, dexpinv3(scale3(dt, th3), w4)
    c = dt / 6.0
    th = (
        c * (th1[0] + 2 * th2[0] + 2 * th3[0] + th4[0]),
        c * (th1[1] + 2 * th2[1] + 2 * th3[1] + th4[1]),
        c * (th1[2] + 2 * th2[2] + 2 * th3[2] + th4[2]),
    )
    return (
        _rk_sum(p0, c, k1p, k2p, k3p, k4p),
        _rk_sum(v0, c, k1v, k2v, k3v, k4v),
        matmul3(R0, expm3(th)),
        _rk_sum(w0, c, k1w, k2w, k3w, k4w),
        k1v,
    )


@jit(inner=True)
def reference_euler_step(p0, v0, R0, w0, memory, rigid, dt):
    """The authors' step (``dynamics.m``) from the stored derivatives: ``W += W' dt;
    v += a dt; R <- orth(R (I + [W dt]x)); x += v dt``; then ``a`` and ``W'`` are recomputed
    from the force and moment stored by :func:`reference_euler_store`.

    ``memory`` (4, 3) holds ``(a, W', T R e3, M)`` and is updated in place. Returns the new
    state ``(p, v, R, w)``.
    """
    w = axpy3(w0, dt, vec3(memory[1]))
    v = axpy3(v0, dt, vec3(memory[0]))
    A = hat3(scale3(dt, w))
    A = (1.0, A[1], A[2], A[3], 1.0, A[5], A[6], A[7], 1.0)
    R = dcm_renormalize3(matmul3(R0, A))
    p = axpy3(p0, dt, v)
    mass = rigid[0]
    memory[0, 0] = -memory[2, 0] / mass
    memory[0, 1] = -memory[2, 1] / mass
    memory[0, 2] = -memory[2, 2] / mass + rigid[1]
    store3(memory[1], angular_acceleration3(w, vec3(memory[3]), rigid))
    return p, v, R, w


@jit(inner=True)
def reference_euler_store(memory, thrust, moment, R):
    """Store the applied wrench (the reference's ``uav_dynamics.f = T R e3`` and ``.M``)."""
    memory[2, 0], memory[2, 1], memory[2, 2] = thrust * R[2], thrust * R[5], thrust * R[8]
    store3(memory[3], moment)


# --- array functions over a batch -----------------------------------------------------------
@jit
def _translational_rows(R, thrust, F, rigid, out):
    for i in range(R.shape[0]):
        if F.shape[0] == 0:
            store3(out[i], translational_acceleration3(mat3(R[i]), thrust[i], rigid))
        else:
            store3(out[i], translational_acceleration3(mat3(R[i]), thrust[i], rigid, vec3(F[i])))


@jit
def _angular_rows(w, moment, Mx, rigid, out):
    for i in range(w.shape[0]):
        if Mx.shape[0] == 0:
            store3(out[i], angular_acceleration3(vec3(w[i]), vec3(moment[i]), rigid))
        else:
            store3(out[i], angular_acceleration3(vec3(w[i]), vec3(moment[i]), rigid, vec3(Mx[i])))


@jit
def _specific_force_rows(R, acc, gravity, out):
    for i in range(R.shape[0]):
        store3(out[i], specific_force3(mat3(R[i]), vec3(acc[i]), gravity))


@jit
def _rk4_rows(p, v, R, w, thrust, moment, rigid, dt, out_p, out_v, out_R, out_w):
    for i in range(p.shape[0]):
        p1, v1, R1, w1, _ = rkmk4_step(
            vec3(p[i]), vec3(v[i]), mat3(R[i]), vec3(w[i]), thrust[i], vec3(moment[i]), rigid, dt[i]
        )
        store3(out_p[i], p1)
        store3(out_v[i], v1)
        store33(out_R[i], R1)
        store3(out_w[i], w1)


def _batch_of(*arrays) -> tuple:
    """The common batch shape of vectors ``(..., 3)`` / matrices ``(..., 3, 3)`` / scalars."""
    shapes = []
    for a, width in arrays:
        if a is not None:
            shapes.append(np.shape(a)[: np.ndim(a) - width])
    return np.broadcast_shapes(*shapes)


def _rows_of(a, batch: tuple, width: tuple) -> np.ndarray:
    a = np.broadcast_to(np.asarray(a, dtype=float), batch + width)
    return np.ascontiguousarray(a.reshape((-1,) + width))


def translational_acceleration(
    R: np.ndarray, thrust, vehicle: Vehicle, force_world=None
) -> np.ndarray:
    """v' of eq. (2) [m/s^2] for collective thrust ``thrust`` [N] (``(...,)``) and an optional
    external force (world) [N]."""
    batch = _batch_of((R, 2), (thrust, 0), (force_world, 1))
    F = np.zeros((0, 3)) if force_world is None else _rows_of(force_world, batch, (3,))
    out = np.empty((int(np.prod(batch)), 3))
    _translational_rows(
        _rows_of(R, batch, (3, 3)), _rows_of(thrust, batch, ()), F, rigid_body(vehicle), out
    )
    return out.reshape(batch + (3,))


def angular_acceleration(
    w: np.ndarray,
    moment: np.ndarray,
    vehicle: Vehicle,
    moment_ext=None,
    inertia=None,
    inertia_inverse=None,
) -> np.ndarray:
    """Omega' of eq. (4) [rad/s^2] (``inertia`` [kg m^2] / ``inertia_inverse`` override the
    vehicle's)."""
    batch = _batch_of((w, 1), (moment, 1), (moment_ext, 1))
    Mx = np.zeros((0, 3)) if moment_ext is None else _rows_of(moment_ext, batch, (3,))
    out = np.empty((int(np.prod(batch)), 3))
    _angular_rows(
        _rows_of(w, batch, (3,)),
        _rows_of(moment, batch, (3,)),
        Mx,
        rigid_body(vehicle, inertia, inertia_inverse),
        out,
    )
    return out.reshape(batch + (3,))


def specific_force_body(
    R: np.ndarray, acceleration_world: np.ndarray, gravity: float
) -> np.ndarray:
    """Accelerometer reading in FRD: ``R^T (a - g e3)`` [m/s^2] ((0, 0, -g) at rest)."""
    batch = _batch_of((R, 2), (acceleration_world, 1))
    out = np.empty((int(np.prod(batch)), 3))
    _specific_force_rows(
        _rows_of(R, batch, (3, 3)), _rows_of(acceleration_world, batch, (3,)), float(gravity), out
    )
    return out.reshape(batch + (3,))


def _expm3_columns(phi):
    """:func:`expm3` on a 3-tuple of equal-length arrays (the interpreted RKMK4 over a
    batch): a compiled loop per row, returned as a 9-tuple of arrays."""
    R = expm_so3(np.stack(np.broadcast_arrays(*(np.asarray(c, dtype=float) for c in phi)), -1))
    return tuple(R[..., r, c] for r in range(3) for c in range(3))


def call_wrench(fx, p, v, R, w, f, t):
    """The interpreted kernels' external wrench: the hook's ``wrench`` method (in place of
    the compiled chain's :func:`~quadfault.model.effects.chain.effects_wrench`)."""
    return fx.wrench(p, v, R, w, f, t)


class _ExternalHook:
    """Adapter of a batched ``external(state) -> (F, M)`` to the kernels' ``fx.wrench``."""

    def __init__(self, external):
        self.external = external

    def wrench(self, p, v, R, w, f, t):
        state = RigidBodyState(
            np.stack(p, -1),
            np.stack(v, -1),
            np.stack(R, -1).reshape(np.shape(R[0]) + (3, 3)),
            np.stack(w, -1),
        )
        F, M = (
            np.broadcast_to(np.asarray(x, dtype=float), state.p.shape) for x in self.external(state)
        )
        return (F[..., 0], F[..., 1], F[..., 2]), (M[..., 0], M[..., 1], M[..., 2])


def step_rk4(
    state: RigidBodyState,
    thrust,
    moment,
    vehicle: Vehicle,
    dt,
    external: ExternalWrench | None = None,
) -> RigidBodyState:
    """One RKMK4 step (:func:`rkmk4_step`) of length ``dt`` [s] (a scalar, or one per row of
    the batch) with thrust [N] and moment [N m] held constant; ``external`` (optional) gives
    the external wrench at a (batched) state, evaluated at every stage."""
    p, v, R, w = (np.asarray(x, dtype=float) for x in state)
    batch = _batch_of((p, 1), (v, 1), (R, 2), (w, 1), (thrust, 0), (moment, 1))
    dt = np.asarray(dt, dtype=float)
    if dt.ndim == len(batch) + 1 and dt.shape[-1] == 1:  # one per row, as a column
        dt = dt[..., 0]
    rigid = rigid_body(vehicle)
    vec, mat = (lambda a: _rows_of(a, batch, (3,))), (lambda a: _rows_of(a, batch, (3, 3)))
    T, dts = _rows_of(thrust, batch, ()), _rows_of(dt, batch, ())
    if external is None:
        n = len(T)
        out = (np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3, 3)), np.empty((n, 3)))
        _rk4_rows(vec(p), vec(v), mat(R), vec(w), T, vec(moment), rigid, dts, *out)
        return RigidBodyState(
            out[0].reshape(batch + (3,)),
            out[1].reshape(batch + (3,)),
            out[2].reshape(batch + (3, 3)),
            out[3].reshape(batch + (3,)),
        )
    kernel = python(rkmk4_step, {"expm3": _expm3_columns, "effects_wrench": call_wrench})

    def cols(a):
        return tuple(a[:, j] for j in range(a.shape[1]))

    M = vec(moment)
    p1, v1, R1, w1, _ = kernel(
        cols(vec(p)),
        cols(vec(v)),
        cols(mat(R).reshape(-1, 9)),
        cols(vec(w)),
        T,
        cols(M),
        rigid,
        dts,
        _ExternalHook(external),
    )
    return RigidBodyState(
        np.stack(p1, -1).reshape(batch + (3,)),
        np.stack(v1, -1).reshape(batch + (3,)),
        np.stack(R1, -1).reshape(batch + (3, 3)),
        np.stack(w1, -1).reshape(batch + (3,)),
    )


__all__ = [
    "E3",
    "RigidBodyState",
    "ExternalWrench",
    "rigid_body",
    "translational_acceleration3",
    "angular_acceleration3",
    "specific_force3",
    "dexpinv3",
    "rkmk4_step",
    "reference_euler_step",
    "reference_euler_store",
    "translational_acceleration",
    "angular_acceleration",
    "specific_force_body",
    "step_rk4",
]
