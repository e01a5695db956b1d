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
quadratic ``c_i + 2 b_i . eta + eta^T H_i eta`` with ``c = r0^T G r0``, ``b = J^T G r0``,
``H = J^T G J`` (eq. 26), which is all the window solver needs.

**Prefilter** (beyond the paper, :func:`prefilter_into`). With sensor noise, one segment's
residual differences two noisy samples 1 ms apart: white velocity noise of 5 mm/s alone puts
7 m/s^2 of noise on a thrust whose signal is about 10 m/s^2, and the same holds for the rate
rows. Because the residual is affine in ``eta``, the same causal low-pass filter applied to
both sides of the regression, to ``r0`` and to ``J``, keeps it exact for a constant ``eta``
(``r_f(eta) = r0_f + J_f eta``) while it removes the differenced noise: a first-order filter
of time constant ``tau``, ``x_f <- a x_f + (1 - a) x`` with ``a = exp(-dt / tau)`` per
segment, cuts the noise of a differenced white stream by about ``dt / tau`` and delays a
change by about ``tau``. ``tau = 0`` is the paper's residual, bit for bit.

Row order of a segment's residual (:data:`RESIDUAL`, ``RESIDUAL_ROWS`` = 10): v (3), x (3),
Omega (3), R (1).

:func:`segment_terms_into` is the model, plain Python compiled by :func:`quadfault.jit.jit`
with 3 x 3 algebra on scalars and no allocation (the estimator calls it once per new sample);
:func:`segment_terms` evaluates it over arrays of samples.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from estimators.state import fields, pack
from quadfault.jit import jit
from quadfault.model.dynamics import rotor_wrench
from quadfault.model.vehicle import Vehicle

#: the rows of a segment's residual: velocity, position, rate, rotation
RESIDUAL = fields("ResidualRows", ("v", 3), ("x", 3), ("w", 3), "R")
RESIDUAL_ROWS = RESIDUAL.size


def residual_weights(g_v: float, g_x: float, g_omega: float, g_R: float) -> np.ndarray:
    """Diagonal of the per-segment weight matrix G_i (eq. 23), shape (10,)."""
    return pack(RESIDUAL, v=np.full(3, g_v), x=np.full(3, g_x), w=np.full(3, g_omega), R=g_R)


class Kinematics(NamedTuple):
    """One sample's measured kinematics: position ``p`` [m] and velocity ``v`` [m/s] (3,)
    in the world frame, attitude ``R`` (3, 3) body to world, body rate ``w`` [rad/s] (3,)."""

    p: np.ndarray
    v: np.ndarray
    R: np.ndarray
    w: np.ndarray


class SegmentModel(NamedTuple):
    """What a segment's residual needs of the vehicle: ``mass`` [kg], gravity ``g``
    [m/s^2], inertia ``Jmat`` and its inverse ``Jinv`` (3, 3) [kg m^2], allocation ``A``
    (4, n); and ``G`` (10,), the diagonal of the residual's weight (eq. 23)."""

    mass: float
    g: float
    Jmat: np.ndarray
    Jinv: np.ndarray
    A: np.ndarray
    G: np.ndarray


class SegmentOut(NamedTuple):
    """Where :func:`segment_terms_into` writes: the affine residual model ``r0`` (10,),
    ``J`` (10, n) and the weighted-energy terms ``b`` (n,), ``H`` (n, n)."""

    r0: np.ndarray
    J: np.ndarray
    b: np.ndarray
    H: np.ndarray


@jit(inner=True)
def segment_terms_into(dt, s0, s1, f, model, out):
    """The segment from sample ``s0`` to sample ``s1`` (:class:`Kinematics`, ``dt`` [s]
    apart, command ``f`` [N] held) under ``model`` (:class:`SegmentModel`): its affine
    residual model ``r(eta) = r0 + J eta`` and its weighted-energy terms into ``out``
    (:class:`SegmentOut`); returns ``(c, thrust)``, the energy at ``eta = 0`` and the
    commanded collective thrust [N]."""
    thrust = segment_model_into(dt, s0, s1, f, model, out.r0, out.J)
    return energy_terms_into(out.r0, out.J, model.G, out.b, out.H), thrust


