"""SO(3) and quaternion helpers.

Two forms, one implementation each:

* **kernels** (compiled with :func:`quadfault.jit.jit`): vectors are 3-tuples of floats,
  rotation matrices row-major 9-tuples, so nothing allocates -- :func:`cross3`, :func:`hat3`,
  :func:`vee3`, :func:`expm3` (Rodrigues, paper eq. 5), :func:`matmul3`, :func:`matvec3`,
  :func:`dcm_renormalize3`; the dynamics, the controller, the sensors and the estimators call
  these.
* **array functions** with a leading batch shape: vectors ``(..., 3)``, rotation matrices
  ``(..., 3, 3)`` and quaternions ``(..., 4)`` (scalar first, Hamilton convention, body to
  world: ``v_world = R(q) @ v_body``). :func:`cross`, :func:`hat`, :func:`vee` and
  :func:`expm_so3` are compiled loops over the kernels; the quaternion and Euler conversions
  exist only here.

The hat map is the paper's eq. (5): ``hat(w) @ x == cross(w, x)``.
"""

from __future__ import annotations

import math

import numpy as np

from quadfault.jit import jit

_SMALL = 1e-8


# --- kernels: 3-tuples and row-major 9-tuples -------------------------------------------
@jit(inner=True)
def dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@jit(inner=True)
def cross3(a, b):
    """``a x b``."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@jit(inner=True)
def axpy3(x, a, y):
    """``x + a y``."""
    return (x[0] + a * y[0], x[1] + a * y[1], x[2] + a * y[2])


@jit(inner=True)
def scale3(a, x):
    return (a * x[0], a * x[1], a * x[2])


@jit(inner=True)
def hat3(w):
    """Skew-symmetric matrix of ``w`` (paper eq. 5)."""
    return (0.0, -w[2], w[1], w[2], 0.0, -w[0], -w[1], w[0], 0.0)


@jit(inner=True)
def vee3(M):
    """Inverse of :func:`hat3` on the antisymmetric part of ``M``."""
    return (0.5 * (M[7] - M[5]), 0.5 * (M[2] - M[6]), 0.5 * (M[3] - M[1]))


@jit(inner=True)
def matmul3(A, B):
    """``A @ B``."""
    return (
        A[0] * B[0] + A[1] * B[3] + A[2] * B[6],
        A[0] * B[1] + A[1] * B[4] + A[2] * B[7],
        A[0] * B[2] + A[1] * B[5] + A[2] * B[8],
        A[3] * B[0] + A[4] * B[3] + A[5] * B[6],
        A[3] * B[1] + A[4] * B[4] + A[5] * B[7],
        A[3] * B[2] + A[4] * B[5] + A[5] * B[8],
        A[6] * B[0] + A[7] * B[3] + A[8] * B[6],
        A[6] * B[1] + A[7] * B[4] + A[8] * B[7],
        A[6] * B[2] + A[7] * B[5] + A[8] * B[8],
    )


@jit(inner=True)
def matvec3(A, x):
    """``A @ x``."""
    return (
        A[0] * x[0] + A[1] * x[1] + A[2] * x[2],
        A[3] * x[0] + A[4] * x[1] + A[5] * x[2],
        A[6] * x[0] + A[7] * x[1] + A[8] * x[2],
    )


@jit(inner=True)
def transpose3(A):
    return (A[0], A[3], A[6], A[1], A[4], A[7], A[2], A[5], A[8])


# Series of a = sin(th)/th and b = (1 - cos th)/th^2 in th^2 (Horner, through th^10): below
# th = 0.1 rad the truncation (th^12 / 13!) is below 2e-22, so they equal the closed forms to
# rounding -- without the sqrt, sin, cos and two divisions (at 1 kHz, th = |Omega| dt / 2
# stays below 0.1 rad up to 200 rad/s, so the hot path never calls libm here).
_EXPM_SERIES_MAX_TH2 = 0.01
_A1, _A2, _A3, _A4, _A5 = -1 / 6, 1 / 120, -1 / 5040, 1 / 362880, -1 / 39916800
_B0, _B1, _B2, _B3, _B4, _B5 = 0.5, -1 / 24, 1 / 720, -1 / 40320, 1 / 3628800, -1 / 479001600


@jit(inner=True)
def expm3(phi):
    """Exponential map ``so(3) -> SO(3)`` (Rodrigues) of a rotation vector ``phi`` [rad]:
    ``I + a [phi]x + b (phi phi^T - |phi|^2 I)`` with ``a = sin(th)/th``,
    ``b = (1 - cos th)/th^2`` (their Taylor series below 0.1 rad, see above)."""
    x, y, z = phi[0], phi[1], phi[2]
    th2 = x * x + y * y + z * z
    if th2 < _EXPM_SERIES_MAX_TH2:
        a = 1.0 + th2 * (_A1 + th2 * (_A2 + th2 * (_A3 + th2 * (_A4 + th2 * _A5))))
        b = _B0 + th2 * (_B1 + th2 * (_B2 + th2 * (_B3 + th2 * (_B4 + th2 * _B5))))
    else:
        th = math.sqrt(th2)
        a = math.sin(th) / th
        b = (1.0 - math.cos(th)) / (th * th)
    d = 1.0 - b * th2
    return (
        b * (x * x) + d,
        b * (x * y) + a * -z,
        b * (x * z) + a * y,
        b * (y * x) + a * z,
        b * (y * y) + d,
        b * (y * z) + a * -x,
        b * (z * x) + a * -y,
        b * (z * y) + a * x,
        b * (z * z) + d,
    )


@jit(inner=True)
def dcm_renormalize3(R):
    """The reference code's first-order DCM renormalisation ("Direction Cosine Matrix IMU"):
    rows x, y share their orthogonality error, z = x' x y', each row rescaled to unit length
    to first order. Used only by the ``reference`` integrator (the authors' step)."""
    x, y = (R[0], R[1], R[2]), (R[3], R[4], R[5])
    err = dot3(x, y)
    h = 0.5 * err
    xo = (x[0] - h * y[0], x[1] - h * y[1], x[2] - h * y[2])
    yo = (y[0] - h * x[0], y[1] - h * x[1], y[2] - h * x[2])
    zo = cross3(xo, yo)
    sx, sy, sz = 0.5 * (3 - dot3(xo, xo)), 0.5 * (3 - dot3(yo, yo)), 0.5 * (3 - dot3(zo, zo))
    return (
        sx * xo[0],
        sx * xo[1],
        sx * xo[2],
        sy * yo[0],
        sy * yo[1],
        sy * yo[2],
        sz * zo[0],
        sz * zo[1],
        sz * zo[2],
    )


# --- bridges between arrays and tuples (inlined into the calling kernel) ------------------
@jit(inline="always")
def vec3(a, off=0):
    """3-tuple from ``a[off:off + 3]`` of a 1-D array."""
    return (a[off], a[off + 1], a[off + 2])


@jit(inline="always")
def mat3(M):
    """Row-major 9-tuple of a (3, 3) array."""
    return (M[0, 0], M[0, 1], M[0, 2], M[1, 0], M[1, 1], M[1, 2], M[2, 0], M[2, 1], M[2, 2])


@jit(inline="always")
def store3(dst, x):
    dst[0], dst[1], dst[2] = x[0], x[1], x[2]


@jit(inline="always")
def store33(dst, M):
    for r in range(3):
        dst[r, 0], dst[r, 1], dst[r, 2] = M[3 * r], M[3 * r + 1], M[3 * r + 2]


# --- array functions over the kernels -----------------------------------------------------
@jit
def _cross_rows(a, b, out):
    for i in range(a.shape[0]):
        store3(out[i], cross3(vec3(a[i]), vec3(b[i])))


@jit
def _hat_rows(w, out):
    for i in range(w.shape[0]):
        store33(out[i], hat3(vec3(w[i])))


@jit
def _vee_rows(m, out):
    for i in range(m.shape[0]):
        store3(out[i], vee3(mat3(m[i])))


@jit
def _expm_rows(phi, out):
    for i in range(phi.shape[0]):
        store33(out[i], expm3(vec3(phi[i])))


def rows(a, width: tuple) -> tuple[np.ndarray, tuple]:
    """``a`` as a C-contiguous float array of rows ``(m,) + width`` and its batch shape."""
    a = np.asarray(a, dtype=float)
    batch = a.shape[: a.ndim - len(width)]
    return np.ascontiguousarray(a.reshape((-1,) + tuple(width))), batch


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (broadcast): :func:`cross3` per row."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    (ra, batch), (rb, _) = rows(a, (3,)), rows(b, (3,))
    out = np.empty_like(ra)
    _cross_rows(ra, rb, out)
    return out.reshape(batch + (3,))


def hat(w: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix of ``w`` (paper eq. 5): ``(..., 3) -> (..., 3, 3)``."""
    r, batch = rows(w, (3,))
    out = np.empty((len(r), 3, 3))
    _hat_rows(r, out)
    return out.reshape(batch + (3, 3))


def vee(m: np.ndarray) -> np.ndarray:
    """Inverse of :func:`hat` (uses the antisymmetric part): ``(..., 3, 3) -> (..., 3)``."""
    r, batch = rows(m, (3, 3))
    out = np.empty((len(r), 3))
    _vee_rows(r, out)
    return out.reshape(batch + (3,))


def expm_so3(phi: np.ndarray) -> np.ndarray:
    """Exponential map of rotation vectors ``(..., 3)`` [rad] -> ``(..., 3, 3)``
    (:func:`expm3` per row)."""
    r, batch = rows(phi, (3,))
    out = np.empty((len(r), 3, 3))
    _expm_rows(r, out)
    return out.reshape(batch + (3, 3))


def logm_so3(R: np.ndarray) -> np.ndarray:
    """Logarithm map ``SO(3) -> so(3)`` as a rotation vector [rad] (robust near 0 and pi)."""
    R = np.asarray(R, dtype=float)
    q = rot_to_quat(R)
    w = np.clip(q[..., 0], -1.0, 1.0)
    v = q[..., 1:]
    s = np.sqrt(np.sum(v * v, axis=-1))
    angle = 2.0 * np.arctan2(s, w)
    small = s < _SMALL
    scale = np.where(
        small, 2.0 / np.where(small, np.maximum(w, _SMALL), 1.0), angle / np.where(small, 1.0, s)
    )
    return v * scale[..., None]


def quat_to_rot(q: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) -> rotation matrix body->world."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        (
            np.stack((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)), -1),
            np.stack((2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)), -1),
            np.stack((2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)), -1),
        ),
        axis=-2,
    )


def rot_to_quat(R: np.ndarray) -> np.ndarray:
    """Rotation matrix -> unit quaternion (w, x, y, z) with w >= 0 (Shepperd's method)."""
    R = np.asarray(R, dtype=float)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    tr = m00 + m11 + m22
    cand = np.stack((tr, m00, m11, m22), axis=-1)
    k = np.argmax(cand, axis=-1)
    out = np.empty(R.shape[:-2] + (4,))
    # case 0: w largest
    s0 = np.sqrt(np.maximum(1.0 + tr, 1e-300)) * 2.0
    q0 = np.stack(
        (
            0.25 * s0,
            (R[..., 2, 1] - R[..., 1, 2]) / s0,
            (R[..., 0, 2] - R[..., 2, 0]) / s0,
            (R[..., 1, 0] - R[..., 0, 1]) / s0,
        ),
        -1,
    )
    s1 = np.sqrt(np.maximum(1.0 + m00 - m11 - m22, 1e-300)) * 2.0
    q1 = np.stack(
        (
            (R[..., 2, 1] - R[..., 1, 2]) / s1,
            0.25 * s1,
            (R[..., 0, 1] + R[..., 1, 0]) / s1,
            (R[..., 0, 2] + R[..., 2, 0]) / s1,
        ),
        -1,
    )
    s2 = np.sqrt(np.maximum(1.0 + m11 - m00 - m22, 1e-300)) * 2.0
    q2 = np.stack(
        (
            (R[..., 0, 2] - R[..., 2, 0]) / s2,
            (R[..., 0, 1] + R[..., 1, 0]) / s2,
            0.25 * s2,
            (R[..., 1, 2] + R[..., 2, 1]) / s2,
        ),
        -1,
    )
    s3 = np.sqrt(np.maximum(1.0 + m22 - m00 - m11, 1e-300)) * 2.0
    q3 = np.stack(
        (
            (R[..., 1, 0] - R[..., 0, 1]) / s3,
            (R[..., 0, 2] + R[..., 2, 0]) / s3,
            (R[..., 1, 2] + R[..., 2, 1]) / s3,
            0.25 * s3,
        ),
        -1,
    )
    out = np.choose(k[..., None], (q0, q1, q2, q3))
    out = out * np.where(out[..., :1] < 0, -1.0, 1.0)
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product ``p * q`` (scalar first)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    pw, pv = p[..., :1], p[..., 1:]
    qw, qv = q[..., :1], q[..., 1:]
    w = pw * qw - np.sum(pv * qv, axis=-1, keepdims=True)
    v = pw * qv + qw * pv + cross(pv, qv)
    return np.concatenate((w, v), axis=-1)


def orthonormalize(R: np.ndarray) -> np.ndarray:
    """Closest rotation matrix (polar decomposition through SVD)."""
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=float))
    D = np.ones(U.shape[:-1])
    D[..., -1] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[..., None, :]) @ Vt


