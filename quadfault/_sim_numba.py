"""Compiled (numba) twin of the core physics: one vehicle step, the single-vehicle simulator
loop and the batched kernel :func:`step_batch`.

The same computation as the pure-numpy code, compiled with ``numba.njit(cache=True)``:
the :class:`~quadfault.controller.GeometricController` (any
:class:`~quadfault.controller.ControllerConfig`), the motor model, the ``rk4`` (RKMK4) or
``reference`` integrator, sensor noise. Everything that is a function of time only
(reference trajectory, feed-forward rates, efficiency schedule) and every random number is
prepared in numpy and passed in as arrays.

Layout of the code:

* **scalar kernels** (``_`` prefix): vectors are 3-tuples of float64 and rotation matrices
  9-tuples (row-major), so the hot path allocates nothing -- LLVM keeps them in registers.
  Each mirrors one pure function and says which; it is a transcription, not a second model,
  guarded by ``tests/test_simulator_fast.py`` (compiled == pure to <= 1e-9 over a flight,
  helper by helper to ~1e-14) and ``tests/test_throughput_kernel.py``.
* :func:`plant_step`: **the** per-vehicle physics step (motor model, allocation, RKMK4).
  The single-vehicle loop :func:`run_steps` and the batched kernel :func:`step_batch` both
  call it, and both call :func:`_controller` for the geometric controller.
* array wrappers with the pure functions' names (``expm_so3``, ``step_rk4``,
  ``motor_commands``, ...): thin conversions around the scalar kernels, for the tests and
  for other compiled modules (``estimators.ekf_numba``). They allocate; the loops don't.

Random numbers: ``Generator.standard_normal((n, m))`` yields exactly the stream of ``n * m``
single draws taken in row order, so blocks of rows drawn before each chunk of steps, with the
columns laid out in the order the pure loop draws them each step (sensor p, v, [attitude],
gyro; the motors; the accelerometer), reproduce the pure path's noise bit for bit (see
:func:`noise_layout`).

All kernels use ``error_model="numpy"`` (a division by zero gives inf / NaN as in numpy,
never an exception inside a parallel loop) and no ``fastmath`` (results stay equal to the
numpy path to rounding). Threads: numba's default, one per core (``NUMBA_NUM_THREADS`` or
``numba.set_num_threads`` to change it).

Without numba this module still imports (``AVAILABLE`` is False) and the helpers run as plain
Python, which is how the tests check them one by one against the pure functions.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from quadfault.errors import ConfigError

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


@njit
def _expm(phi):
    """Mirrors :func:`quadfault.rotation.expm_so3` (Rodrigues, Taylor series below 1e-4 rad):
    ``I + a [phi]x + b (phi phi^T - |phi|^2 I)`` as a row-major 9-tuple."""
    x, y, z = phi
    th2 = x * x + y * y + z * z
    if th2 < 1e-8:
        a = 1.0 - th2 / 6.0 + th2 * th2 / 120.0
        b = 0.5 - th2 / 24.0 + th2 * th2 / 720.0
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


@njit
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


@njit
def _vec(a, off=0):
    """3-tuple from ``a[off:off + 3]`` of a 1-D array."""
    return (a[off], a[off + 1], a[off + 2])


@njit
def _mat(M):
    """Row-major 9-tuple of a (3, 3) array."""
    return (M[0, 0], M[0, 1], M[0, 2], M[1, 0], M[1, 1], M[1, 2], M[2, 0], M[2, 1], M[2, 2])


@njit
def _store_vec(dst, x):
    dst[0], dst[1], dst[2] = x[0], x[1], x[2]


@njit
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


@njit
def _tacc(R, thrust, body):
    """Mirrors :func:`quadfault.dynamics.translational_acceleration` (eq. 2, no F_ext)."""
    s = thrust / body.mass
    return (0.0 - s * R[2], 0.0 - s * R[5], body.gravity - s * R[8])


@njit
def _wacc(w, moment, body):
    """Mirrors :func:`quadfault.dynamics.angular_acceleration` (eq. 4, no M_ext)."""
    c = _cross(w, _mv(body.inertia, w))
    return _mv(body.inertia_inverse, (moment[0] - c[0], moment[1] - c[1], moment[2] - c[2]))


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
def _rk4(p0, v0, R0, w0, thrust, moment, body, dt):
    """Mirrors :func:`quadfault.dynamics.step_rk4` (RKMK4, eqs. 1-4, no external wrench):
    ``R(t) = R0 exp([theta(t)]x)``, ``theta' = dexp^-1(Omega)``; ``_derivatives`` inlined as
    (p', v', Omega') = (v, eq. 2, eq. 4)."""
    h = 0.5 * dt
    k1p, k1v, k1w = v0, _tacc(R0, thrust, body), _wacc(w0, moment, body)
    th1 = w0
    v2, R2, w2 = _axpy(v0, h, k1v), _mul(R0, _expm(_scale(h, th1))), _axpy(w0, h, k1w)
    k2p, k2v, k2w = v2, _tacc(R2, thrust, body), _wacc(w2, moment, body)
    th2 = _dexpinv(_scale(h, th1), w2)
    v3, R3, w3 = _axpy(v0, h, k2v), _mul(R0, _expm(_scale(h, th2))), _axpy(w0, h, k2w)
    k3p, k3v, k3w = v3, _tacc(R3, thrust, body), _wacc(w3, moment, body)
    th3 = _dexpinv(_scale(h, th2), w3)
    v4, R4, w4 = _axpy(v0, dt, k3v), _mul(R0, _expm(_scale(dt, th3))), _axpy(w0, dt, k3w)
    k4p, k4v, k4w = v4, _tacc(R4, thrust, body), _wacc(w4, moment, body)
    th4 = _dexpinv(_scale(dt, th3), w4)
    c = dt / 6.0
    th = (c * (th1[0] + 2 * th2[0] + 2 * th3[0] + th4[0]),
          c * (th1[1] + 2 * th2[1] + 2 * th3[1] + th4[1]),
          c * (th1[2] + 2 * th2[2] + 2 * th3[2] + th4[2]))
    return (_rk_sum(p0, c, k1p, k2p, k3p, k4p), _rk_sum(v0, c, k1v, k2v, k3v, k4v),
            _mul(R0, _expm(th)), _rk_sum(w0, c, k1w, k2w, k3w, k4w))


# --- scalar kernels: motors.py + Vehicle.wrench ----------------------------------------------
@njit
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


@njit
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
def _controller(p, v, R, w, ref, gains, body, out):
    """Mirrors :meth:`GeometricController.compute` (eqs. 9, 10) followed by
    :meth:`GeometricController.motor_commands`: writes the rotor commands [N] (nominal
    allocation inverse) into ``out`` (n,).

    ``ref`` (6, 3) rows: position, velocity, acceleration, b1d, Omega_d, Omega_d' (the last
    two used only with angular feed-forward); ``body`` is the *nominal* vehicle.
    """
    kx, kv = gains.kx, gains.kv
    mg = body.mass * body.gravity
    f_n = (kx[0] * (p[0] - ref[0, 0]) + kv[0] * (v[0] - ref[1, 0]),
           kx[1] * (p[1] - ref[0, 1]) + kv[1] * (v[1] - ref[1, 1]),
           kx[2] * (p[2] - ref[0, 2]) + kv[2] * (v[2] - ref[1, 2]) + mg)
    if gains.acceleration_feedforward:
        m = body.mass
        f_n = (f_n[0] - m * ref[2, 0], f_n[1] - m * ref[2, 1], f_n[2] - m * ref[2, 2])
    Rd = _desired_attitude(f_n, (ref[3, 0], ref[3, 1], ref[3, 2]), gains.normalize_b2d)
    thrust = f_n[0] * R[2] + f_n[1] * R[5] + f_n[2] * R[8]
    # A = Rd^T R; e_R = vee(A - A^T) / 2 (eq. 10); R^T Rd = A^T
    A = _mul((Rd[0], Rd[3], Rd[6], Rd[1], Rd[4], Rd[7], Rd[2], Rd[5], Rd[8]), R)
    eR = (0.5 * (0.5 * ((A[7] - A[5]) - (A[5] - A[7]))),
          0.5 * (0.5 * ((A[2] - A[6]) - (A[6] - A[2]))),
          0.5 * (0.5 * ((A[3] - A[1]) - (A[1] - A[3]))))
    J = body.inertia
    Jw = _mv(J, w)
    if gains.angular_feedforward:
        RtRd = (A[0], A[3], A[6], A[1], A[4], A[7], A[2], A[5], A[8])
        w_d, w_dot_d = (ref[4, 0], ref[4, 1], ref[4, 2]), (ref[5, 0], ref[5, 1], ref[5, 2])
        w_d_body = (RtRd[0] * w_d[0] + RtRd[1] * w_d[1] + RtRd[2] * w_d[2],
                    RtRd[3] * w_d[0] + RtRd[4] * w_d[1] + RtRd[5] * w_d[2],
                    RtRd[6] * w_d[0] + RtRd[7] * w_d[1] + RtRd[8] * w_d[2])
        eW = (w[0] - w_d_body[0], w[1] - w_d_body[1], w[2] - w_d_body[2])
        c1 = _cross(w, w_d_body)
        x = (c1[0] - (RtRd[0] * w_dot_d[0] + RtRd[1] * w_dot_d[1] + RtRd[2] * w_dot_d[2]),
             c1[1] - (RtRd[3] * w_dot_d[0] + RtRd[4] * w_dot_d[1] + RtRd[5] * w_dot_d[2]),
             c1[2] - (RtRd[6] * w_dot_d[0] + RtRd[7] * w_dot_d[1] + RtRd[8] * w_dot_d[2]))
        c0, Jx = _cross(w, Jw), _mv(J, x)
        ff = (c0[0] - Jx[0], c0[1] - Jx[1], c0[2] - Jx[2])
    else:
        eW = w
        ff = _cross(w, Jw)
    kR, kW = gains.kR, gains.kW
    M = (-kR[0] * eR[0] - kW[0] * eW[0] + ff[0], -kR[1] * eR[1] - kW[1] * eW[1] + ff[1],
         -kR[2] * eR[2] - kW[2] * eW[2] + ff[2])
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


# --- the batched kernel ----------------------------------------------------------------------
@njit
def _advance(i, p, v, R, w, f_cmd, eta, sigma, z, z_off, saturate, body, dt,
             control_every, refs, gains, nominal):
    """Vehicle ``i`` of :func:`step_batch`: ``eta.shape[1]`` substeps, in place."""
    pi, vi, Ri, wi = _vec(p[i]), _vec(v[i]), _mat(R[i]), _vec(w[i])
    fi, zi, ei, si = f_cmd[i], z[i], eta[i], sigma[i]  # views made once per vehicle and call
    ri = refs[i] if control_every > 0 else refs[0]
    for j in range(eta.shape[1]):
        if control_every > 0 and j % control_every == 0:
            _controller(pi, vi, Ri, wi, ri, gains, nominal, fi)
        pi, vi, Ri, wi, _, _ = plant_step(pi, vi, Ri, wi, fi, ei, j, saturate, si, zi,
                                          z_off[i, j], body, dt)
    _store_vec(p[i], pi)
    _store_vec(v[i], vi)
    _store_mat(R[i], Ri)
    _store_vec(w[i], wi)


@njit(parallel=True)
def _step_batch_parallel(p, v, R, w, f_cmd, eta, sigma, z, z_off, saturate, body, dt,
                         control_every, refs, gains, nominal):
    for i in prange(p.shape[0]):
        _advance(i, p, v, R, w, f_cmd, eta, sigma, z, z_off, saturate, body, dt,
                 control_every, refs, gains, nominal)


@njit
def _step_batch_serial(p, v, R, w, f_cmd, eta, sigma, z, z_off, saturate, body, dt,
                       control_every, refs, gains, nominal):
    for i in range(p.shape[0]):
        _advance(i, p, v, R, w, f_cmd, eta, sigma, z, z_off, saturate, body, dt,
                 control_every, refs, gains, nominal)


#: below this many vehicles :func:`step_batch` runs on the calling thread (a parallel launch
#: costs more than it saves for a handful of vehicles)
PARALLEL_MIN_VEHICLES = 64


def step_batch(p, v, R, w, f_cmd, eta, sigma, z, z_off, saturate, body, dt,
               control_every=0, refs=None, gains=None, nominal=None):
    """Advance N vehicles by ``k = eta.shape[1]`` physics substeps, in place, in parallel.

    Per vehicle i and substep j: when ``control_every > 0`` and ``j % control_every == 0``
    the geometric controller (eqs. 9, 10; :func:`_controller`, from the *true* state, with
    the reference ``refs[i]`` (6, 3) held over the call, ``gains`` and the nominal vehicle
    ``nominal`` (default ``body``)) writes ``f_cmd[i]``; then :func:`plant_step` (motor model
    eqs. 11, 13 with efficiency ``eta[i, j]`` and thrust noise
    ``sigma[i] * z[i, z_off[i, j]:+n]``, allocation, RKMK4 eqs. 1-4 of length ``dt`` [s]).

    Shapes: ``p, v, w`` (N, 3), ``R`` (N, 3, 3), ``f_cmd`` (N, n) (updated with the
    controller), ``eta`` (N, k, n), ``sigma`` (N,), ``z`` (N, m) standard normals, ``z_off``
    (N, k) int64, ``refs`` (N, 6, 3). All float64 and C-contiguous (numba's prange over the
    vehicles from ``PARALLEL_MIN_VEHICLES`` on; numba's thread count, one per core by default).
    """
    if control_every > 0 and (refs is None or gains is None):
        raise ConfigError("step_batch: the controller (control_every > 0) needs refs and gains")
    if refs is None:
        refs = np.zeros((1, 6, 3))
    gains = no_gains() if gains is None else gains
    nominal = body if nominal is None else nominal
    kernel = _step_batch_parallel if len(p) >= PARALLEL_MIN_VEHICLES else _step_batch_serial
    kernel(p, v, R, w, f_cmd, eta, sigma, z, z_off, bool(saturate), body, float(dt),
           int(control_every), refs, gains, nominal)


@njit(parallel=True)
def _controller_batch_parallel(p, v, R, w, refs, gains, nominal, out):
    for i in prange(p.shape[0]):
        _controller(_vec(p[i]), _vec(v[i]), _mat(R[i]), _vec(w[i]), refs[i], gains, nominal,
                    out[i])


@njit
def _controller_batch_serial(p, v, R, w, refs, gains, nominal, out):
    for i in range(p.shape[0]):
        _controller(_vec(p[i]), _vec(v[i]), _mat(R[i]), _vec(w[i]), refs[i], gains, nominal,
                    out[i])


def controller_batch(p, v, R, w, refs, gains, nominal, out):
    """The geometric controller (eqs. 9, 10; :func:`_controller`) for N states into ``out``
    (N, n): ``p, v, w`` (N, 3), ``R`` (N, 3, 3), ``refs`` (N, 6, 3) as in :func:`_controller`."""
    kernel = (_controller_batch_parallel if len(p) >= PARALLEL_MIN_VEHICLES
              else _controller_batch_serial)
    kernel(p, v, R, w, refs, gains, nominal, out)


@njit
def draw_normals(generators, rows, sizes, z):
    """``z[i, :sizes[i]] = generators[i].standard_normal(sizes[i])`` for i in ``rows``.

    numba's ``Generator.standard_normal`` is numpy's algorithm on the generator's own bit
    generator (shared state), so this gives the numbers -- and leaves the generators in the
    state -- of the same calls in Python, without a Python call per generator.
    """
    for r in range(rows.shape[0]):
        i = rows[r]
        g = generators[i]
        for k in range(sizes[i]):
            z[i, k] = g.standard_normal()


def no_gains() -> Gains:
    """Placeholder gains for :func:`step_batch` calls without the controller."""
    z = np.zeros(3)
    return Gains(z, z, z, z, False, False, False)


# --- array wrappers with the pure functions' names (tests, estimators.ekf_numba) -----------
@njit
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit
def _arr3(x):
    out = np.empty(3)
    _store_vec(out, x)
    return out


@njit
def _arr33(M):
    out = np.empty((3, 3))
    _store_mat(out, M)
    return out


@njit
def cross(a, b):
    """Mirrors :func:`quadfault.rotation.cross` (one 3-vector)."""
    return _arr3(_cross(_vec(a), _vec(b)))


@njit
def hat(w):
    """Mirrors :func:`quadfault.rotation.hat` (paper eq. 5)."""
    out = np.zeros((3, 3))
    out[0, 1] = -w[2]
    out[0, 2] = w[1]
    out[1, 0] = w[2]
    out[1, 2] = -w[0]
    out[2, 0] = -w[1]
    out[2, 1] = w[0]
    return out


@njit
def vee(m):
    """Mirrors :func:`quadfault.rotation.vee`."""
    out = np.empty(3)
    out[0] = 0.5 * (m[2, 1] - m[1, 2])
    out[1] = 0.5 * (m[0, 2] - m[2, 0])
    out[2] = 0.5 * (m[1, 0] - m[0, 1])
    return out


@njit
def matmul(A, B):
    """``A @ B`` for 3x3 matrices."""
    return _arr33(_mul(_mat(A), _mat(B)))


@njit
def matvec(A, x):
    """``A @ x`` for a matrix with any number of rows and a vector."""
    out = np.zeros(A.shape[0])
    for i in range(A.shape[0]):
        s = 0.0
        for j in range(A.shape[1]):
            s += A[i, j] * x[j]
        out[i] = s
    return out


@njit
def put(dst, src):
    """``dst[...] = src`` element by element (1-D or 2-D). Array-valued slice assignment
    would compile numba's shape-error formatting, which costs seconds of JIT time."""
    if dst.ndim == 1:
        for i in range(dst.shape[0]):
            dst[i] = src[i]
    else:
        for i in range(dst.shape[0]):
            for j in range(dst.shape[1]):
                dst[i, j] = src[i, j]


@njit
def expm_so3(phi):
    """Mirrors :func:`quadfault.rotation.expm_so3` (array in, (3, 3) array out)."""
    return _arr33(_expm(_vec(phi)))


@njit
def dcm_orthonormalize_reference(R):
    """Mirrors :func:`quadfault.rotation.dcm_orthonormalize_reference`."""
    x, y = R[0].copy(), R[1].copy()
    err = dot(x, y)
    xo = x - 0.5 * err * y
    yo = y - 0.5 * err * x
    zo = cross(xo, yo)
    out = np.empty((3, 3))
    put(out[0], 0.5 * (3 - dot(xo, xo)) * xo)
    put(out[1], 0.5 * (3 - dot(yo, yo)) * yo)
    put(out[2], 0.5 * (3 - dot(zo, zo)) * zo)
    return out


@njit
def translational_acceleration(R, thrust, body):
    """Mirrors :func:`quadfault.dynamics.translational_acceleration` (eq. 2, no F_ext)."""
    return _arr3(_tacc(_mat(R), thrust, body))


@njit
def angular_acceleration(w, moment, body):
    """Mirrors :func:`quadfault.dynamics.angular_acceleration` (eq. 4, no M_ext)."""
    return _arr3(_wacc(_vec(w), _vec(moment), body))


@njit
def specific_force_body(R, acceleration_world, gravity):
    """Mirrors :func:`quadfault.dynamics.specific_force_body`: ``R^T (a - g e3)``."""
    return _arr3(_specific_force(_mat(R), _vec(acceleration_world), gravity))


@njit
def dexpinv(theta, w):
    """Mirrors :func:`quadfault.dynamics._dexpinv`."""
    return _arr3(_dexpinv(_vec(theta), _vec(w)))


@njit
def step_rk4(p0, v0, R0, w0, thrust, moment, body, dt):
    """Mirrors :func:`quadfault.dynamics.step_rk4` (RKMK4, no external wrench), on arrays."""
    p, v, R, w = _rk4(_vec(p0), _vec(v0), _mat(R0), _vec(w0), thrust, _vec(moment), body, dt)
    return _arr3(p), _arr3(v), _arr33(R), _arr3(w)


@njit
def reference_euler_step(p0, v0, R0, w0, lag, body, dt):
    """Mirrors :meth:`quadfault.dynamics.ReferenceEuler.step`.

    ``lag`` holds the reference's stored ``(a, w_dot, force_world, moment)`` as rows of a
    (4, 3) array and is updated in place, like the object's attributes.
    """
    w = w0 + lag[1] * dt
    v = v0 + lag[0] * dt
    A = hat(w * dt)
    A[0, 0] += 1.0
    A[1, 1] += 1.0
    A[2, 2] += 1.0
    R = dcm_orthonormalize_reference(matmul(R0, A))
    p = p0 + v * dt
    for i in range(3):
        lag[0, i] = -lag[2, i] / body.mass
    lag[0, 2] += body.gravity
    put(lag[1], matvec(body.inertia_inverse, lag[3] - cross(w, matvec(body.inertia, w))))
    return p, v, R, w


@njit
def reference_euler_apply(lag, thrust, moment, R):
    """Mirrors :meth:`quadfault.dynamics.ReferenceEuler.apply` (stores T R e3 and M)."""
    for i in range(3):
        lag[2, i] = thrust * R[i, 2]
        lag[3, i] = moment[i]


@njit
def motor_apply(f_cmd, eta, f_max, saturate, thrust_noise, eps):
    """Mirrors :meth:`quadfault.motors.MotorModel.apply` (eqs. 11, 13), with the standard
    normal draws ``eps`` passed in (ignored when ``thrust_noise`` is 0)."""
    n = f_cmd.shape[0]
    f = np.empty(n)
    for i in range(n):
        fi = max(f_cmd[i], 0.0)
        if saturate:
            fi = min(fi, f_max)
        f[i] = fi * eta[i]
        if thrust_noise > 0:
            f[i] = f[i] * math.exp(thrust_noise * eps[i])
    return f


@njit
def desired_attitude(f_n, b1d, normalize_b2d):
    """Mirrors :meth:`GeometricController._desired_attitude`: columns (b1, b2d, b3d)."""
    return _arr33(_desired_attitude(_vec(f_n), _vec(b1d), normalize_b2d))


@njit
def motor_commands(p, v, R, w, pos_d, vel_d, acc_d, b1d, w_d, w_dot_d, gains, body):
    """Mirrors :meth:`GeometricController.compute` + ``motor_commands`` (eqs. 9, 10)."""
    ref = np.empty((6, 3))
    for i in range(3):
        ref[0, i], ref[1, i], ref[2, i] = pos_d[i], vel_d[i], acc_d[i]
        ref[3, i], ref[4, i], ref[5, i] = b1d[i], w_d[i], w_dot_d[i]
    out = np.empty(body.allocation_inverse.shape[0])
    _controller(_vec(p), _vec(v), _mat(R), _vec(w), ref, gains, body, out)
    return out


@njit
def measure(p, v, R, w, noise_row, layout, sensor_std):
    """Mirrors :meth:`quadfault.simulator.SensorNoise.measure` (state part), on arrays."""
    pm, vm, Rm, wm = _measure(_vec(p), _vec(v), _mat(R), _vec(w), noise_row, layout,
                              sensor_std)
    return _arr3(pm), _arr3(vm), _arr33(Rm), _arr3(wm)


# --- simulator.py: the single-vehicle loop ----------------------------------------------------
@njit
def _reference_step(p, v, R, w, lag, body, dt):
    """:func:`reference_euler_step` on tuples (the MATLAB reproduction; allocates)."""
    pa, va, Ra, wa = reference_euler_step(_arr3(p), _arr3(v), _arr33(R), _arr3(w), lag, body, dt)
    return _vec(pa), _vec(va), _mat(Ra), _vec(wa)


@njit
def _store_row(dst, x):
    for i in range(dst.shape[0]):
        dst[i] = x[i]


@njit
def run_steps(k0, k1, reference, decimation, dt, carry, lag, f_cmd, sf_meas,
              refs, eta, noise, layout, sensor_std, accel_std, record_accel,
              gains, nominal, plant, saturate, thrust_noise, out):
    """Steps ``k0 .. k1-1`` of the loop in :func:`quadfault.simulator.simulate`.

    ``carry`` (rows p, v, w, then R in rows 3..5 of a (6, 3) array) the plant state, ``lag``
    the reference integrator's memory, ``f_cmd`` the held command and ``sf_meas`` the last
    accelerometer reading are updated in place, so the loop runs in chunks; ``noise`` holds
    the chunk's draws (row 0 = step ``k0``); ``refs`` (n_steps, 6, 3) the controller's
    reference rows (see :func:`_controller`). Returns the first step whose new state is not
    finite, or -1.
    """
    out_p, out_v, out_R, out_w, out_f, out_eta, out_acc = out
    p, v, w = _vec(carry[0]), _vec(carry[1]), _vec(carry[2])
    R = (carry[3, 0], carry[3, 1], carry[3, 2], carry[4, 0], carry[4, 1], carry[4, 2],
         carry[5, 0], carry[5, 1], carry[5, 2])
    e_off = max(layout[4], 0)
    diverged = -1
    for k in range(k0, k1):
        row = noise[k - k0]
        if reference:
            p, v, R, w = _reference_step(p, v, R, w, lag, plant, dt)
        mp, mv, mR, mw = _measure(p, v, R, w, row, layout, sensor_std)
        if k % decimation == 0:
            _controller(mp, mv, mR, mw, refs[k], gains, nominal, f_cmd)
        # Plant.step: produced thrust, wrench, accelerometer truth, integration
        R_before = R
        if reference:
            thrust, moment = _motor_wrench(f_cmd, eta, k, saturate, thrust_noise, row, e_off,
                                           plant)
            reference_euler_apply(lag, thrust, _arr3(moment), _arr33(R))
        else:
            p, v, R, w, thrust, moment = plant_step(p, v, R, w, f_cmd, eta, k, saturate,
                                                    thrust_noise, row, e_off, plant, dt)
        if record_accel:
            sf = _specific_force(R_before, _tacc(R_before, thrust, plant), plant.gravity)
            if accel_std != 0.0:
                sf = _axpy(sf, accel_std, _vec(row, layout[5]))
            _store_vec(sf_meas, sf)
        _store_vec(out_p[k], mp)
        _store_vec(out_v[k], mv)
        _store_vec(out_w[k], mw)
        _store_mat(out_R[k], mR)
        _store_row(out_f[k], f_cmd)
        _store_row(out_eta[k], eta[k])
        _store_row(out_acc[k], sf_meas)
        if not (np.isfinite(p[0]) and np.isfinite(p[1]) and np.isfinite(p[2])):
            diverged = k
            break
    _store_vec(carry[0], p)
    _store_vec(carry[1], v)
    _store_vec(carry[2], w)
    for r in range(3):
        carry[3 + r, 0], carry[3 + r, 1], carry[3 + r, 2] = R[3 * r], R[3 * r + 1], R[3 * r + 2]
    return diverged


# --- driver (plain Python) -------------------------------------------------------------------
def noise_layout(sensor_noise, n_rotors: int, thrust_noise: float, record_accel: bool):
    """Column offsets of one step's standard-normal draws, in the pure loop's order.

    Returns ``(layout, width)``: ``layout`` = offsets of (position, velocity, attitude, gyro,
    motors, accelerometer), -1 where the pure loop draws nothing.
    """
    layout = [-1] * 6
    col = 0
    if sensor_noise.any:  # SensorNoise.measure: p, v, [attitude], w
        layout[0], layout[1] = 0, 3
        col = 6
        if sensor_noise.attitude:
            layout[2] = col
            col += 3
        layout[3] = col
        col += 3
    if thrust_noise > 0:  # MotorModel.apply
        layout[4] = col
        col += n_rotors
    if record_accel and sensor_noise.accel:  # the accelerometer, after the plant step
        layout[5] = col
        col += 3
    return np.array(layout, dtype=np.int64), col


def reference_rows(refs, w_d, w_dot_d) -> np.ndarray:
    """(n, 6, 3) rows (position, velocity, acceleration, b1d, Omega_d, Omega_d') for
    :func:`_controller` from a FlatOutput of arrays and the feed-forward rates."""
    pos, vel, acc, b1d = (np.asarray(a, float) for a in refs[:4])
    n = pos.shape[0]
    out = np.empty((n, 6, 3))
    for r, a in enumerate((pos, vel, acc, b1d, w_d, w_dot_d)):
        out[:, r] = a
    return out


def run(plant, controller, config, rng, times, refs, feedforward, initial, bar=None,
        chunk: int = 5000):
    """Run the compiled loop; returns ``(out_p, out_v, out_R, out_w, out_f, out_eta, out_acc,
    diverged_step)`` exactly as the pure loop fills them (``diverged_step`` = -1 if none).

    ``refs`` is the trajectory at ``times`` (a FlatOutput of arrays), ``feedforward`` the
    pair (Omega_d, Omega_d') at ``times`` or None, ``initial`` the plant's initial state.
    The loop runs ``chunk`` steps at a time (noise drawn per chunk: the same stream, bounded
    memory; the progress bar moves per chunk).
    """
    n = len(times)
    vehicle = plant.vehicle
    n_rot = vehicle.n_rotors
    sn = config.sensor_noise
    layout, width = noise_layout(sn, n_rot, plant.motor.thrust_noise, config.record_accel)
    eta = np.asarray(plant.efficiency(times), dtype=float)
    if eta.shape != (n, n_rot):
        raise ConfigError(f"the efficiency schedule gave shape {eta.shape} for {n} times, "
                          f"expected ({n}, {n_rot}); use backend='numpy' for a scalar-only one")
    eta = np.ascontiguousarray(eta)
    if feedforward is None:
        w_d = w_dot_d = np.zeros((n, 3))
    else:
        w_d, w_dot_d = (np.asarray(a, float) for a in feedforward)
    ref_rows = reference_rows(refs, w_d, w_dot_d)
    carry = np.empty((6, 3))
    carry[0], carry[1], carry[2], carry[3:6] = initial.p, initial.v, initial.w, initial.R
    lag = np.zeros((4, 3))
    f_cmd = np.zeros(n_rot)
    sf_meas = np.array([0.0, 0.0, -vehicle.gravity])
    out = (np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3, 3)), np.empty((n, 3)),
           np.empty((n, n_rot)), np.empty((n, n_rot)), np.empty((n, 3)))
    head = (config.integrator == "reference", config.control_decimation, float(config.dt),
            carry, lag, f_cmd, sf_meas, ref_rows, eta)
    tail = (layout, np.array([sn.position, sn.velocity, sn.attitude, sn.gyro], float),
            float(sn.accel), bool(config.record_accel), gains_of(controller),
            body_of(controller.vehicle), body_of(vehicle), bool(plant.motor.saturate),
            float(plant.motor.thrust_noise), out)
    diverged = -1
    for k0 in range(0, n, chunk):
        k1 = min(n, k0 + chunk)
        noise = rng.standard_normal((k1 - k0, width)) if width else np.zeros((k1 - k0, 1))
        diverged = run_steps(k0, k1, *head, noise, *tail)
        if bar is not None:
            bar.update(k1 - k0)
        if diverged >= 0:
            break
    return out + (diverged,)
