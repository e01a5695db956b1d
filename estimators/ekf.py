"""Extended Kalman filter baseline for motor efficiency (paper Sec. "EKF Baseline").

State (22 for four rotors), as in the paper and the reference ``motor_estimator_ekf.m``::

    x = [p (3); v (3); Omega (3); vec(R) (9, column-major); eta (n)]

with the efficiencies as a random walk (``eta' = w_eta``, ``w_eta ~ N(0, Q_eta)``). One
update per measurement row: predict from row k-1 to row k with the command of row k-1 held
over ``dt_k = t_k - t_{k-1}`` (zero-order hold, docs/formats.md), then update with the
pose and rate measured at row k. The estimate's ``t`` is ``t_k``.

Deviations from the reference code (each discussed in ``docs/ekf.md``):

* attitude measurement: 3 rows, innovation ``y = log(R_pred^T R_meas)`` with the Jacobian of
  the skew part (constant and well-defined at zero error), instead of the one-sided scalar
  ``acos((tr(R^T R_m) - 1) / 2)`` whose Jacobian is singular at zero;
* attitude prediction with the exponential map at the mid-step rate
  (``R_pred = R exp([Omega dt + Omega' dt^2 / 2]x)``) instead of ``R + R [Omega]x dt`` + SVD;
* full gyroscopic block in ``F`` (the reference leaves ``dOmega/dOmega = I``);
* the covariance update in the square-root form of the optimal gain (``S = L L^T``,
  ``W = L^-1 H P``, ``P = P - W^T W``, symmetric by construction; no inverse), the predicted
  covariance from the structure of ``F`` (:mod:`estimators.ekf_filter`);
* the recording's allocation matrix and per-sample ``dt``; process noise scaled by
  ``dt / 1 ms`` so the reference's per-step values are the defaults at 1 kHz;
* efficiency clamp ``[-0.001, 1.001]`` (the IRLS bounds) by default;
  ``EKFConfig.reference()`` restores the reference's ``[1e-3, 1 - 1e-3]``.

One update per sample is :func:`ekf_step` (plain Python compiled by :func:`quadfault.jit.jit`)
on the state of one filter in a flat buffer (:class:`EKFState`); the single filter, its
offline :meth:`MotorEfficiencyEKF.run` (:func:`ekf_run`) and the batched filter
(:class:`estimators.batched.BatchedEKF`) all run it.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, replace

import numpy as np

from estimators.accelerometer import (
    NO_ACCEL,
    check_mode,
    finite3,
    recording_accel,
    warn_missing,
)
from estimators.base import (
    BAD_SAMPLE,
    NO_EXCITATION,
    OK,
    STATUSES,
    WARMUP,
    Estimate,
    EstimateSeries,
    Sample,
    command_limit,
    sample_accel,
    sample_arrays,
)
from estimators.ekf_filter import (
    BLOCKS,
    EFFICIENCY,
    MATS,
    N_VEC_R,
    SQUARES,
    VECS,
    WORKSPACE,
    Measurement,
    Model,
    Workspace,
    X,
    Y,
    predict_update_accel_into,
    predict_update_into,
)
from estimators.freshness import (
    SAMPLE,
    accel_fresh,
    fresh_since,
    measurement_variances_into,
    remember_into,
)
from estimators.options import check_bounds, check_finite, check_positive, from_options
from estimators.recursive import recording_arrays, run_filter
from estimators.state import (
    FlatState,
    Layout,
    all_finite,
    fields,
    pack,
    piece,
    piece_rows,
    reset_rows,
)
from quadfault.errors import ConfigError
from quadfault.io.recording import Recording
from quadfault.jit import jit
from quadfault.model.rotation import mat3
from quadfault.model.vehicle import Vehicle

#: Sample period the per-step noise values refer to [s] (the reference's 1 kHz).
NOISE_REFERENCE_DT = 1e-3

#: A rotor commanded at most this thrust [N] carries no information on its efficiency. A step
#: whose command has such a rotor leaves the whole efficiency vector where it was (status
#: ``no_excitation``): the kinematic states are filtered as usual, the efficiencies are held,
#: decorrelated from the kinematic states, and their variance grows by Q_eta dt.
IDLE_THRUST = 1e-3


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
        eta_bounds: clamp of the efficiency after each update, or None for no clamp. The
            default lets a rotor read up to 20 % above nominal: a clamp at 1 truncates the
            filter's state on every healthy rotor and biases it low, the more so the noisier
            the sensors (docs/ekf.md, "Bounds").
        clip_commands: clip the commanded thrusts to ``[0, vehicle.rotor_max_thrust]`` before
            use (as IRLS does: a saturated rotor cannot deliver its command; ``run(recording)``
            clips above only when the recording does not say its flight was unsaturated,
            :func:`estimators.base.command_limit`); ``False`` = the reference code.
        accelerometer: beyond the paper: also measure the accelerometer's body-z specific
            force, ``-T(eta) / m`` for the sample's own command (the thrust it feels), one
            row linear in the efficiencies (docs/ekf.md, "Accelerometer";
            :mod:`estimators.accelerometer`): ``"off"`` not (the paper), ``"auto"`` wherever
            a sample has a reading, ``"on"`` the same, and a recording or sample without one
            is said once. True / False mean ``"on"`` / ``"off"``.
        r_accel: that row's measurement-noise variance [(m/s^2)^2] at zero thrust: the
            accelerometer's noise and vibration.
        accel_scatter: the relative scatter [1] of each rotor's thrust about what the filter
            predicts from its command: the row's variance grows by
            ``accel_scatter^2 sum_j (A[0, j] f_j / m)^2``. The default is larger than the
            log-thrust noise of the simulator (0.07): the same scatter moves the velocity and
            the rate the filter predicts, which its process noise does not carry
            (docs/ekf.md, "Accelerometer").
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
    eta_bounds: tuple | None = (-0.001, 1.2)
    clip_commands: bool = True
    accelerometer: str = "off"
    r_accel: float = 0.1
    accel_scatter: float = 0.5

    def __post_init__(self):
        object.__setattr__(self, "accelerometer", check_mode("EKFConfig", self.accelerometer))
        check_positive(
            self,
            "q_eta",
            "q_position",
            "q_velocity",
            "q_rate",
            "q_rotation",
            "r_position",
            "r_velocity",
            "r_rate",
            "r_attitude",
            "r_accel",
            "p0",
        )
        check_bounds("EKFConfig", self.eta_bounds)
        check_finite(self, "accel_scatter")
        if self.accel_scatter < 0:
            raise ConfigError(f"EKFConfig.accel_scatter must be >= 0, got {self.accel_scatter!r}")

    @classmethod
    def from_options(
        cls, q_eta: float | None = None, accelerometer: str | bool | None = None
    ) -> EKFConfig:
        """The configuration of ``quadfault estimate``'s options (the registry's
        ``from_options``): ``q_eta`` the efficiency random walk per 1 ms step,
        ``accelerometer`` the accelerometer's row (:data:`estimators.accelerometer.MODES`)."""
        return from_options(cls, q_eta=q_eta, accelerometer=accelerometer)

    @classmethod
    def reference(cls, **changes) -> EKFConfig:
        """The reference code's settings, including its clamp ``[1e-3, 1 - 1e-3]``."""
        return replace(cls(eta_bounds=(1e-3, 1.0 - 1e-3), clip_commands=False), **changes)

    def replace(self, **changes) -> EKFConfig:
        return replace(self, **changes)


