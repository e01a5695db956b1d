"""Unscented Kalman filter (UKF) with the motor efficiencies in its state.

State (n rotors, ``L = 6 + n``)::

    x = [v (3, world [m/s]); Omega (3, body [rad/s]); eta (n)]

Why this state: the efficiencies act on the vehicle only through the wrench
``[T; M] = A diag(f) eta``, which the velocity (thrust, eq. 13) and the body rate (moments,
eq. 15) integrate over one sample. The attitude is measured far more precisely than the
filter could predict it and enters the thrust direction only, so the measured ``R`` of the
previous sample is an input (as in the IRLS's regression), not a state: no rotation in the
state, no manifold for the sigma points. Position is the integral of the velocity and adds
no information on ``eta`` that the velocity lacks. The efficiencies are a random walk
(``eta' = w_eta``, ``w_eta ~ N(0, Q_eta)``), ``Q_eta`` the tuning knob (as the EKF's).

One update per sample, from row k-1 to row k over ``dt_k`` with the command of row k-1 held
(zero-order hold):

* predict: ``2 L + 1`` sigma points ``x +- sqrt(L + lambda) columns of chol(P)`` (the scaled
  unscented transform, ``lambda = alpha^2 (L + kappa) - L``; weights ``W_m``, ``W_c``), each
  propagated by ``v' = v + (g e3 - T(eta) R_{k-1} e3 / m) dt``,
  ``Omega' = Omega + J^-1 (M(eta) - Omega x J Omega) dt``, ``eta' = eta``; the predicted mean
  and covariance are their weighted mean and scatter plus ``Q dt``;
* update with the measured ``z = [v_k; Omega_k]``: the measurement is linear (``H = [I_6 0]``),
  so the unscented update equals the Kalman update of the predicted moments, done in the
  square-root form of the optimal gain (as the EKF's): ``S = P_zz + R = L L^T``,
  ``W = L^-1 P_zx``, ``x += W^T L^-1 (z - x_z)``, ``P -= W^T W``; with the accelerometer
  (``UKFConfig.accelerometer``, as the EKF's: docs/ekf.md, "Accelerometer") one more row,
  the body-z specific force ``-T(eta) / m = h . eta`` of the sample's own command, also
  linear;
* the efficiencies are clamped to ``eta_bounds`` (as the EKF's, up to 1.2).

Online rules, as the EKF's: a non-finite sample or a time not after the previous one is
skipped (``bad_sample``); the first sample sets ``v`` and ``Omega`` (``warmup``); a step whose
command had an idle rotor (``<= IDLE_THRUST``) keeps the efficiencies, decorrelated, their
variance grown by ``Q_eta dt`` (``no_excitation``); commands are clipped to
``[0, rotor_max_thrust]`` (``run`` lifts the upper clip for an unsaturated flight).

Process noise is per 1 ms step and scales with ``dt / 1 ms`` (the EKF's convention); the
kinematic noise values are the EKF's defaults.

The step is :func:`ukf_step` (plain Python compiled by :func:`quadfault.jit.jit`) on one row of a
flat state; :class:`UnscentedKalmanFilter`, its offline ``run`` and :class:`BatchedUKF` (the
vector environment's) all run it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from estimators.accelerometer import check_mode, finite3
from estimators.base import (
    BAD_SAMPLE,
    ILL_CONDITIONED,
    NO_EXCITATION,
    OK,
    WARMUP,
)
from estimators.ekf import IDLE_THRUST, NOISE_REFERENCE_DT
from estimators.freshness import (
    SAMPLE,
    accel_fresh,
    fresh_since,
    measurement_variances_into,
    remember_into,
)
from estimators.linalg import cholesky_into
from estimators.options import check_bounds, check_finite, check_positive, from_options
from estimators.recursive import BatchedRecursive, RecursiveEstimator, _Kernels
from estimators.state import Layout, all_finite, fields, pack, piece, piece_rows, reset_rows
from quadfault.errors import ConfigError
from quadfault.jit import jit, prange
from quadfault.model.dynamics import (
    angular_acceleration3,
    rotor_wrench,
    translational_acceleration3,
)
from quadfault.model.vehicle import Vehicle


@dataclass(frozen=True)
class UKFConfig:
    """UKF tuning. Process-noise variances are per 1 ms step and scale with ``dt / 1 ms``.

    Attributes:
        q_eta: random-walk variance of each efficiency per 1 ms step [1] (the tuning knob,
            ``--q-eta``; the EKF's default).
        q_velocity [(m/s)^2], q_rate [(rad/s)^2]: process noise of the kinematic states per
            1 ms step (the EKF's defaults).
        r_velocity [(m/s)^2], r_rate [(rad/s)^2]: measurement-noise variances (the EKF's).
        p0: initial covariance ``p0 * I``.
        alpha, beta, kappa: the scaled unscented transform's spread, prior-knowledge and
            secondary scaling parameters (``alpha = 1, kappa = 0``: the sigma points at
            ``+- sqrt(L)`` standard deviations, the central point's mean weight 0).
        eta0: initial efficiency (one value for all rotors, or one per rotor).
        eta_bounds: clamp of the efficiency after each update, or None for no clamp. The
            default lets a rotor read up to 20 % above nominal: a clamp at 1 truncates the
            filter's state on every healthy rotor and biases it low, the more so the noisier
            the sensors (docs/ekf.md, "Bounds").
        clip_commands: clip the commanded thrusts to ``[0, rotor_max_thrust]`` (as IRLS).
        accelerometer, r_accel, accel_scatter: the accelerometer's row, as the EKF's
            (:class:`estimators.ekf.EKFConfig`; ``"off"``: the filter without it).
    """

    q_eta: float = 0.5
    q_velocity: float = 1e-3
    q_rate: float = 1e-4
    r_velocity: float = 5e-2
    r_rate: float = 5e-2
    p0: float = 1e-2
    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0
    eta0: float | tuple = 1.0
    eta_bounds: tuple | None = (-0.001, 1.2)
    clip_commands: bool = True
    accelerometer: str = "off"
    r_accel: float = 0.1
    accel_scatter: float = 0.5

    def __post_init__(self):
        check_positive(
            self, "q_eta", "q_velocity", "q_rate", "r_velocity", "r_rate", "r_accel", "p0", "alpha"
        )
        check_finite(self, "beta", "kappa", "accel_scatter")
        check_bounds("UKFConfig", self.eta_bounds)
        if self.accel_scatter < 0:
            raise ConfigError(f"UKFConfig.accel_scatter must be >= 0, got {self.accel_scatter!r}")
        object.__setattr__(self, "accelerometer", check_mode("UKFConfig", self.accelerometer))

    def weights(self, n: int) -> tuple[float, float, float, float]:
        """``(scale, W_m0, W_c0, W_i)`` of ``L = 6 + n`` states: the sigma points are
        ``x +- scale * columns of chol(P)``."""
        L = X.eta + n
        lam = self.alpha**2 * (L + self.kappa) - L
        if not L + lam > 0:
            raise ConfigError(
                f"UKFConfig: alpha^2 (L + kappa) must be positive for L = {L} "
                f"states, got alpha = {self.alpha}, kappa = {self.kappa}"
            )
        wm0 = lam / (L + lam)
        return (math.sqrt(L + lam), wm0, wm0 + 1.0 - self.alpha**2 + self.beta, 0.5 / (L + lam))

    @classmethod
    def from_options(
        cls, q_eta: float | None = None, accelerometer: str | bool | None = None
    ) -> UKFConfig:
        """The configuration of ``quadfault estimate --estimator ukf [--q-eta Q]
        [--accelerometer MODE]``."""
        return from_options(cls, q_eta=q_eta, accelerometer=accelerometer)

    def replace(self, **changes) -> UKFConfig:
        return replace(self, **changes)


#: the filter's state: velocity (world), body rate, then the n efficiencies
X = fields("UKFStates", ("v", 3), ("w", 3), ("eta", 0))
#: rows of the measurement: velocity and rate, each reading its state (``H = [I 0]``), then
#: the accelerometer's body-z specific force (``h . eta``; only on an update that measures
#: it: the first ``Y.a`` rows otherwise)
Y = fields("UKFMeasurementRows", ("v", 3), ("w", 3), ("a", 1))
assert (X.v, X.w) == (Y.v, Y.w) and X.eta == Y.a  # the rows read the first states
#: the float state of one filter (dimensions: rotors ``n``, states ``L = X.eta + n``, sigma
#: points ``sigma = 2 L + 1``): ``x`` and ``P``, the previous sample's time, (clipped)
#: command and attitude, the initial efficiency, the efficiencies kept across an idle step,
#: then the workspace of one update (the sigma points, chol(P), the predicted moments, the
#: innovation's covariance and its factor, ``W``, the innovation, the factorisation's shift)
FLOATS = Layout(
    "UKFPieces",
    x=("L",),
    P=("L", "L"),
    last_t=(1,),
    last_f=("n",),
    last_R=(3, 3),
    eta0=("n",),
    keep=("n",),
    P_keep=("n", "n"),
    sigma=("sigma", "L"),
    chol=("L", "L"),
    xp=("L",),
    Pp=("L", "L"),
    S=(Y.size, Y.size),
    SL=(Y.size, Y.size),
    W=(Y.size, "L"),
    y=(Y.size,),
    shift=("L",),
    last_z=(SAMPLE.size, 3),  # the previous sample (estimators.freshness)
    r_now=(Y.size,),  # the measurement variances of this update
    last_a=(3,),  # the previous accelerometer reading
    ha=("n",),  # the accelerometer row's Jacobian on the efficiencies
)
F = FLOATS.index
UKFPieces = FLOATS.pieces
#: the int state: 1 once the first good sample set the kinematic states
COUNTERS = fields("UKFCounters", "initialised")
#: the constants: scalars (the clamp ``lo``, ``hi``; the unscented transform's ``scale`` and
#: weights, :meth:`UKFConfig.weights`), the inertia and its inverse, the measurement-noise
#: variances ``r``; last the arrays sized by the rotors: the allocation ``A`` (4, n), then
#: the process-noise variance rates ``qc`` (L,) [1/s] (:func:`ukf_constants`)
CONSTANTS = fields(
    "UKFConstants",
    "mass",
    "gravity",
    "f_max",
    "clip",
    "lo",
    "hi",
    "p0",
    "accel",
    "scatter",
    "scale",
    "wm0",
    "wc0",
    "wi",
    ("J", 9),
    ("Jinv", 9),
    ("r", Y.size),
    ("per_rotor", 0),
)


def _dims(n: int) -> dict:
    L = X.eta + n
    return {"n": n, "L": L, "sigma": 2 * L + 1}


def ukf_constants(vehicle: Vehicle, cfg: UKFConfig) -> np.ndarray:
    """The constants of :func:`ukf_step` (:data:`CONSTANTS`)."""
    n = vehicle.n_rotors
    b = cfg.eta_bounds
    lo, hi = (-np.inf, np.inf) if b is None else (float(b[0]), float(b[1]))
    q = pack(X, v=np.full(3, cfg.q_velocity), w=np.full(3, cfg.q_rate), eta=np.full(n, cfg.q_eta))
    r = pack(Y, v=np.full(3, cfg.r_velocity), w=np.full(3, cfg.r_rate), a=np.full(1, cfg.r_accel))
    scale, wm0, wc0, wi = cfg.weights(n)
    per_rotor = np.concatenate(
        (np.asarray(vehicle.allocation, dtype=float).ravel(), q / NOISE_REFERENCE_DT)
    )  # A, then qc (_model)
    return pack(
        CONSTANTS,
        mass=vehicle.mass,
        gravity=vehicle.gravity,
        f_max=vehicle.rotor_max_thrust,
        clip=float(cfg.clip_commands),
        lo=lo,
        hi=hi,
        p0=cfg.p0,
        accel=float(cfg.accelerometer != "off"),
        scatter=cfg.accel_scatter,
        scale=scale,
        wm0=wm0,
        wc0=wc0,
        wi=wi,
        J=vehicle.inertia,
        Jinv=vehicle.inertia_inverse,
        r=r,
        per_rotor=per_rotor,
    )


@jit(inline="always")
def _model(const, n):
    """``(A, qc, r)``: the allocation (4, n), the process-noise variance rates (L,) and the
    measurement-noise variances (:data:`Y`), views of ``const``."""
    a, L = CONSTANTS.per_rotor, X.eta + n
    return (
        const[a : a + 4 * n].reshape((4, n)),
        const[a + 4 * n : a + 4 * n + L],
        const[CONSTANTS.r : CONSTANTS.per_rotor],
    )


@jit
def state_views(fs, offsets, n, N):
    """The pieces of the float state of ``N`` filters, each ``(N, *shape)``, as a plain tuple
    in the order of :data:`FLOATS` (what a ``prange`` loop can capture; :func:`named_pieces`
    names them)."""
    L, o, m = X.eta + n, offsets, Y.size
    return (
        piece_rows(fs, o[F.x], o[F.x + 1], N),
        piece(fs, o, F.P, (N, L, L)),
        piece_rows(fs, o[F.last_t], o[F.last_t + 1], N),
        piece_rows(fs, o[F.last_f], o[F.last_f + 1], N),
        piece(fs, o, F.last_R, (N, 3, 3)),
        piece_rows(fs, o[F.eta0], o[F.eta0 + 1], N),
        piece_rows(fs, o[F.keep], o[F.keep + 1], N),
        piece(fs, o, F.P_keep, (N, n, n)),
        piece(fs, o, F.sigma, (N, 2 * L + 1, L)),
        piece(fs, o, F.chol, (N, L, L)),
        piece_rows(fs, o[F.xp], o[F.xp + 1], N),
        piece(fs, o, F.Pp, (N, L, L)),
        piece(fs, o, F.S, (N, m, m)),
        piece(fs, o, F.SL, (N, m, m)),
        piece(fs, o, F.W, (N, m, L)),
        piece_rows(fs, o[F.y], o[F.y + 1], N),
        piece_rows(fs, o[F.shift], o[F.shift + 1], N),
        piece(fs, o, F.last_z, (N, SAMPLE.size, 3)),
        piece_rows(fs, o[F.r_now], o[F.r_now + 1], N),
        piece_rows(fs, o[F.last_a], o[F.last_a + 1], N),
        piece_rows(fs, o[F.ha], o[F.ha + 1], N),
    )


@jit(inline="always")
def named_pieces(views):
    """:func:`state_views` by name (:data:`FLOATS`'s pieces)."""
    return UKFPieces(*views)


@jit(inline="always")
def state_pieces(fs, offsets, n, N):
    """The pieces of the float state of ``N`` filters (:data:`FLOATS`) by name, each
    ``(N, *shape)``."""
    return named_pieces(state_views(fs, offsets, n, N))


@jit(inline="always")
def _propagate(chi, f, R9, dt, rigid, A) -> None:
    """One sigma point ``chi = [v, Omega, eta]`` (:data:`X`) over ``dt`` with the command
    ``f`` held and the attitude ``R9`` (row-major 9-tuple), in place: the model's allocation
    and rigid body (:mod:`quadfault.model.dynamics`, eqs. 2, 4 and 12; the efficiencies a random
    walk)."""
    n = f.shape[0]
    T, M = rotor_wrench(A, f, chi[X.eta : X.eta + n])
    acc = translational_acceleration3(R9, T, rigid)
    wdot = angular_acceleration3((chi[X.w], chi[X.w + 1], chi[X.w + 2]), M, rigid)
    for a in range(3):
        chi[X.v + a] += acc[a] * dt
        chi[X.w + a] += wdot[a] * dt


@jit
def ukf_step(t, p, v, R, w, f, sf, const, S, ks, i) -> int:
    """One sample into filter ``i`` of the state ``(S, ks)`` (:func:`state_pieces`), in place;
    returns the status code (module docstring). ``sf``: the accelerometer's reading (3 floats)
    [m/s^2], body FRD, read only when the constants say so; a non-finite or held reading
    is not measured."""
    n = f.shape[0]
    L = X.eta + n
    x, P, last_t, last_f, last_R = S.x[i], S.P[i], S.last_t[i], S.last_f[i], S.last_R[i]
    if not (
        math.isfinite(t)
        and all_finite(p)
        and all_finite(v)
        and all_finite(R)
        and all_finite(w)
        and all_finite(f)
    ):
        return BAD_SAMPLE
    if ks[i, COUNTERS.initialised] == 0:  # the first sample sets the kinematic states
        eta0 = S.eta0[i]
        for a in range(3):
            x[X.v + a], x[X.w + a] = v[a], w[a]
        for j in range(n):
            x[X.eta + j] = eta0[j]
        for a in range(L):
            for b in range(L):
                P[a, b] = const[CONSTANTS.p0] if a == b else 0.0
        ks[i, COUNTERS.initialised] = 1
        code = WARMUP
    else:
        dt = t - last_t[0]
        if not dt > 0:
            return BAD_SAMPLE
        # a held stream (its sample repeated, estimators.freshness) is not measured again
        r_now = S.r_now[i]
        measurement_variances_into(
            _model(const, n)[2], fresh_since(p, v, R, w, S.last_z[i]), -1, Y.v, -1, Y.w, r_now
        )
        # the accelerometer: the body-z specific force of this sample's command, -T(eta) / m
        ha, rows = last_f, Y.a  # (ha unread without the accelerometer)
        if const[CONSTANTS.accel] != 0.0 and finite3(sf) and accel_fresh(sf, S.last_a[i], v):
            ha, rows, h2 = S.ha[i], Y.size, 0.0
            f_max, clip = const[CONSTANTS.f_max], const[CONSTANTS.clip] != 0.0
            for j in range(n):
                fj = min(max(f[j], 0.0), f_max) if clip else f[j]
                ha[j] = -_model(const, n)[0][0, j] * fj / const[CONSTANTS.mass]
                h2 += ha[j] * ha[j]
            r_now[Y.a] += const[CONSTANTS.scatter] * const[CONSTANTS.scatter] * h2
        code = _predict_update(
            x, P, v, w, sf[2], ha, rows, last_f, last_R, dt, const, r_now, S, i, n
        )
        if code == OK:
            idle = False
            for j in range(n):
                idle = idle or last_f[j] <= IDLE_THRUST
            if idle:  # the efficiencies stay, decorrelated; their variance grows by Q_eta dt
                keep, P_keep, e = S.keep[i], S.P_keep[i], X.eta
                qc = _model(const, n)[1]
                for j in range(n):
                    x[e + j] = keep[j]
                    for k in range(e):
                        P[e + j, k] = 0.0
                        P[k, e + j] = 0.0
                    for k in range(n):
                        P[e + j, e + k] = P_keep[j, k]
                    P[e + j, e + j] += qc[e + j] * dt
                code = NO_EXCITATION
    last_t[0] = t
    remember_into(S.last_z[i], p, v, R, w)
    if const[CONSTANTS.accel] != 0.0:
        for a in range(3):
            S.last_a[i][a] = sf[a]
    for a in range(3):
        for b in range(3):
            last_R[a, b] = R[a, b]
    for j in range(n):
        last_f[j] = (
            min(max(f[j], 0.0), const[CONSTANTS.f_max]) if const[CONSTANTS.clip] != 0.0 else f[j]
        )
    return code


@jit(inline="always")
def _predict_update(x, P, zv, zw, za, ha, rows, f, R, dt, const, r, S, i, n) -> int:
    """The unscented predict over ``dt`` and the update with ``z = [zv, zw]`` (and, with
    ``rows`` = ``Y.size``, the accelerometer's ``za = ha . eta``) of measurement variances
    ``r`` (:data:`Y`), in place; ``ill_conditioned`` (nothing changed) when ``P`` or ``S``
    is not positive definite."""
    L, e, C_ = X.eta + n, X.eta, CONSTANTS
    A, qc, _r = _model(const, n)
    keep, P_keep = S.keep[i], S.P_keep[i]
    for j in range(n):  # the efficiencies before the step (an idle step restores them)
        keep[j] = x[e + j]
        for k in range(n):
            P_keep[j, k] = P[e + j, e + k]
    sig, C, xp, Pp, shift = S.sigma[i], S.chol[i], S.xp[i], S.Pp[i], S.shift[i]
    for a in range(L):
        shift[a] = 0.0
    if not cholesky_into(P, shift, C, L):
        return ILL_CONDITIONED
    scale, wm0, wc0, wi = const[C_.scale], const[C_.wm0], const[C_.wc0], const[C_.wi]
    for a in range(L):
        sig[0, a] = x[a]
    for c in range(L):  # sigma points x +- scale C[:, c]
        for a in range(L):
            d = scale * C[a, c] if a >= c else 0.0
            sig[1 + c, a] = x[a] + d
            sig[1 + L + c, a] = x[a] - d
    rigid = (const[C_.mass], const[C_.gravity], const[C_.J : C_.Jinv], const[C_.Jinv : C_.r])
    R9 = (R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2], R[2, 0], R[2, 1], R[2, 2])
    for s in range(2 * L + 1):
        _propagate(sig[s], f, R9, dt, rigid, A)
    for a in range(L):  # predicted mean and covariance
        acc = wm0 * sig[0, a]
        for s in range(1, 2 * L + 1):
            acc += wi * sig[s, a]
        xp[a] = acc
    for s in range(2 * L + 1):
        for a in range(L):
            sig[s, a] -= xp[a]
    for a in range(L):
        for b in range(a + 1):
            acc = wc0 * sig[0, a] * sig[0, b]
            for s in range(1, 2 * L + 1):
                acc += wi * sig[s, a] * sig[s, b]
            Pp[a, b] = acc
            Pp[b, a] = acc
        Pp[a, a] += qc[a] * dt
    if rows == Y.a:  # (each with its rows' count known when compiled)
        return _update(x, P, xp, Pp, zv, zw, za, ha, const, r, S, i, L, Y.a)
    return _update(x, P, xp, Pp, zv, zw, za, ha, const, r, S, i, L, Y.size)


@jit(inline="always")
def _update(x, P, xp, Pp, zv, zw, za, ha, const, r, S, i, L, m) -> int:
    """The update of the predicted ``xp``, ``Pp`` with the ``m`` rows measured (``Y.a``:
    velocity and rate; ``Y.size``: and the accelerometer's ``za = ha . eta``)."""
    e, C_, n = X.eta, CONSTANTS, L - X.eta
    # z = [v, Omega (, a)], H = [I_6 0 (; 0 ha^T)]: S = H Pp H^T + R = L L^T, W = L^-1 H Pp
    Sm, SL, W, y = S.S[i], S.SL[i], S.W[i], S.y[i]
    for a in range(Y.a):
        for b in range(Y.a):
            Sm[a, b] = Pp[a, b]
    if m > Y.a:  # the accelerometer's row of H Pp (into W's last row) and of S
        for c in range(L):
            acc = 0.0
            for j in range(ha.shape[0]):
                acc += ha[j] * Pp[e + j, c]
            W[Y.a, c] = acc
        for b in range(Y.a):
            Sm[Y.a, b] = W[Y.a, b]
        acc = 0.0
        for j in range(ha.shape[0]):
            acc += W[Y.a, e + j] * ha[j]
        Sm[Y.a, Y.a] = acc
    if not cholesky_into(Sm, r, SL, m):
        return ILL_CONDITIONED
    for a in range(3):
        y[Y.v + a] = zv[a] - xp[X.v + a]
        y[Y.w + a] = zw[a] - xp[X.w + a]
    if m > Y.a:
        acc = za
        for j in range(ha.shape[0]):
            acc -= ha[j] * xp[e + j]
        y[Y.a] = acc
    for a in range(m):  # forward substitution on W's rows and on y
        for c in range(L):
            acc = Pp[a, c] if a < Y.a else W[a, c]
            for k in range(a):
                acc -= SL[a, k] * W[k, c]
            W[a, c] = acc / SL[a, a]
        acc = y[a]
        for k in range(a):
            acc -= SL[a, k] * y[k]
        y[a] = acc / SL[a, a]
    for a in range(L):
        acc = 0.0
        for k in range(m):
            acc += W[k, a] * y[k]
        x[a] = xp[a] + acc
    for a in range(L):  # P = Pp - W^T W
        for b in range(a + 1):
            acc = 0.0
            for k in range(m):
                acc += W[k, a] * W[k, b]
            P[a, b] = Pp[a, b] - acc
            P[b, a] = P[a, b]
    for j in range(n):
        x[e + j] = min(max(x[e + j], const[C_.lo]), const[C_.hi])
    return OK


@jit(inline="always")
def _estimate_row(S, ks, i, n, eta, sd) -> None:
    x, P, eta0, e = S.x[i], S.P[i], S.eta0[i], X.eta
    for j in range(n):
        if ks[i, COUNTERS.initialised] == 1:
            eta[j] = x[e + j]
            sd[j] = math.sqrt(max(P[e + j, e + j], 0.0))
        else:
            eta[j] = eta0[j]
            sd[j] = np.nan


@jit
def ukf_estimate(offsets, n, fs, ks, eta, sd) -> None:
    """Every row's estimate and sd (``sqrt(diag P)`` of the efficiencies; NaN before the
    first sample)."""
    S = state_pieces(fs, offsets, n, ks.shape[0])
    for i in range(ks.shape[0]):
        _estimate_row(S, ks, i, n, eta[i], sd[i])


@jit
def ukf_reset(const, offsets, n, fs, ks, rows, eta0) -> None:
    """Forget the filters ``rows``; the next good sample initialises them, with the
    efficiencies ``eta0`` (N, n)."""
    reset_rows(offsets, F.eta0, COUNTERS.initialised, n, fs, ks, rows, eta0)


@jit
def ukf_update(t, p, v, R, w, f, a, const, offsets, fs, ks) -> int:
    """One sample into the single filter (row 0); ``a`` its accelerometer reading."""
    S = state_pieces(fs, offsets, f.shape[0], ks.shape[0])
    return ukf_step(t, p, v, R, w, f, (a[0], a[1], a[2]), const, S, ks, ks.shape[0] - 1)


@jit
def ukf_run(t, p, v, R, w, f, a, const, offsets, fs, ks, eta, sd, code) -> None:
    """The single filter over the rows of a recording (``a``: the accelerometer's rows):
    estimate, sd and status of each row."""
    n = f.shape[1]
    S = state_pieces(fs, offsets, n, ks.shape[0])
    row = ks.shape[0] - 1  # 0, a run-time value like the batch's rows
    for k in range(t.shape[0]):
        sf = (a[k, 0], a[k, 1], a[k, 2])  # (scalars: no view per row)
        code[k] = ukf_step(t[k], p[k], v[k], R[k], w[k], f[k], sf, const, S, ks, row)
        _estimate_row(S, ks, row, n, eta[k], sd[k])


@jit(parallel=True)
def ukf_update_rows(t, p, v, R, w, f, a, const, offsets, fs, ks, code) -> None:
    """One sample into every row of a batch (``a`` (N, 3): the accelerometer's readings), in
    parallel; status codes into ``code``."""
    N = ks.shape[0]
    views = state_views(fs, offsets, f.shape[1], N)  # formed once; named inside the loop
    for i in prange(N):
        code[i] = ukf_step(
            t[i],
            p[i],
            v[i],
            R[i],
            w[i],
            f[i],
            (a[i, 0], a[i, 1], a[i, 2]),
            const,
            named_pieces(views),
            ks,
            np.int64(i),
        )


def _kernels():
    return ukf_reset, ukf_update, ukf_run, ukf_update_rows, ukf_estimate


class _UKF(_Kernels):
    name = "ukf"
    config_class = UKFConfig
    kernels = staticmethod(_kernels)
    floats = FLOATS
    dims = staticmethod(_dims)
    counters = COUNTERS
    constants = staticmethod(ukf_constants)
    fmax_index = CONSTANTS.f_max
    reads_accel = True


class UnscentedKalmanFilter(_UKF, RecursiveEstimator):
    """UKF over ``[v, Omega, eta]`` (name ``"ukf"``); see the module docstring. Args:
    ``vehicle`` (the nominal one), ``config`` (:class:`UKFConfig`)."""

    @property
    def x(self) -> np.ndarray | None:
        """The state ``[v, Omega, eta]`` (None before the first good sample)."""
        return self._state.views.x[0] if self._state.ints[0, COUNTERS.initialised] else None

    @property
    def P(self) -> np.ndarray | None:
        """The state covariance (None before the first good sample)."""
        return self._state.views.P[0] if self._state.ints[0, COUNTERS.initialised] else None


class BatchedUKF(_UKF, BatchedRecursive):
    """N :class:`UnscentedKalmanFilter` filters updated together."""


__all__ = ["BatchedUKF", "UKFConfig", "UnscentedKalmanFilter", "ukf_step"]
