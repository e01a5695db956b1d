"""Scalar kernels of the compiled physics (numba): the one compiled twin of the core model.

Vectors are 3-tuples of float64 and rotation matrices row-major 9-tuples, so nothing here
allocates -- LLVM keeps them in registers. Each kernel mirrors one pure function of the core
(``quadfault.rotation``, ``dynamics``, ``motors``, ``controller``, ``simulator``) one to one
and names it; :func:`plant_step` is the per-vehicle physics step that both the single-vehicle
loop and the batched kernel of :mod:`quadfault._sim_numba` call. Array wrappers with the pure
functions' names live in :mod:`quadfault._numba_mirrors`.

Compile options: ``cache=True``, ``error_model="numpy"`` (a division by zero gives inf / NaN
as in numpy, never an exception inside a parallel loop), nopython, no ``fastmath``. Without
numba (``AVAILABLE`` is False) the functions stay plain Python.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

try:  # the optional ``fast`` extra
    import numba
    from numba import prange

    AVAILABLE = True

    def njit(*args, **kwargs):
        """``numba.njit`` with this module's defaults (cache, numpy error model)."""
        kwargs.setdefault("cache", True)
        kwargs.setdefault("error_model", "numpy")
        if len(args) == 1 and callable(args[0]):
            return numba.njit(**kwargs)(args[0])
        return numba.njit(*args, **kwargs)
except ImportError:  # pragma: no cover - exercised only without numba
    AVAILABLE = False
    prange = range

    def njit(*args, **kwargs):
        """Stand-in decorator: the functions stay plain Python."""
        if len(args) == 1 and callable(args[0]) and not kwargs:
            return args[0]
        return lambda f: f



# --- scalar kernels: rotation.py -------------------------------------------------------------
@njit
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit
def _cross(a, b):
    """Mirrors :func:`quadfault.rotation.cross`."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


# Series of a = sin(th)/th and b = (1 - cos th)/th^2 in th^2 (Horner, through th^10): below
# th = 0.1 rad the truncation (th^12 / 13!) is below 2e-22, so they equal the closed forms to
# rounding -- without the sqrt, sin, cos and two divisions (at 1 kHz, th = |Omega| dt / 2
# stays below 0.1 rad up to 200 rad/s, so the hot path never calls libm here).
_EXPM_SERIES_MAX_TH2 = 0.01
_A1, _A2, _A3, _A4, _A5 = -1 / 6, 1 / 120, -1 / 5040, 1 / 362880, -1 / 39916800
_B0, _B1, _B2, _B3, _B4, _B5 = 0.5, -1 / 24, 1 / 720, -1 / 40320, 1 / 3628800, -1 / 479001600


@njit
def _expm(phi):
    """Mirrors :func:`quadfault.rotation.expm_so3` (Rodrigues, paper eq. 5 hat map):
    ``I + a [phi]x + b (phi phi^T - |phi|^2 I)`` as a row-major 9-tuple. ``a``, ``b`` from
    their Taylor series below 0.1 rad (equal to the closed forms to rounding, see above),
    ``sin(th)/th``, ``(1 - cos th)/th^2`` above."""
    x, y, z = phi
    th2 = x * x + y * y + z * z
    if th2 < _EXPM_SERIES_MAX_TH2:
        a = 1.0 + th2 * (_A1 + th2 * (_A2 + th2 * (_A3 + th2 * (_A4 + th2 * _A5))))
        b = _B0 + th2 * (_B1 + th2 * (_B2 + th2 * (_B3 + th2 * (_B4 + th2 * _B5))))
    else:
        th = math.sqrt(th2)
        a = math.sin(th) / th
        b = (1.0 - math.cos(th)) / (th * th)
    d = 1.0 - b * th2
    return (b * (x * x) + d, b * (x * y) + a * -z, b * (x * z) + a * y,
            b * (y * x) + a * z, b * (y * y) + d, b * (y * z) + a * -x,
            b * (z * x) + a * -y, b * (z * y) + a * x, b * (z * z) + d)


@njit
def _mul(A, B):
    """``A @ B`` for row-major 9-tuples."""
    return (A[0] * B[0] + A[1] * B[3] + A[2] * B[6], A[0] * B[1] + A[1] * B[4] + A[2] * B[7],
            A[0] * B[2] + A[1] * B[5] + A[2] * B[8],
            A[3] * B[0] + A[4] * B[3] + A[5] * B[6], A[3] * B[1] + A[4] * B[4] + A[5] * B[7],
            A[3] * B[2] + A[4] * B[5] + A[5] * B[8],
            A[6] * B[0] + A[7] * B[3] + A[8] * B[6], A[6] * B[1] + A[7] * B[4] + A[8] * B[7],
            A[6] * B[2] + A[7] * B[5] + A[8] * B[8])


@njit(inline="always")
def _mv(A, x):
    """``A @ x`` for a (3, 3) array and a 3-tuple."""
    return (A[0, 0] * x[0] + A[0, 1] * x[1] + A[0, 2] * x[2],
            A[1, 0] * x[0] + A[1, 1] * x[1] + A[1, 2] * x[2],
            A[2, 0] * x[0] + A[2, 1] * x[1] + A[2, 2] * x[2])


@njit
def _axpy(x, a, y):
    """``x + a * y`` for 3-tuples."""
    return (x[0] + a * y[0], x[1] + a * y[1], x[2] + a * y[2])


@njit
def _rk_sum(x0, c, k1, k2, k3, k4):
    """``x0 + c (k1 + 2 k2 + 2 k3 + k4)`` (the RK4 combination, in the pure code's order)."""
    return (x0[0] + c * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0]),
            x0[1] + c * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1]),
            x0[2] + c * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2]))


