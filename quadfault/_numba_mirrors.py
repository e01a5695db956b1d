"""Array-in / array-out wrappers of the compiled scalar kernels, with the pure functions'
names (``expm_so3``, ``step_rk4``, ``motor_commands``, ``measure``, ...).

For the tests (each against its pure function), the reference integrator of the
single-vehicle loop and other compiled modules (``estimators.ekf_numba``). They allocate their
results; the hot loops in :mod:`quadfault._sim_numba` call the kernels directly.
"""

from __future__ import annotations

import math

import numpy as np

from quadfault._numba_kernels import (
    _controller,
    _cross,
    _desired_attitude,
    _dexpinv,
    _expm,
    _mat,
    _measure,
    _mul,
    _rk4,
    _specific_force,
    _store_mat,
    _store_vec,
    _tacc,
    _vec,
    _wacc,
    njit,
)


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
