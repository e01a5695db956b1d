"""The EKF's predict and update in readable numpy form: the test oracle of the compiled
filter (:mod:`estimators.ekf_filter`). Textbook forms: the dense transition Jacobian ``F``,
``P = F P F^T + Q`` and the Joseph-form covariance update."""

from __future__ import annotations

import math

import numpy as np

from quadfault.model.dynamics import angular_acceleration, translational_acceleration
from quadfault.model.rotation import expm_so3, hat, logm_so3, orthonormalize
from quadfault.model.vehicle import Vehicle

#: Sample period the per-step noise values refer to [s] (the reference's 1 kHz).
NOISE_REFERENCE_DT = 1e-3
P_, V_, W_, R_, ETA_ = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 18), 18
#: vec(R) entries of the third column R e3 (column-major vec).
R_E3 = slice(15, 18)


def right_jacobian_so3(phi: np.ndarray) -> np.ndarray:
    """Right Jacobian of SO(3): ``exp(phi + d) ~= exp(phi) exp(Jr(phi) d)``."""
    th2 = float(phi @ phi)
    K = hat(phi)
    if th2 < 1e-8:
        a, b = 0.5 - th2 / 24.0, 1.0 / 6.0 - th2 / 120.0
    else:
        th = math.sqrt(th2)
        a, b = (1.0 - math.cos(th)) / th2, (th - math.sin(th)) / (th2 * th)
    return np.eye(3) - a * K + b * (K @ K)


def attitude_jacobian(R_meas: np.ndarray) -> np.ndarray:
    """``(3, 9)`` Jacobian ``H_R = -d vee(skew(R^T R_meas)) / d vec(R)`` (column-major vec).

    ``vee(skew(R^T R_m))`` equals ``log(R^T R_m)`` to first order, so this is the measurement
    Jacobian of the rotation-error innovation; it does not depend on the estimate and is
    well-defined at zero error (unlike the reference's ``d acos / d vec(R)``).
    """
    H = np.zeros((3, 9))
    for k, a, b in ((0, 2, 1), (1, 0, 2), (2, 1, 0)):  # g_k = (A_ab - A_ba) / 2, A = R^T R_m
        H[k, 3 * a : 3 * a + 3] -= 0.5 * R_meas[:, b]
        H[k, 3 * b : 3 * b + 3] += 0.5 * R_meas[:, a]
    return H


