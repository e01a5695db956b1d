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

from estimators.accelerometer import (
    NO_ACCEL,
    accelerometer_rows,
    recording_accel,
    repeats,
    warn_missing,
)
from estimators.base import (
    BAD_SAMPLE,
    NO_EXCITATION,
    STATUS_NO_EXCITATION,
    STATUS_WARMUP,
    STATUSES,
    WARMUP,
    Estimate,
    EstimateSeries,
    Sample,
    command_limit,
    run_rows,
)
from estimators.change_completion import COUNTERS as COMPLETION_COUNTERS
from estimators.change_completion import N_COUNTERS, complete_into, observe_into
from estimators.freshness import N_COUNTERS as N_FRESH_COUNTERS
from estimators.freshness import (
    N_TIMES,
    fresh_rows_into,
    fresh_streams,
    prefilter_fresh_into,
    restart_into,
)
from estimators.ipm import any_size
from estimators.irls_config import (  # noqa: F401  (re-exported)
    SCALINGS,
    IRLSConfig,
    IRLSDiagnostics,
    LazyWindowDiagnostics,
    window_diagnostics,
)
from estimators.median import median_push_into, postprocess_label
from estimators.residuals import (
    RESIDUAL_ROWS,
    Kinematics,
    SegmentModel,
    energy_terms_into,
    segment_model_into,
)
from estimators.state import FlatState, Layout, all_finite, fields, pack, piece, piece_rows
from estimators.window import (
    MATRICES,
    MAX_ITER,
    N_FLOAT_SETTINGS,
    N_INT_SETTINGS,
    N_MATRICES,
    N_SEGMENT_ROWS,
    N_VECTORS,
    OK,
    SETTINGS,
    history,
    no_history,
    solve_window,
    solve_window_into,
    window_settings,
)
from quadfault.errors import ConfigError
from quadfault.io.recording import Recording
from quadfault.jit import jit
from quadfault.model.vehicle import Vehicle

__all__ = [
    "IRLSConfig",
    "IRLSDiagnostics",
    "IRLSState",
    "SlidingWindowIRLS",
    "irls_update",
    "solve_window",
]

#: why :func:`irls_update` refused a sample (``bad_sample``)
WHY_NONFINITE, WHY_TIME = 1, 2
_ROW0 = np.zeros(1, dtype=np.int64)
_WHY = {WHY_NONFINITE: "non-finite or malformed sample", WHY_TIME: "time not increasing"}
#: the diagnostics of the statuses that solve nothing (frozen, so one instance serves all)
_HELD = {
    WARMUP: IRLSDiagnostics(STATUS_WARMUP),
    NO_EXCITATION: IRLSDiagnostics(STATUS_NO_EXCITATION, "commanded thrust ~ 0 in the window"),
}