#: the float state of one filter: the state ``x`` (:data:`estimators.ekf_filter.X`) and its
#: covariance ``P``, the previous sample's time and (clipped) command, the initial
#: efficiency, the efficiencies kept across an idle step, then the workspace of
#: :func:`predict_update_into` (dimensions: rotors ``n``, states ``ns = X.size + n``)
FLOATS = Layout(
    "EKFPieces",
    x=("ns",),
    P=("ns", "ns"),
    last_t=(1,),
    last_f=("n",),
    eta0=("n",),
    eta_keep=("n",),
    P_keep=("n", "n"),
    last_z=(SAMPLE.size, 3),  # the previous sample (estimators.freshness)
    last_a=(3,),  # the previous accelerometer reading
    ha=("n",),  # the accelerometer row's Jacobian on the efficiencies
    r_now=(Y.size,),  # the measurement variances of this update
    **WORKSPACE.declared,
)
F = FLOATS.index
EKFPieces = FLOATS.pieces
#: the int state: 1 once the first good sample set the kinematic states
COUNTERS = fields("EKFCounters", "initialised")
#: the constants: scalars (``accel`` 1: measure the accelerometer), the inertia and its
#: inverse, the measurement-noise variances ``r``; last the arrays sized by the rotors: the
#: allocation ``A`` (4, n), then the process-noise variance rates ``qc`` (ns,) [1/s]
#: (:func:`constant_arrays`)
CONSTANTS = fields(
    "EKFConstants",
    "mass",
    "gravity",
    "f_max",
    "clip",
    "lo",
    "hi",
    "p0",
    "accel",
    "scatter",
    ("J", 9),
    ("Jinv", 9),
    ("r", Y.size),
    ("per_rotor", 0),
)


