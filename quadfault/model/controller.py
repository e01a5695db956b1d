"""Geometric tracking controller on SE(3) (Lee, Leok, McClamroch 2010; paper eqs. 5-10).

NED world, FRD body: the thrust acts along ``-b3`` so the desired body z-axis is
``b3d = f_n / |f_n|`` with ``f_n = k_x e_x + k_v e_v + m g e3 - m a_d`` and the collective
thrust is ``T = f_n . R e3`` (eq. 9). The moment is eq. (10).

The controller knows only the *nominal* vehicle. Options reproduce the reference code:
``acceleration_feedforward=False`` (its a_d = 0), ``angular_feedforward=False`` (its
Omega_d = 0) and ``normalize_b2d=False`` (its un-normalised b2d).

:func:`geometric_control` is the kernel (one state; the closed loop calls it), with
:func:`desired_attitude3`, :func:`feedforward_rates3` and :func:`rotor_commands` (the nominal
allocation inverse, eq. 12); :class:`GeometricController` runs them over arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from quadfault.jit import jit, python
from quadfault.model.rotation import (
    cross3,
    dot3,
    mat3,
    matmul3,
    matvec3,
    store3,
    store33,
    transpose3,
    vec3,
    vee3,
)
from quadfault.model.trajectory import FlatOutput, Trajectory
from quadfault.model.vehicle import Vehicle


@dataclass(frozen=True)
class GeometricGains:
    """Diagonal gains of eqs. (9)-(10); the paper's Table I by default."""

    kx: tuple = (9.0, 9.0, 12.0)
    kv: tuple = (7.0, 7.0, 12.0)
    kR: tuple = (10.0, 10.0, 10.0)
    kW: tuple = (2.0, 2.0, 2.0)

    def scaled(self, vehicle: Vehicle, reference: Vehicle | None = None) -> GeometricGains:
        """These gains, written for ``reference`` (the paper's F450 by default), carried over
        to ``vehicle``: ``kx``, ``kv`` times the mass ratio and ``kR``, ``kW`` times the
        inertia ratio of each axis, so the closed loop keeps the same natural frequencies and
        damping (eqs. 9-10 divide the force by the mass and the moment by the inertia). The
        F450's gains on a 30 g Crazyflie are 60x too stiff in position and ~10^3 x in attitude.
        """
        ref = reference or Vehicle()
        m = vehicle.mass / ref.mass
        J = np.diag(vehicle.inertia) / np.diag(ref.inertia)
        return GeometricGains(
            tuple(float(k) * m for k in self.kx),
            tuple(float(k) * m for k in self.kv),
            tuple(float(k) * float(j) for k, j in zip(self.kR, J)),
            tuple(float(k) * float(j) for k, j in zip(self.kW, J)),
        )


@dataclass(frozen=True)
class ControllerConfig:
    """Geometric controller options.

    Attributes:
        gains: the diagonal gains.
        acceleration_feedforward: use the reference acceleration a_d in eq. (9).
        angular_feedforward: use Omega_d and Omega_d' of the feed-forward attitude (computed by
            central differences of the trajectory's desired attitude, step ``ff_step`` [s]).
        normalize_b2d: normalise ``b2d = b3d x b1d`` (Lee et al.); the reference code does not.
        yaw_release: the mixer gives up yaw first where the yaw moment alone would push a
            rotor's command below zero, or above the thrust limit in a flight whose motors
            saturate (:func:`rotor_commands`); the reference code mixes with the plain
            inverse.
    """

    gains: GeometricGains = field(default_factory=GeometricGains)
    acceleration_feedforward: bool = True
    angular_feedforward: bool = True
    normalize_b2d: bool = True
    ff_step: float = 1e-3
    yaw_release: bool = True

    @classmethod
    def reference(cls) -> ControllerConfig:
        """The authors' MATLAB controller: a_d = 0, Omega_d = 0, b2d not normalised."""
        return cls(
            acceleration_feedforward=False,
            angular_feedforward=False,
            normalize_b2d=False,
            yaw_release=False,
        )