#: the float settings (``fp``): the window solve's (:data:`estimators.window.SETTINGS`), then
#: the change completion's threshold
FLOAT_SETTINGS = fields("IRLSFloatSettings", ("window", N_FLOAT_SETTINGS), "change_threshold")
#: the int settings (``ip``): the window solve's, the sizes (segments ``m``, rotors ``n``, the
#: output median's ``L``), the completion's, then the offsets of the float state's pieces
INT_SETTINGS = fields(
    "IRLSIntSettings",
    ("window", N_INT_SETTINGS),
    "m",
    "n",
    "L",
    "completion",
    "hold",
    ("offsets", 0),
)
#: the vehicle constants (``const``); ``A`` (4 n) the allocation, last
CONSTANTS = fields(
    "IRLSConstants",
    "mass",
    "gravity",
    "f_max",
    "clip",
    "min_thrust",
    "prefilter",
    "accel",
    ("J", 9),
    ("Jinv", 9),
    ("G", RESIDUAL_ROWS),
    ("A", 0),
)
#: rows of the piece ``sample``: the previous sample's p, v, w, accelerometer reading (NaN:
#: none) and R
SAMPLE_ROWS = fields("IRLSSampleRows", "p", "v", "w", "a", ("R", 3))
#: rows of the piece ``vn`` (n each): the previous command, the estimate, its sd, the
#: reported estimate, the window's solution and sd, the completion's anchor, direction and
#: scratch, then the window solver's vectors (:data:`estimators.window.VECTORS`)
VN_ROWS = fields(
    "IRLSVectorRows",
    "last_f",
    "eta",
    "sd",
    "out",
    "x",
    "sd_x",
    "anchor",
    "direction",
    ("scratch", 3),
    ("window", N_VECTORS),
)
#: rows of the piece ``vm`` (m each): the ring's energy constants and thrusts, the final
#: weights, then the window solver's segment rows
VM_ROWS = fields("IRLSSegmentRows", "c", "thrust", "weights", ("window", N_SEGMENT_ROWS))
#: rows of the piece ``bh`` (m x n each): the ring's b, the completion's history
BH_ROWS = fields("IRLSRingRows", "b", "history")
#: the int state: counters, the completion's (:mod:`estimators.change_completion`), then the
#: interior-point iterations of each IRLS round
COUNTERS = fields(
    "IRLSCounters",
    "head",
    "count",
    "has_last",
    "has_sd",
    "median_k",
    "median_fresh",
    "code",
    "accel_held",
    ("fresh", N_FRESH_COUNTERS),
    ("completion", N_COUNTERS),
    ("iters", 0),
)
#: the float state of one estimator: its pieces and their shapes in the window's segments
#: ``m``, the rotors ``n`` and the output median's length ``L`` (offsets derived)
FLOATS = Layout(
    "IRLSPieces",
    t=(1,),  # the previous sample's time [s]
    sample=(SAMPLE_ROWS.size, 3),  # its p, v, w, accelerometer, R (SAMPLE_ROWS)
    vn=(VN_ROWS.size, "n"),  # n-vectors (VN_ROWS)
    vm=(VM_ROWS.size, "m"),  # m-vectors (VM_ROWS)
    bh=(BH_ROWS.size, "m", "n"),  # (BH_ROWS)
    H=("m", "n", "n"),  # the ring's H
    M=(N_MATRICES, "n", "n"),  # the window solver's matrices
    r0=(RESIDUAL_ROWS,),  # a segment's residual at eta = 0 (scratch)
    J=(RESIDUAL_ROWS, "n"),  # its Jacobian (scratch)
    r0f=(RESIDUAL_ROWS,),  # the prefilter's residual at eta = 0 (IRLSConfig.prefilter)
    Jf=(RESIDUAL_ROWS, "n"),  # and its Jacobian
    median=(2, "L", "n"),  # the output median's ring and sorted copy
    acc_r0=(RESIDUAL_ROWS,),  # the pending rows of held streams (estimators.freshness)
    acc_J=(RESIDUAL_ROWS, "n"),
    fresh_times=(N_TIMES,),
)
F = FLOATS.index
IRLSPieces = FLOATS.pieces


class IRLSState(FlatState):
    """The state of ``N`` online IRLS estimators (one for :class:`SlidingWindowIRLS`, a batch
    for :class:`estimators.batched.BatchedIRLS`) in a float and an int buffer
    (:class:`estimators.state.FlatState`), with numpy views of its pieces, each
    ``(N, *shape)``; the compiled update reads the same pieces through :func:`state_pieces`
    and the offsets in ``ip``.

    Float pieces (:data:`FLOATS`): the previous sample's time, its state and (clipped)
    command, the ring of segment terms (``c, b, H, thrust``; ``ints[:, COUNTERS.head]`` is the
    slot written next, the oldest segment of a full window), the unfiltered estimate ``eta``
    and its ``sd``, the reported ``out``, the last window solve (``x, sd_x, weights``) and its
    workspace, the change completion (``history, anchor, direction``) and the output median's
    ring. Pieces of the same length are grouped (rows :data:`VN_ROWS`, :data:`VM_ROWS`,
    :data:`BH_ROWS`), so the compiled update forms few views.
    """

    def __init__(self, m: int, n: int, L: int, rounds: int, num: int = 1):
        super().__init__(FLOATS.shapes(m=m, n=n, L=L), num, COUNTERS.size + rounds, FLOATS.pieces)

    def reset(self, rows: np.ndarray, eta0: np.ndarray) -> None:
        """Forget everything of the estimators ``rows`` (int64); start them from ``eta0``
        (len(rows), n): their estimate, reported estimate and the completion's history. (A
        few numpy writes per reset: nothing to compile for it.)"""
        self.ints[rows] = 0
        for view in self.views:
            view[rows] = 0.0
        V = self.views
        V.vn[rows, VN_ROWS.eta] = eta0
        V.vn[rows, VN_ROWS.out] = eta0
        V.vn[rows, VN_ROWS.sd] = np.nan
        V.bh[rows, BH_ROWS.history] = eta0[:, None, :]
        self.ints[rows, COUNTERS.median_fresh] = 1