class EKFState(FlatState):
    """The state of ``N`` filters in a float and an int buffer
    (:class:`estimators.state.FlatState`), with numpy views of the pieces, each
    ``(N, *shape)``: ``x``, ``P``, the previous sample's time and (clipped)
    command, the initial efficiency, the efficiencies kept across an idle step, and the
    workspace of :func:`predict_update_into`."""

    def __init__(self, n: int, num: int = 1):
        super().__init__(FLOATS.shapes(n=n, ns=X.size + n), num, COUNTERS.size, FLOATS.pieces)


@jit
def state_pieces(fs, offsets, n, N):
    """The pieces of the float state of ``N`` filters (:data:`FLOATS`) by name, each
    ``(N, *shape)``."""
    ns, o, nm = X.size + n, offsets, Y.size
    return EKFPieces(
        x=piece_rows(fs, o[F.x], o[F.x + 1], N),
        P=piece(fs, o, F.P, (N, ns, ns)),
        last_t=piece_rows(fs, o[F.last_t], o[F.last_t + 1], N),
        last_f=piece_rows(fs, o[F.last_f], o[F.last_f + 1], N),
        eta0=piece_rows(fs, o[F.eta0], o[F.eta0 + 1], N),
        eta_keep=piece_rows(fs, o[F.eta_keep], o[F.eta_keep + 1], N),
        P_keep=piece(fs, o, F.P_keep, (N, n, n)),
        last_z=piece(fs, o, F.last_z, (N, SAMPLE.size, 3)),
        last_a=piece_rows(fs, o[F.last_a], o[F.last_a + 1], N),
        ha=piece_rows(fs, o[F.ha], o[F.ha + 1], N),
        r_now=piece_rows(fs, o[F.r_now], o[F.r_now + 1], N),
        mats=piece(fs, o, F.mats, (N, MATS.size, ns, ns)),
        blocks=piece(fs, o, F.blocks, (N, BLOCKS.size, 3, 3)),
        vecs=piece(fs, o, F.vecs, (N, VECS.size, ns)),
        squares=piece(fs, o, F.squares, (N, SQUARES.size, nm, nm)),
        efficiency=piece(fs, o, F.efficiency, (N, EFFICIENCY.size, n, 3)),
        dT=piece_rows(fs, o[F.dT], o[F.dT + 1], N),
        dR=piece(fs, o, F.dR, (N, N_VEC_R, 3)),
        Z=piece(fs, o, F.Z, (N, 3, ns)),
        y=piece_rows(fs, o[F.y], o[F.y + 1], N),
        HR=piece(fs, o, F.HR, (N, Y.a - Y.R, N_VEC_R)),
        HP=piece(fs, o, F.HP, (N, nm, ns)),
        WT=piece(fs, o, F.WT, (N, ns, nm)),
    )