class ControllerConstants(NamedTuple):
    """A :class:`GeometricController`'s gains, options and nominal vehicle in the kernels'
    argument form (scalars and arrays; :func:`controller_tuples` gives the tuples)."""

    gains: np.ndarray  # (4, 3): kx, kv, kR, kW
    acceleration_feedforward: bool
    angular_feedforward: bool
    normalize_b2d: bool
    mass: float  # nominal vehicle [kg]
    gravity: float  # [m/s^2]
    inertia: np.ndarray  # (3, 3) [kg m^2]
    inertia_inverse: np.ndarray  # (3, 3)
    allocation_inverse: np.ndarray  # (n, 4)
    yaw_release: bool  # the mixer gives up yaw first at the rotors' bounds


class ControlOutput(NamedTuple):
    thrust: np.ndarray  # collective thrust T [N]
    moment: np.ndarray  # body moment M [N m]
    position_error: np.ndarray  # e_x [m]
    velocity_error: np.ndarray  # e_v [m/s]
    attitude_error: np.ndarray  # e_R
    rate_error: np.ndarray  # e_Omega [rad/s]
    Rd: np.ndarray  # desired attitude


# --- kernels -------------------------------------------------------------------------------
@jit(inner=True)
def desired_attitude3(f_n, b1d, normalize_b2d):
    """Desired attitude with columns ``(b2d x b3d, b2d, b3d)``, ``b3d = f_n / |f_n|``,
    ``b2d = b3d x b1d`` (normalised with ``normalize_b2d``)."""
    nf = math.sqrt(dot3(f_n, f_n))
    b3d = (f_n[0] / nf, f_n[1] / nf, f_n[2] / nf)
    b2d = cross3(b3d, b1d)
    if normalize_b2d:
        nb = math.sqrt(dot3(b2d, b2d))
        b2d = (b2d[0] / nb, b2d[1] / nb, b2d[2] / nb)
    b1 = cross3(b2d, b3d)
    return (b1[0], b2d[0], b3d[0], b1[1], b2d[1], b3d[1], b1[2], b2d[2], b3d[2])


@jit(inner=True)
def geometric_control(p, v, R, w, ref, gains, nominal):
    """Eqs. 9 and 10 for the measured state ``(p, v, R, w)``.

    ``ref``: six 3-tuples -- position, velocity, acceleration, b1d, Omega_d, Omega_d' (the
    last two used only with angular feed-forward); ``gains``: ``(kx, kv, kR, kW,
    acceleration feed-forward, angular feed-forward, normalize b2d)``; ``nominal``: the
    nominal vehicle's ``rigid_body`` constants. Returns ``(T, M, e_x, e_v, e_R, e_Omega,
    R_d)``.
    """
    kx, kv, kR, kW, acc_ff, ang_ff, normalize_b2d = gains
    mass, J = nominal[0], nominal[2]
    pd, vd, ad = ref[0], ref[1], ref[2]
    ex = (p[0] - pd[0], p[1] - pd[1], p[2] - pd[2])
    ev = (v[0] - vd[0], v[1] - vd[1], v[2] - vd[2])
    f_n = (
        kx[0] * ex[0] + kv[0] * ev[0],
        kx[1] * ex[1] + kv[1] * ev[1],
        kx[2] * ex[2] + kv[2] * ev[2] + mass * nominal[1],
    )
    if acc_ff:
        f_n = (f_n[0] - mass * ad[0], f_n[1] - mass * ad[1], f_n[2] - mass * ad[2])
    Rd = desired_attitude3(f_n, ref[3], normalize_b2d)
    thrust = f_n[0] * R[2] + f_n[1] * R[5] + f_n[2] * R[8]
    # A = Rd^T R; e_R = vee(A - A^T) / 2 (eq. 10); R^T Rd = A^T
    A = matmul3(transpose3(Rd), R)
    eR = (
        0.5 * (0.5 * ((A[7] - A[5]) - (A[5] - A[7]))),
        0.5 * (0.5 * ((A[2] - A[6]) - (A[6] - A[2]))),
        0.5 * (0.5 * ((A[3] - A[1]) - (A[1] - A[3]))),
    )
    Jw = matvec3(J, w)
    if ang_ff:
        RtRd = transpose3(A)
        w_d_body = matvec3(RtRd, ref[4])
        eW = (w[0] - w_d_body[0], w[1] - w_d_body[1], w[2] - w_d_body[2])
        c1, a_d = cross3(w, w_d_body), matvec3(RtRd, ref[5])
        c0 = cross3(w, Jw)
        Jx = matvec3(J, (c1[0] - a_d[0], c1[1] - a_d[1], c1[2] - a_d[2]))
        ff = (c0[0] - Jx[0], c0[1] - Jx[1], c0[2] - Jx[2])
    else:
        eW = w
        ff = cross3(w, Jw)
    M = (
        -kR[0] * eR[0] - kW[0] * eW[0] + ff[0],
        -kR[1] * eR[1] - kW[1] * eW[1] + ff[1],
        -kR[2] * eR[2] - kW[2] * eW[2] + ff[2],
    )
    return thrust, M, ex, ev, eR, eW, Rd