def beyond_paper(cfg: IRLSConfig):
    """The ``beyond`` argument of the kernels (:func:`irls_step`): True when ``cfg`` turns on
    an option beyond the paper (the change completion, an output median), else None."""
    return True if (cfg.change_completion or cfg.output_median > 1) else None


def irls_parameters(vehicle: Vehicle, cfg: IRLSConfig, offsets: np.ndarray):
    """``(const, fp, ip)`` of :func:`irls_update`: the vehicle constants, the float and the
    int settings (with the state's piece offsets)."""
    m, n = cfg.window - 1, vehicle.n_rotors
    const = pack(
        CONSTANTS,
        mass=vehicle.mass,
        gravity=vehicle.gravity,
        f_max=vehicle.rotor_max_thrust,
        clip=float(cfg.clip_commands),
        min_thrust=cfg.min_thrust,
        prefilter=cfg.prefilter,
        accel=float(cfg.accelerometer != "off"),
        J=vehicle.inertia,
        Jinv=vehicle.inertia_inverse,
        G=cfg.segment_weights,
        A=vehicle.allocation,
    )
    fp, ip = window_settings(cfg, m)
    fp = pack(FLOAT_SETTINGS, window=fp, change_threshold=cfg.change_threshold)
    ip = pack(
        INT_SETTINGS,
        window=ip,
        m=m,
        n=n,
        L=cfg.output_median,
        completion=int(cfg.change_completion),
        hold=cfg.change_hold,
        offsets=offsets,
    ).astype(np.int64)
    return const, fp, ip


@jit(inline="always")
def state_views(fs, ip, N):
    """The pieces of the float state of ``N`` estimators, each ``(N, *shape)``, as a plain
    tuple in the order of :data:`FLOATS` (what a ``prange`` loop can capture;
    :func:`named_pieces` names them)."""
    m, n, L = ip[INT_SETTINGS.m], ip[INT_SETTINGS.n], ip[INT_SETTINGS.L]
    o = ip[INT_SETTINGS.offsets :]
    return (
        piece_rows(fs, o[F.t], o[F.t + 1], N),
        piece(fs, o, F.sample, (N, SAMPLE_ROWS.size, 3)),
        piece(fs, o, F.vn, (N, VN_ROWS.size, n)),
        piece(fs, o, F.vm, (N, VM_ROWS.size, m)),
        piece(fs, o, F.bh, (N, BH_ROWS.size, m, n)),
        piece(fs, o, F.H, (N, m, n, n)),
        piece(fs, o, F.M, (N, N_MATRICES, n, n)),
        piece_rows(fs, o[F.r0], o[F.r0 + 1], N),
        piece(fs, o, F.J, (N, RESIDUAL_ROWS, n)),
        piece_rows(fs, o[F.r0f], o[F.r0f + 1], N),
        piece(fs, o, F.Jf, (N, RESIDUAL_ROWS, n)),
        piece(fs, o, F.median, (N, 2, L, n)),
        piece_rows(fs, o[F.acc_r0], o[F.acc_r0 + 1], N),
        piece(fs, o, F.acc_J, (N, RESIDUAL_ROWS, n)),
        piece_rows(fs, o[F.fresh_times], o[F.fresh_times + 1], N),
    )


@jit(inline="always")
def named_pieces(views):
    """:func:`state_views` by name (:data:`FLOATS`'s pieces)."""
    return IRLSPieces(*views)


@jit(inline="always")
def state_pieces(fs, ip, N):
    """The pieces of the float state of ``N`` estimators (:data:`FLOATS`) by name, each
    ``(N, *shape)``."""
    return named_pieces(state_views(fs, ip, N))