@jit(inline="always")
def workspace_row(S, i):
    """The workspace of filter ``i`` (:class:`estimators.ekf_filter.Workspace`)."""
    return Workspace(
        mats=S.mats[i],
        blocks=S.blocks[i],
        vecs=S.vecs[i],
        squares=S.squares[i],
        efficiency=S.efficiency[i],
        dT=S.dT[i],
        dR=S.dR[i],
        Z=S.Z[i],
        y=S.y[i],
        HR=S.HR[i],
        HP=S.HP[i],
        WT=S.WT[i],
    )


@jit
def constant_arrays(const, n):
    """The filter's :class:`~estimators.ekf_filter.Model` from the constants (views of
    ``const``, :func:`ekf_constants`)."""
    C, ns = CONSTANTS, X.size + n
    J, Jinv = const[C.J : C.Jinv].reshape((3, 3)), const[C.Jinv : C.r].reshape((3, 3))
    a = C.per_rotor  # A (4, n), then qc (ns,)
    return Model(
        (const[C.mass], const[C.gravity], mat3(J), mat3(Jinv)),
        J,
        Jinv,
        const[a : a + 4 * n].reshape((4, n)),
        const[a + 4 * n : a + 4 * n + ns],
        const[C.r : C.per_rotor],
        const[C.lo],
        const[C.hi],
    )


