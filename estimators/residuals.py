"""Trajectory residuals of the sliding-window IRLS estimator (paper eqs. 17-22).

A *segment* is the transition from sample i to sample i+1. The estimator predicts the state
at i+1 from the state at i and the commanded rotor thrusts ``f_i`` (held from ``t_i`` to
``t_{i+1}``) scaled by the unknown efficiencies ``eta``, and compares the prediction with the
measurement. Per segment, with ``dt = t_{i+1} - t_i`` (each segment its own, so non-uniform
logs work) and the wrench ``[T; M] = A diag(f_i) eta`` through the vehicle's allocation ``A``::

    a_i        = g e3 - T R_i e3 / m
    r_v        = v_{i+1} - (v_i + a_i dt)                              (eq. 17, pred. eq. 13)
    r_x        = p_{i+1} - (p_i + v_i dt + a_i dt^2 / 2)               (eq. 18, pred. eq. 14)
    W_hat      = W_i + J^-1 (M - W_i x J W_i) dt                      (eq. 15)
    r_W        = W_{i+1} - W_hat                                       (eq. 19)
    dR         = R_i^T R_{i+1}                                         (eq. 20)
    dR_hat     = I + [W_hat]x dt      (the reference code's predicted rate at i+1, eq. 21)
    r_R        = 1/2 tr(I - dR^T dR_hat)                               (eq. 22)

Every residual is *affine* in ``eta``: ``r(eta) = r0 + J eta``. For the rotation residual this
follows from ``tr(dR^T [w]x) = 2 w . vee(dR)`` (``vee`` of the antisymmetric part), so
``r_R = 1/2 (3 - tr dR) - dt vee(dR) . W_hat``; the Jacobian row equals the reference code's
analytic ``(dt^2/2) [...]`` row for the paper's layout. The Jacobian is therefore constant per
window (computed once), and per segment the weighted energy ``e_i(eta) = r_i^T G_i r_i`` is a
quadratic ``c_i + 2 b_i . eta + eta^T H_i eta`` (:func:`quadratic_terms`), which is all the
window solver needs.

Row order of a segment's residual (``RESIDUAL_ROWS`` = 10): v (3), x (3), Omega (3), R (1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadfault.dynamics import E3
from quadfault.rotation import cross, vee
from quadfault.vehicle import Vehicle

RESIDUAL_ROWS = 10


@dataclass(frozen=True)
class SegmentModels:
    """Affine residual models of consecutive segments: ``r_k(eta) = r0[k] + J[k] @ eta``.

    Attributes:
        r0: residuals at ``eta = 0``, shape (S, 10) [m/s, m, rad/s, 1].
        J: constant Jacobians d r / d eta, shape (S, 10, n).
        dt: segment durations [s], shape (S,).
        thrust: commanded collective thrust of each segment [N], shape (S,).
    """

    r0: np.ndarray
    J: np.ndarray
    dt: np.ndarray
    thrust: np.ndarray

    def __len__(self) -> int:
        return len(self.dt)

    def residuals(self, eta) -> np.ndarray:
        """``(S, 10)`` residuals at efficiency ``eta`` (n,)."""
        return self.r0 + self.J @ np.asarray(eta, dtype=float)

    def window(self, start: int, stop: int) -> "SegmentModels":
        sl = slice(start, stop)
        return SegmentModels(self.r0[sl], self.J[sl], self.dt[sl], self.thrust[sl])


def segment_models(vehicle: Vehicle, t, p, v, R, w, f) -> SegmentModels:
    """Residual models of the segments between consecutive samples (vectorised).

    Args:
        vehicle: the nominal vehicle (mass, inertia, allocation, gravity).
        t: (N,) sample times [s]; p, v: (N, 3) world NED [m], [m/s]; R: (N, 3, 3) body->world;
        w: (N, 3) body rate [rad/s]; f: (N, n) commanded rotor thrusts [N].

    Returns:
        the ``N - 1`` segment models (segment k uses samples k and k+1 and command ``f[k]``).
    """
    t = np.asarray(t, dtype=float)
    p, v, R, w, f = (np.asarray(a, dtype=float) for a in (p, v, R, w, f))
    dt = np.diff(t)
    m, g = vehicle.mass, vehicle.gravity
    A = vehicle.allocation
    Jmat, Jinv = vehicle.inertia, vehicle.inertia_inverse
    S, n = len(dt), f.shape[1]
    Ri, fi, wi = R[:-1], f[:-1], w[:-1]
    dtc = dt[:, None]
    b3 = Ri[:, :, 2]  # R_i e3
    thrust_gain = fi * A[0]  # dT / d eta_j  (S, n)
    r0 = np.empty((S, RESIDUAL_ROWS))
    J = np.empty((S, RESIDUAL_ROWS, n))
    # velocity and position (eqs. 13, 14, 17, 18): a = g e3 - T R e3 / m
    r0[:, 0:3] = v[1:] - v[:-1] - g * E3 * dtc
    r0[:, 3:6] = p[1:] - p[:-1] - v[:-1] * dtc - g * E3 * (0.5 * dtc**2)
    dv = b3[:, :, None] * thrust_gain[:, None, :] / m  # -(d a / d eta)  (S, 3, n)
    J[:, 0:3] = dv * dt[:, None, None]
    J[:, 3:6] = dv * (0.5 * dt**2)[:, None, None]
    # angular rate (eqs. 15, 19): W_hat = W + J^-1 (M - W x J W) dt
    gyro = cross(wi, wi @ Jmat.T) @ Jinv.T
    w_hat0 = wi - gyro * dtc  # predicted rate at eta = 0
    # d W_hat / d eta = dt J^-1 A_M diag(f_i)  (S, 3, n), A_M = moment rows of the allocation
    dw = (Jinv @ A[1:4])[None] * (fi * dtc)[:, None, :]
    r0[:, 6:9] = w[1:] - w_hat0
    J[:, 6:9] = -dw
    # rotation (eqs. 20-22): r_R = 1/2 (3 - tr dR) - dt vee(dR) . W_hat
    dR = np.einsum("sji,sjk->sik", Ri, R[1:])
    u = vee(dR) * dtc
    r0[:, 9] = 0.5 * (3.0 - np.trace(dR, axis1=1, axis2=2)) - np.einsum("si,si->s", u, w_hat0)
    J[:, 9] = -np.einsum("si,sij->sj", u, dw)
    return SegmentModels(r0, J, dt, fi @ A[0])


def residual_weights(g_v: float, g_x: float, g_omega: float, g_R: float) -> np.ndarray:
    """Diagonal of the per-segment weight matrix G_i (eq. 23), shape (10,)."""
    return np.array([g_v] * 3 + [g_x] * 3 + [g_omega] * 3 + [g_R], dtype=float)


def quadratic_terms(models: SegmentModels, G_diag) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-segment quadratic form of the weighted energy (eq. 26).

    ``e_k(eta) = r_k^T G r_k = c[k] + 2 b[k] . eta + eta^T H[k] eta`` with
    ``c = r0^T G r0``, ``b = J^T G r0`` and ``H = J^T G J``.

    Returns:
        ``c`` (S,), ``b`` (S, n), ``H`` (S, n, n).
    """
    G = np.asarray(G_diag, dtype=float)
    GJ = models.J * G[None, :, None]
    c = np.einsum("si,i,si->s", models.r0, G, models.r0)
    b = np.einsum("sin,si->sn", GJ, models.r0)
    H = np.einsum("sin,sim->snm", models.J, GJ)
    return c, b, H