@njit(inline="always")
def _vec(a, off=0):
    """3-tuple from ``a[off:off + 3]`` of a 1-D array."""
    return (a[off], a[off + 1], a[off + 2])


@njit(inline="always")
def _mat(M):
    """Row-major 9-tuple of a (3, 3) array."""
    return (M[0, 0], M[0, 1], M[0, 2], M[1, 0], M[1, 1], M[1, 2], M[2, 0], M[2, 1], M[2, 2])


@njit(inline="always")
def _store_vec(dst, x):
    dst[0], dst[1], dst[2] = x[0], x[1], x[2]


@njit(inline="always")
def _store_mat(dst, M):
    for r in range(3):
        dst[r, 0], dst[r, 1], dst[r, 2] = M[3 * r], M[3 * r + 1], M[3 * r + 2]


# --- scalar kernels: dynamics.py -------------------------------------------------------------
class Body(NamedTuple):
    """Rigid-body parameters of a :class:`~quadfault.vehicle.Vehicle` as plain arrays."""

    mass: float  # [kg]
    gravity: float  # [m/s^2]
    inertia: np.ndarray  # (3, 3) [kg m^2]
    inertia_inverse: np.ndarray  # (3, 3)
    allocation: np.ndarray  # (4, n): rotor thrusts -> [T; Mx; My; Mz]
    allocation_inverse: np.ndarray  # (n, 4)
    max_thrust: float  # per-rotor f_max [N] (inf = no upper limit)


def body_of(vehicle) -> Body:
    return Body(float(vehicle.mass), float(vehicle.gravity),
                np.ascontiguousarray(vehicle.inertia, dtype=float),
                np.ascontiguousarray(vehicle.inertia_inverse, dtype=float),
                np.ascontiguousarray(vehicle.allocation, dtype=float),
                np.ascontiguousarray(vehicle.allocation_inverse, dtype=float),
                float(vehicle.rotor_max_thrust))


