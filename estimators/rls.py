"""Recursive least squares with a forgetting factor (RLS), the estimator INDI controllers fly.

The regression is the IRLS's (:mod:`estimators.residuals`, paper eqs. 13-19): the segment from
sample k-1 to sample k, its command ``f`` held over ``dt_k``, has the residual
``r_k(eta) = r0_k + J_k eta``, affine in the efficiencies. RLS uses its velocity rows (the
thrust, eq. 17) and its rate rows (the moments, eq. 19): ``y = -r0``, regressor rows
``phi_r^T = J_k[r]``, and fits the ``eta`` minimising the exponentially forgotten weighted sum
of squares ``sum_i lambda^((t_k - t_i) / 1 ms) sum_r g_r (y_r - phi_r^T eta)^2``. One update
per sample is the textbook covariance form (Ljung), the rows taken one at a time::

    lambda_k = lambda^(dt_k / 1 ms)                    (per 1 ms step, so any rate works)
    P  <- P / lambda_k
    for each row r:
        g_r = 1 / sum_j c_rj^2,   c_rj = J_k[r, j] / f_j   (row r's sensitivity to rotor j's thrust)
        e   = y_r - phi_r^T theta
        k   = P phi_r / (1 / g_r + phi_r^T P phi_r)
        theta <- theta + k e
        P   <- P - k phi_r^T P

The weight ``g_r`` is the inverse of the variance a unit, independent noise on every rotor's
thrust puts on row r: the rows are in the units of the actuator noise, so the yaw-rate row
(whose signal and noise both scale with the small torque coefficient) counts as much as the
roll row. With the IRLS's fixed weights instead, the yaw-differential direction is so weakly
determined that, after an abrupt fault, the forgotten fit over data before and after it
swings far outside both (docs/rls.md). The position and rotation rows carry the same
noise draws as the velocity and rate rows and are left out.

Against sensor noise (``RLSConfig.prefilter``, on by default, 10 ms): the segment's residual
model is low-passed on both sides before the update (:func:`estimators.residuals.prefilter_into`;
the weights ``g_r`` still come from the segment's own rows), and the three velocity rows
share one weight, ``1 / sum_(rows, j) c_rj^2``, so that noise on the measured attitude, which
is most of a horizontal row's regressor at a small tilt, does not bias the fit low.

The reported estimate is ``theta`` projected onto ``eta_bounds`` after each update (as the
EKF's clamp, ``[-0.001, 1.2]``). The one-sigma ``sd`` is ``sqrt(diag(P) s2)``, ``s2`` the forgotten mean of the
weighted a-priori residual energy per row: the least-squares covariance with the noise scale
estimated from the data.

State (n rotors): ``theta`` (n), ``P`` (n x n), the noise scale and the previous sample (time,
p, v, Omega, R, clipped command): no window and no kinematic states.

Online rules, as the other estimators: a non-finite sample or a time that does not increase is
``bad_sample`` and the next good sample starts afresh (no segment across the gap; the estimate
and ``P`` are kept); the first sample is ``warmup``; a segment whose command has an idle rotor
(``<= IDLE_THRUST``) carries no information on it: the update and the forgetting are skipped
(``no_excitation``, so ``P`` does not wind up while the motors are off); commands are clipped
to ``[0, rotor_max_thrust]`` (``run`` lifts the upper clip for an unsaturated flight,
:func:`estimators.base.command_limit`).

The step is :func:`rls_step` (plain Python compiled by :func:`quadfault.jit.jit`) on one row of a
flat state; :class:`RecursiveLeastSquares`, its offline ``run`` and :class:`BatchedRLS` (the
vector environment's) all run it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from estimators.accelerometer import accelerometer_rows, check_mode, repeats
from estimators.base import (
    BAD_SAMPLE,
    NO_EXCITATION,
    OK,
    WARMUP,
)
from estimators.ekf import IDLE_THRUST
from estimators.freshness import N_COUNTERS as N_FRESH_COUNTERS
from estimators.freshness import (
    N_TIMES,
    fresh_rows_into,
    fresh_streams,
    prefilter_fresh_into,
    restart_into,
)
from estimators.options import (
    check_bounds,
    check_fraction,
    check_positive,
    check_prefilter,
    from_options,
)
from estimators.recursive import BatchedRecursive, RecursiveEstimator, _Kernels
from estimators.residuals import (
    RESIDUAL,
    RESIDUAL_ROWS,
    Kinematics,
    SegmentModel,
    segment_model_into,
)
from estimators.state import Layout, all_finite, fields, pack, piece, piece_rows
from quadfault.jit import jit, prange
from quadfault.model.vehicle import Vehicle

#: the sample period the forgetting factor refers to [s]
FORGETTING_REFERENCE_DT = 1e-3


@dataclass(frozen=True)
class RLSConfig:
    """RLS settings.

    Attributes:
        forgetting: the forgetting factor lambda per 1 ms step, in (0, 1]; the memory is about
            ``1 ms / (1 - lambda)`` (0.99: 0.1 s). The tuning knob (``--forgetting``).
        p0: initial covariance ``p0 * I`` [1].
        eta0: initial efficiency (one value, or one per rotor).
        eta_bounds: the box the estimate is projected onto (None: no projection); up to
            1.2 as the EKF's clamp (a projection at 1 biases the healthy rotors low).
        clip_commands: clip the commanded thrusts to ``[0, rotor_max_thrust]`` (as IRLS).
        prefilter: the time constant [s] of the low-pass filter applied to both sides of the
            regression, the residual ``r0`` and its rows ``J`` (as ``IRLSConfig.prefilter``,
            :func:`estimators.residuals.prefilter_into`; 0 = off, the textbook RLS): sensor
            noise differenced over one sample falls by about ``dt / prefilter``. With it on,
            the three velocity rows share one weight, that of the thrust along any axis
            (velocity noise is the same along every axis; the per-row weights would trust
            the horizontal rows most where their regressor, the tilt, is mostly attitude
            noise, and bias the estimate low).
        accelerometer: where the thrust (velocity) rows come from
            (:mod:`estimators.accelerometer`, as ``IRLSConfig.accelerometer``): ``"off"``
            the differenced velocity, ``"auto"`` the accelerometer's specific force wherever
            a sample has it, ``"on"`` the same, and data without one is said once.
    """

    forgetting: float = 0.99
    p0: float = 1.0
    eta0: float | tuple = 1.0
    eta_bounds: tuple | None = (-0.001, 1.2)
    clip_commands: bool = True
    prefilter: float = 0.01
    accelerometer: str = "off"

    def __post_init__(self):
        object.__setattr__(self, "accelerometer", check_mode("RLSConfig", self.accelerometer))
        check_fraction(self, "forgetting")
        check_positive(self, "p0")
        check_bounds("RLSConfig", self.eta_bounds)
        check_prefilter("RLSConfig", self.prefilter)

    @classmethod
    def from_options(
        cls,
        forgetting: float | None = None,
        prefilter: float | None = None,
        accelerometer: str | bool | None = None,
    ) -> RLSConfig:
        """The configuration of ``quadfault estimate --estimator rls [--forgetting L]
        [--prefilter TAU] [--accelerometer MODE]``."""
        return from_options(
            cls, forgetting=forgetting, prefilter=prefilter, accelerometer=accelerometer
        )

    def replace(self, **changes) -> RLSConfig:
        return replace(self, **changes)


#: the residual rows RLS fits (:data:`estimators.residuals.RESIDUAL`): velocity, then rate
ROWS = tuple(RESIDUAL.v + a for a in range(3)) + tuple(RESIDUAL.w + a for a in range(3))
N_ROWS = len(ROWS)

#: rows of the previous sample's piece (3 columns): p, v, Omega, the accelerometer reading
#: (NaN: none), then R (3 rows)
SAMPLE_ROWS = fields("RLSSampleRows", "p", "v", "w", "a", ("R", 3))
#: the noise scale: the forgotten mean of the weighted residual energy per row, and the
#: forgotten sample count it is the mean of
NOISE = fields("RLSNoise", "mean", "count")
#: the float state of one filter (dimension: rotors ``n``): the estimate ``theta`` and its
#: covariance ``P``, the previous sample's time, its p, v, Omega, R and (clipped) command,
#: the initial efficiency, the noise scale, scratch of one update (the segment's residual
#: model ``r0``, ``J`` of :func:`segment_model_into`), the prefilter's state ``r0f``, ``Jf``,
#: then scratch (``P phi``, the rows' weights ``g``)
FLOATS = Layout(
    "RLSPieces",
    theta=("n",),
    P=("n", "n"),
    last_t=(1,),
    sample=(SAMPLE_ROWS.size, 3),
    last_f=("n",),
    eta0=("n",),
    noise=(NOISE.size,),
    r0=(RESIDUAL_ROWS,),
    J=(RESIDUAL_ROWS, "n"),
    r0f=(RESIDUAL_ROWS,),
    Jf=(RESIDUAL_ROWS, "n"),
    Pphi=("n",),
    g=(N_ROWS,),
    acc_r0=(RESIDUAL_ROWS,),  # the pending rows of held streams (estimators.freshness)
    acc_J=(RESIDUAL_ROWS, "n"),
    fresh_times=(N_TIMES,),
)
F = FLOATS.index
RLSPieces = FLOATS.pieces
#: the int state: 1 once a previous sample is held; 1 once the first update was made; 1 once
#: the prefilter holds a segment (0 again after a bad sample); the counters of
#: :func:`estimators.freshness.fresh_rows_into`
COUNTERS = fields(
    "RLSCounters", "has_last", "updated", "filtered", "accel_held", ("fresh", N_FRESH_COUNTERS)
)
#: the constants: scalars (the box ``lo``, ``hi``; ``log_lambda``: ln(lambda) per second),
#: the inertia and its inverse, the residual weights ``G`` (ones: :func:`segment_terms_into`'s
#: energy is unused), last the allocation ``A`` (4, n) (:func:`rls_constants`)
CONSTANTS = fields(
    "RLSConstants",
    "mass",
    "gravity",
    "f_max",
    "clip",
    "lo",
    "hi",
    "p0",
    "log_lambda",
    "prefilter",
    "isotropic",
    "accel",
    ("J", 9),
    ("Jinv", 9),
    ("G", RESIDUAL_ROWS),
    ("A", 0),
)


def _dims(n: int) -> dict:
    return {"n": n}


def rls_constants(vehicle: Vehicle, cfg: RLSConfig) -> np.ndarray:
    """The constants of :func:`rls_step` (:data:`CONSTANTS`)."""
    b = cfg.eta_bounds
    lo, hi = (-np.inf, np.inf) if b is None else (float(b[0]), float(b[1]))
    return pack(
        CONSTANTS,
        mass=vehicle.mass,
        gravity=vehicle.gravity,
        f_max=vehicle.rotor_max_thrust,
        clip=float(cfg.clip_commands),
        lo=lo,
        hi=hi,
        p0=cfg.p0,
        log_lambda=math.log(cfg.forgetting) / FORGETTING_REFERENCE_DT,
        prefilter=cfg.prefilter,
        isotropic=float(cfg.prefilter > 0),
        accel=float(cfg.accelerometer != "off"),
        J=vehicle.inertia,
        Jinv=vehicle.inertia_inverse,
        G=np.ones(RESIDUAL_ROWS),
        A=vehicle.allocation,
    )


@jit
def state_views(fs, offsets, n, N):
    """The pieces of the float state of ``N`` filters, each ``(N, *shape)``, as a plain tuple
    in the order of :data:`FLOATS` (what a ``prange`` loop can capture; :func:`named_pieces`
    names them)."""
    o = offsets
    return (
        piece_rows(fs, o[F.theta], o[F.theta + 1], N),
        piece(fs, o, F.P, (N, n, n)),
        piece_rows(fs, o[F.last_t], o[F.last_t + 1], N),
        piece(fs, o, F.sample, (N, SAMPLE_ROWS.size, 3)),
        piece_rows(fs, o[F.last_f], o[F.last_f + 1], N),
        piece_rows(fs, o[F.eta0], o[F.eta0 + 1], N),
        piece_rows(fs, o[F.noise], o[F.noise + 1], N),
        piece_rows(fs, o[F.r0], o[F.r0 + 1], N),
        piece(fs, o, F.J, (N, RESIDUAL_ROWS, n)),
        piece_rows(fs, o[F.r0f], o[F.r0f + 1], N),
        piece(fs, o, F.Jf, (N, RESIDUAL_ROWS, n)),
        piece_rows(fs, o[F.Pphi], o[F.Pphi + 1], N),
        piece_rows(fs, o[F.g], o[F.g + 1], N),
        piece_rows(fs, o[F.acc_r0], o[F.acc_r0 + 1], N),
        piece(fs, o, F.acc_J, (N, RESIDUAL_ROWS, n)),
        piece_rows(fs, o[F.fresh_times], o[F.fresh_times + 1], N),
    )


@jit(inline="always")
def named_pieces(views):
    """:func:`state_views` by name (:data:`FLOATS`'s pieces)."""
    return RLSPieces(*views)


@jit(inline="always")
def state_pieces(fs, offsets, n, N):
    """The pieces of the float state of ``N`` filters (:data:`FLOATS`) by name, each
    ``(N, *shape)``."""
    return named_pieces(state_views(fs, offsets, n, N))


@jit
def rls_step(t, p, v, R, w, f, sf, const, S, ks, i) -> int:
    """One sample into filter ``i`` of the state ``(S, ks)`` (:func:`state_pieces`), in place;
    returns the status code (module docstring)."""
    n = f.shape[0]
    C = CONSTANTS
    theta, P, last_t, sample = S.theta[i], S.P[i], S.last_t[i], S.sample[i]
    last_f, s2 = S.last_f[i], S.noise[i]
    last_p, last_v, last_w = sample[SAMPLE_ROWS.p], sample[SAMPLE_ROWS.v], sample[SAMPLE_ROWS.w]
    last_a, last_R = sample[SAMPLE_ROWS.a], sample[SAMPLE_ROWS.R :]
    if not (
        math.isfinite(t)
        and all_finite(p)
        and all_finite(v)
        and all_finite(R)
        and all_finite(w)
        and all_finite(f)
    ) or (ks[i, COUNTERS.has_last] == 1 and not t > last_t[0]):
        ks[i, COUNTERS.has_last] = 0  # the next good sample starts afresh
        ks[i, COUNTERS.filtered] = 0
        restart_into(ks[i, COUNTERS.fresh :], S.fresh_times[i])
        return BAD_SAMPLE
    code = WARMUP
    if ks[i, COUNTERS.has_last] == 1:
        dt = t - last_t[0]
        idle = False
        for j in range(n):
            idle = idle or last_f[j] <= IDLE_THRUST
        if idle:  # (no segment spans it: the pending rows of held streams are dropped)
            restart_into(ks[i, COUNTERS.fresh :], S.fresh_times[i])
            code = NO_EXCITATION
        else:
            r0, Jr = S.r0[i], S.J[i]
            model = SegmentModel(
                const[C.mass],
                const[C.gravity],
                const[C.J : C.Jinv].reshape((3, 3)),
                const[C.Jinv : C.G].reshape((3, 3)),
                const[C.A : C.A + 4 * n].reshape((4, n)),
                const[C.G : C.A],
            )
            segment_model_into(
                dt,
                Kinematics(last_p, last_v, last_R, last_w),
                Kinematics(p, v, R, w),
                last_f,
                model,
                r0,
                Jr,
            )
            fresh = fresh_streams(p, v, R, w, last_p, last_v, last_R, last_w)
            if const[C.accel] != 0.0 and all_finite(last_a):
                # the velocity rows from the accelerometer, whose holds they follow
                fresh = accelerometer_rows(
                    dt,
                    last_R,
                    last_a,
                    ks[i, COUNTERS.accel_held] == 1,
                    fresh,
                    ks[i, COUNTERS.fresh :],
                    r0,
                    Jr,
                )
            # held streams: their rows over the interval between fresh samples
            dt = fresh_rows_into(
                r0,
                Jr,
                dt,
                fresh,
                ks[i, COUNTERS.fresh :],
                S.acc_r0[i],
                S.acc_J[i],
                S.fresh_times[i],
            )
        if not idle and dt == 0.0:  # nothing fresh: the estimate as it was
            code = OK if ks[i, COUNTERS.updated] == 1 else WARMUP
        elif not idle:
            lam = math.exp(const[C.log_lambda] * dt)
            g = S.g[i]  # the rows' weights, from the segment's own rows
            for q in range(N_ROWS):
                r = ROWS[q]
                c2 = 0.0
                for j in range(n):
                    c = Jr[r, j] / last_f[j]  # d r / d f_j, the row's sensitivity to rotor j
                    c2 += c * c
                g[q] = 1.0 / c2 if c2 > 0.0 else 0.0
            if const[C.isotropic] != 0.0:  # one weight for the three velocity rows
                c2 = 0.0
                for q in range(3):
                    c2 += 1.0 / g[q] if g[q] > 0.0 else 0.0
                for q in range(3):
                    g[q] = 1.0 / c2 if c2 > 0.0 else 0.0
            tau = const[C.prefilter]
            if tau > 0.0:  # the same low-pass on both sides of the regression
                fresh = ks[i, COUNTERS.filtered] == 0
                prefilter_fresh_into(
                    r0,
                    Jr,
                    S.r0f[i],
                    S.Jf[i],
                    dt,
                    tau,
                    fresh,
                    ks[i, COUNTERS.fresh :],
                    S.fresh_times[i],
                )
                ks[i, COUNTERS.filtered] = 1
            energy = 0.0  # the weighted a-priori residual energy, per row
            for q in range(N_ROWS):
                r = ROWS[q]
                e = -r0[r]
                for j in range(n):
                    e -= Jr[r, j] * theta[j]
                energy += g[q] * e * e
            s2[NOISE.count] = lam * s2[NOISE.count] + 1.0  # the forgotten count, then the mean
            s2[NOISE.mean] += (energy / N_ROWS - s2[NOISE.mean]) / s2[NOISE.count]
            for a in range(n):
                for b in range(n):
                    P[a, b] /= lam
            Pphi = S.Pphi[i]
            for q in range(N_ROWS):
                r = ROWS[q]
                if g[q] == 0.0:
                    continue
                den = 1.0 / g[q]
                e = -r0[r]
                for a in range(n):
                    acc = 0.0
                    for b in range(n):
                        acc += P[a, b] * Jr[r, b]
                    Pphi[a] = acc
                    den += Jr[r, a] * acc
                    e -= Jr[r, a] * theta[a]
                for a in range(n):
                    theta[a] += Pphi[a] * (e / den)
                for a in range(n):  # P - P phi phi^T P / den, symmetric
                    for b in range(a + 1):
                        P[a, b] -= Pphi[a] * Pphi[b] / den
                        P[b, a] = P[a, b]
            ks[i, COUNTERS.updated] = 1
            code = OK
    last_t[0] = t
    held = ks[i, COUNTERS.has_last] == 1 and repeats(sf, last_a)
    ks[i, COUNTERS.accel_held] = 1 if held else 0
    for k in range(3):
        last_p[k], last_v[k], last_w[k], last_a[k] = p[k], v[k], w[k], sf[k]
        for b in range(3):
            last_R[k, b] = R[k, b]
    for j in range(n):
        last_f[j] = min(max(f[j], 0.0), const[C.f_max]) if const[C.clip] != 0.0 else f[j]
    ks[i, COUNTERS.has_last] = 1
    return code


@jit(inline="always")
def _estimate_row(S, ks, i, n, eta, sd) -> None:
    theta, P, s2 = S.theta[i], S.P[i], S.noise[i]
    for j in range(n):
        eta[j] = theta[j]
        sd[j] = (
            math.sqrt(max(P[j, j] * s2[NOISE.mean], 0.0))
            if ks[i, COUNTERS.updated] == 1
            else np.nan
        )


@jit
def rls_estimate(offsets, n, fs, ks, eta, sd) -> None:
    """Every row's estimate (``theta``, projected onto the box after each update) and its sd
    (NaN before the first update)."""
    S = state_pieces(fs, offsets, n, ks.shape[0])
    for i in range(ks.shape[0]):
        _estimate_row(S, ks, i, n, eta[i], sd[i])


@jit
def rls_reset(const, offsets, n, fs, ks, rows, eta0) -> None:
    """Forget the filters ``rows``; start them from ``eta0`` (N, n) with ``P = p0 I``."""
    N = ks.shape[0]
    for i in rows:
        for k in range(ks.shape[1]):
            ks[i, k] = 0
        for k in range(offsets.shape[0] - 1):  # every piece
            row = piece_rows(fs, offsets[k], offsets[k + 1], N)[i]
            for a in range(row.shape[0]):
                row[a] = 0.0
        theta = piece_rows(fs, offsets[F.theta], offsets[F.theta + 1], N)[i]
        e0 = piece_rows(fs, offsets[F.eta0], offsets[F.eta0 + 1], N)[i]
        P = piece(fs, offsets, F.P, (N, n, n))[i]
        for j in range(n):
            theta[j] = eta0[i, j]
            e0[j] = eta0[i, j]
            P[j, j] = const[CONSTANTS.p0]


@jit(inline="always")
def _one(t, p, v, R, w, f, a, const, S, ks, i) -> int:
    """:func:`rls_step`, then the projection of ``theta`` onto the box."""
    code = rls_step(t, p, v, R, w, f, a, const, S, ks, i)
    if code == OK:
        theta = S.theta[i]
        for j in range(f.shape[0]):
            theta[j] = min(max(theta[j], const[CONSTANTS.lo]), const[CONSTANTS.hi])
    return code


@jit
def rls_update(t, p, v, R, w, f, a, const, offsets, fs, ks) -> int:
    """One sample into the single filter (row 0)."""
    S = state_pieces(fs, offsets, f.shape[0], ks.shape[0])
    return _one(t, p, v, R, w, f, a, const, S, ks, ks.shape[0] - 1)


@jit
def rls_run(t, p, v, R, w, f, a, const, offsets, fs, ks, eta, sd, code) -> None:
    """The single filter over the rows of a recording: estimate, sd and status of each row."""
    n = f.shape[1]
    S = state_pieces(fs, offsets, n, ks.shape[0])
    row = ks.shape[0] - 1  # 0, a run-time value like the batch's rows
    for k in range(t.shape[0]):
        code[k] = _one(t[k], p[k], v[k], R[k], w[k], f[k], a[k], const, S, ks, row)
        _estimate_row(S, ks, row, n, eta[k], sd[k])


@jit(parallel=True)
def rls_update_rows(t, p, v, R, w, f, a, const, offsets, fs, ks, code) -> None:
    """One sample into every row of a batch, in parallel; status codes into ``code``."""
    N = ks.shape[0]
    views = state_views(fs, offsets, f.shape[1], N)  # formed once; named inside the loop
    for i in prange(N):
        code[i] = _one(
            t[i], p[i], v[i], R[i], w[i], f[i], a[i], const, named_pieces(views), ks, np.int64(i)
        )


def _kernels():
    return rls_reset, rls_update, rls_run, rls_update_rows, rls_estimate


class _RLS(_Kernels):
    name = "rls"
    config_class = RLSConfig
    kernels = staticmethod(_kernels)
    floats = FLOATS
    dims = staticmethod(_dims)
    counters = COUNTERS
    constants = staticmethod(rls_constants)
    fmax_index = CONSTANTS.f_max
    reads_accel = True


class RecursiveLeastSquares(_RLS, RecursiveEstimator):
    """RLS with forgetting over the IRLS's segment regression (name ``"rls"``); see the module
    docstring. Args: ``vehicle`` (the nominal one), ``config`` (:class:`RLSConfig`)."""

    @property
    def P(self) -> np.ndarray:
        """The covariance of ``theta`` (n x n) as the filter holds it (``s2`` not applied)."""
        return self._state.views.P[0]


class BatchedRLS(_RLS, BatchedRecursive):
    """N :class:`RecursiveLeastSquares` filters updated together."""


__all__ = ["BatchedRLS", "RLSConfig", "RecursiveLeastSquares", "rls_step"]
