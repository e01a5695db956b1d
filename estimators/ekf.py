"""Extended Kalman filter baseline for motor efficiency (paper Sec. "EKF Baseline").

State (22 for four rotors), as in the paper and the reference ``motor_estimator_ekf.m``::

    x = [p (3); v (3); Omega (3); vec(R) (9, column-major); eta (n)]

with the efficiencies as a random walk (``eta' = w_eta``, ``w_eta ~ N(0, Q_eta)``). One
update per measurement row: predict from row k-1 to row k with the command of row k-1 held
over ``dt_k = t_k - t_{k-1}`` (zero-order hold, CONTRACT sec. 3), then update with the
pose and rate measured at row k. The estimate's ``t`` is ``t_k``.

Deviations from the reference code (each discussed in ``docs/ekf.md``):

* attitude measurement: 3 rows, innovation ``y = log(R_pred^T R_meas)`` with the Jacobian of
  the skew part (constant and well-defined at zero error), instead of the one-sided scalar
  ``acos((tr(R^T R_m) - 1) / 2)`` whose Jacobian is singular at zero;
* attitude prediction with the exponential map at the mid-step rate
  (``R_pred = R exp([Omega dt + Omega' dt^2 / 2]x)``) instead of ``R + R [Omega]x dt`` + SVD;
* full gyroscopic block in ``F`` (the reference leaves ``dOmega/dOmega = I``);
* Joseph-form covariance update and ``numpy.linalg.solve`` instead of an inverse;
* the recording's allocation matrix and per-sample ``dt``; process noise scaled by
  ``dt / 1 ms`` so the reference's per-step values are the defaults at 1 kHz;
* efficiency clamp ``[-0.001, 1.001]`` (the IRLS bounds) by default;
  ``EKFConfig.reference()`` restores the reference's ``[1e-3, 1 - 1e-3]``.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, replace

import numpy as np

from estimators.base import (STATUS_BAD_SAMPLE, STATUS_NO_EXCITATION, STATUS_OK,
                             STATUS_WARMUP, Estimate,
                             EstimateSeries, Sample, samples)
from quadfault.dynamics import angular_acceleration, translational_acceleration
from quadfault.errors import ConfigError
from quadfault.recording import Recording
from quadfault.rotation import expm_so3, hat, logm_so3, orthonormalize
from quadfault.vehicle import Vehicle

#: Sample period the per-step noise values refer to [s] (the reference's 1 kHz).
NOISE_REFERENCE_DT = 1e-3
BACKENDS = ("auto", "numpy", "numba")

P_, V_, W_, R_, ETA_ = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 18), 18
#: vec(R) entries of the third column R e3 (column-major vec).
R_E3 = slice(15, 18)



#: A rotor commanded at most this thrust [N] carries no information on its efficiency. A step
#: whose command has such a rotor leaves the whole efficiency vector where it was (status
#: ``no_excitation``): the kinematic states are filtered as usual, the efficiencies are held,
#: decorrelated from the kinematic states, and their variance grows by Q_eta dt.
IDLE_THRUST = 1e-3

_STATUS_WIDTH = max(len(s) for s in (STATUS_BAD_SAMPLE, STATUS_NO_EXCITATION, STATUS_OK,
                                        STATUS_WARMUP))


def _freeze_eta(x, P, eta_keep, P_keep, qc, dt) -> None:
    """Restore the efficiencies and their covariance block after a step without excitation."""
    x[ETA_:] = eta_keep
    P[ETA_:, :ETA_] = 0.0
    P[:ETA_, ETA_:] = 0.0
    P[ETA_:, ETA_:] = P_keep + np.diag(qc[ETA_:] * dt)

@dataclass(frozen=True)
class EKFConfig:
    """EKF tuning (defaults: reference ``motor_estimator_ekf.m``, facts sec. 5).

    Process-noise variances are per 1 ms step and scale with ``dt / 1 ms``.

    Attributes:
        q_eta: random-walk variance of each efficiency per 1 ms step [1] (the calibrated knob).
        q_position [m^2], q_velocity [(m/s)^2], q_rate [(rad/s)^2], q_rotation [1]: process
            noise of the kinematic states per 1 ms step.
        r_position [m^2], r_velocity [(m/s)^2], r_rate [(rad/s)^2], r_attitude [rad^2]:
            measurement-noise variances (the attitude value applies to each of its 3 rows).
        p0: initial covariance ``p0 * I``.
        eta0: initial efficiency (one value for all rotors, or one per rotor).
        eta_bounds: clamp of the efficiency after each update, or None for no clamp.
        clip_commands: clip the commanded thrusts to ``[0, vehicle.rotor_max_thrust]`` before
            use (as IRLS does: a saturated rotor cannot deliver its command); ``False`` = the
            reference code.
        backend: ``"auto"`` (numba when installed), ``"numpy"`` or ``"numba"``; same results.
    """

    q_eta: float = 0.5
    q_position: float = 1e-6
    q_velocity: float = 1e-3
    q_rate: float = 1e-4
    q_rotation: float = 1e-5
    r_position: float = 5e-2
    r_velocity: float = 5e-2
    r_rate: float = 5e-2
    r_attitude: float = 5e-2
    p0: float = 1e-2
    eta0: float | tuple = 1.0
    eta_bounds: tuple | None = (-0.001, 1.001)
    clip_commands: bool = True
    backend: str = "auto"

    def __post_init__(self):
        for key in ("q_eta", "q_position", "q_velocity", "q_rate", "q_rotation", "r_position",
                    "r_velocity", "r_rate", "r_attitude", "p0"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not (math.isfinite(value) and value > 0):
                raise ConfigError(f"EKFConfig.{key} must be a positive number, got {value!r}")
        if self.eta_bounds is not None:
            lo, hi = self.eta_bounds
            if not (lo < hi):
                raise ConfigError(f"EKFConfig.eta_bounds must be (low, high) with low < high, "
                                  f"got {self.eta_bounds!r}")
        if self.backend not in BACKENDS:
            raise ConfigError(f"EKFConfig.backend must be one of {BACKENDS}, got {self.backend!r}")

    @classmethod
    def reference(cls, **changes) -> "EKFConfig":
        """The reference code's settings, including its clamp ``[1e-3, 1 - 1e-3]``."""
        return replace(cls(eta_bounds=(1e-3, 1.0 - 1e-3), clip_commands=False), **changes)

    def replace(self, **changes) -> "EKFConfig":
        return replace(self, **changes)


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
        H[k, 3 * a:3 * a + 3] -= 0.5 * R_meas[:, b]
        H[k, 3 * b:3 * b + 3] += 0.5 * R_meas[:, a]
    return H