@njit(inline="always")
def _rigid(body):
    """The rigid-body constants of ``body`` as floats: ``(mass, gravity, J, J^-1)`` with the
    matrices as row-major 9-tuples. The RKMK4 core takes these, not the arrays: a compiled call
    that receives an array increments and decrements its reference count (an atomic operation,
    shared between the threads of the parallel kernel), which cost more than the physics."""
    return (body.mass, body.gravity, _mat(body.inertia), _mat(body.inertia_inverse))


@njit
def _mv9(A, x):
    """``A @ x`` for a row-major 9-tuple and a 3-tuple."""
    return (A[0] * x[0] + A[1] * x[1] + A[2] * x[2],
            A[3] * x[0] + A[4] * x[1] + A[5] * x[2],
            A[6] * x[0] + A[7] * x[1] + A[8] * x[2])


@njit
def _tacc_c(R, thrust, rigid):
    """Eq. 2 (no F_ext) on the constants of :func:`_rigid`."""
    s = thrust / rigid[0]
    return (0.0 - s * R[2], 0.0 - s * R[5], rigid[1] - s * R[8])


@njit
def _wacc_c(w, moment, rigid):
    """Eq. 4 (no M_ext) on the constants of :func:`_rigid`."""
    c = _cross(w, _mv9(rigid[2], w))
    return _mv9(rigid[3], (moment[0] - c[0], moment[1] - c[1], moment[2] - c[2]))


@njit(inline="always")
def _tacc(R, thrust, body):
    """Mirrors :func:`quadfault.dynamics.translational_acceleration` (eq. 2, no F_ext)."""
    return _tacc_c(R, thrust, (body.mass, body.gravity))


@njit(inline="always")
def _wacc(w, moment, body):
    """Mirrors :func:`quadfault.dynamics.angular_acceleration` (eq. 4, no M_ext)."""
    return _wacc_c(w, moment, _rigid(body))


@njit
def _specific_force(R, acc, gravity):
    """Mirrors :func:`quadfault.dynamics.specific_force_body`: ``R^T (a - g e3)``."""
    f2 = acc[2] - gravity
    return (R[0] * acc[0] + R[3] * acc[1] + R[6] * f2,
            R[1] * acc[0] + R[4] * acc[1] + R[7] * f2,
            R[2] * acc[0] + R[5] * acc[1] + R[8] * f2)


@njit
def _dexpinv(theta, w):
    """Mirrors :func:`quadfault.dynamics._dexpinv`."""
    tw = _cross(theta, w)
    ttw = _cross(theta, tw)
    return (w[0] + 0.5 * tw[0] + ttw[0] / 12.0, w[1] + 0.5 * tw[1] + ttw[1] / 12.0,
            w[2] + 0.5 * tw[2] + ttw[2] / 12.0)


@njit
def _scale(a, x):
    return (a * x[0], a * x[1], a * x[2])


