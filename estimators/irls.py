"""The paper's sliding-window IRLS motor-efficiency estimator (Algorithm 2).

Per update, over the last ``n = 10`` samples (9 segments, :mod:`estimators.residuals`)::

    min_eta  1/2 sum_i w_i r_i(eta)^T G_i r_i(eta) + gamma/2 ||eta - eta_prev||^2   (eq. 24)
    s.t.     eta_min - eps <= eta <= eta_max + eps                                   (eq. 25)

solved by an outer IRLS loop (robust MAD z-score weights ``w_i``, :mod:`estimators.robust`)
around a primal-dual interior-point method (:mod:`estimators.ipm`), warm-started from the
previous estimate. The residuals are affine in ``eta``, so each window reduces to per-segment
quadratic terms ``(c_i, b_i, H_i)`` computed once.

Guards (the previous estimate is kept): a window with (almost) no commanded thrust
(``no_excitation``), ``cond_1(J^T G J) > cond_max`` (``ill_conditioned``, the reference's
``rcond < 1e-4``), every segment rejected (``rejected``), a non-finite sample (``bad_sample``).

Uncertainty (``Estimate.sd``), from the window's information matrix with the final weights::

    s^2 = sum_i w_i e_i(eta) / max(10 k - n, 1)        (k = segments with w_i > 0)
    sd  = sqrt(diag(s^2 (J^T G J + gamma I)^-1))
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict

import numpy as np

from estimators.base import (
    STATUS_BAD_SAMPLE,
    STATUS_ILL_CONDITIONED,
    STATUS_MAX_ITER,
    STATUS_NO_EXCITATION,
    STATUS_OK,
    STATUS_REJECTED,
    STATUS_WARMUP,
    STATUSES,
    Estimate,
    EstimateSeries,
    Sample,
)
from estimators.change_completion import (
    CausalMedian,
    ChangeCompletion,
    causal_median,
    run_completed,
)
from estimators.ipm import solve_box_qp
from estimators.irls_config import (  # noqa: F401
    BACKENDS,
    SCALINGS,
    CompiledWindowDiagnostics,
    IRLSConfig,
    IRLSDiagnostics,
)
from estimators.residuals import quadratic_terms, segment_models
from estimators.robust import mad_weights
from quadfault.errors import ConfigError
from quadfault.recording import Recording
from quadfault.vehicle import Vehicle

_START_MARGIN = 1e-6  # the interior-point start is kept this far inside the bounds
_F64 = np.dtype(np.float64)
# status codes of the compiled online update that solved nothing (estimators._irls_online_numba)
_HELD_CODES = frozenset(STATUSES.index(s) for s in (STATUS_WARMUP, STATUS_BAD_SAMPLE,
                                                    STATUS_NO_EXCITATION))
_WHY_TIME = 2  # estimators._irls_online_numba.WHY_TIME (that module needs numba)


def condition_number_1(A) -> float:
    """``||A||_1 ||A^-1||_1`` (inf when singular); MATLAB's ``1/rcond`` up to its estimate."""
    A = np.asarray(A, dtype=float)
    try:
        Ainv = np.linalg.inv(A)
    except np.linalg.LinAlgError:
        return math.inf
    value = float(np.abs(A).sum(0).max() * np.abs(Ainv).sum(0).max())
    return value if math.isfinite(value) else math.inf


def _weighted_sum(w, H) -> np.ndarray:
    """``sum_i w_i H_i`` of (m, n, n) blocks as one matrix-vector product (less call overhead
    than ``tensordot``)."""
    m, n = H.shape[0], H.shape[1]
    return (w @ H.reshape(m, n * n)).reshape(n, n)


def segment_energies(c, b, H, x, scale: float = 1.0) -> np.ndarray:
    """``e_i = r_i^T G_i r_i = c_i + 2 b_i . x + x^T H_i x`` (eq. 26), times ``scale``."""
    return (c + 2.0 * (b @ x) + (H @ x) @ x) * scale


