"""The paper's sliding-window IRLS motor-efficiency estimator (Algorithm 2), online.

One update per measurement sample (:func:`irls_update`, plain Python compiled by
:func:`quadfault.jit.jit`, allocation-free, one call):

1. check the sample (finite, time increasing; otherwise ``bad_sample`` and the window
   restarts) and clip its command to ``[0, rotor_max_thrust]`` (``clip_commands``; ``run``
   clips above only when the recording's flight was saturated,
   :func:`estimators.base.command_limit`);
2. write the segment previous sample -> this sample into a ring of the last ``window - 1``
   segments' quadratic terms (:mod:`estimators.residuals`, eqs. 13-26);
3. when the ring is full (else ``warmup``) and the window's mean commanded thrust reaches
   ``min_thrust`` (else ``no_excitation``), solve the window from the previous estimate
   (:mod:`estimators.window`, Algorithm 2 around the interior point of
   :mod:`estimators.ipm`); on a guard (``ill_conditioned``, ``rejected``) the previous
   estimate is kept;
4. beyond the paper, both off by default (:meth:`IRLSConfig.improved` turns them on): the
   change completion of the solved estimate (:mod:`estimators.change_completion`), and the
   reported estimate is the causal running median of the estimates (:mod:`estimators.median`).

The state of one estimator lives in a float and an int buffer (:class:`IRLSState`); the
offline :meth:`SlidingWindowIRLS.run` is the same update in a compiled loop over the
recording, and :class:`estimators.batched.BatchedIRLS` runs it over a batch of such states.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict

import numpy as np

from estimators.base import (
    STATUS_BAD_SAMPLE,
    STATUS_NO_EXCITATION,
    STATUS_WARMUP,
    STATUSES,
    Estimate,
    EstimateSeries,
    Sample,
    command_limit,
)
from estimators.change_completion import N_COUNTERS, complete_into, observe_into
from estimators.irls_config import (  # noqa: F401  (re-exported)
    SCALINGS,
    IRLSConfig,
    IRLSDiagnostics,
    LazyWindowDiagnostics,
    window_diagnostics,
)
from estimators.median import median_push_into, postprocess_label
from estimators.residuals import segment_terms_into
from estimators.state import FlatState, all_finite, piece, piece_rows
from estimators.window import (
    M_A,
    M_B,
    M_JGJ,
    MAX_ITER,
    N_FLOAT_SETTINGS,
    N_INT_SETTINGS,
    N_MATRICES,
    N_VECTORS,
    OK,
    P_GAMMA,
    P_HI,
    P_LO,
    history,
    no_history,
    solve_window,
    solve_window_into,
    window_settings,
)
from quadfault.errors import ConfigError
from quadfault.jit import jit
from quadfault.recording import Recording
from quadfault.vehicle import Vehicle

__all__ = [
    "IRLSConfig",
    "IRLSDiagnostics",
    "IRLSState",
    "SlidingWindowIRLS",
    "irls_update",
    "solve_window",
]

WARMUP = STATUSES.index(STATUS_WARMUP)
NO_EXCITATION = STATUSES.index(STATUS_NO_EXCITATION)
BAD_SAMPLE = STATUSES.index(STATUS_BAD_SAMPLE)
#: why :func:`irls_update` refused a sample (``bad_sample``)
WHY_NONFINITE, WHY_TIME = 1, 2
_ROW0 = np.zeros(1, dtype=np.int64)
_WHY = {WHY_NONFINITE: "non-finite or malformed sample", WHY_TIME: "time not increasing"}
#: the diagnostics of the statuses that solve nothing (frozen, so one instance serves all)
_HELD = {WARMUP: IRLSDiagnostics(STATUS_WARMUP),
         NO_EXCITATION: IRLSDiagnostics(STATUS_NO_EXCITATION,
                                        "commanded thrust ~ 0 in the window")}

# extra settings after the window's (estimators.window.window_settings)
P_THRESHOLD = N_FLOAT_SETTINGS  # change_threshold
(I_M, I_N, I_L, I_COMPLETION, I_HOLD) = range(N_INT_SETTINGS, N_INT_SETTINGS + 5)
I_OFFSETS = N_INT_SETTINGS + 5  # then the offsets of the float state's pieces
# pieces of the float state, in order (their shapes: IRLSState.shapes); rows of the grouped ones
F_T, F_SAMPLE, F_VN, F_VM, F_BH, F_H, F_M, F_R0, F_J, F_MEDIAN = range(10)
N_PIECES = 10
S_P, S_V, S_W, S_R = 0, 1, 2, 3  # F_SAMPLE (6, 3): the previous sample's p, v, w; R (rows 3-5)
# F_VN (n-vectors): the previous command, the estimate, its sd, the reported estimate, the
# window's solution and sd, the completion's anchor, direction and scratch (3 rows), then the
# window solver's vectors (estimators.window)
(VN_LAST_F, VN_ETA, VN_SD, VN_OUT, VN_X, VN_SD_X, VN_ANCHOR, VN_DIRECTION, VN_SCRATCH) = range(9)
VN_WINDOW = VN_SCRATCH + 3
# F_VM (m-vectors): the ring's energy constants and thrusts, the final weights, then the window
# solver's segment rows; F_BH: the ring's b and the completion's history; F_MEDIAN: the
# output median's ring and its sorted copy
VM_C, VM_THRUST, VM_WEIGHTS, VM_WINDOW = 0, 1, 2, 3
BH_B, BH_HISTORY = 0, 1
# the int state: counters, then the completion's (estimators.change_completion), then the
# interior-point iterations of each IRLS round
K_HEAD, K_COUNT, K_HAS_LAST, K_HAS_SD, K_MEDIAN_K, K_MEDIAN_FRESH = range(6)
K_COMPLETION = 6
K_ITERS = K_COMPLETION + N_COUNTERS
# the vehicle constants: mass, gravity, rotor_max_thrust, clip, min_thrust, J, J^-1, A, G
C_MASS, C_G, C_FMAX, C_CLIP, C_MIN_THRUST, C_J, C_JINV, C_A = 0, 1, 2, 3, 4, 5, 14, 23


class IRLSState(FlatState):
    """The state of ``N`` online IRLS estimators (one for :class:`SlidingWindowIRLS`, a batch
    for :class:`estimators.batched.BatchedIRLS`) in a float and an int buffer
    (:class:`estimators.state.FlatState`), with numpy views of its pieces, each
    ``(N, *shape)``; the compiled update reads the same pieces through :func:`state_pieces`
    and the offsets in ``ip``.

    Float pieces: the previous sample's time, its state and (clipped) command, the ring of
    segment terms (``c, b, H, thrust``; ``ints[:, K_HEAD]`` is the slot written next, the oldest
    segment of a full window), the unfiltered estimate ``eta`` and its ``sd``, the reported
    ``out``, the last window solve (``x, sd_x, weights``) and its workspace, the change
    completion (``history, anchor, direction``) and the output median's ring. Pieces of the
    same length are grouped (the ``VN_*``, ``VM_*`` rows), so the compiled update forms few
    views.
    """

    @staticmethod
    def shapes(m: int, n: int, L: int) -> tuple:
        return ((1,), (6, 3), (VN_WINDOW + N_VECTORS, n), (VM_WINDOW + 3, m), (2, m, n),
                (m, n, n), (N_MATRICES, n, n), (10,), (10, n), (2, L, n))

    def __init__(self, m: int, n: int, L: int, rounds: int, num: int = 1):
        super().__init__(self.shapes(m, n, L), num, K_ITERS + rounds)


def irls_parameters(vehicle: Vehicle, cfg: IRLSConfig, offsets: np.ndarray):
    """``(const, fp, ip)`` of :func:`irls_update`: the vehicle constants, the float and the
    int settings (with the state's piece offsets)."""
    m, n = cfg.window - 1, vehicle.n_rotors
    const = np.concatenate([np.asarray(a, dtype=np.float64).ravel() for a in (
        [vehicle.mass, vehicle.gravity, vehicle.rotor_max_thrust, float(cfg.clip_commands),
         cfg.min_thrust], vehicle.inertia, vehicle.inertia_inverse, vehicle.allocation,
        cfg.segment_weights)])
    fp, ip = window_settings(cfg, m)
    fp = np.concatenate((fp, [cfg.change_threshold]))
    ip = np.concatenate((ip, [m, n, cfg.output_median, int(cfg.change_completion),
                              cfg.change_hold], offsets)).astype(np.int64)
    return const, fp, ip


@jit(inline="always")
def state_pieces(fs, ip, N):
    """The pieces of the float state of ``N`` estimators (:class:`IRLSState`), each
    ``(N, *shape)``, in the order of the ``F_*`` constants."""
    m, n, L = ip[I_M], ip[I_N], ip[I_L]
    o = ip[I_OFFSETS:]
    return (piece_rows(fs, o[F_T], o[F_T + 1], N),
            piece(fs, o, F_SAMPLE, (N, 6, 3)),
            piece(fs, o, F_VN, (N, VN_WINDOW + N_VECTORS, n)),
            piece(fs, o, F_VM, (N, VM_WINDOW + 3, m)),
            piece(fs, o, F_BH, (N, 2, m, n)),
            piece(fs, o, F_H, (N, m, n, n)),
            piece(fs, o, F_M, (N, N_MATRICES, n, n)),
            piece_rows(fs, o[F_R0], o[F_R0 + 1], N),
            piece(fs, o, F_J, (N, 10, n)),
            piece(fs, o, F_MEDIAN, (N, 2, L, n)))


@jit(inline="always")
def constant_arrays(const, ip):
    """``(J (3, 3), J^-1 (3, 3), A (4, n), G (10))``: the vehicle's array constants of
    :func:`irls_step`, as views of ``const`` (:func:`irls_parameters`)."""
    n = ip[I_N]
    return (const[C_J:C_JINV].reshape((3, 3)), const[C_JINV:C_A].reshape((3, 3)),
            const[C_A:C_A + 4 * n].reshape((4, n)), const[C_A + 4 * n:C_A + 4 * n + 10])


@jit(inline="always")
def irls_step(t, p, v, R, w, f, const, arrays, fp, ip, S, ks, i, hist):
    """One online update of the sliding-window IRLS (module docstring) of row ``i`` of the
    state ``(S, ks)`` (:func:`state_pieces`, int state (N, K)), in place (``arrays``:
    :func:`constant_arrays` of ``const``). Returns ``(status
    code, why, rounds, cond)``: ``why`` is :data:`WHY_NONFINITE` or :data:`WHY_TIME` for a
    ``bad_sample``, else 0; ``rounds`` and ``cond`` describe the window solve (0 and NaN when
    none ran)."""
    m, n, L = ip[I_M], ip[I_N], ip[I_L]
    last_t, sample, VN, VM, BH = S[F_T][i], S[F_SAMPLE][i], S[F_VN][i], S[F_VM][i], S[F_BH][i]
    last_p, last_v, last_w, last_R = sample[S_P], sample[S_V], sample[S_W], sample[S_R:]
    last_f, eta, sd, out, x, sd_x = (VN[VN_LAST_F], VN[VN_ETA], VN[VN_SD], VN[VN_OUT],
                                     VN[VN_X], VN[VN_SD_X])
    c, thrust, b, history_, H, M = VM[VM_C], VM[VM_THRUST], BH[BH_B], BH[BH_HISTORY], S[F_H][i], \
        S[F_M][i]
    k_row = ks[i]
    completion = k_row[K_COMPLETION:K_ITERS]
    code, why, rounds, cond = WARMUP, 0, 0, np.nan
    finite = (math.isfinite(t) and all_finite(p) and all_finite(v) and all_finite(R)
              and all_finite(w) and all_finite(f))
    if not finite or (k_row[K_HAS_LAST] == 1 and not t > last_t[0]):
        k_row[K_COUNT] = 0
        k_row[K_HAS_LAST] = 0
        code, why = BAD_SAMPLE, (WHY_TIME if finite else WHY_NONFINITE)
    else:
        if k_row[K_HAS_LAST] == 1:  # the segment last -> this sample into the ring (eqs. 13-26)
            slot = k_row[K_HEAD]
            Jmat, Jinv, A, G = arrays
            c[slot], thrust[slot] = segment_terms_into(
                t - last_t[0], last_p, p, last_v, v, last_R, R, last_w, w, last_f,
                const[C_MASS], const[C_G], Jmat, Jinv, A, G, S[F_R0][i], S[F_J][i], b[slot],
                H[slot])
            k_row[K_HEAD] = (slot + 1) % m
            k_row[K_COUNT] = min(k_row[K_COUNT] + 1, m)
        last_t[0] = t
        for a in range(3):
            last_p[a], last_v[a], last_w[a] = p[a], v[a], w[a]
            for k in range(3):
                last_R[a, k] = R[a, k]
        for j in range(n):
            last_f[j] = min(max(f[j], 0.0), const[C_FMAX]) if const[C_CLIP] != 0.0 else f[j]
        k_row[K_HAS_LAST] = 1
        if k_row[K_COUNT] == m:
            mean = 0.0
            for s in range(m):
                mean += thrust[(k_row[K_HEAD] + s) % m]
            if mean / m < const[C_MIN_THRUST]:
                code = NO_EXCITATION
            else:
                code, rounds, cond = solve_window_into(
                    c, b, H, k_row[K_HEAD], eta, fp, ip, VN[VN_WINDOW:], M, VM[VM_WINDOW:],
                    VM[VM_WEIGHTS], k_row[K_ITERS:], hist, x, sd_x)
            if code == OK or code == MAX_ITER:
                if ip[I_COMPLETION] == 1:
                    complete_into(x, M[M_JGJ], history_, VN[VN_ANCHOR], VN[VN_DIRECTION],
                                  completion, fp[P_THRESHOLD], ip[I_HOLD], fp[P_GAMMA],
                                  fp[P_LO], fp[P_HI], M[M_A], M[M_B],
                                  VN[VN_SCRATCH:VN_SCRATCH + 3])
                for j in range(n):
                    eta[j] = x[j]
                    sd[j] = sd_x[j]
                k_row[K_HAS_SD] = 1
            elif ip[I_COMPLETION] == 1:  # a held window: the completion sees the kept estimate
                observe_into(eta, history_, completion)
    if L > 1:
        median = S[F_MEDIAN][i]
        median_push_into(median[0], median[1], k_row[K_MEDIAN_K], eta,
                         k_row[K_MEDIAN_FRESH] == 1, out)
        k_row[K_MEDIAN_K] = (k_row[K_MEDIAN_K] + 1) % L
        k_row[K_MEDIAN_FRESH] = 0
    else:
        for j in range(n):
            out[j] = eta[j]
    return code, why, rounds, cond


@jit
def irls_update(t, p, v, R, w, f, const, fp, ip, fs, ks, hist):
    """:func:`irls_step` of a single estimator (state of one row): the online update."""
    S = state_pieces(fs, ip, ks.shape[0])
    return irls_step(t, p, v, R, w, f, const, constant_arrays(const, ip), fp, ip, S, ks,
                     ks.shape[0] - 1, hist)  # row 0, a run-time value like the batch's rows


@jit
def irls_reset(eta0, ip, fs, ks, rows) -> None:
    """Forget everything of the estimators ``rows``; start them from ``eta0`` (N, n)."""
    N = ks.shape[0]
    S = state_pieces(fs, ip, N)
    n = ip[I_N]
    for i in rows:
        for k in range(ks.shape[1]):
            ks[i, k] = 0
        for k in range(N_PIECES):
            row = piece_rows(fs, ip[I_OFFSETS + k], ip[I_OFFSETS + k + 1], N)[i]
            for a in range(row.shape[0]):
                row[a] = 0.0
        VN, history_ = S[F_VN][i], S[F_BH][i, BH_HISTORY]
        eta, out, sd = VN[VN_ETA], VN[VN_OUT], VN[VN_SD]
        for j in range(n):
            eta[j] = eta0[i, j]
            out[j] = eta0[i, j]
            sd[j] = np.nan
            for s in range(history_.shape[0]):
                history_[s, j] = eta0[i, j]
        ks[i, K_MEDIAN_FRESH] = 1


@jit
def irls_run(t, p, v, R, w, f, const, fp, ip, fs, ks, hist, eta, sd, code):
    """:func:`irls_step` over the rows of a recording (a single estimator's state): the
    reported estimate, its sd (NaN until a window is solved) and the status code of every
    row."""
    n = ip[I_N]
    S = state_pieces(fs, ip, ks.shape[0])
    row = ks.shape[0] - 1  # 0, a run-time value like the batch's rows
    out, sd_now = S[F_VN][row, VN_OUT], S[F_VN][row, VN_SD]
    arrays = constant_arrays(const, ip)
    for k in range(t.shape[0]):
        code[k], _why, _rounds, _cond = irls_step(t[k], p[k], v[k], R[k], w[k], f[k], const,
                                                  arrays, fp, ip, S, ks, row, hist)
        for j in range(n):
            eta[k, j] = out[j]
            sd[k, j] = sd_now[j] if ks[0, K_HAS_SD] == 1 else np.nan


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
        cfg, n = self.config, vehicle.n_rotors
        self._state = IRLSState(cfg.window - 1, n, cfg.output_median, cfg.max_irls)
        self._const, self._fp, self._ip = irls_parameters(vehicle, cfg, self._state.offsets)
        self._hist = history(cfg, n) if cfg.record_history else no_history(n)
        self._nan_sample = (np.full(3, np.nan), np.full(3, np.nan), np.full((3, 3), np.nan),
                            np.full(3, np.nan), np.full(n, np.nan))
        self._shape_f = (n,)
        self._row = self._state.views[F_VN][0]  # the n-vectors of the state (estimate, sd, ...)
        self._weights = self._state.views[F_VM][0, VM_WEIGHTS]
        self.reset()

    def reset(self, eta0=None) -> None:
        """Forget the window; start from ``eta0`` (default: all ones)."""
        n = self.vehicle.n_rotors
        if eta0 is None:
            eta = np.ones(n)
        else:
            eta = np.array(eta0, dtype=float).reshape(-1)
            if eta.shape != (n,) or not np.all(np.isfinite(eta)):
                raise ConfigError(f"eta0 must be {n} finite numbers, got {eta0!r}")
        irls_reset(eta[None], self._ip, self._state.floats, self._state.ints, _ROW0)

    @property
    def eta(self) -> np.ndarray:
        """The current (unfiltered) estimate, a copy."""
        return self._state.views[F_VN][0, VN_ETA].copy()

    @property
    def change_events(self) -> int:
        """Changes the change completion has started since the last reset."""
        return int(self._state.ints[0, K_COMPLETION + 3])

    def update(self, sample: Sample) -> Estimate:
        """Add one measurement row; returns the estimate of the window ending at it."""
        try:
            t = float(sample.t)
            p, v, R, w, f = [np.ascontiguousarray(a, dtype=float) for a in sample[1:]]
            malformed = (p.shape != (3,) or v.shape != (3,) or R.shape != (3, 3)
                         or w.shape != (3,) or f.shape != self._shape_f)
        except (AttributeError, TypeError, ValueError, IndexError):
            t, malformed = math.nan, True
        if malformed:
            p, v, R, w, f = self._nan_sample
        st = self._state
        code, why, rounds, cond = irls_update(math.nan if malformed else t, p, v, R, w, f,
                                              self._const, self._fp, self._ip, st.floats,
                                              st.ints, self._hist)
        row, ints = self._row, st.ints[0]
        sd = row[VN_SD].copy() if ints[K_HAS_SD] == 1 else None
        if code in _HELD:
            diag = _HELD[code]
        elif code == BAD_SAMPLE:
            diag = IRLSDiagnostics(STATUSES[code], f"{_WHY[why]}; window restarted")
        else:  # a window was solved (or held by a guard)
            cfg = self.config
            if cfg.record_history:
                diag = window_diagnostics(code, rounds, cond, ints[K_ITERS:], self._weights, cfg,
                                          self._hist)
            else:
                diag = LazyWindowDiagnostics(code, rounds, cond, ints[K_ITERS:].copy(),
                                             self._weights.copy(), cfg)
        return Estimate(t, row[VN_OUT].copy(), sd, STATUSES[code], diag)

    def run(self, recording: Recording, progress: bool = False) -> EstimateSeries:
        """Estimate over a whole recording, one row per sample (the first ``window - 1`` rows
        are ``warmup``); starts from the current estimate and leaves the estimator reset."""
        from quadfault.progress import progress_bar

        start = time.perf_counter()
        t, p, v, R, w, f = _recording_arrays(recording, self.vehicle, self.config.window)
        const = self._const.copy()
        const[C_FMAX] = command_limit(recording, self.vehicle)  # the recording's saturation
        self.reset(self.eta)
        st, N, n = self._state, len(t), self.vehicle.n_rotors
        eta, sd, code = np.empty((N, n)), np.empty((N, n)), np.empty(N, dtype=np.int64)
        chunk = 20000
        bar = progress_bar(total=N, desc="irls", unit="sample",
                           disable=None if progress else True)
        for k0 in range(0, N, chunk):
            k = slice(k0, min(k0 + chunk, N))
            irls_run(t[k], p[k], v[k], R[k], w[k], f[k], const, self._fp, self._ip,
                     st.floats, st.ints, self._hist, eta[k], sd[k], code[k])
            bar.update(k.stop - k0)
        bar.close()
        self.reset()
        return EstimateSeries(t=t.copy(), eta=eta, sd=sd,
                              status=np.asarray(STATUSES)[code],
                              estimator=self.name, config=asdict(self.config),
                              seconds=time.perf_counter() - start,
                              postprocess=postprocess_label(self.config.output_median))


def _recording_arrays(recording: Recording, vehicle: Vehicle, window: int):
    """Measurement arrays of a recording (never its truth columns), validated, contiguous."""
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
    return tuple(np.ascontiguousarray(a, dtype=np.float64) for a in (
        t, recording.position, recording.velocity, recording.rotation, recording.omega,
        recording.thrust_cmd))