def rotation_angle(R: np.ndarray) -> np.ndarray:
    """Angle [rad] of a rotation matrix, robust near 0 and pi."""
    return np.linalg.norm(logm_so3(R), axis=-1)


def euler_zyx_to_rot(roll, pitch, yaw) -> np.ndarray:
    """Rotation matrix from Z-Y-X (yaw, pitch, roll) Euler angles [rad], body->world."""
    roll, pitch, yaw = (np.asarray(a, dtype=float) for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = (
        np.cos(roll),
        np.sin(roll),
        np.cos(pitch),
        np.sin(pitch),
        np.cos(yaw),
        np.sin(yaw),
    )
    return np.stack(
        (
            np.stack((cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr), -1),
            np.stack((sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr), -1),
            np.stack((-sp, cp * sr, cp * cr), -1),
        ),
        axis=-2,
    )


def rot_to_euler_zyx(R: np.ndarray) -> np.ndarray:
    """Z-Y-X Euler angles (roll, pitch, yaw) [rad] of a body->world rotation matrix."""
    R = np.asarray(R, dtype=float)
    roll = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    pitch = -np.arcsin(np.clip(R[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack((roll, pitch, yaw), axis=-1)


# Frame conversions -----------------------------------------------------------------------
#: World ENU -> NED (a proper rotation: x_ned = y_enu, y_ned = x_enu, z_ned = -z_enu).
ENU_TO_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
#: Body FLU -> FRD (rotation by pi about x).
FLU_TO_FRD = np.diag([1.0, -1.0, -1.0])