def window_uncertainty(c, b, H, w, x, gamma: float, scale: float = 1.0,
                       info=None) -> np.ndarray:
    """One-sigma uncertainty of ``x`` from the window's information matrix (module doc);
    ``info`` is that matrix when the caller has it already."""
    e = segment_energies(c, b, H, x, scale)
    n = len(x)
    active = int(np.count_nonzero(w > 0))
    s2 = max(float(w @ e), 0.0) / max(10 * active - n, 1)
    if info is None:
        info = _weighted_sum(w, H) * scale + gamma * np.eye(n)
    try:
        cov = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return np.full(n, np.nan)
    return np.sqrt(np.maximum(np.diag(cov), 0.0) * s2)


def solve_window(c, b, H, x_prev, config: IRLSConfig, record_history: bool = False):
    """Algorithm 2 on one window given its per-segment quadratic terms.

    Args:
        c, b, H: ``quadratic_terms`` of the window's segments, (m,), (m, n), (m, n, n).
        x_prev: previous estimate (warm start and smoothness anchor), (n,).

    Returns:
        ``(eta, sd, diagnostics)``; on a guard ``eta`` is ``x_prev`` and ``sd`` is None.
    """
    cfg = config
    m, n = b.shape
    lo, hi = cfg.lower, cfg.upper
    scale = 1.0 / m if cfg.scaling == "paper" else 1.0
    paper = cfg.scaling == "paper"
    x_prev = np.asarray(x_prev, dtype=float)
    x_cur = np.clip(x_prev, lo + _START_MARGIN, hi - _START_MARGIN)
    gI = cfg.gamma * np.eye(n)
    iters, hist = [], ([], [], [], []) if record_history else None
    converged, cond, w = True, math.nan, None
    for _ in range(cfg.max_irls):
        e = segment_energies(c, b, H, x_cur, scale)  # eq. 26
        w, _z = mad_weights(e, z_soft=cfg.z_soft, power=cfg.soft_power, z_hard=cfg.z_hard,
                            hard_drop=cfg.hard_drop, w_min=cfg.w_min, mad_eps=cfg.mad_eps,
                            median_normalize=not paper, floor=paper)
        if not np.any(w > 0):
            return x_prev, None, _diag(STATUS_REJECTED, "every segment rejected", iters, w,
                                       cond, hist)
        JGJ = _weighted_sum(w, H) * scale
        cond = condition_number_1(JGJ)
        if not cond <= cfg.cond_max:
            return x_prev, None, _diag(STATUS_ILL_CONDITIONED, f"cond(J^T G J) = {cond:.3g} > "
                                       f"{cfg.cond_max:g}", iters, w, cond, hist)
        q = (w @ b) * scale - cfg.gamma * x_prev
        info = JGJ + gI  # J^T W G J + gamma I: the Newton matrix, and the information matrix
        res = solve_box_qp(info, q, lo, hi, x_cur, cfg.ipm, record_history)
        iters.append(res.iterations)
        converged = res.converged
        if hist is not None:
            rr = [math.sqrt(max(float(w @ segment_energies(c, b, H, xk, scale)), 0.0))
                  for xk in res.x_history]
            for lst, arr in zip(hist, (res.dual_history, res.cent_history, res.gap_history, rr)):
                lst.append(np.asarray(arr))
        step = float(np.max(np.abs(res.x - x_cur)))
        x_cur = res.x
        if step < cfg.irls_tol:
            break
    sd = window_uncertainty(c, b, H, w, x_cur, cfg.gamma, scale, info)  # w of the last round
    status = STATUS_OK if converged else STATUS_MAX_ITER
    msg = "" if converged else f"interior point stopped at {cfg.ipm.max_iter} iterations"
    return x_cur, sd, _diag(status, msg, iters, w, cond, hist)