@jit(inner=True)
def segment_model_into(dt, s0, s1, f, model, r0, J):
    """The affine residual model ``r(eta) = r0 + J eta`` of the segment from sample ``s0``
    to sample ``s1`` (:class:`Kinematics`, ``dt`` [s] apart, command ``f`` [N] held) under
    ``model`` (:class:`SegmentModel`) into ``r0`` (10,) and ``J`` (10, n); returns the
    commanded collective thrust [N]."""
    p0, v0, R0, w0 = s0.p, s0.v, s0.R, s0.w
    p1, v1, R1, w1 = s1.p, s1.v, s1.R, s1.w
    mass, g, Jmat, Jinv, A = model.mass, model.g, model.Jmat, model.Jinv, model.A
    n = f.size
    V, X, W, RR = RESIDUAL.v, RESIDUAL.x, RESIDUAL.w, RESIDUAL.R
    thrust, _moment = rotor_wrench(A, f)  # the collective thrust (eq. 12)
    # velocity / position (eqs. 13, 14, 17, 18)
    for a in range(3):
        ge = g if a == 2 else 0.0
        r0[V + a] = v1[a] - v0[a] - ge * dt
        r0[X + a] = p1[a] - p0[a] - v0[a] * dt - ge * 0.5 * dt * dt
        for j in range(n):
            dv = R0[a, 2] * f[j] * A[0, j] / mass
            J[V + a, j] = dv * dt
            J[X + a, j] = dv * (0.5 * dt * dt)
    # rate (eqs. 15, 19): gyro = W x (J W), W_hat0 = W - J^-1 gyro dt
    jw0 = Jmat[0, 0] * w0[0] + Jmat[0, 1] * w0[1] + Jmat[0, 2] * w0[2]
    jw1 = Jmat[1, 0] * w0[0] + Jmat[1, 1] * w0[1] + Jmat[1, 2] * w0[2]
    jw2 = Jmat[2, 0] * w0[0] + Jmat[2, 1] * w0[1] + Jmat[2, 2] * w0[2]
    gy0 = w0[1] * jw2 - w0[2] * jw1
    gy1 = w0[2] * jw0 - w0[0] * jw2
    gy2 = w0[0] * jw1 - w0[1] * jw0
    wh0 = w0[0] - (Jinv[0, 0] * gy0 + Jinv[0, 1] * gy1 + Jinv[0, 2] * gy2) * dt
    wh1 = w0[1] - (Jinv[1, 0] * gy0 + Jinv[1, 1] * gy1 + Jinv[1, 2] * gy2) * dt
    wh2 = w0[2] - (Jinv[2, 0] * gy0 + Jinv[2, 1] * gy1 + Jinv[2, 2] * gy2) * dt
    r0[W] = w1[0] - wh0
    r0[W + 1] = w1[1] - wh1
    r0[W + 2] = w1[2] - wh2
    for a in range(3):
        for j in range(n):
            ja = 0.0
            for k in range(3):
                ja += Jinv[a, k] * A[1 + k, j]
            J[W + a, j] = -ja * f[j] * dt
    # rotation (eqs. 20-22): r_R = 1/2 (3 - tr dR) - dt vee(dR) . W_hat, dR = R0^T R1
    d00 = R0[0, 0] * R1[0, 0] + R0[1, 0] * R1[1, 0] + R0[2, 0] * R1[2, 0]
    d11 = R0[0, 1] * R1[0, 1] + R0[1, 1] * R1[1, 1] + R0[2, 1] * R1[2, 1]
    d22 = R0[0, 2] * R1[0, 2] + R0[1, 2] * R1[1, 2] + R0[2, 2] * R1[2, 2]
    d21 = R0[0, 2] * R1[0, 1] + R0[1, 2] * R1[1, 1] + R0[2, 2] * R1[2, 1]
    d12 = R0[0, 1] * R1[0, 2] + R0[1, 1] * R1[1, 2] + R0[2, 1] * R1[2, 2]
    d02 = R0[0, 0] * R1[0, 2] + R0[1, 0] * R1[1, 2] + R0[2, 0] * R1[2, 2]
    d20 = R0[0, 2] * R1[0, 0] + R0[1, 2] * R1[1, 0] + R0[2, 2] * R1[2, 0]
    d10 = R0[0, 1] * R1[0, 0] + R0[1, 1] * R1[1, 0] + R0[2, 1] * R1[2, 0]
    d01 = R0[0, 0] * R1[0, 1] + R0[1, 0] * R1[1, 1] + R0[2, 0] * R1[2, 1]
    u0 = 0.5 * (d21 - d12) * dt
    u1 = 0.5 * (d02 - d20) * dt
    u2 = 0.5 * (d10 - d01) * dt
    r0[RR] = 0.5 * (3.0 - (d00 + d11 + d22)) - (u0 * wh0 + u1 * wh1 + u2 * wh2)
    for j in range(n):
        J[RR, j] = u0 * J[W, j] + u1 * J[W + 1, j] + u2 * J[W + 2, j]
    return thrust