@jit
def ekf_step(t, p, v, R, w, f, sf, const, model, S, ks, i) -> int:
    """One sample into filter ``i`` of the state ``(S, ks)`` (:func:`state_pieces`), in place;
    returns the status code. A non-finite sample or a time not after the previous one is
    skipped (``bad_sample``); the first good sample sets the kinematic states (``warmup``);
    later ones predict from the previous sample, its command held, and update
    (:func:`predict_update_into`); a step whose command had an idle rotor (``<= IDLE_THRUST``)
    keeps the efficiencies, decorrelated, their variance grown by ``Q_eta dt``
    (``no_excitation``). ``model`` is :func:`constant_arrays` of ``const``. ``sf``: the
    accelerometer's reading (3 floats) [m/s^2], body FRD, read only when the constants say so
    (``accel``); a non-finite or held reading (:func:`estimators.freshness.accel_fresh`)
    is not measured."""
    n = f.shape[0]
    ns = X.size + n
    x, P, last_t, last_f = S.x[i], S.P[i], S.last_t[i], S.last_f[i]
    clip, f_max = const[CONSTANTS.clip] != 0.0, const[CONSTANTS.f_max]
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
            x[X.p + a], x[X.v + a], x[X.w + a] = p[a], v[a], w[a]
            for b in range(3):
                x[X.Re1 + 3 * b + a] = R[a, b]  # vec(R), column-major
        for j in range(n):
            x[X.eta + j] = eta0[j]
        for a in range(ns):
            for b in range(ns):
                P[a, b] = const[CONSTANTS.p0] if a == b else 0.0
        ks[i, COUNTERS.initialised] = 1
        code = WARMUP
    else:
        dt = t - last_t[0]
        if not dt > 0:
            return BAD_SAMPLE
        idle = False
        for j in range(n):
            idle = idle or last_f[j] <= IDLE_THRUST
        keep, P_keep, e = S.eta_keep[i], S.P_keep[i], X.eta
        if idle:
            for j in range(n):
                keep[j] = x[e + j]
                for k in range(n):
                    P_keep[j, k] = P[e + j, e + k]
        # a held stream (its sample repeated, estimators.freshness) is not measured again
        r_now = S.r_now[i]
        measurement_variances_into(
            model.r, fresh_since(p, v, R, w, S.last_z[i]), Y.p, Y.v, Y.R, Y.w, r_now
        )
        step_model = Model(
            model.rigid, model.J, model.Jinv, model.A, model.qc, r_now, model.lo, model.hi
        )
        # the accelerometer: the body-z specific force of this sample's command, -T(eta) / m
        ha, rows = last_f, Y.a  # (ha unread without the accelerometer)
        if const[CONSTANTS.accel] != 0.0 and finite3(sf) and accel_fresh(sf, S.last_a[i], v):
            ha, rows = S.ha[i], Y.size
            h2 = 0.0
            for j in range(n):
                fj = min(max(f[j], 0.0), f_max) if clip else f[j]
                ha[j] = -model.A[0, j] * fj / const[CONSTANTS.mass]
                h2 += ha[j] * ha[j]
            r_now[Y.a] += const[CONSTANTS.scatter] * const[CONSTANTS.scatter] * h2
        z = Measurement(p, v, w, R, sf[2], ha, rows)
        if rows == Y.size:
            predict_update_accel_into(x, P, last_f, dt, z, step_model, workspace_row(S, i))
        else:
            predict_update_into(x, P, last_f, dt, z, step_model, workspace_row(S, i))
        code = OK
        if idle:  # the efficiencies stay, decorrelated; their variance grows by Q_eta dt
            for j in range(n):
                x[e + j] = keep[j]
                for k in range(e):
                    P[e + j, k] = 0.0
                    P[k, e + j] = 0.0
                for k in range(n):
                    P[e + j, e + k] = P_keep[j, k]
                P[e + j, e + j] += model.qc[e + j] * dt
            code = NO_EXCITATION
    last_t[0] = t
    remember_into(S.last_z[i], p, v, R, w)
    if const[CONSTANTS.accel] != 0.0:
        for k in range(3):
            S.last_a[i][k] = sf[k]
    for j in range(n):
        last_f[j] = min(max(f[j], 0.0), f_max) if clip else f[j]
    return code


@jit
def ekf_reset(ip_offsets, n, fs, ks, rows, eta0) -> None:
    """Forget the filters ``rows``; the next good sample initialises them, with the
    efficiencies ``eta0`` (N, n)."""
    reset_rows(ip_offsets, F.eta0, COUNTERS.initialised, n, fs, ks, rows, eta0)


@jit
def ekf_update_row(t, p, v, R, w, f, sf, const, offsets, fs, ks, i) -> int:
    """:func:`ekf_step` of filter ``i`` of the state ``(fs, ks)``, its pieces and model formed
    here (a batch's rows run it under ``prange``: the records are formed inside the loop);
    ``sf`` the accelerometer's reading (3 floats)."""
    S = state_pieces(fs, offsets, f.shape[0], ks.shape[0])
    return ekf_step(t, p, v, R, w, f, sf, const, constant_arrays(const, f.shape[0]), S, ks, i)


@jit
def ekf_update(t, p, v, R, w, f, a, const, offsets, fs, ks) -> int:
    """:func:`ekf_step` of a single filter (the online update)."""
    return ekf_update_row(
        t, p, v, R, w, f, (a[0], a[1], a[2]), const, offsets, fs, ks, ks.shape[0] - 1
    )  # row 0, a run-time value like the batch's rows