@njit
def _rk4_c(p0, v0, R0, w0, thrust, moment, rigid, dt):
    """Mirrors :func:`quadfault.dynamics.step_rk4` (RKMK4, eqs. 1-4, no external wrench):
    ``R(t) = R0 exp([theta(t)]x)``, ``theta' = dexp^-1(Omega)``; ``_derivatives`` inlined as
    (p', v', Omega') = (v, eq. 2, eq. 4); ``rigid`` from :func:`_rigid`."""
    h = 0.5 * dt
    k1p, k1v, k1w = v0, _tacc_c(R0, thrust, rigid), _wacc_c(w0, moment, rigid)
    th1 = w0
    v2, R2, w2 = _axpy(v0, h, k1v), _mul(R0, _expm(_scale(h, th1))), _axpy(w0, h, k1w)
    k2p, k2v, k2w = v2, _tacc_c(R2, thrust, rigid), _wacc_c(w2, moment, rigid)
    th2 = _dexpinv(_scale(h, th1), w2)
    v3, R3, w3 = _axpy(v0, h, k2v), _mul(R0, _expm(_scale(h, th2))), _axpy(w0, h, k2w)
    k3p, k3v, k3w = v3, _tacc_c(R3, thrust, rigid), _wacc_c(w3, moment, rigid)
    th3 = _dexpinv(_scale(h, th2), w3)
    v4, R4, w4 = _axpy(v0, dt, k3v), _mul(R0, _expm(_scale(dt, th3))), _axpy(w0, dt, k3w)
    k4p, k4v, k4w = v4, _tacc_c(R4, thrust, rigid), _wacc_c(w4, moment, rigid)
    th4 = _dexpinv(_scale(dt, th3), w4)
    c = dt / 6.0
    th = (c * (th1[0] + 2 * th2[0] + 2 * th3[0] + th4[0]),
          c * (th1[1] + 2 * th2[1] + 2 * th3[1] + th4[1]),
          c * (th1[2] + 2 * th2[2] + 2 * th3[2] + th4[2]))
    return (_rk_sum(p0, c, k1p, k2p, k3p, k4p), _rk_sum(v0, c, k1v, k2v, k3v, k4v),
            _mul(R0, _expm(th)), _rk_sum(w0, c, k1w, k2w, k3w, k4w))


@njit(inline="always")
def _rk4(p0, v0, R0, w0, thrust, moment, body, dt):
    """:func:`_rk4_c` for a :class:`Body` (inlined into the caller: no array crosses the call)."""
    return _rk4_c(p0, v0, R0, w0, thrust, moment, _rigid(body), dt)


# --- scalar kernels: motors.py + Vehicle.wrench ----------------------------------------------
@njit(inline="always")
def _motor_wrench(f_cmd, eta, row, saturate, sigma, eps, e0, body):
    """Mirrors :meth:`quadfault.motors.MotorModel.apply` (eqs. 11, 13) followed by
    :meth:`quadfault.vehicle.Vehicle.wrench`: collective thrust T [N] and moment (3-tuple,
    [N m]) of the rotor thrusts ``eta[row, i] clip(f_cmd_i) exp(sigma eps[e0 + i])`` (the
    normals ``eps`` are read only when ``sigma > 0``). Arrays are indexed element by element:
    a sliced view per step would touch the parent's reference count, an atomic operation
    that threads of the parallel kernel would contend for."""
    A = body.allocation
    T = m0 = m1 = m2 = 0.0
    for i in range(f_cmd.shape[0]):
        fi = max(f_cmd[i], 0.0)
        if saturate:
            fi = min(fi, body.max_thrust)
        fi = fi * eta[row, i]
        if sigma > 0:
            fi = fi * math.exp(sigma * eps[e0 + i])
        T += A[0, i] * fi
        m0 += A[1, i] * fi
        m1 += A[2, i] * fi
        m2 += A[3, i] * fi
    return T, (m0, m1, m2)


@njit(inline="always")
def plant_step(p, v, R, w, f_cmd, eta, row, saturate, sigma, eps, e0, body, dt):
    """One physics step of one vehicle -- :meth:`quadfault.plant.Plant.step` without effects:
    the motor model (eqs. 11, 13), the allocation, then RKMK4 (eqs. 1-4) with the wrench held.

    ``p, v, w`` are 3-tuples, ``R`` a row-major 9-tuple; ``f_cmd`` (n,) the held commands
    [N], ``eta[row]`` (n,) the efficiencies, ``sigma`` the thrust-noise std with its normals
    at ``eps[e0:e0 + n]``. Returns ``(p, v, R, w, T, M)``: the new state and the applied wrench.
    Both :func:`run_steps` and :func:`step_batch` call this function.
    """
    T, M = _motor_wrench(f_cmd, eta, row, saturate, sigma, eps, e0, body)
    p1, v1, R1, w1 = _rk4(p, v, R, w, T, M, body, dt)
    return p1, v1, R1, w1, T, M