@jit(inline="always")
def constant_arrays(const, ip):
    """``(J (3, 3), J^-1 (3, 3), A (4, n), G (10))``: the vehicle's array constants of
    :func:`irls_step`, as views of ``const`` (:data:`CONSTANTS`)."""
    n = ip[INT_SETTINGS.n]
    C = CONSTANTS
    return (
        const[C.J : C.Jinv].reshape((3, 3)),
        const[C.Jinv : C.G].reshape((3, 3)),
        const[C.A : C.A + 4 * n].reshape((4, n)),
        const[C.G : C.A],
    )


@jit(inline="always")
def irls_step(t, p, v, R, w, f, a, const, arrays, fp, ip, S, ks, i, hist, beyond, any_n):
    """One online update of the sliding-window IRLS (module docstring) of row ``i`` of the
    state ``(S, ks)`` (:func:`state_pieces`, int state (N, K)), in place (``arrays``:
    :func:`constant_arrays` of ``const``). Returns ``(status
    code, why, rounds, cond)``: ``why`` is :data:`WHY_NONFINITE` or :data:`WHY_TIME` for a
    ``bad_sample``, else 0; ``rounds`` and ``cond`` describe the window solve (0 and NaN when
    none ran).

    ``beyond`` (:func:`beyond_paper`): None for the paper's estimator, whose kernels then hold
    neither the change completion nor the output median (numba drops the branches of a None
    argument before compiling them: a first run compiles about 2 CPU-s less); True when
    ``ip`` turns either on. ``any_n`` (:func:`estimators.ipm.any_size`): None for a
    quadrotor's four rotors (the window's interior point is then compiled for that size
    only), else True."""
    m, n, L = ip[INT_SETTINGS.m], ip[INT_SETTINGS.n], ip[INT_SETTINGS.L]
    last_t, sample, VN, VM, BH = S.t[i], S.sample[i], S.vn[i], S.vm[i], S.bh[i]
    last_p, last_v, last_w = sample[SAMPLE_ROWS.p], sample[SAMPLE_ROWS.v], sample[SAMPLE_ROWS.w]
    last_a, last_R = sample[SAMPLE_ROWS.a], sample[SAMPLE_ROWS.R :]
    last_f, eta, sd, out, x, sd_x = (
        VN[VN_ROWS.last_f],
        VN[VN_ROWS.eta],
        VN[VN_ROWS.sd],
        VN[VN_ROWS.out],
        VN[VN_ROWS.x],
        VN[VN_ROWS.sd_x],
    )
    c, thrust, b, history_ = VM[VM_ROWS.c], VM[VM_ROWS.thrust], BH[BH_ROWS.b], BH[BH_ROWS.history]
    H, M = S.H[i], S.M[i]
    k_row = ks[i]
    completion = k_row[COUNTERS.completion : COUNTERS.iters]
    code, why, rounds, cond = WARMUP, 0, 0, np.nan
    finite = (
        math.isfinite(t)
        and all_finite(p)
        and all_finite(v)
        and all_finite(R)
        and all_finite(w)
        and all_finite(f)
    )
    fresh_counters = k_row[COUNTERS.fresh : COUNTERS.completion]
    pushed = False
    if not finite or (k_row[COUNTERS.has_last] == 1 and not t > last_t[0]):
        k_row[COUNTERS.count] = 0
        k_row[COUNTERS.has_last] = 0
        restart_into(fresh_counters, S.fresh_times[i])
        code, why = BAD_SAMPLE, (WHY_TIME if finite else WHY_NONFINITE)
    else:
        if k_row[COUNTERS.has_last] == 1:  # the segment last -> this sample into the ring
            slot = k_row[COUNTERS.head]  # (eqs. 13-26)
            Jmat, Jinv, A, G = arrays
            r0, Jr = S.r0[i], S.J[i]
            thrust_now = segment_model_into(
                t - last_t[0],
                Kinematics(last_p, last_v, last_R, last_w),
                Kinematics(p, v, R, w),
                last_f,
                SegmentModel(const[CONSTANTS.mass], const[CONSTANTS.gravity], Jmat, Jinv, A, G),
                r0,
                Jr,
            )
            fresh = fresh_streams(p, v, R, w, last_p, last_v, last_R, last_w)
            if const[CONSTANTS.accel] != 0.0 and all_finite(last_a):
                # the velocity rows from the accelerometer, whose holds they follow
                fresh = accelerometer_rows(
                    t - last_t[0],
                    last_R,
                    last_a,
                    k_row[COUNTERS.accel_held] == 1,
                    fresh,
                    fresh_counters,
                    r0,
                    Jr,
                )
            # held streams: their rows over the interval between fresh samples
            dt = fresh_rows_into(
                r0,
                Jr,
                t - last_t[0],
                fresh,
                fresh_counters,
                S.acc_r0[i],
                S.acc_J[i],
                S.fresh_times[i],
            )
            if dt > 0.0:
                pushed = True
                thrust[slot] = thrust_now
                tau = const[CONSTANTS.prefilter]
                if tau > 0.0:  # the same low-pass on both sides (beyond the paper)
                    fresh = k_row[COUNTERS.count] == 0
                    prefilter_fresh_into(
                        r0, Jr, S.r0f[i], S.Jf[i], dt, tau, fresh, fresh_counters, S.fresh_times[i]
                    )
                c[slot] = energy_terms_into(r0, Jr, G, b[slot], H[slot])
                k_row[COUNTERS.head] = (slot + 1) % m
                k_row[COUNTERS.count] = min(k_row[COUNTERS.count] + 1, m)
        last_t[0] = t
        held = k_row[COUNTERS.has_last] == 1 and repeats(a, last_a)
        k_row[COUNTERS.accel_held] = 1 if held else 0
        for k in range(3):
            last_p[k], last_v[k], last_w[k], last_a[k] = p[k], v[k], w[k], a[k]
            for m_ in range(3):
                last_R[k, m_] = R[k, m_]
        for j in range(n):
            last_f[j] = (
                min(max(f[j], 0.0), const[CONSTANTS.f_max])
                if const[CONSTANTS.clip] != 0.0
                else f[j]
            )
        k_row[COUNTERS.has_last] = 1
        if k_row[COUNTERS.count] == m and not pushed:  # no fresh rows: the window as it was
            code = k_row[COUNTERS.code]
        elif k_row[COUNTERS.count] == m:
            mean = 0.0
            for s in range(m):
                mean += thrust[(k_row[COUNTERS.head] + s) % m]
            if mean / m < const[CONSTANTS.min_thrust]:
                code = NO_EXCITATION
            else:
                code, rounds, cond = solve_window_into(
                    c,
                    b,
                    H,
                    k_row[COUNTERS.head],
                    eta,
                    fp,
                    ip,
                    VN[VN_ROWS.window :],
                    M,
                    VM[VM_ROWS.window :],
                    VM[VM_ROWS.weights],
                    k_row[COUNTERS.iters :],
                    hist,
                    x,
                    sd_x,
                    any_n,
                )
            if code == OK or code == MAX_ITER:
                if beyond is not None and ip[INT_SETTINGS.completion] == 1:
                    complete_into(
                        x,
                        M[MATRICES.JGJ],
                        history_,
                        VN[VN_ROWS.anchor],
                        VN[VN_ROWS.direction],
                        completion,
                        fp[FLOAT_SETTINGS.change_threshold],
                        ip[INT_SETTINGS.hold],
                        fp[SETTINGS.gamma],
                        fp[SETTINGS.lo],
                        fp[SETTINGS.hi],
                        M[MATRICES.A],
                        M[MATRICES.B],
                        VN[VN_ROWS.scratch : VN_ROWS.window],
                    )
                for j in range(n):
                    eta[j] = x[j]
                    sd[j] = sd_x[j]
                k_row[COUNTERS.has_sd] = 1
            elif beyond is not None and ip[INT_SETTINGS.completion] == 1:  # a held window:
                observe_into(eta, history_, completion)  # the completion sees the kept estimate
            k_row[COUNTERS.code] = code
    if beyond is not None and L > 1:
        median = S.median[i]
        median_push_into(
            median[0],
            median[1],
            k_row[COUNTERS.median_k],
            eta,
            k_row[COUNTERS.median_fresh] == 1,
            out,
        )
        k_row[COUNTERS.median_k] = (k_row[COUNTERS.median_k] + 1) % L
        k_row[COUNTERS.median_fresh] = 0
    else:
        for j in range(n):
            out[j] = eta[j]
    return code, why, rounds, cond