@jit
def ekf_run(t, p, v, R, w, f, a, const, offsets, fs, ks, eta, sd, code) -> None:
    """:func:`ekf_step` over the rows of a recording (a single filter's state): the estimate
    (the initial efficiency before the first good sample), its sd (NaN before it) and the
    status code of every row. ``a``: the accelerometer's rows (len(t), 3)."""
    n = f.shape[1]
    S = state_pieces(fs, offsets, n, ks.shape[0])
    row = ks.shape[0] - 1  # 0, a run-time value like the batch's rows
    x, P, eta0 = S.x[row], S.P[row], S.eta0[row]
    model = constant_arrays(const, n)
    for k in range(t.shape[0]):
        sf = (a[k, 0], a[k, 1], a[k, 2])  # (scalars: no view per row)
        code[k] = ekf_step(t[k], p[k], v[k], R[k], w[k], f[k], sf, const, model, S, ks, row)
        for j in range(n):
            if ks[row, COUNTERS.initialised] == 1:
                eta[k, j] = x[X.eta + j]
                sd[k, j] = math.sqrt(P[X.eta + j, X.eta + j])
            else:
                eta[k, j] = eta0[j]
                sd[k, j] = np.nan


class MotorEfficiencyEKF:
    """EKF over ``[p, v, Omega, vec(R), eta]`` (name ``"ekf"``); see the module docstring.

    Args:
        vehicle: the nominal vehicle (mass, inertia, allocation, gravity).
        config: :class:`EKFConfig`.
    """

    name = "ekf"

    def __init__(self, vehicle: Vehicle, config: EKFConfig | None = None):
        if not isinstance(vehicle, Vehicle):
            raise ConfigError(f"MotorEfficiencyEKF needs a Vehicle, got {type(vehicle).__name__}")
        self.vehicle = vehicle
        self.config = config or EKFConfig()
        if not isinstance(self.config, EKFConfig):
            raise ConfigError("config must be an EKFConfig")
        self.n_rotors = vehicle.n_rotors
        self._eta0_default = default_eta0(self.config, self.n_rotors)
        self._const = ekf_constants(vehicle, self.config)
        cfg, n = self.config, self.n_rotors
        #: process-noise variances per 1 ms step (diagonal of Q at dt = 1 ms)
        self.q_diag = process_noise(cfg, n)
        #: measurement-noise variances (p, v, Omega, attitude rows)
        self.r_diag = measurement_noise(cfg)
        self._state = EKFState(self.n_rotors)
        self._said_missing = False  # accelerometer "on" and a sample without one: said once
        self.reset()

    @property
    def n_states(self) -> int:
        return X.size + self.n_rotors

    @property
    def x(self) -> np.ndarray | None:
        """The state ``[p, v, Omega, vec(R), eta]`` (None before the first good sample)."""
        return self._state.views.x[0] if self._state.ints[0, COUNTERS.initialised] else None

    @property
    def P(self) -> np.ndarray | None:
        """The state covariance (None before the first good sample)."""
        return self._state.views.P[0] if self._state.ints[0, COUNTERS.initialised] else None

    def reset(self, eta0=None) -> None:
        """Forget everything; the next sample initialises the kinematic states."""
        eta = self._eta0_default if eta0 is None else np.asarray(eta0, dtype=float)
        if eta.shape != (self.n_rotors,) or not np.all(np.isfinite(eta)):
            raise ConfigError(f"eta0 must be {self.n_rotors} finite values, got {eta0!r}")
        st = self._state
        ekf_reset(st.offsets, self.n_rotors, st.floats, st.ints, _ROW0, eta[None])

    def _estimate(self, t, code) -> Estimate:
        views = self._state.views
        if self._state.ints[0, COUNTERS.initialised]:
            eta = views.x[0, X.eta :].copy()
            sd = np.sqrt(np.diagonal(views.P[0])[X.eta :])
        else:
            eta, sd = views.eta0[0].copy(), None
        return Estimate(t=float(t), eta=eta, sd=sd, status=STATUSES[code])

    def update(self, sample: Sample) -> Estimate:
        """One predict (from the previous sample, its command held) and one update (with
        the sample's accelerometer reading when configured so)."""
        t, p, v, R, w, f = sample_arrays(sample, self.n_rotors, "EKF")
        a = NO_ACCEL
        if self.config.accelerometer != "off":
            reading = sample_accel(sample, "EKF")
            if reading is not None:
                a = reading
            elif self.config.accelerometer == "on" and not self._said_missing:
                warn_missing("EKF", f"the sample at t = {t}")
                self._said_missing = True
        st = self._state
        code = ekf_update(t, p, v, R, w, f, a, self._const, st.offsets, st.floats, st.ints)
        return self._estimate(t, code)

    def run(self, recording: Recording, progress: bool = False) -> EstimateSeries:
        """Estimates at every row of ``recording`` (row 0 is the initial guess, ``warmup``);
        the filter is left at the end of the recording."""
        start = time.perf_counter()
        arrays = recording_arrays(recording, self.n_rotors, self.name)
        arrays = (*arrays, recording_accel(recording, self.config.accelerometer, self.name))
        const = self._const.copy()
        const[CONSTANTS.f_max] = command_limit(recording, self.vehicle)  # its saturation
        self.reset(self._state.views.eta0[0].copy())
        return run_filter(self, ekf_run, arrays, const, progress, start)

    def describe(self) -> dict:
        """JSON-ready description (for sidecars and reports)."""
        cfg = asdict(self.config)
        cfg["eta_bounds"] = None if cfg["eta_bounds"] is None else list(cfg["eta_bounds"])
        cfg["eta0"] = self._eta0_default.tolist()
        return cfg