@jit(inner=True)
def _feedforward_attitude(acc, b1d, gains, nominal):
    """R_d of the reference alone: ``f_n = m g e3 - m a_d`` (a_d = 0 without acceleration
    feed-forward)."""
    mass = nominal[0]
    a = acc if gains[4] else (0.0, 0.0, 0.0)
    f_n = (0.0 - mass * a[0], 0.0 - mass * a[1], mass * nominal[1] - mass * a[2])
    return desired_attitude3(f_n, b1d, gains[6])


@jit(inner=True)
def _combine9(A, B, C, b):
    """``A + b B + C`` element by element (9-tuples)."""
    return (
        A[0] + b * B[0] + C[0],
        A[1] + b * B[1] + C[1],
        A[2] + b * B[2] + C[2],
        A[3] + b * B[3] + C[3],
        A[4] + b * B[4] + C[4],
        A[5] + b * B[5] + C[5],
        A[6] + b * B[6] + C[6],
        A[7] + b * B[7] + C[7],
        A[8] + b * B[8] + C[8],
    )


@jit(inner=True)
def _difference9(A, C):
    """``A - C`` element by element (9-tuples)."""
    return (
        A[0] - C[0],
        A[1] - C[1],
        A[2] - C[2],
        A[3] - C[3],
        A[4] - C[4],
        A[5] - C[5],
        A[6] - C[6],
        A[7] - C[7],
        A[8] - C[8],
    )


@jit(inner=True)
def feedforward_rates3(acc, b1d, h, gains, nominal):
    """The feed-forward attitude R_d(t) and its rates Omega_d [rad/s], Omega_d' [rad/s^2] by
    central differences of step ``h`` [s]: ``acc`` and ``b1d`` are the reference's at
    ``t - h, t, t + h`` (three 3-tuples each);
    ``Omega_d = vee(R_d(t)^T (R_d(t+h) - R_d(t-h))) / 2h``,
    ``Omega_d' = vee(R_d(t)^T (R_d(t+h) - 2 R_d(t) + R_d(t-h))) / h^2``."""
    Rm = _feedforward_attitude(acc[0], b1d[0], gains, nominal)
    R0 = _feedforward_attitude(acc[1], b1d[1], gains, nominal)
    Rp = _feedforward_attitude(acc[2], b1d[2], gains, nominal)
    R0T = transpose3(R0)
    w_d = vee3(matmul3(R0T, _difference9(Rp, Rm)))
    w_dot_d = vee3(matmul3(R0T, _combine9(Rp, R0, Rm, -2.0)))
    return (
        R0,
        (w_d[0] / (2 * h), w_d[1] / (2 * h), w_d[2] / (2 * h)),
        (w_dot_d[0] / (h * h), w_dot_d[1] / (h * h), w_dot_d[2] / (h * h)),
    )