@jit
def irls_update(t, p, v, R, w, f, a, const, fp, ip, fs, ks, hist, beyond, any_n):
    """:func:`irls_step` of a single estimator (state of one row): the online update."""
    S = state_pieces(fs, ip, ks.shape[0])
    row = ks.shape[0] - 1  # 0, a run-time value like the batch's rows
    arrays = constant_arrays(const, ip)
    return irls_step(t, p, v, R, w, f, a, const, arrays, fp, ip, S, ks, row, hist, beyond, any_n)


@jit
def irls_run(t, p, v, R, w, f, a, const, fp, ip, fs, ks, hist, beyond, any_n, eta, sd, code):
    """:func:`irls_step` over the rows of a recording (a single estimator's state): the
    reported estimate, its sd (NaN until a window is solved) and the status code of every
    row."""
    n = ip[INT_SETTINGS.n]
    S = state_pieces(fs, ip, ks.shape[0])
    row = ks.shape[0] - 1  # 0, a run-time value like the batch's rows
    out, sd_now = S.vn[row, VN_ROWS.out], S.vn[row, VN_ROWS.sd]
    arrays = constant_arrays(const, ip)
    for k in range(t.shape[0]):
        code[k], _why, _rounds, _cond = irls_step(
            t[k],
            p[k],
            v[k],
            R[k],
            w[k],
            f[k],
            a[k],
            const,
            arrays,
            fp,
            ip,
            S,
            ks,
            row,
            hist,
            beyond,
            any_n,
        )
        for j in range(n):
            eta[k, j] = out[j]
            sd[k, j] = sd_now[j] if ks[0, COUNTERS.has_sd] == 1 else np.nan


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
        self._beyond, self._any_n = beyond_paper(cfg), any_size(n)
        self._nan_sample = (
            np.full(3, np.nan),
            np.full(3, np.nan),
            np.full((3, 3), np.nan),
            np.full(3, np.nan),
            np.full(n, np.nan),
        )
        self._shape_f = (n,)
        self._said_missing = False  # the accelerometer asked for and missing: said once
        self._row = self._state.views.vn[0]  # the n-vectors of the state (estimate, sd, ...)
        self._weights = self._state.views.vm[0, VM_ROWS.weights]
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
        self._state.reset(_ROW0, eta[None])

    @property
    def eta(self) -> np.ndarray:
        """The current (unfiltered) estimate, a copy."""
        return self._state.views.vn[0, VN_ROWS.eta].copy()

    @property
    def change_events(self) -> int:
        """Changes the change completion has started since the last reset."""
        return int(self._state.ints[0, COUNTERS.completion + COMPLETION_COUNTERS.events])

    def update(self, sample: Sample) -> Estimate:
        """Add one measurement row; returns the estimate of the window ending at it."""
        try:
            t = float(sample.t)
            p, v, R, w, f = [np.ascontiguousarray(a, dtype=float) for a in sample[1:6]]
            a = sample[6] if len(sample) > 6 else None
            a = NO_ACCEL if a is None else np.ascontiguousarray(a, dtype=float)
            malformed = (
                p.shape != (3,)
                or v.shape != (3,)
                or R.shape != (3, 3)
                or w.shape != (3,)
                or f.shape != self._shape_f
                or a.shape != (3,)
            )
        except (AttributeError, TypeError, ValueError, IndexError):
            t, malformed = math.nan, True
        if malformed:
            p, v, R, w, f = self._nan_sample
            a = NO_ACCEL
        elif a is NO_ACCEL and self.config.accelerometer == "on" and not self._said_missing:
            self._said_missing = True
            warn_missing(self.name, f"the sample at t = {t}")
        st = self._state
        code, why, rounds, cond = irls_update(
            math.nan if malformed else t,
            p,
            v,
            R,
            w,
            f,
            a,
            self._const,
            self._fp,
            self._ip,
            st.floats,
            st.ints,
            self._hist,
            self._beyond,
            self._any_n,
        )
        row, ints = self._row, st.ints[0]
        sd = row[VN_ROWS.sd].copy() if ints[COUNTERS.has_sd] == 1 else None
        if code in _HELD:
            diag = _HELD[code]
        elif code == BAD_SAMPLE:
            diag = IRLSDiagnostics(STATUSES[code], f"{_WHY[why]}; window restarted")
        else:  # a window was solved (or held by a guard)
            cfg = self.config
            if cfg.record_history:
                diag = window_diagnostics(
                    code, rounds, cond, ints[COUNTERS.iters :], self._weights, cfg, self._hist
                )
            else:
                diag = LazyWindowDiagnostics(
                    code, rounds, cond, ints[COUNTERS.iters :].copy(), self._weights.copy(), cfg
                )
        return Estimate(t, row[VN_ROWS.out].copy(), sd, STATUSES[code], diag)

    def run(self, recording: Recording, progress: bool = False) -> EstimateSeries:
        """Estimate over a whole recording, one row per sample (the first ``window - 1`` rows
        are ``warmup``); starts from the current estimate and leaves the estimator reset."""
        start = time.perf_counter()
        t, p, v, R, w, f = _recording_arrays(recording, self.vehicle, self.config.window)
        a = recording_accel(recording, self.config.accelerometer, self.name)
        const = self._const.copy()
        const[CONSTANTS.f_max] = command_limit(recording, self.vehicle)  # its saturation
        self.reset(self.eta)
        st = self._state
        args = (const, self._fp, self._ip, st.floats, st.ints, self._hist, self._beyond)
        eta, sd, code = run_rows(
            irls_run,
            (t, p, v, R, w, f, a),
            args + (self._any_n,),
            self.vehicle.n_rotors,
            "irls",
            progress,
            chunk=20000,
        )
        self.reset()
        return EstimateSeries(
            t=t.copy(),
            eta=eta,
            sd=sd,
            status=np.asarray(STATUSES)[code],
            estimator=self.name,
            config=asdict(self.config),
            seconds=time.perf_counter() - start,
            postprocess=postprocess_label(self.config.output_median),
        )