# --- scalar kernels: controller.py -----------------------------------------------------------
class Gains(NamedTuple):
    """:class:`~quadfault.controller.GeometricController` gains and options as arrays."""

    kx: np.ndarray
    kv: np.ndarray
    kR: np.ndarray
    kW: np.ndarray
    acceleration_feedforward: bool
    angular_feedforward: bool
    normalize_b2d: bool


def gains_of(controller) -> Gains:
    cfg = controller.config
    return Gains(np.asarray(controller.kx, float), np.asarray(controller.kv, float),
                 np.asarray(controller.kR, float), np.asarray(controller.kW, float),
                 bool(cfg.acceleration_feedforward), bool(cfg.angular_feedforward),
                 bool(cfg.normalize_b2d))


@njit
def _desired_attitude(f_n, b1d, normalize_b2d):
    """Mirrors :meth:`GeometricController._desired_attitude`: columns (b1, b2d, b3d)."""
    nf = math.sqrt(_dot(f_n, f_n))
    b3d = (f_n[0] / nf, f_n[1] / nf, f_n[2] / nf)
    b2d = _cross(b3d, b1d)
    if normalize_b2d:
        nb = math.sqrt(_dot(b2d, b2d))
        b2d = (b2d[0] / nb, b2d[1] / nb, b2d[2] / nb)
    b1 = _cross(b2d, b3d)
    return (b1[0], b2d[0], b3d[0], b1[1], b2d[1], b3d[1], b1[2], b2d[2], b3d[2])


@njit
def _controller_c(p, v, R, w, ref, gains, rigid):
    """Mirrors :meth:`GeometricController.compute` (eqs. 9, 10) on tuples: returns the
    collective thrust [N] and the moment (3-tuple, [N m]).

    ``ref`` six 3-tuples: position, velocity, acceleration, b1d, Omega_d, Omega_d' (the last
    two used only with angular feed-forward); ``gains`` = (kx, kv, kR, kW, acceleration
    feed-forward, angular feed-forward, normalize b2d); ``rigid`` the *nominal* vehicle's
    :func:`_rigid` constants.
    """
    kx, kv, kR, kW, acc_ff, ang_ff, normalize_b2d = gains
    mass, gravity, J = rigid[0], rigid[1], rigid[2]
    pd, vd, ad = ref[0], ref[1], ref[2]
    mg = mass * gravity
    f_n = (kx[0] * (p[0] - pd[0]) + kv[0] * (v[0] - vd[0]),
           kx[1] * (p[1] - pd[1]) + kv[1] * (v[1] - vd[1]),
           kx[2] * (p[2] - pd[2]) + kv[2] * (v[2] - vd[2]) + mg)
    if acc_ff:
        f_n = (f_n[0] - mass * ad[0], f_n[1] - mass * ad[1], f_n[2] - mass * ad[2])
    Rd = _desired_attitude(f_n, ref[3], normalize_b2d)
    thrust = f_n[0] * R[2] + f_n[1] * R[5] + f_n[2] * R[8]
    # A = Rd^T R; e_R = vee(A - A^T) / 2 (eq. 10); R^T Rd = A^T
    A = _mul((Rd[0], Rd[3], Rd[6], Rd[1], Rd[4], Rd[7], Rd[2], Rd[5], Rd[8]), R)
    eR = (0.5 * (0.5 * ((A[7] - A[5]) - (A[5] - A[7]))),
          0.5 * (0.5 * ((A[2] - A[6]) - (A[6] - A[2]))),
          0.5 * (0.5 * ((A[3] - A[1]) - (A[1] - A[3]))))
    Jw = _mv9(J, w)
    if ang_ff:
        RtRd = (A[0], A[3], A[6], A[1], A[4], A[7], A[2], A[5], A[8])
        w_d, w_dot_d = ref[4], ref[5]
        w_d_body = _mv9(RtRd, w_d)
        eW = (w[0] - w_d_body[0], w[1] - w_d_body[1], w[2] - w_d_body[2])
        c1 = _cross(w, w_d_body)
        x = (c1[0] - (RtRd[0] * w_dot_d[0] + RtRd[1] * w_dot_d[1] + RtRd[2] * w_dot_d[2]),
             c1[1] - (RtRd[3] * w_dot_d[0] + RtRd[4] * w_dot_d[1] + RtRd[5] * w_dot_d[2]),
             c1[2] - (RtRd[6] * w_dot_d[0] + RtRd[7] * w_dot_d[1] + RtRd[8] * w_dot_d[2]))
        c0, Jx = _cross(w, Jw), _mv9(J, x)
        ff = (c0[0] - Jx[0], c0[1] - Jx[1], c0[2] - Jx[2])
    else:
        eW = w
        ff = _cross(w, Jw)
    M = (-kR[0] * eR[0] - kW[0] * eW[0] + ff[0], -kR[1] * eR[1] - kW[1] * eW[1] + ff[1],
         -kR[2] * eR[2] - kW[2] * eW[2] + ff[2])
    return thrust, M