def predict(x: np.ndarray, P: np.ndarray, f: np.ndarray, dt: float, vehicle: Vehicle,
            Q: np.ndarray):
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
    x_pred = np.concatenate((p + v * dt + 0.5 * a * dt * dt, v + a * dt, w + wdot * dt,
                             R_new.reshape(9, order="F"), eta))
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


def kalman_update(x: np.ndarray, P: np.ndarray, y: np.ndarray, H: np.ndarray,
                  R: np.ndarray):
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


def measurement_update(x: np.ndarray, P: np.ndarray, sample: Sample, r_diag: np.ndarray,
                       bounds):
    """Update with the measured ``p, v, Omega`` and attitude; project R, clamp eta."""
    n = x.shape[0]
    R_est = x[R_].reshape(3, 3, order="F")
    y = np.concatenate((sample.p - x[P_], sample.v - x[V_], sample.w - x[W_],
                        logm_so3(R_est.T @ sample.R)))
    H = np.zeros((12, n))
    H[:9, :9] = np.eye(9)
    H[9:, R_] = attitude_jacobian(sample.R)
    x, P = kalman_update(x, P, y, H, np.diag(r_diag))
    x[R_] = orthonormalize(x[R_].reshape(3, 3, order="F")).reshape(9, order="F")
    if bounds is not None:
        x[ETA_:] = np.clip(x[ETA_:], bounds[0], bounds[1])
    return x, P


def _numba_available() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