def _diag(status, message, iters, w, cond, hist) -> IRLSDiagnostics:
    rejected = () if w is None else tuple(int(i) for i in np.flatnonzero(w == 0))
    kw = {}
    if hist is not None:
        kw = dict(dual_history=tuple(hist[0]), cent_history=tuple(hist[1]),
                  gap_history=tuple(hist[2]), residual_history=tuple(hist[3]))
    return IRLSDiagnostics(status, message, tuple(iters), w, rejected, cond, **kw)


def numba_available() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


class SlidingWindowIRLS:
    """The paper's estimator (implements :class:`estimators.base.OnlineEstimator`).

    Args:
        vehicle: the *nominal* vehicle (mass, inertia, allocation, gravity).
        config: settings (default: the reference code's).
    """

    name = "irls"

    def __init__(self, vehicle: Vehicle, config: IRLSConfig | None = None):
        if not isinstance(vehicle, Vehicle):
            raise ConfigError(f"SlidingWindowIRLS needs a Vehicle, got {type(vehicle).__name__}")
        self.vehicle = vehicle
        self.config = config or IRLSConfig()
        if not isinstance(self.config, IRLSConfig):
            raise ConfigError("config must be an IRLSConfig")
        backend = self.config.backend
        if backend == "numba" and not numba_available():
            raise ConfigError("IRLS backend 'numba' needs numba (install the 'fast' extra)")
        if backend == "auto":
            backend = "numba" if numba_available() and not self.config.record_history else "numpy"
        self.backend = "numpy" if self.config.record_history else backend
        self._G = self.config.segment_weights
        self._kernel_params = None
        if self.backend == "numba":
            from estimators._irls_numba import kernel_parameters
            from estimators._irls_online_numba import online_constants, online_update

            cfg = self.config
            self._kernel_params = kernel_parameters(cfg, cfg.window - 1)
            # the arguments of online_update that never change: vehicle, settings
            self._const = online_constants(vehicle, self._G, cfg.clip_commands, cfg.min_thrust)
            self._online_update = online_update
        self.reset()

    # online ---------------------------------------------------------------------------
    def reset(self, eta0=None) -> None:
        """Forget the window; start from ``eta0`` (default: all ones)."""
        n = self.vehicle.n_rotors
        if eta0 is None:
            eta = np.ones(n)
        else:
            eta = np.array(eta0, dtype=float).reshape(-1)
            if eta.shape != (n,) or not np.all(np.isfinite(eta)):
                raise ConfigError(f"eta0 must be {n} finite numbers, got {eta0!r}")
        self._eta = eta
        self._sd = None
        self._last: Sample | None = None
        m = self.config.window - 1  # ring of the window's segment terms, oldest first
        cfg = self.config
        if self.backend == "numba":  # the compiled online state (estimators._irls_online_numba)
            from estimators._irls_online_numba import online_state

            self._fstate, self._istate, self._online = online_state(m, n, cfg.max_irls)
        else:
            self._c, self._b = np.zeros(m), np.zeros((m, n))
            self._H, self._thrust = np.zeros((m, n, n)), np.zeros(m)
            self._count = 0
        self._completion = ChangeCompletion(cfg.change_threshold, cfg.change_hold, cfg.gamma,
                                            cfg.lower, cfg.upper, span=m)
        self._completion.reset(eta)
        median = None
        if self.backend == "numba" and cfg.output_median > 1:
            from estimators._irls_online_numba import median_columns as median
        self._median = CausalMedian(cfg.output_median, median)

    def _segment_terms(self, a: Sample, z: Sample):
        """``(c, b, H, thrust)`` of the segment from sample ``a`` to ``z``."""
        if self.backend == "numba":
            from estimators._irls_numba import segment_terms

            v = self.vehicle
            return segment_terms(z.t - a.t, a.p, z.p, a.v, z.v, a.R, z.R, a.w, z.w, a.f,
                                 v.mass, v.gravity, v.inertia, v.inertia_inverse, v.allocation,
                                 self._G)
        seg = segment_models(self.vehicle, (a.t, z.t), (a.p, z.p), (a.v, z.v), (a.R, z.R),
                             (a.w, z.w), (a.f, z.f))
        c, b, H = quadratic_terms(seg, self._G)
        return c[0], b[0], H[0], seg.thrust[0]

    def _commands(self, f: np.ndarray) -> np.ndarray:
        if not self.config.clip_commands:
            return f
        return np.clip(f, 0.0, self.vehicle.rotor_max_thrust)

    @property
    def eta(self) -> np.ndarray:
        """The current estimate (a copy)."""
        return self._eta.copy()

    def _keep(self, t, status, message="") -> Estimate:
        return Estimate(float(t), self._median.push(self._eta),
                        None if self._sd is None else self._sd.copy(),
                        status, IRLSDiagnostics(status, message))

    def update(self, sample: Sample) -> Estimate:
        """Add one measurement row; returns the estimate of the window ending at it."""
        if self.backend == "numba":
            return self._update_compiled(sample)
        n = self.vehicle.n_rotors
        try:
            t = float(sample.t)
            arrays = [np.asarray(a, dtype=float) for a in sample[1:]]
            shapes_ok = [a.shape for a in arrays] == [(3,), (3,), (3, 3), (3,), (n,)]
            finite = shapes_ok and math.isfinite(t) and all(np.all(np.isfinite(a))
                                                            for a in arrays)
        except (AttributeError, TypeError, ValueError, IndexError):
            t, finite = math.nan, False
        if not finite or (self._last is not None and not t > self._last.t):
            self._last = None
            self._count = 0
            why = "non-finite or malformed sample" if not finite else "time not increasing"
            return self._keep(t, STATUS_BAD_SAMPLE, f"{why}; window restarted")
        sample = Sample(float(t), *arrays[:4], self._commands(arrays[4]))
        if self._last is not None:
            for ring, new in zip((self._c, self._b, self._H, self._thrust),
                                 self._segment_terms(self._last, sample)):
                ring[:-1] = ring[1:]
                ring[-1] = new
            self._count = min(self._count + 1, len(self._c))
        self._last = sample
        if self._count < len(self._c):
            return self._keep(t, STATUS_WARMUP)
        c, b, H = self._c, self._b, self._H
        if self._thrust.mean() < self.config.min_thrust:
            self._completion.observe(self._eta)
            return self._keep(t, STATUS_NO_EXCITATION, "commanded thrust ~ 0 in the window")
        if self.backend == "numba":
            from estimators._irls_numba import kernel_parameters, solve_window_numba

            if self._kernel_params is None:
                self._kernel_params = kernel_parameters(self.config, len(c))
            eta, sd, diag = solve_window_numba(c, b, H, self._eta, self.config,
                                               self._kernel_params)
        else:
            eta, sd, diag = solve_window(c, b, H, self._eta, self.config,
                                         self.config.record_history)
        if sd is None:
            self._completion.observe(self._eta)
            return Estimate(float(t), self._median.push(self._eta), None if self._sd is None
                            else self._sd.copy(), diag.status, diag)
        if self.config.change_completion:
            eta = self._completion.step(eta, lambda: _window_information(H, diag.weights,
                                                                         self.config))
        self._eta, self._sd = eta, sd
        return Estimate(float(t), self._median.push(eta), sd.copy(), diag.status, diag)

    def _update_compiled(self, sample: Sample) -> Estimate:
        """:meth:`update` in one compiled call (``_irls_online_numba.online_update``): the same
        rules, ring and window solver as the numpy path; Python only checks shapes and
        applies the options beyond the paper."""
        try:
            t = float(sample.t)
            p, v, R, w, f = [np.asarray(a, dtype=_F64) for a in sample[1:]]
            malformed = (p.shape != (3,) or v.shape != (3,) or R.shape != (3, 3)
                         or w.shape != (3,) or f.shape != self._eta.shape)
        except (AttributeError, TypeError, ValueError, IndexError):
            t, malformed = math.nan, True
        state = self._online
        if malformed:
            state["ints"][1:3] = 0  # window restarted
            return self._keep(t, STATUS_BAD_SAMPLE,
                              "non-finite or malformed sample; window restarted")
        code, why, rounds, cond = self._online_update(
            t, p, v, R, w, f, self._const, *self._kernel_params, self._fstate, self._istate,
            self._eta)
        status = STATUSES[code]
        if code in _HELD_CODES:  # warm-up, bad sample, no excitation: nothing solved
            if status == STATUS_BAD_SAMPLE:
                why = "time not increasing" if why == _WHY_TIME \
                    else "non-finite or malformed sample"
                return self._keep(t, STATUS_BAD_SAMPLE, f"{why}; window restarted")
            if status == STATUS_WARMUP:
                return self._keep(t, STATUS_WARMUP)
            self._completion.observe(self._eta)
            return self._keep(t, STATUS_NO_EXCITATION, "commanded thrust ~ 0 in the window")
        cfg = self.config
        diag = CompiledWindowDiagnostics(code, rounds, cond, state["iters"].copy(),
                                         state["weights"].copy(), cfg)
        if status not in (STATUS_OK, STATUS_MAX_ITER):
            self._completion.observe(self._eta)
            return Estimate(t, self._median.push(self._eta), None if self._sd is None
                            else self._sd.copy(), status, diag)
        eta, sd = state["x_out"].copy(), state["sd_out"].copy()
        if cfg.change_completion:
            head, m = state["ints"][0], cfg.window - 1
            eta = self._completion.step(eta, lambda: _window_information(
                state["H"][(head + np.arange(m)) % m], diag.weights, cfg))
        self._eta, self._sd = eta, sd
        return Estimate(t, self._median.push(eta), sd.copy(), status, diag)

    # offline --------------------------------------------------------------------------
    def run(self, recording: Recording, progress: bool = False) -> EstimateSeries:
        """Estimate over a whole recording, one row per sample (the first ``window - 1`` rows
        are ``warmup``); starts from the current estimate and leaves the estimator reset."""
        start = time.perf_counter()
        t, p, v, R, w, f = _recording_arrays(recording, self.vehicle, self.config.window)
        models = segment_models(self.vehicle, t, p, v, R, w, self._commands(f))
        c, b, H = quadratic_terms(models, self._G)
        m = self.config.window - 1
        kernel = np.ones(m) / m
        excited = np.convolve(models.thrust, kernel, mode="valid") >= self.config.min_thrust
        x0 = self._eta.copy()
        if self.config.change_completion:
            eta_w, sd_w, status_w = self._run_completed(c, b, H, excited, x0)
        elif self.backend == "numba":
            from estimators._irls_numba import run_windows_numba

            eta_w, sd_w, code_w = run_windows_numba(c, b, H, excited, x0, self.config,
                                                    progress=progress)
            status_w = np.asarray(STATUSES, dtype=object)[code_w]
        else:
            eta_w, sd_w, status_w = _run_windows_numpy(c, b, H, excited, x0, self.config, progress)
        N, n = len(t), len(x0)
        eta = np.empty((N, n))
        sd = np.full((N, n), np.nan)
        status = np.empty(N, dtype=object)
        eta[:m], status[:m] = x0, STATUS_WARMUP
        eta[m:], sd[m:], status[m:] = eta_w, sd_w, status_w
        eta = causal_median(eta, self.config.output_median)
        self.reset()
        return EstimateSeries(t=t.copy(), eta=eta, sd=sd, status=status.astype(str),
                              estimator=self.name, config=asdict(self.config),
                              seconds=time.perf_counter() - start)


    def _run_completed(self, c, b, H, excited, x0):
        """Windows with the change completion (compiled/numpy chunks between changes)."""
        cfg = self.config
        if self.backend == "numba":
            from estimators._irls_numba import (
                kernel_parameters,
                run_windows_numba,
                solve_window_numba,
            )

            params = kernel_parameters(cfg, cfg.window - 1)

            def run_chunk(c_, b_, H_, ex, x):
                eta_w, sd_w, code_w = run_windows_numba(c_, b_, H_, ex, x, cfg)
                return eta_w, sd_w, np.asarray(STATUSES, dtype=object)[code_w]

            def solve_one(c_, b_, H_, x):
                return solve_window_numba(c_, b_, H_, x, cfg, params)
        else:
            def run_chunk(c_, b_, H_, ex, x):
                return _run_windows_numpy(c_, b_, H_, ex, x, cfg, False)

            def solve_one(c_, b_, H_, x):
                return solve_window(c_, b_, H_, x, cfg)
        completion = ChangeCompletion(cfg.change_threshold, cfg.change_hold, cfg.gamma,
                                      cfg.lower, cfg.upper, span=cfg.window - 1)
        return run_completed(c, b, H, excited, x0, completion, run_chunk, solve_one,
                             lambda Hw, w: _window_information(Hw, w, cfg))