@njit(inline="always")
def _gains(gains):
    """The :class:`Gains` as the tuple :func:`_controller_c` takes."""
    return (_vec(gains.kx), _vec(gains.kv), _vec(gains.kR), _vec(gains.kW),
            gains.acceleration_feedforward, gains.angular_feedforward, gains.normalize_b2d)


@njit(inline="always")
def _refs(ref):
    """The (6, 3) reference rows as six 3-tuples."""
    return ((ref[0, 0], ref[0, 1], ref[0, 2]), (ref[1, 0], ref[1, 1], ref[1, 2]),
            (ref[2, 0], ref[2, 1], ref[2, 2]), (ref[3, 0], ref[3, 1], ref[3, 2]),
            (ref[4, 0], ref[4, 1], ref[4, 2]), (ref[5, 0], ref[5, 1], ref[5, 2]))


@njit(inline="always")
def _controller(p, v, R, w, ref, gains, body, out):
    """Mirrors :meth:`GeometricController.compute` (eqs. 9, 10) followed by
    :meth:`GeometricController.motor_commands`: writes the rotor commands [N] (nominal
    allocation inverse) into ``out`` (n,).

    ``ref`` (6, 3) rows: position, velocity, acceleration, b1d, Omega_d, Omega_d' (the last
    two used only with angular feed-forward); ``body`` is the *nominal* vehicle. Inlined into
    the caller; the arithmetic is :func:`_controller_c` (no array crosses that call).
    """
    thrust, M = _controller_c(p, v, R, w, _refs(ref), _gains(gains), _rigid(body))
    Ai = body.allocation_inverse
    for i in range(out.shape[0]):
        out[i] = Ai[i, 0] * thrust + Ai[i, 1] * M[0] + Ai[i, 2] * M[1] + Ai[i, 3] * M[2]


# --- scalar kernels: simulator.py ------------------------------------------------------------
@njit
def _measure(p, v, R, w, row, layout, sensor_std):
    """Mirrors :meth:`quadfault.simulator.SensorNoise.measure` (state part).

    ``sensor_std`` = (position, velocity, attitude, gyro); ``layout`` = column offsets of
    the draws in ``row`` (see :func:`noise_layout`; -1 = not drawn).
    """
    if layout[0] < 0:
        return p, v, R, w
    pm = _axpy(p, sensor_std[0], _vec(row, layout[0]))
    vm = _axpy(v, sensor_std[1], _vec(row, layout[1]))
    Rm = R
    if layout[2] >= 0:
        Rm = _mul(R, _expm(_scale(sensor_std[2], _vec(row, layout[2]))))
    wm = _axpy(w, sensor_std[3], _vec(row, layout[3]))
    return pm, vm, Rm, wm
