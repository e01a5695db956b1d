"""SO(3) and quaternion helpers.

Every function accepts a leading batch shape: vectors are ``(..., 3)``, rotation
matrices ``(..., 3, 3)`` and quaternions ``(..., 4)`` (scalar first, Hamilton
convention, body to world: ``v_world = R(q) @ v_body``).

The hat map is the paper's eq. (5): ``hat(w) @ x == cross(w, x)``.
"""

from __future__ import annotations

import numpy as np

_SMALL = 1e-8


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (faster than ``np.cross`` for small arrays)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    out = np.empty(a.shape if a.shape == b.shape else np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def hat(w: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix of ``w`` (paper eq. 5): ``(..., 3) -> (..., 3, 3)``."""
    w = np.asarray(w, dtype=float)
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1] = -w[..., 2]
    out[..., 0, 2] = w[..., 1]
    out[..., 1, 0] = w[..., 2]
    out[..., 1, 2] = -w[..., 0]
    out[..., 2, 0] = -w[..., 1]
    out[..., 2, 1] = w[..., 0]
    return out


def vee(m: np.ndarray) -> np.ndarray:
    """Inverse of :func:`hat` (uses the antisymmetric part): ``(..., 3, 3) -> (..., 3)``."""
    m = np.asarray(m, dtype=float)
    out = np.empty(m.shape[:-1])
    out[..., 0] = 0.5 * (m[..., 2, 1] - m[..., 1, 2])
    out[..., 1] = 0.5 * (m[..., 0, 2] - m[..., 2, 0])
    out[..., 2] = 0.5 * (m[..., 1, 0] - m[..., 0, 1])
    return out


def expm_so3(phi: np.ndarray) -> np.ndarray:
    """Exponential map ``so(3) -> SO(3)`` (Rodrigues), for a rotation vector ``phi`` [rad]:
    ``R = I + a [phi]x + b [phi]x^2`` with ``a = sin(th)/th``, ``b = (1 - cos th)/th^2``."""
    phi = np.asarray(phi, dtype=float)
    th2 = np.asarray(np.einsum("...i,...i->...", phi, phi))
    small = th2 < 1e-8  # Taylor series keep full double precision below 1e-4 rad
    th = np.sqrt(np.where(small, 1.0, th2))
    a = np.where(small, 1.0 - th2 / 6.0 + th2 * th2 / 120.0, np.sin(th) / th)
    b = np.where(small, 0.5 - th2 / 24.0 + th2 * th2 / 720.0, (1.0 - np.cos(th)) / (th * th))
    # [phi]x^2 = phi phi^T - |phi|^2 I
    out = b[..., None, None] * (phi[..., :, None] * phi[..., None, :])
    out += a[..., None, None] * hat(phi)
    d = 1.0 - b * th2
    out[..., 0, 0] += d
    out[..., 1, 1] += d
    out[..., 2, 2] += d
    return out


def logm_so3(R: np.ndarray) -> np.ndarray:
    """Logarithm map ``SO(3) -> so(3)`` as a rotation vector [rad] (robust near 0 and pi)."""
    R = np.asarray(R, dtype=float)
    q = rot_to_quat(R)
    w = np.clip(q[..., 0], -1.0, 1.0)
    v = q[..., 1:]
    s = np.sqrt(np.sum(v * v, axis=-1))
    angle = 2.0 * np.arctan2(s, w)
    small = s < _SMALL
    scale = np.where(small, 2.0 / np.where(small, np.maximum(w, _SMALL), 1.0),
                     angle / np.where(small, 1.0, s))
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
    q0 = np.stack((0.25 * s0, (R[..., 2, 1] - R[..., 1, 2]) / s0,
                   (R[..., 0, 2] - R[..., 2, 0]) / s0, (R[..., 1, 0] - R[..., 0, 1]) / s0), -1)
    s1 = np.sqrt(np.maximum(1.0 + m00 - m11 - m22, 1e-300)) * 2.0
    q1 = np.stack(((R[..., 2, 1] - R[..., 1, 2]) / s1, 0.25 * s1,
                   (R[..., 0, 1] + R[..., 1, 0]) / s1, (R[..., 0, 2] + R[..., 2, 0]) / s1), -1)
    s2 = np.sqrt(np.maximum(1.0 + m11 - m00 - m22, 1e-300)) * 2.0
    q2 = np.stack(((R[..., 0, 2] - R[..., 2, 0]) / s2, (R[..., 0, 1] + R[..., 1, 0]) / s2,
                   0.25 * s2, (R[..., 1, 2] + R[..., 2, 1]) / s2), -1)
    s3 = np.sqrt(np.maximum(1.0 + m22 - m00 - m11, 1e-300)) * 2.0
    q3 = np.stack(((R[..., 1, 0] - R[..., 0, 1]) / s3, (R[..., 0, 2] + R[..., 2, 0]) / s3,
                   (R[..., 1, 2] + R[..., 2, 1]) / s3, 0.25 * s3), -1)
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


def dcm_orthonormalize_reference(R: np.ndarray) -> np.ndarray:
    """The reference code's first-order DCM renormalisation ("Direction Cosine Matrix IMU").

    Used only by the ``reference`` integrator, to reproduce the authors' step exactly.
    """
    x, y = R[0], R[1]
    err = float(x @ y)
    xo = x - 0.5 * err * y
    yo = y - 0.5 * err * x
    zo = np.cross(xo, yo)
    return np.stack((0.5 * (3 - xo @ xo) * xo, 0.5 * (3 - yo @ yo) * yo, 0.5 * (3 - zo @ zo) * zo))


def rotation_angle(R: np.ndarray) -> np.ndarray:
    """Angle [rad] of a rotation matrix, robust near 0 and pi."""
    return np.linalg.norm(logm_so3(R), axis=-1)


def euler_zyx_to_rot(roll, pitch, yaw) -> np.ndarray:
    """Rotation matrix from Z-Y-X (yaw, pitch, roll) Euler angles [rad], body->world."""
    roll, pitch, yaw = (np.asarray(a, dtype=float) for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
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