@jit(inline="always")
def controller_tuples(K):
    """``(gains, nominal)`` of :func:`geometric_control` from :class:`ControllerConstants`."""
    g = K.gains
    gains = (
        vec3(g[0]),
        vec3(g[1]),
        vec3(g[2]),
        vec3(g[3]),
        K.acceleration_feedforward,
        K.angular_feedforward,
        K.normalize_b2d,
    )
    return gains, (K.mass, K.gravity, mat3(K.inertia), mat3(K.inertia_inverse))


@jit(inline="always")
def rotor_commands(thrust, M, allocation_inverse, out, yaw_release=False, f_max=math.inf):
    """Rotor thrust commands [N] realising ``(T, M)`` through the nominal allocation inverse
    (eq. 12, least-norm) into ``out`` (n,).

    ``yaw_release``: the mixer gives up yaw first, as an autopilot's mixer does: where the yaw
    moment alone pushes a rotor's command below zero (a rotor cannot push) or above ``f_max``
    [N] (``inf``: the motors do not saturate), the yaw moment is scaled down, to none at most,
    until no command passes a bound through it; thrust, roll and pitch are kept (a command
    they alone push past a bound stays there and the motor clips it). A quadrotor's yaw
    authority is the rotors' drag, a few percent of their lift's moment, so a yaw demand that
    the plain inverse meets drives a pair of rotors to their bounds and takes roll and pitch
    with it. Commands within the bounds are the plain inverse's, bit for bit."""
    Ai = allocation_inverse
    s = 1.0
    if yaw_release:
        for i in range(out.shape[0]):
            base = Ai[i, 0] * thrust + Ai[i, 1] * M[0] + Ai[i, 2] * M[1]
            yaw = Ai[i, 3] * M[2]
            if yaw < 0.0 and base + yaw < 0.0:
                s = min(s, max(0.0, -base / yaw))
            elif yaw > 0.0 and base + yaw > f_max:
                s = min(s, max(0.0, (f_max - base) / yaw))
    for i in range(out.shape[0]):
        out[i] = Ai[i, 0] * thrust + Ai[i, 1] * M[0] + Ai[i, 2] * M[1] + s * (Ai[i, 3] * M[2])


@jit(inline="always")
def reference_row(refs, k):
    """Row ``k`` of a reference table (K, 6, 3) as the six 3-tuples of
    :func:`geometric_control`."""
    r = refs[k]
    return (
        (r[0, 0], r[0, 1], r[0, 2]),
        (r[1, 0], r[1, 1], r[1, 2]),
        (r[2, 0], r[2, 1], r[2, 2]),
        (r[3, 0], r[3, 1], r[3, 2]),
        (r[4, 0], r[4, 1], r[4, 2]),
        (r[5, 0], r[5, 1], r[5, 2]),
    )


# --- loops over rows ------------------------------------------------------------------------
@jit
def _control_rows(p, v, R, w, refs, K, f, T, M, ex, ev, eR, eW, Rd):
    gains, nominal = controller_tuples(K)
    for i in range(p.shape[0]):
        out = geometric_control(
            vec3(p[i]), vec3(v[i]), mat3(R[i]), vec3(w[i]), reference_row(refs, i), gains, nominal
        )
        rotor_commands(out[0], out[1], K.allocation_inverse, f[i], K.yaw_release)
        T[i] = out[0]
        store3(M[i], out[1])
        store3(ex[i], out[2])
        store3(ev[i], out[3])
        store3(eR[i], out[4])
        store3(eW[i], out[5])
        store33(Rd[i], out[6])


@jit
def _command_rows(p, v, R, w, refs, K, f):
    gains, nominal = controller_tuples(K)
    for i in range(p.shape[0]):
        out = geometric_control(
            vec3(p[i]), vec3(v[i]), mat3(R[i]), vec3(w[i]), reference_row(refs, i), gains, nominal
        )
        rotor_commands(out[0], out[1], K.allocation_inverse, f[i], K.yaw_release)


@jit
def _feedforward_rows(acc, b1d, h, K, R_d, w_d, w_dot_d):
    gains, nominal = controller_tuples(K)
    for i in range(acc.shape[0]):
        a, b = acc[i], b1d[i]
        Rd, wd, wdd = feedforward_rates3(
            (vec3(a[0]), vec3(a[1]), vec3(a[2])),
            (vec3(b[0]), vec3(b[1]), vec3(b[2])),
            h,
            gains,
            nominal,
        )
        store33(R_d[i], Rd)
        store3(w_d[i], wd)
        store3(w_dot_d[i], wdd)