def predict(
    x: np.ndarray, P: np.ndarray, f: np.ndarray, dt: float, vehicle: Vehicle, Q: np.ndarray
):
    """EKF time update over ``dt`` [s] with rotor commands ``f`` [N] held.

    Returns ``(x_pred, P_pred, F)``. Mean: eqs. (1)-(4) discretised as
    ``v+ = v + a dt``, ``p+ = p + v dt + a dt^2/2``, ``Omega+ = Omega + Omega' dt``,
    ``R+ = R exp([phi]x)`` with ``phi = (Omega + Omega+) dt / 2``.
    """
    n = f.shape[0]
    p, v, w = x[P_], x[V_], x[W_]
    R = x[R_].reshape(3, 3, order="F")
    eta = x[ETA_:]
    A = vehicle.allocation
    m, Jinv = vehicle.mass, vehicle.inertia_inverse
    wrench = A @ (eta * f)  # eq. (12) with efficiency: [T; M] = A diag(eta) f
    a = translational_acceleration(R, wrench[0], vehicle)  # eq. (2)
    wdot = angular_acceleration(w, wrench[1:], vehicle)  # eq. (4)
    phi = w * dt + 0.5 * wdot * dt * dt
    E = expm_so3(phi)
    R_new = R @ E  # eq. (3), exponential map
    x_pred = np.concatenate(
        (
            p + v * dt + 0.5 * a * dt * dt,
            v + a * dt,
            w + wdot * dt,
            R_new.reshape(9, order="F"),
            eta,
        )
    )
    # Jacobian F = d x_pred / d x
    J = vehicle.inertia
    b3 = R[:, 2]
    dT = A[0] * f  # d T / d eta
    B = Jinv @ (A[1:] * f)  # d Omega' / d eta
    G = Jinv @ (hat(J @ w) - hat(w) @ J)  # d Omega' / d Omega (gyroscopic term of eq. 4)
    F = np.eye(18 + n)
    F[P_, V_] = dt * np.eye(3)
    F[P_, R_E3] = -(wrench[0] / m) * 0.5 * dt * dt * np.eye(3)
    F[P_, ETA_:] = -np.outer(b3, dT) * (0.5 * dt * dt / m)
    F[V_, R_E3] = -(wrench[0] / m) * dt * np.eye(3)
    F[V_, ETA_:] = -np.outer(b3, dT) * (dt / m)
    F[W_, W_] += dt * G
    F[W_, ETA_:] = dt * B
    F[R_, R_] = np.kron(E.T, np.eye(3))  # vec(R E) = (E^T kron I) vec(R)
    RE, Jr = R_new, right_jacobian_so3(phi)
    dR_dphi = np.stack([(RE @ hat(Jr[:, i])).reshape(9, order="F") for i in range(3)], axis=1)
    F[R_, W_] = dR_dphi @ (dt * np.eye(3) + 0.5 * dt * dt * G)
    F[R_, ETA_:] = dR_dphi @ (0.5 * dt * dt * B)
    P_pred = F @ P @ F.T + Q
    return x_pred, P_pred, F


def kalman_update(x: np.ndarray, P: np.ndarray, y: np.ndarray, H: np.ndarray, R: np.ndarray):
    """Measurement update with innovation ``y``, Jacobian ``H`` and noise ``R``.

    ``S = H P H^T + R``, ``K = P H^T S^-1`` (by ``solve``), ``x+ = x + K y`` and the Joseph
    form ``P+ = (I - K H) P (I - K H)^T + K R K^T``, symmetric and positive semi-definite
    even when ``K`` is not exactly optimal.
    """
    S = H @ P @ H.T + R
    K = np.linalg.solve(S, H @ P).T  # P, S symmetric: (S^-1 H P)^T = P H^T S^-1
    IKH = np.eye(P.shape[0]) - K @ H
    P_new = IKH @ P @ IKH.T + K @ R @ K.T
    return x + K @ y, 0.5 * (P_new + P_new.T)


def measurement_update(
    x: np.ndarray, P: np.ndarray, sample, r_diag: np.ndarray, bounds, accel=None
):
    """Update with the measured ``p, v, Omega`` and attitude (``r_diag``: their 12 variances;
    more entries are ignored) and, when ``accel = (a_z, h, var)`` is given, the
    accelerometer's body-z specific force ``a_z = h . eta`` of variance ``var``; project R,
    clamp eta."""
    n = x.shape[0]
    R_est = x[R_].reshape(3, 3, order="F")
    y = np.concatenate(
        (sample.p - x[P_], sample.v - x[V_], sample.w - x[W_], logm_so3(R_est.T @ sample.R))
    )
    H = np.zeros((12, n))
    H[:9, :9] = np.eye(9)
    H[9:, R_] = attitude_jacobian(sample.R)
    r = np.asarray(r_diag, dtype=float)[:12]
    if accel is not None:
        a_z, h, var = accel
        row = np.zeros((1, n))
        row[0, ETA_:] = h
        y = np.append(y, a_z - h @ x[ETA_:])
        H = np.vstack((H, row))
        r = np.append(r, var)
    x, P = kalman_update(x, P, y, H, np.diag(r))
    x[R_] = orthonormalize(x[R_].reshape(3, 3, order="F")).reshape(9, order="F")
    if bounds is not None:
        x[ETA_:] = np.clip(x[ETA_:], bounds[0], bounds[1])
    return x, P