@jit(inner=True)
def energy_terms_into(r0, J, G, b, H):
    """The weighted energy ``e(eta) = c + 2 b . eta + eta^T H eta`` of the residual model
    ``r(eta) = r0 + J eta`` under the weights ``G`` (10,) (eq. 26): fills ``b`` (n,), ``H``
    (n, n); returns ``c``."""
    n = b.shape[0]
    c = 0.0
    for j in range(n):
        b[j] = 0.0
        for k in range(n):
            H[j, k] = 0.0
    for r in range(RESIDUAL_ROWS):
        c += r0[r] * G[r] * r0[r]
        for j in range(n):
            gj = G[r] * J[r, j]
            b[j] += gj * r0[r]
            for k in range(n):
                H[j, k] += gj * J[r, k]
    return c


@jit(inner=True)
def prefilter_into(r0, J, r0f, Jf, a, fresh):
    """The prefilter of the residual model (module docstring): ``r0f <- a r0f + (1 - a) r0``
    and ``Jf <- a Jf + (1 - a) J`` (``fresh``: start the filter at ``r0``, ``J``), then the
    filtered model written back into ``r0``, ``J``; ``a = exp(-dt / tau)`` [1]."""
    b = 0.0 if fresh else a
    for r in range(r0.shape[0]):
        r0f[r] = b * r0f[r] + (1.0 - b) * r0[r]
        r0[r] = r0f[r]
        for j in range(J.shape[1]):
            Jf[r, j] = b * Jf[r, j] + (1.0 - b) * J[r, j]
            J[r, j] = Jf[r, j]


@dataclass(frozen=True)
class SegmentTerms:
    """The segments between consecutive samples (:func:`segment_terms`).

    Attributes:
        r0: residuals at ``eta = 0``, (S, 10) [m/s, m, rad/s, 1]; J: Jacobians (S, 10, n),
            so ``r_k(eta) = r0[k] + J[k] @ eta``.
        c, b, H: weighted-energy terms (S,), (S, n), (S, n, n) (eq. 26).
        dt: segment durations [s] (S,); thrust: commanded collective thrust [N] (S,).
    """

    r0: np.ndarray
    J: np.ndarray
    c: np.ndarray
    b: np.ndarray
    H: np.ndarray
    dt: np.ndarray
    thrust: np.ndarray

    def residuals(self, eta) -> np.ndarray:
        """``(S, 10)`` residuals at efficiency ``eta`` (n,)."""
        return self.r0 + self.J @ np.asarray(eta, dtype=float)


def segment_terms(vehicle: Vehicle, t, p, v, R, w, f, G) -> SegmentTerms:
    """:func:`segment_terms_into` for the ``N - 1`` segments of ``N`` samples: times ``t``
    (N,) [s], positions / velocities ``p``, ``v`` (N, 3) world NED, attitudes ``R``
    (N, 3, 3) body to world, rates ``w`` (N, 3) [rad/s], commands ``f`` (N, n) [N]
    (segment k uses samples k, k + 1 and command ``f[k]``) and weights ``G`` (10,)."""
    t = np.asarray(t, dtype=float)
    p, v, w, f = (np.ascontiguousarray(a, dtype=float) for a in (p, v, w, f))
    R = np.ascontiguousarray(R, dtype=float)
    G = np.ascontiguousarray(G, dtype=float)
    S, n = len(t) - 1, f.shape[1]
    r0, J = np.empty((S, RESIDUAL_ROWS)), np.empty((S, RESIDUAL_ROWS, n))
    c, b, H, thrust = np.empty(S), np.empty((S, n)), np.empty((S, n, n)), np.empty(S)
    model = SegmentModel(
        float(vehicle.mass),
        float(vehicle.gravity),
        np.ascontiguousarray(vehicle.inertia, dtype=float),
        np.ascontiguousarray(vehicle.inertia_inverse, dtype=float),
        np.ascontiguousarray(vehicle.allocation, dtype=float),
        G,
    )
    for k in range(S):
        c[k], thrust[k] = segment_terms_into(
            t[k + 1] - t[k],
            Kinematics(p[k], v[k], R[k], w[k]),
            Kinematics(p[k + 1], v[k + 1], R[k + 1], w[k + 1]),
            f[k],
            model,
            SegmentOut(r0[k], J[k], b[k], H[k]),
        )
    return SegmentTerms(r0, J, c, b, H, np.diff(t), thrust)