#: from this many times on, :meth:`GeometricController.feedforward` runs its kernel over whole
#: arrays in numpy (as fast as the compiled kernel there; a flight's table of references is
#: made without compiling it)
FEEDFORWARD_ARRAY_ROWS = 64


class GeometricController:
    """The SE(3) tracking controller; the array methods work on a leading batch axis too.

    Args:
        vehicle: the nominal vehicle (mass, inertia, allocation).
        trajectory: reference trajectory ``t -> FlatOutput``.
        config: options and gains.
    """

    def __init__(
        self, vehicle: Vehicle, trajectory: Trajectory, config: ControllerConfig | None = None
    ):
        self.vehicle = vehicle
        self.trajectory = trajectory
        self.config = config or ControllerConfig()
        g = self.config.gains
        self.kx, self.kv = np.asarray(g.kx, float), np.asarray(g.kv, float)
        self.kR, self.kW = np.asarray(g.kR, float), np.asarray(g.kW, float)
        self._constants = None

    @property
    def constants(self) -> ControllerConstants:
        """The kernels' form of the gains, options and nominal vehicle (made on first use)."""
        if self._constants is None:
            g, c, veh = self.config.gains, self.config, self.vehicle

            def arr(a):
                return np.array(a, dtype=float, order="C")  # writable: one specialisation

            self._constants = ControllerConstants(
                arr((g.kx, g.kv, g.kR, g.kW)),
                bool(c.acceleration_feedforward),
                bool(c.angular_feedforward),
                bool(c.normalize_b2d),
                float(veh.mass),
                float(veh.gravity),
                arr(veh.inertia),
                arr(veh.inertia_inverse),
                arr(veh.allocation_inverse),
                bool(c.yaw_release),
            )
        return self._constants

    def feedforward(
        self, t, compiled: bool | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The feed-forward attitude R_d (the reference alone: ``f_n = m g e3 - m a_d``) and
        its rates Omega_d [rad/s], Omega_d' [rad/s^2] at ``t`` (:func:`feedforward_rates3`).

        ``compiled``: run the compiled kernel (True) or the same kernel over whole arrays in
        numpy (False: the same numbers, nothing to compile; about 0.5 ms per call); None:
        numpy from :data:`FEEDFORWARD_ARRAY_ROWS` times on (as fast as compiled there)."""
        h = self.config.ff_step
        t = np.asarray(t, dtype=float)
        ref = self.trajectory(np.stack((t - h, t, t + h), axis=-1))
        acc = np.asarray(ref.acceleration, float).reshape(-1, 3, 3)
        b1d = np.asarray(ref.b1d, float).reshape(-1, 3, 3)
        shape = np.shape(ref.acceleration)[:-2]
        if compiled or (compiled is None and len(acc) < FEEDFORWARD_ARRAY_ROWS):
            acc, b1d = np.ascontiguousarray(acc), np.ascontiguousarray(b1d)
            R_d, w_d, w_dot_d = (
                np.empty((len(acc), 3, 3)),
                np.empty((len(acc), 3)),
                np.empty((len(acc), 3)),
            )
            _feedforward_rows(acc, b1d, float(h), self.constants, R_d, w_d, w_dot_d)
            return (
                R_d.reshape(shape + (3, 3)),
                w_d.reshape(shape + (3,)),
                w_dot_d.reshape(shape + (3,)),
            )
        columns = [tuple(tuple(x[:, j, c] for c in range(3)) for j in range(3)) for x in (acc, b1d)]
        gains, nominal = python(controller_tuples)(self.constants)
        R_d, w_d, w_dot_d = (
            np.stack(np.broadcast_arrays(*x), -1)
            for x in python(feedforward_rates3, {"math": np})(*columns, float(h), gains, nominal)
        )
        return (
            R_d.reshape(shape + (3, 3)),
            w_d.reshape(shape + (3,)),
            w_dot_d.reshape(shape + (3,)),
        )

    def feedforward_rates(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Omega_d [rad/s] and Omega_d' [rad/s^2] of the feed-forward attitude at ``t``."""
        return self.feedforward(t)[1:]

    def reference_rows(
        self, t, reference: FlatOutput | None = None, feedforward: tuple | None = None
    ) -> np.ndarray:
        """The kernel's reference rows ``(..., 6, 3)`` at ``t``: position, velocity,
        acceleration, b1d, Omega_d, Omega_d' (zeros without angular feed-forward)."""
        ref = self.trajectory(t) if reference is None else reference
        parts = [np.asarray(a, dtype=float) for a in ref[:4]]
        if self.config.angular_feedforward:
            ff = self.feedforward_rates(t) if feedforward is None else feedforward
            parts += [np.asarray(a, dtype=float) for a in ff]
        batch = np.broadcast_shapes(*(a.shape[:-1] for a in parts))
        out = np.zeros(batch + (6, 3))
        for r, a in enumerate(parts):
            out[..., r, :] = a
        return out

    def _rows(self, p, v, R, w, refs):
        """The inputs as C-contiguous rows of their common batch shape."""
        args = [np.asarray(a, dtype=float) for a in (p, v, R, w, refs)]
        widths = ((3,), (3,), (3, 3), (3,), (6, 3))
        batch = args[0].shape[:-1]
        if any(a.shape != batch + wd for a, wd in zip(args, widths)):
            batch = np.broadcast_shapes(
                *(a.shape[: a.ndim - len(wd)] for a, wd in zip(args, widths))
            )
            args = [np.broadcast_to(a, batch + wd) for a, wd in zip(args, widths)]
        return batch, tuple(
            np.ascontiguousarray(a.reshape((-1,) + wd)) for a, wd in zip(args, widths)
        )

    def _control(self, p, v, R, w, refs):
        """``(rotor commands, ControlOutput)`` for reference rows ``refs``."""
        batch, args = self._rows(p, v, R, w, refs)
        n, n_rot = len(args[0]), self.vehicle.n_rotors
        f, T, Rd = np.empty((n, n_rot)), np.empty(n), np.empty((n, 3, 3))
        vecs = [np.empty((n, 3)) for _ in range(5)]
        _control_rows(*args, self.constants, f, T, *vecs, Rd)
        M, ex, ev, eR, eW = (x.reshape(batch + (3,)) for x in vecs)
        return f.reshape(batch + (n_rot,)), ControlOutput(
            T.reshape(batch), M, ex, ev, eR, eW, Rd.reshape(batch + (3, 3))
        )

    def compute(
        self, t, p, v, R, w, reference: FlatOutput | None = None, feedforward: tuple | None = None
    ) -> ControlOutput:
        """Thrust and moment (eqs. 9, 10) for the measured state at time ``t`` [s].

        ``reference`` and ``feedforward`` (Omega_d, Omega_d') may be passed precomputed (the
        simulator evaluates them for all times at once); otherwise they are computed here.
        """
        return self._control(p, v, R, w, self.reference_rows(t, reference, feedforward))[1]

    def motor_commands(
        self, t, p, v, R, w, reference: FlatOutput | None = None, feedforward: tuple | None = None
    ) -> tuple[np.ndarray, ControlOutput]:
        """Rotor thrust commands [N] through the nominal allocation inverse (eq. 12), and the
        details."""
        return self._control(p, v, R, w, self.reference_rows(t, reference, feedforward))

    def commands(self, p, v, R, w, refs: np.ndarray) -> np.ndarray:
        """Rotor thrust commands [N] (eqs. 9, 10, 12) for states ``(..., 3)`` and reference
        rows ``refs`` ``(..., 6, 3)`` (see :meth:`reference_rows`)."""
        batch, args = self._rows(p, v, R, w, refs)
        f = np.empty((len(args[0]), self.vehicle.n_rotors))
        _command_rows(*args, self.constants, f)
        return f.reshape(batch + (self.vehicle.n_rotors,))