class MotorEfficiencyEKF:
    """EKF over ``[p, v, Omega, vec(R), eta]`` (name ``"ekf"``); see the module docstring.

    Args:
        vehicle: the nominal vehicle (mass, inertia, allocation, gravity).
        config: :class:`EKFConfig`.
    """

    name = "ekf"

    def __init__(self, vehicle: Vehicle, config: EKFConfig | None = None):
        self.vehicle = vehicle
        self.config = config or EKFConfig()
        cfg = self.config
        self.n_rotors = vehicle.n_rotors
        if cfg.backend == "numba" and not _numba_available():
            raise ConfigError("EKFConfig.backend='numba' needs numba (install the 'fast' extra)")
        self.use_numba = cfg.backend == "numba" or (cfg.backend == "auto" and _numba_available())
        eta0 = np.broadcast_to(np.asarray(cfg.eta0, dtype=float), (self.n_rotors,)).copy()
        self._eta0_default = eta0
        self.q_diag = np.concatenate((np.full(3, cfg.q_position), np.full(3, cfg.q_velocity),
                                      np.full(3, cfg.q_rate), np.full(9, cfg.q_rotation),
                                      np.full(self.n_rotors, cfg.q_eta)))
        self.r_diag = np.concatenate((np.full(3, cfg.r_position), np.full(3, cfg.r_velocity),
                                      np.full(3, cfg.r_rate), np.full(3, cfg.r_attitude)))
        self.reset()

    @property
    def n_states(self) -> int:
        return 18 + self.n_rotors

    def reset(self, eta0=None) -> None:
        """Forget everything; the next sample initialises the kinematic states."""
        eta = self._eta0_default if eta0 is None else np.asarray(eta0, dtype=float)
        if eta.shape != (self.n_rotors,) or not np.all(np.isfinite(eta)):
            raise ConfigError(f"eta0 must be {self.n_rotors} finite values, got {eta0!r}")
        self._eta_init = eta.copy()
        self.x = None
        self.P = None
        self._last = None  # (t, f) of the previous sample

    def _initialise(self, sample: Sample) -> None:
        self.x = np.concatenate((sample.p, sample.v, sample.w,
                                 np.asarray(sample.R, float).reshape(9, order="F"),
                                 self._eta_init))
        self.P = self.config.p0 * np.eye(self.n_states)

    def _estimate(self, t, status) -> Estimate:
        eta = self.x[ETA_:].copy() if self.x is not None else self._eta_init.copy()
        sd = np.sqrt(np.diag(self.P)[ETA_:]) if self.P is not None else None
        return Estimate(t=float(t), eta=eta, sd=sd, status=status)

    def update(self, sample: Sample) -> Estimate:
        """One predict (from the previous sample, its command held) and one update."""
        shapes = [np.shape(a) for a in (sample.p, sample.v, sample.R, sample.w, sample.f)]
        if shapes != [(3,), (3,), (3, 3), (3,), (self.n_rotors,)]:
            raise ConfigError(f"EKF: sample at t = {sample.t} has shapes {shapes}; expected "
                              f"p, v, w (3,), R (3, 3), f ({self.n_rotors},)")
        finite = all(np.all(np.isfinite(a)) for a in (sample.p, sample.v, sample.R, sample.w,
                                                      sample.f)) and math.isfinite(sample.t)
        if not finite:
            return self._estimate(sample.t, STATUS_BAD_SAMPLE)
        if self.x is None:
            self._initialise(sample)
            self._last = (float(sample.t), self._commands(sample.f))
            return self._estimate(sample.t, STATUS_WARMUP)
        t_prev, f_prev = self._last
        dt = float(sample.t) - t_prev
        if not dt > 0:  # a repeated or decreasing time stamp: skip it, keep the state
            return self._estimate(sample.t, STATUS_BAD_SAMPLE)
        idle = bool(np.any(f_prev <= IDLE_THRUST))
        if idle:
            eta_keep, P_keep = self.x[ETA_:].copy(), self.P[ETA_:, ETA_:].copy()
        if self.use_numba:
            from estimators.ekf_numba import step_inplace

            step_inplace(self.x, self.P, f_prev, dt, sample.p, sample.v, sample.w,
                         np.ascontiguousarray(sample.R, dtype=float), *self._kernel_args())
        else:
            Q = np.diag(self.q_diag * (dt / NOISE_REFERENCE_DT))
            x, P, _ = predict(self.x, self.P, f_prev, dt, self.vehicle, Q)
            self.x, self.P = measurement_update(x, P, sample, self.r_diag, self.config.eta_bounds)
        if idle:
            _freeze_eta(self.x, self.P, eta_keep, P_keep, self.q_diag / NOISE_REFERENCE_DT, dt)
        self._last = (float(sample.t), self._commands(sample.f))
        return self._estimate(sample.t, STATUS_NO_EXCITATION if idle else STATUS_OK)

    def _commands(self, f) -> np.ndarray:
        f = np.array(f, dtype=float)
        if self.config.clip_commands:
            f = np.clip(f, 0.0, self.vehicle.rotor_max_thrust)
        return f

    def _kernel_args(self):
        veh, b = self.vehicle, self.config.eta_bounds
        lo, hi = (-np.inf, np.inf) if b is None else (float(b[0]), float(b[1]))
        return (np.ascontiguousarray(veh.allocation), veh.mass, veh.gravity,
                np.ascontiguousarray(veh.inertia), np.ascontiguousarray(veh.inertia_inverse),
                self.q_diag / NOISE_REFERENCE_DT, self.r_diag, lo, hi)

    def run(self, recording: Recording, progress: bool = False) -> EstimateSeries:
        """Estimates at every row of ``recording`` (row 0 is the initial guess, ``warmup``)."""
        start = time.perf_counter()
        self.reset(self._eta_init)
        n = len(recording)
        if self.use_numba and n > 0 and recording.has_pose:
            eta, sd, ok = self._run_numba(recording)
            status = np.full(n, STATUS_BAD_SAMPLE, dtype=f"<U{_STATUS_WIDTH}")
            status[ok] = STATUS_OK
            # a row whose predict used an idle rotor's command (previous good row)
            rows = np.flatnonzero(ok)
            idle = np.any(self._commands(recording.thrust_cmd) <= IDLE_THRUST, axis=1)
            status[rows[1:][idle[rows[:-1]]]] = STATUS_NO_EXCITATION
            if ok.any():
                status[int(np.argmax(ok))] = STATUS_WARMUP  # the row that initialised x
        else:
            eta, sd = np.empty((n, self.n_rotors)), np.empty((n, self.n_rotors))
            status = np.empty(n, dtype=object)
            bar = None
            if progress:
                from quadfault.progress import progress_bar

                bar = progress_bar(total=n, desc="ekf", unit="sample")
            for k, s in enumerate(samples(recording)):
                est = self.update(s)
                eta[k], status[k] = est.eta, est.status
                sd[k] = est.sd if est.sd is not None else np.nan
                if bar is not None and k % 1000 == 999:
                    bar.update(1000)
            if bar is not None:
                bar.close()
        return EstimateSeries(t=np.array(recording.t, dtype=float), eta=eta, sd=sd,
                              status=status.astype(str), estimator=self.name,
                              config=self.describe(), seconds=time.perf_counter() - start)

    def _run_numba(self, recording: Recording):
        from estimators.ekf_numba import run_series

        R = np.ascontiguousarray(recording.rotation, dtype=float)
        args = [np.ascontiguousarray(a, dtype=float) for a in (
            recording.t, recording.position, recording.velocity, recording.omega,
            self._commands(recording.thrust_cmd))]
        x0 = np.empty(self.n_states)
        P0 = self.config.p0 * np.eye(self.n_states)
        eta, sd, ok, x, P, k_last = run_series(*args[:3], R, *args[3:], self._eta_init.copy(),
                                               x0, P0, *self._kernel_args())
        if k_last >= 0:
            self.x, self.P = x, P
            self._last = (float(recording.t[k_last]), args[4][k_last].copy())
        return eta, sd, ok

    def describe(self) -> dict:
        """JSON-ready description (for sidecars and reports)."""
        cfg = asdict(self.config)
        cfg["eta_bounds"] = None if cfg["eta_bounds"] is None else list(cfg["eta_bounds"])
        cfg["eta0"] = self._eta0_default.tolist()
        cfg["backend_used"] = "numba" if self.use_numba else "numpy"
        return cfg
