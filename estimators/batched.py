"""Batched motor-efficiency estimators: N independent estimators updated in one call.

:class:`BatchedIRLS` is N copies of :class:`estimators.irls.SlidingWindowIRLS` and
:class:`BatchedEKF` N copies of :class:`estimators.ekf.MotorEfficiencyEKF`, so the vectorised
environment keeps an estimate in every observation. Nothing of the algorithms is written
again: the state of the N estimators is the single estimator's state with a leading batch
axis, and one update is a ``prange`` over the rows of the single estimator's compiled step
(:func:`estimators.irls.irls_step`, :func:`estimators.ekf.ekf_step`). Row i of a batch fed
the samples of vehicle i therefore gives the single estimator's estimates, statuses and
uncertainties, every online rule included (warm-up, ``no_excitation`` / ``bad_sample``
guards, idle rotors, and with ``IRLSConfig.improved()`` the change completion and the causal
output median).

Inputs of :meth:`update` are the N samples of one instant: ``t`` (N,) [s], ``p``, ``v``
(N, 3) world NED [m], [m/s], ``R`` (N, 3, 3) body FRD -> world, ``w`` (N, 3) [rad/s] and
``f`` (N, n) commanded rotor thrusts [N] held from ``t`` until the next sample.
"""

from __future__ import annotations

import warnings

import numpy as np

from estimators.accelerometer import warn_missing
from estimators.base import (
    STATUSES,
    BatchedEstimate,
    batch_accel,
    batch_arrays,
    batch_eta0,
    check_num,
    reset_rows,
)
from estimators.change_completion import COUNTERS as COMPLETION_COUNTERS
from estimators.ekf import COUNTERS as EKF_COUNTERS
from estimators.ekf import (
    EKFConfig,
    EKFState,
    default_eta0,
    ekf_constants,
    ekf_reset,
    ekf_update_row,
)
from estimators.ekf_filter import X
from estimators.ipm import any_size
from estimators.irls import (
    COUNTERS,
    VN_ROWS,
    IRLSConfig,
    IRLSState,
    beyond_paper,
    irls_parameters,
    irls_step,
    named_pieces,
    state_views,
)
from estimators.irls import constant_arrays as irls_constant_arrays
from estimators.registry import make_estimator
from estimators.window import no_history
from quadfault.errors import ConfigError
from quadfault.jit import jit, prange
from quadfault.model.vehicle import Vehicle

CODE = {name: k for k, name in enumerate(STATUSES)}  # status name -> integer code


@jit(parallel=True)
def irls_update_rows(t, p, v, R, w, f, a, const, fp, ip, fs, ks, hist, beyond, any_n, code):
    """:func:`estimators.irls.irls_step` of every row, in parallel; status codes into
    ``code``."""
    N = ks.shape[0]
    views = state_views(fs, ip, N)  # formed once; a prange captures plain tuples only
    arrays = irls_constant_arrays(const, ip)
    for i in prange(N):
        code[i] = irls_step(
            t[i],
            p[i],
            v[i],
            R[i],
            w[i],
            f[i],
            a[i],
            const,
            arrays,
            fp,
            ip,
            named_pieces(views),
            ks,
            np.int64(i),
            hist,
            beyond,
            any_n,
        )[0]


@jit(parallel=True)
def ekf_update_rows(t, p, v, R, w, f, a, const, offsets, fs, ks, code):
    """:func:`estimators.ekf.ekf_step` of every row, in parallel (``a`` (N, 3): the
    accelerometer's readings); status codes into ``code``."""
    for i in prange(ks.shape[0]):
        sf = (a[i, 0], a[i, 1], a[i, 2])
        code[i] = ekf_update_row(
            t[i], p[i], v[i], R[i], w[i], f[i], sf, const, offsets, fs, ks, np.int64(i)
        )


class BatchedIRLS:
    """N sliding-window IRLS estimators (the paper's Algorithm 2) updated together.

    Args:
        vehicle: the *nominal* vehicle.
        num: number of vehicles N.
        config: :class:`~estimators.irls.IRLSConfig` shared by all rows (``record_history``
            is not supported). With the options beyond the paper (``IRLSConfig.improved()``)
            the returned ``eta`` is the filtered estimate and :attr:`eta` the unfiltered one.
    """

    name = "irls"

    def __init__(self, vehicle: Vehicle, num: int, config: IRLSConfig | None = None):
        if not isinstance(vehicle, Vehicle):
            raise ConfigError(f"BatchedIRLS needs a Vehicle, got {type(vehicle).__name__}")
        self.vehicle = vehicle
        self.num = check_num(num)
        self.config = config or IRLSConfig()
        if not isinstance(self.config, IRLSConfig):
            raise ConfigError("config must be an IRLSConfig")
        if self.config.record_history:
            raise ConfigError("BatchedIRLS does not record KKT histories (record_history=True)")
        cfg, n = self.config, vehicle.n_rotors
        self._state = IRLSState(cfg.window - 1, n, cfg.output_median, cfg.max_irls, self.num)
        self._const, self._fp, self._ip = irls_parameters(vehicle, cfg, self._state.offsets)
        self._hist = no_history(n)
        self._beyond, self._any_n = beyond_paper(cfg), any_size(n)
        self._code = np.zeros(self.num, dtype=np.int64)
        self._no_accel = np.full((self.num, 3), np.nan)
        self._said_missing = False  # the accelerometer asked for and missing: said once
        self.reset()

    @property
    def eta(self) -> np.ndarray:
        """The unfiltered estimates (the next windows' anchors), (N, n)."""
        return self._state.views.vn[:, VN_ROWS.eta]

    @property
    def change_events(self) -> np.ndarray:
        """Per row, the changes the change completion has started since its last reset."""
        return self._state.ints[:, COUNTERS.completion + COMPLETION_COUNTERS.events].copy()

    def reset(self, mask=None, eta0=None) -> None:
        """Forget the windows of the rows in ``mask`` (default all); start from ``eta0``
        ((n,) or (N, n), default ones)."""
        rows = reset_rows(self.num, mask)
        n = self.vehicle.n_rotors
        eta = batch_eta0(np.ones(n) if eta0 is None else eta0, self.num, n)
        self._state.reset(rows, eta[rows])

    def update(self, t, p, v, R, w, f, accel=None) -> BatchedEstimate:
        """Add one sample per vehicle (``accel`` (N, 3): their accelerometer readings, body
        FRD [m/s^2], or None); returns the estimates of the windows ending at them."""
        t, p, v, R, w, f = batch_arrays(self.num, self.vehicle.n_rotors, t, p, v, R, w, f)
        accel = batch_accel(self.num, accel)
        if accel is None:
            if self.config.accelerometer == "on" and not self._said_missing:
                self._said_missing = True
                warn_missing("irls", "a batch of samples")
            accel = self._no_accel
        st = self._state
        irls_update_rows(
            t,
            p,
            v,
            R,
            w,
            f,
            accel,
            self._const,
            self._fp,
            self._ip,
            st.floats,
            st.ints,
            self._hist,
            self._beyond,
            self._any_n,
            self._code,
        )
        VN = st.views.vn
        sd = np.where(st.ints[:, COUNTERS.has_sd, None] == 1, VN[:, VN_ROWS.sd], np.nan)
        return BatchedEstimate(t.copy(), VN[:, VN_ROWS.out].copy(), sd, self._code.copy())