def _window_information(H, w, cfg: IRLSConfig) -> np.ndarray:
    """``J^T W G J`` of a window (segment terms ``H`` (m, n, n), weights ``w`` (m,))."""
    scale = 1.0 / len(H) if cfg.scaling == "paper" else 1.0
    return np.tensordot(np.asarray(w, dtype=float), H, 1) * scale


def _run_windows_numpy(c, b, H, excited, x0, cfg: IRLSConfig, progress: bool):
    from quadfault.progress import progress_bar

    m = cfg.window - 1
    n_win = len(c) - m + 1
    n = len(x0)
    eta = np.empty((n_win, n))
    sd = np.full((n_win, n), np.nan)
    status = np.empty(n_win, dtype=object)
    x, s = x0.copy(), np.full(n, np.nan)
    bar = progress_bar(total=n_win, desc="irls", unit="win", disable=None if progress else True)
    for k in range(n_win):
        if excited[k]:
            xk, sk, diag = solve_window(c[k:k + m], b[k:k + m], H[k:k + m], x, cfg)
            if sk is not None:
                x, s = xk, sk
            status[k] = diag.status
        else:
            status[k] = STATUS_NO_EXCITATION
        eta[k], sd[k] = x, s
        if k % 2000 == 1999:
            bar.update(2000)
    bar.close()
    return eta, sd, status