def default_eta0(cfg: EKFConfig, n: int) -> np.ndarray:
    """``EKFConfig.eta0`` as one value per rotor."""
    try:
        return np.broadcast_to(np.asarray(cfg.eta0, dtype=float), (n,)).copy()
    except ValueError:
        raise ConfigError(f"EKFConfig.eta0 must be one value or {n}, got {cfg.eta0!r}") from None


def process_noise(cfg: EKFConfig, n: int) -> np.ndarray:
    """The process-noise variances per 1 ms step of the states :data:`X` (``n`` rotors)."""
    return pack(
        X,
        n,
        p=np.full(3, cfg.q_position),
        v=np.full(3, cfg.q_velocity),
        w=np.full(3, cfg.q_rate),
        Re1=np.full(3, cfg.q_rotation),
        Re2=np.full(3, cfg.q_rotation),
        Re3=np.full(3, cfg.q_rotation),
        eta=np.full(n, cfg.q_eta),
    )


def measurement_noise(cfg: EKFConfig) -> np.ndarray:
    """The measurement-noise variances of the rows :data:`Y` (the attitude's value on each
    of its 3 rows; the accelerometer's row last)."""
    return pack(
        Y,
        p=np.full(3, cfg.r_position),
        v=np.full(3, cfg.r_velocity),
        w=np.full(3, cfg.r_rate),
        R=np.full(3, cfg.r_attitude),
        a=np.full(1, cfg.r_accel),
    )


def ekf_constants(vehicle: Vehicle, cfg: EKFConfig) -> np.ndarray:
    """The constants of :func:`ekf_step`: mass, gravity, rotor_max_thrust, clip, the clamp,
    p0, the allocation, the inertia and its inverse, the process-noise variance rates
    ``qc`` [1/s] (per 1 ms values divided by 1 ms) and the measurement-noise variances."""
    n = vehicle.n_rotors
    b = cfg.eta_bounds
    lo, hi = (-np.inf, np.inf) if b is None else (float(b[0]), float(b[1]))
    q, r = process_noise(cfg, n), measurement_noise(cfg)
    per_rotor = np.concatenate(
        (np.asarray(vehicle.allocation, dtype=float).ravel(), q / NOISE_REFERENCE_DT)
    )  # A, then qc (constant_arrays)
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
        J=vehicle.inertia,
        Jinv=vehicle.inertia_inverse,
        r=r,
        per_rotor=per_rotor,
    )


_ROW0 = np.zeros(1, dtype=np.int64)