class BatchedEKF:
    """N :class:`~estimators.ekf.MotorEfficiencyEKF` filters over ``[p, v, Omega, vec(R), eta]``
    updated together (state :attr:`x` (N, 18 + n), covariance :attr:`P` (N, 18 + n, 18 + n)).

    Args:
        vehicle: the *nominal* vehicle.
        num: number of vehicles N.
        config: :class:`~estimators.ekf.EKFConfig` shared by all rows.
    """

    name = "ekf"

    def __init__(self, vehicle: Vehicle, num: int, config: EKFConfig | None = None):
        if not isinstance(vehicle, Vehicle):
            raise ConfigError(f"BatchedEKF needs a Vehicle, got {type(vehicle).__name__}")
        self.num = check_num(num)
        self.vehicle = vehicle
        self.config = config or EKFConfig()
        if not isinstance(self.config, EKFConfig):
            raise ConfigError("config must be an EKFConfig")
        self._eta0_default = default_eta0(self.config, vehicle.n_rotors)
        self._const = ekf_constants(vehicle, self.config)
        self._state = EKFState(vehicle.n_rotors, self.num)
        self._code = np.zeros(self.num, dtype=np.int64)
        self._no_accel = np.full((self.num, 3), np.nan)  # no accelerometer readings
        self._said_missing = False
        self.reset()

    @property
    def x(self) -> np.ndarray:
        return self._state.views.x

    @property
    def P(self) -> np.ndarray:
        return self._state.views.P

    def reset(self, mask=None, eta0=None) -> None:
        """Forget the rows in ``mask`` (default all); the next sample initialises them."""
        rows = reset_rows(self.num, mask)
        n = self.vehicle.n_rotors
        eta = batch_eta0(self._eta0_default if eta0 is None else eta0, self.num, n)
        st = self._state
        ekf_reset(st.offsets, n, st.floats, st.ints, rows, eta)

    def update(self, t, p, v, R, w, f, accel=None) -> BatchedEstimate:
        """One predict (previous sample's command held) and one update per vehicle
        (``accel`` (N, 3): their accelerometer readings, body FRD [m/s^2], or None; needed
        with ``EKFConfig.accelerometer``)."""
        t, p, v, R, w, f = batch_arrays(self.num, self.vehicle.n_rotors, t, p, v, R, w, f)
        accel = batch_accel(self.num, accel)
        a = self._no_accel
        if accel is not None and self.config.accelerometer != "off":
            a = accel
        elif self.config.accelerometer == "on" and not self._said_missing:
            warn_missing("BatchedEKF", "a batched sample")
            self._said_missing = True
        st = self._state
        ekf_update_rows(
            t, p, v, R, w, f, a, self._const, st.offsets, st.floats, st.ints, self._code
        )
        init = st.ints[:, EKF_COUNTERS.initialised, None] == 1
        eta = np.where(init, st.views.x[:, X.eta :], st.views.eta0)
        diag = np.diagonal(st.views.P, axis1=1, axis2=2)[:, X.eta :]
        sd = np.where(init, np.sqrt(np.where(init, diag, 0.0)), np.nan)
        return BatchedEstimate(t.copy(), eta, sd, self._code.copy())


def make_batched_estimator(name: str, vehicle: Vehicle, num: int, **kwargs):
    """Deprecated: ``estimators.registry.make_estimator(name, vehicle, num=num, ...)``."""
    warnings.warn(
        "make_batched_estimator is deprecated; use "
        "estimators.registry.make_estimator(name, vehicle, num=N)",
        DeprecationWarning,
        stacklevel=2,
    )
    return make_estimator(name, vehicle, num=num, **kwargs)


__all__ = [
    "CODE",
    "BatchedEKF",
    "BatchedEstimate",
    "BatchedIRLS",
    "ekf_update_rows",
    "irls_update_rows",
    "make_batched_estimator",
]
