"""Batched motor-efficiency estimators: N independent estimators updated in one call.

:class:`BatchedIRLS` is N copies of :class:`estimators.irls.SlidingWindowIRLS` and
:class:`BatchedEKF` N copies of :class:`estimators.ekf.MotorEfficiencyEKF`, stored as arrays
with a leading batch axis so the vectorised environment keeps an estimate in every
observation. Nothing of the algorithms is written again:

* with numba (the ``fast`` extra), the segment terms and the windows are computed by the single
  estimator's compiled kernels: ``estimators._residuals_numba.segment_terms_batch`` and
  ``estimators._irls_numba.solve_ring_batch`` call the same allocation-free
  ``segment_terms_into`` and window solver ``_solve_window_into`` (paper eqs. 17-26,
  Algorithms 1-2), in parallel over chunks of vehicles, reading each window from the ring;
* without numba, :func:`estimators.residuals.segment_models` /
  :func:`~estimators.residuals.quadratic_terms` run over the whole batch at once and
  :func:`estimators.irls.solve_window` in a Python loop;
* the EKF step is ``estimators.ekf_numba.step_ws`` (one workspace per chunk of vehicles) or
  the numpy ``predict`` / ``measurement_update`` pair, applied to each row of the batched state.

Each row follows exactly the single estimator's online rules (window ring, warm-up,
``no_excitation`` / ``bad_sample`` guards, the previous estimate kept on a guard, and with
``IRLSConfig.improved()`` the change completion and the causal output median), so row i of a
batch fed the samples of vehicle i gives the single estimator's estimates (tested to 1e-6).

Inputs of :meth:`update` are the N samples of one instant: ``t`` (N,) [s], ``p``, ``v``
(N, 3) world NED [m], [m/s], ``R`` (N, 3, 3) body FRD -> world, ``w`` (N, 3) [rad/s] and
``f`` (N, n) commanded rotor thrusts [N] held from ``t`` until the next sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimators.base import (STATUS_BAD_SAMPLE, STATUS_MAX_ITER, STATUS_NO_EXCITATION,
                             STATUS_OK, STATUS_WARMUP, STATUSES, Sample)
from estimators.ekf import (NOISE_REFERENCE_DT, EKFConfig, MotorEfficiencyEKF,
                            measurement_update, predict)
from estimators.change_completion import BatchedCausalMedian, BatchedChangeCompletion
from estimators.irls import IRLSConfig, numba_available, solve_window
from estimators.residuals import quadratic_terms, segment_models
from quadfault.errors import ConfigError
from quadfault.vehicle import Vehicle

try:  # the compiled batch loops call the existing per-vehicle kernels (``fast`` extra)
    from numba import njit, prange

    from estimators._irls_numba import batch_chunks, solve_ring_batch
    from estimators._irls_online_numba import median_push_rows
    from estimators._residuals_numba import segment_terms_batch
    from estimators.ekf_numba import step_ws
    from estimators.ekf_numba import workspace as ekf_workspace
except ImportError:  # pragma: no cover - exercised without numba
    njit = median_push_rows = None

CODE = {name: k for k, name in enumerate(STATUSES)}  # status name -> integer code
_OK, _MAXIT = CODE[STATUS_OK], CODE[STATUS_MAX_ITER]


@dataclass(frozen=True)
class BatchedEstimate:
    """Estimates of N vehicles at one instant.

    Attributes:
        t: time of the newest sample used, (N,) [s].
        eta: estimated efficiency, (N, n) [-] (1 = nominal).
        sd: one-sigma uncertainty, (N, n); NaN where the single estimator reports None.
        status: integer codes (N,), ``STATUSES[code]`` is the status name.
    """

    t: np.ndarray
    eta: np.ndarray
    sd: np.ndarray
    status: np.ndarray

    @property
    def status_names(self) -> np.ndarray:
        return np.asarray(STATUSES, dtype=object)[self.status]


def _check_batch(num: int, n: int, t, p, v, R, w, f):
    """Arrays of one batched sample as float64, and the rows whose values are all finite."""
    t = np.asarray(t, dtype=float).reshape(-1)
    arrays = [np.asarray(a, dtype=float) for a in (p, v, R, w, f)]
    shapes = [(num, 3), (num, 3), (num, 3, 3), (num, 3), (num, n)]
    if t.shape != (num,) or [a.shape for a in arrays] != shapes:
        raise ConfigError(f"batched sample must have t {(num,)}, p, v {(num, 3)}, R "
                          f"{(num, 3, 3)}, w {(num, 3)}, f {(num, n)}; got "
                          f"{[t.shape] + [a.shape for a in arrays]}")
    finite = np.isfinite(t)
    for a in arrays:
        finite &= np.isfinite(a.reshape(num, -1)).all(axis=1)
    return (t, *arrays), finite


def _eta_rows(eta, num: int, n: int) -> np.ndarray:
    """``eta0`` given as (n,) or (num, n), broadcast to (num, n) and checked finite."""
    try:
        eta = np.broadcast_to(eta, (num, n))
    except ValueError:
        raise ConfigError(f"eta0 must be {n} or ({num}, {n}) numbers") from None
    if not np.all(np.isfinite(eta)):
        raise ConfigError("eta0 must be finite")
    return eta


def _mask(num: int, mask) -> np.ndarray:
    if mask is None:
        return np.ones(num, dtype=bool)
    mask = np.asarray(mask, dtype=bool).reshape(-1)
    if mask.shape != (num,):
        raise ConfigError(f"reset mask must have {num} booleans, got shape {mask.shape}")
    return mask


def _check_num(num) -> int:
    if isinstance(num, bool) or not isinstance(num, (int, np.integer)) or num < 1:
        raise ConfigError(f"number of estimators must be an integer >= 1, got {num!r}")
    return int(num)


class BatchedIRLS:
    """N sliding-window IRLS estimators (the paper's Algorithm 2) updated together.

    Args:
        vehicle: the *nominal* vehicle.
        num: number of vehicles N.
        config: :class:`~estimators.irls.IRLSConfig` shared by all rows (``backend`` selects
            the compiled batch kernel or the numpy loop; ``record_history`` is not supported).
            The options beyond the paper (``IRLSConfig.improved()``: change completion, output
            median) are applied per row as in the single estimator
            (:class:`~estimators.change_completion.BatchedChangeCompletion`,
            :class:`~estimators.change_completion.BatchedCausalMedian`); the returned ``eta``
            is then the filtered estimate and :attr:`eta` the unfiltered one.
    """

    name = "irls"

    def __init__(self, vehicle: Vehicle, num: int, config: IRLSConfig | None = None):
        if not isinstance(vehicle, Vehicle):
            raise ConfigError(f"BatchedIRLS needs a Vehicle, got {type(vehicle).__name__}")
        self.vehicle = vehicle
        self.num = _check_num(num)
        self.config = config or IRLSConfig()
        if not isinstance(self.config, IRLSConfig):
            raise ConfigError("config must be an IRLSConfig")
        if self.config.record_history:
            raise ConfigError("BatchedIRLS does not record KKT histories (record_history=True)")
        backend = self.config.backend
        if backend == "numba" and not numba_available():
            raise ConfigError("IRLS backend 'numba' needs numba (install the 'fast' extra)")
        self.backend = ("numba" if numba_available() else "numpy") if backend == "auto" else backend
        self._G = self.config.segment_weights
        m, n, N = self.config.window - 1, vehicle.n_rotors, self.num
        self._m = m
        self._c, self._b = np.zeros((N, m)), np.zeros((N, m, n))
        self._H, self._thrust = np.zeros((N, m, n, n)), np.zeros((N, m))
        self._head = 0  # ring slot written next; the window runs oldest-first from here
        self._last = (np.zeros(N), np.zeros((N, 3)), np.zeros((N, 3)), np.zeros((N, 3, 3)),
                      np.zeros((N, 3)), np.zeros((N, n)))
        self._params = None
        if self.backend == "numba":
            from estimators._irls_numba import kernel_parameters

            self._params = kernel_parameters(self.config, m)
        self.eta = np.ones((N, n))  # the unfiltered estimate (next window's anchor)
        self.sd = np.full((N, n), np.nan)
        self._has_last = np.zeros(N, dtype=bool)
        self._count = np.zeros(N, dtype=np.int64)
        self._t = np.zeros(N)
        self._status = np.full(N, CODE[STATUS_WARMUP])
        cfg = self.config  # the options beyond the paper (estimators.change_completion)
        self._completion = BatchedChangeCompletion(N, n, cfg.change_threshold, cfg.change_hold,
                                                   cfg.gamma, cfg.lower, cfg.upper, span=m) \
            if cfg.change_completion else None
        self._median = BatchedCausalMedian(N, n, cfg.output_median, median_push_rows
                                           if self.backend == "numba" else None)
        self.reset()

    def reset(self, mask=None, eta0=None) -> None:
        """Forget the windows of the rows in ``mask`` (default all); start from ``eta0``
        ((n,) or (N, n), default ones)."""
        mask = _mask(self.num, mask)
        n = self.vehicle.n_rotors
        eta = np.ones(n) if eta0 is None else np.asarray(eta0, dtype=float)
        eta = _eta_rows(eta, self.num, n)
        self.eta[mask] = eta[mask]
        self.sd[mask] = np.nan
        if self._completion is not None:
            self._completion.reset(mask, self.eta)
        self._median.reset(mask)
        self._has_last[mask] = False
        self._count[mask] = 0
        self._status[mask] = CODE[STATUS_WARMUP]

    def _commands(self, f: np.ndarray) -> np.ndarray:
        if not self.config.clip_commands:
            return f
        return np.clip(f, 0.0, self.vehicle.rotor_max_thrust)

    def _add_segments(self, rows: np.ndarray, sample) -> None:
        """Quadratic terms of the segments last -> sample of ``rows`` into the ring."""
        if self.backend == "numba":
            v = self.vehicle
            old = [np.ascontiguousarray(a) for a in self._last[:5]]
            new = [np.ascontiguousarray(a) for a in sample[:5]]
            segment_terms_batch(rows.astype(np.int64), self._head, old[0], old[1], old[2], old[3],
                                old[4], np.ascontiguousarray(self._last[5]), new[0], new[1],
                                new[2], new[3], new[4], v.mass, v.gravity, v.inertia,
                                v.inertia_inverse, v.allocation, self._G, self._c, self._b,
                                self._H, self._thrust, batch_chunks(rows.size))
            return
        K = rows.size
        pairs = []
        for old, new in zip(self._last, sample):
            both = np.empty((2 * K,) + new.shape[1:])
            both[0::2], both[1::2] = old[rows], new[rows]
            pairs.append(both)
        # consecutive samples (a_0, z_0, a_1, z_1, ...): the even segments are the wanted ones
        seg = segment_models(self.vehicle, *pairs)
        c, b, H = quadratic_terms(seg, self._G)
        slot = self._head
        self._c[rows, slot], self._b[rows, slot] = c[0::2], b[0::2]
        self._H[rows, slot], self._thrust[rows, slot] = H[0::2], seg.thrust[0::2]

    def update(self, t, p, v, R, w, f) -> BatchedEstimate:
        """Add one sample per vehicle; returns the estimates of the windows ending at them."""
        N = self.num
        (t, p, v, R, w, f), finite = _check_batch(N, self.vehicle.n_rotors, t, p, v, R, w, f)
        f = self._commands(f)
        bad = ~finite | (self._has_last & ~(t > self._last[0]))
        status = np.full(N, CODE[STATUS_WARMUP])
        status[bad] = CODE[STATUS_BAD_SAMPLE]
        self._has_last[bad] = False
        self._count[bad] = 0
        grow = ~bad & self._has_last
        rows = np.flatnonzero(grow)
        if rows.size:
            self._add_segments(rows, (t, p, v, R, w, f))
        self._head = (self._head + 1) % self._m
        self._count[grow] = np.minimum(self._count[grow] + 1, self._m)
        good = ~bad
        for last, new in zip(self._last, (t, p, v, R, w, f)):
            last[good] = new[good]
        self._has_last |= good
        ready = good & (self._count == self._m)
        no_exc = ready & (self._thrust.mean(axis=1) < self.config.min_thrust)
        status[no_exc] = CODE[STATUS_NO_EXCITATION]
        solve = np.flatnonzero(ready & ~no_exc)
        held = no_exc.copy()  # windows whose previous estimate is kept (no_exc, guards)
        if solve.size:
            x, sd, code, weights = self._solve(solve)
            status[solve] = code
            keep = (code == _OK) | (code == _MAXIT)
            held[solve[~keep]] = True
            if self._completion is not None and keep.any():
                x[keep] = self._complete(solve[keep], x[keep], weights[keep])
            self.eta[solve[keep]], self.sd[solve[keep]] = x[keep], sd[keep]
        if self._completion is not None:
            rows = np.flatnonzero(held)
            self._completion.observe(rows, self.eta[rows])
        self._t = np.where(np.isfinite(t), t, self._t)
        self._status = status
        return BatchedEstimate(t.copy(), self._median.push(self.eta), self.sd.copy(), status)

    def _complete(self, rows: np.ndarray, x_raw: np.ndarray, weights: np.ndarray):
        """The change completion of the solved windows of ``rows`` (final robust weights
        ``weights`` (K, m), oldest segment first)."""
        order = (self._head + np.arange(self._m)) % self._m  # oldest segment first
        scale = 1.0 / self._m if self.config.scaling == "paper" else 1.0

        def infos(J):  # J^T W G J of the windows of rows[J] (as _window_information)
            H = self._H[rows[J]][:, order]
            return np.einsum("km,kmij->kij", weights[J], H) * scale

        return self._completion.step(rows, x_raw, infos)

    def _solve(self, rows: np.ndarray):
        """Algorithm 2 on the windows of ``rows``; (x, sd, status code, final robust
        weights (K, m), oldest segment first) per row."""
        start = self._head  # after the write the oldest segment sits at the head
        K, n, m = rows.size, self.vehicle.n_rotors, self._m
        weights = np.zeros((K, m))
        if self.backend == "numba":
            fp, ip = self._params
            x, sd, code = np.empty((K, n)), np.empty((K, n)), np.empty(K, dtype=np.int64)
            solve_ring_batch(self._c, self._b, self._H, int(start), rows.astype(np.int64),
                             self.eta, fp, ip, x, sd, code, weights, batch_chunks(K))
            return x, sd, code, weights
        order = (start + np.arange(m)) % m
        x, sd, code = np.empty((K, n)), np.full((K, n), np.nan), np.empty(K, dtype=np.int64)
        for k, i in enumerate(rows):
            xi, si, diag = solve_window(self._c[i, order], self._b[i, order], self._H[i, order],
                                        self.eta[i], self.config)
            x[k], code[k] = xi, CODE[diag.status]
            if diag.weights is not None:
                weights[k] = diag.weights
            if si is not None:
                sd[k] = si
        return x, sd, code, weights


class BatchedEKF:
    """N :class:`~estimators.ekf.MotorEfficiencyEKF` filters over ``[p, v, Omega, vec(R), eta]``
    updated together (state ``x`` (N, 18 + n), covariance ``P`` (N, 18 + n, 18 + n)).

    Args:
        vehicle: the *nominal* vehicle.
        num: number of vehicles N.
        config: :class:`~estimators.ekf.EKFConfig` shared by all rows.
    """

    name = "ekf"

    def __init__(self, vehicle: Vehicle, num: int, config: EKFConfig | None = None):
        self.num = _check_num(num)
        self.single = MotorEfficiencyEKF(vehicle, config)  # configuration and kernel arguments
        self.vehicle = vehicle
        self.config = self.single.config
        self.use_numba = self.single.use_numba
        N, ns = self.num, self.single.n_states
        self.x = np.zeros((N, ns))
        self.P = np.zeros((N, ns, ns))
        self._eta_init = np.broadcast_to(self.single._eta_init, (N, vehicle.n_rotors)).copy()
        self._init = np.zeros(N, dtype=bool)
        self._t_last = np.zeros(N)
        self._f_last = np.zeros((N, vehicle.n_rotors))

    def reset(self, mask=None, eta0=None) -> None:
        """Forget the rows in ``mask`` (default all); the next sample initialises them."""
        mask = _mask(self.num, mask)
        n = self.vehicle.n_rotors
        eta = self.single._eta0_default if eta0 is None else np.asarray(eta0, dtype=float)
        eta = _eta_rows(eta, self.num, n)
        self._eta_init[mask] = eta[mask]
        self._init[mask] = False

    def update(self, t, p, v, R, w, f) -> BatchedEstimate:
        """One predict (previous sample's command held) and one update per vehicle."""
        N, n = self.num, self.vehicle.n_rotors
        (t, p, v, R, w, f), finite = _check_batch(N, n, t, p, v, R, w, f)
        status = np.full(N, CODE[STATUS_OK])
        status[~finite] = CODE[STATUS_BAD_SAMPLE]
        new = finite & ~self._init
        if new.any():  # initialise the kinematic states from the first sample
            self.x[new, 0:3], self.x[new, 3:6], self.x[new, 6:9] = p[new], v[new], w[new]
            self.x[new, 9:18] = np.swapaxes(R[new], 1, 2).reshape(-1, 9)  # vec(R), column-major
            self.x[new, 18:] = self._eta_init[new]
            self.P[new] = self.config.p0 * np.eye(self.single.n_states)
            status[new] = CODE[STATUS_WARMUP]
        step = finite & self._init
        rows = np.flatnonzero(step)
        dt = t - self._t_last
        if rows.size and not np.all(dt[rows] > 0):
            i = int(rows[np.flatnonzero(~(dt[rows] > 0))[0]])
            raise ConfigError(f"EKF row {i}: sample time {t[i]} is not after the previous one "
                              f"({self._t_last[i]}); times must increase strictly")
        if rows.size:
            if self.use_numba:
                _ekf_steps(self.x, self.P, self._f_last, dt, p, v, w, R, rows,
                          *self.single._kernel_args())
            else:
                self._steps_numpy(rows, t, p, v, R, w, dt)
        ok = finite
        self._t_last[ok] = t[ok]
        self._f_last[ok] = np.clip(f[ok], 0.0, self.vehicle.rotor_max_thrust) \
            if self.config.clip_commands else f[ok]
        self._init |= ok
        eta = np.where(self._init[:, None], self.x[:, 18:], self._eta_init)
        diag = np.diagonal(self.P, axis1=1, axis2=2)[:, 18:]
        sd = np.where(self._init[:, None], np.sqrt(np.where(self._init[:, None], diag, 0.0)),
                      np.nan)
        return BatchedEstimate(t.copy(), eta, sd, status)

    def _steps_numpy(self, rows, t, p, v, R, w, dt) -> None:
        s = self.single
        for i in rows:
            Q = np.diag(s.q_diag * (dt[i] / NOISE_REFERENCE_DT))
            x, P, _ = predict(self.x[i], self.P[i], self._f_last[i], float(dt[i]), self.vehicle, Q)
            sample = Sample(float(t[i]), p[i], v[i], R[i], w[i], self._f_last[i])
            self.x[i], self.P[i] = measurement_update(x, P, sample, s.r_diag,
                                                      self.config.eta_bounds)


def make_batched_estimator(name: str, vehicle: Vehicle, num: int, **kwargs):
    """``"irls"`` -> :class:`BatchedIRLS`, ``"ekf"`` -> :class:`BatchedEKF` (``config=...``)."""
    if name == "irls":
        return BatchedIRLS(vehicle, num, **kwargs)
    if name == "ekf":
        return BatchedEKF(vehicle, num, **kwargs)
    raise ConfigError(f"no batched estimator {name!r}; choose 'irls' or 'ekf'")


__all__ = ["BatchedIRLS", "BatchedEKF", "BatchedEstimate", "make_batched_estimator", "CODE"]


if njit is not None:
    @njit(cache=True, parallel=True)
    def _ekf_steps_kernel(x, P, f, dt, p, v, w, R, rows, chunks, A, m, g, J, Jinv, qc, r, lo,
                          hi):
        K = rows.size
        for ch in prange(chunks):  # one workspace per chunk of rows
            ws = ekf_workspace(x.shape[1])
            for k in range(ch * K // chunks, (ch + 1) * K // chunks):
                i = rows[k]
                step_ws(x[i], P[i], f[i], dt[i], p[i], v[i], w[i], R[i], A, m, g, J, Jinv, qc,
                        r, lo, hi, ws)


def _ekf_steps(x, P, f, dt, p, v, w, R, rows, *kernel_args):
    """Compiled EKF predict + update of ``rows`` (parallel over the batch), in place."""
    _ekf_steps_kernel(x, P, f, dt, np.ascontiguousarray(p), np.ascontiguousarray(v),
                      np.ascontiguousarray(w), np.ascontiguousarray(R), rows.astype(np.int64),
                      batch_chunks(rows.size), *kernel_args)