def _recording_arrays(recording: Recording, vehicle: Vehicle, window: int):
    """Measurement arrays of a recording (never its truth columns), validated."""
    if not isinstance(recording, Recording):
        raise ConfigError(f"run() needs a Recording, got {type(recording).__name__}")
    where = recording.path or "recording"
    if not recording.has_pose:
        raise ConfigError(f"{where}: the IRLS estimator needs position, velocity and attitude "
                          "columns (px..pz, vx..vz, qw..qz); this recording is IMU-only")
    N = len(recording)
    if N == 0:
        raise ConfigError(f"{where}: the recording is empty")
    if N < window:
        raise ConfigError(f"{where}: the IRLS window of {window} samples is longer than the "
                          f"recording ({N} samples)")
    if recording.thrust_cmd.shape[1] != vehicle.n_rotors:
        raise ConfigError(f"{where}: {recording.thrust_cmd.shape[1]} rotor commands, the "
                          f"vehicle has {vehicle.n_rotors} rotors")
    t = np.asarray(recording.t, dtype=float)
    cols = (("t", t[:, None]), ("px..pz", recording.position), ("vx..vz", recording.velocity),
            ("qw..qz", recording.quaternion), ("wx..wz", recording.omega),
            ("f1..f4", recording.thrust_cmd))
    for name, arr in cols:
        bad = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
        if bad.size:
            raise ConfigError(f"{where}: NaN or inf in {name} at row {bad[0] + 1}")
    if np.any(np.diff(t) <= 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise ConfigError(f"{where}: time must be strictly increasing (row {k + 2})")
    return (t, recording.position, recording.velocity, recording.rotation, recording.omega,
            recording.thrust_cmd)