def _recording_arrays(recording: Recording, vehicle: Vehicle, window: int):
    """Measurement arrays of a recording (never its truth columns), validated, contiguous."""
    if not isinstance(recording, Recording):
        raise ConfigError(f"run() needs a Recording, got {type(recording).__name__}")
    where = recording.path or "recording"
    position, velocity, quaternion = recording.position, recording.velocity, recording.quaternion
    if position is None or velocity is None or quaternion is None:  # not recording.has_pose
        raise ConfigError(
            f"{where}: the IRLS estimator needs position, velocity and attitude "
            "columns (px..pz, vx..vz, qw..qz); this recording is IMU-only"
        )
    N = len(recording)
    if N == 0:
        raise ConfigError(f"{where}: the recording is empty")
    if N < window:
        raise ConfigError(
            f"{where}: the IRLS window of {window} samples is longer than the "
            f"recording ({N} samples)"
        )
    if recording.thrust_cmd.shape[1] != vehicle.n_rotors:
        raise ConfigError(
            f"{where}: {recording.thrust_cmd.shape[1]} rotor commands, the "
            f"vehicle has {vehicle.n_rotors} rotors"
        )
    t = np.asarray(recording.t, dtype=float)
    cols = (
        ("t", t[:, None]),
        ("px..pz", position),
        ("vx..vz", velocity),
        ("qw..qz", quaternion),
        ("wx..wz", recording.omega),
        ("f1..f4", recording.thrust_cmd),
    )
    for name, arr in cols:
        bad = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
        if bad.size:
            raise ConfigError(f"{where}: NaN or inf in {name} at row {bad[0] + 1}")
    if np.any(np.diff(t) <= 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise ConfigError(f"{where}: time must be strictly increasing (row {k + 2})")
    return tuple(
        np.ascontiguousarray(a, dtype=np.float64)
        for a in (
            t,
            recording.position,
            recording.velocity,
            recording.rotation,
            recording.omega,
            recording.thrust_cmd,
        )
    )
