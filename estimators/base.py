"""The one estimator interface shared by IRLS, the EKF and the oracle.

Online: ``est.update(sample) -> Estimate``, one measurement row at a time (the environment
calls this); a batch of N estimators (the vector environment's) takes one sample per row and
gives a :class:`BatchedEstimate`. Offline: ``est.run(recording) -> EstimateSeries`` over a
whole recording.
Estimators receive the *nominal* vehicle and measurements only; they never read the
recording's true efficiency columns. The measurement record :class:`~quadfault.io.sample.Sample`
and :func:`~quadfault.io.sample.samples` live in the core and are re-exported here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from quadfault.errors import ConfigError
from quadfault.io.recording import Recording
from quadfault.io.sample import Sample, samples  # the measurement record lives in the core
from quadfault.progress import progress_bar

#: Status values an estimate may carry.
STATUS_OK = "ok"
STATUS_WARMUP = "warmup"  # not enough samples in the window yet; previous estimate kept
STATUS_ILL_CONDITIONED = "ill_conditioned"  # conditioning guard tripped; previous estimate kept
STATUS_NO_EXCITATION = "no_excitation"  # data carries no information on eta (e.g. zero thrust)
STATUS_REJECTED = "rejected"  # every segment rejected as an outlier; previous estimate kept
STATUS_MAX_ITER = "max_iter"  # solver stopped at its iteration limit (estimate still usable)
STATUS_BAD_SAMPLE = "bad_sample"  # non-finite measurement skipped; previous estimate kept
STATUSES = (
    STATUS_OK,
    STATUS_WARMUP,
    STATUS_ILL_CONDITIONED,
    STATUS_NO_EXCITATION,
    STATUS_REJECTED,
    STATUS_MAX_ITER,
    STATUS_BAD_SAMPLE,
)
#: the status codes the compiled kernels return: indices into :data:`STATUSES`
OK = STATUSES.index(STATUS_OK)
WARMUP = STATUSES.index(STATUS_WARMUP)
ILL_CONDITIONED = STATUSES.index(STATUS_ILL_CONDITIONED)
NO_EXCITATION = STATUSES.index(STATUS_NO_EXCITATION)
REJECTED = STATUSES.index(STATUS_REJECTED)
MAX_ITER = STATUSES.index(STATUS_MAX_ITER)
BAD_SAMPLE = STATUSES.index(STATUS_BAD_SAMPLE)


@dataclass(frozen=True)
class Estimate:
    """An efficiency estimate.

    Attributes:
        t: time of the newest sample the estimate used [s] (estimates are causal).
        eta: estimated efficiency per rotor (1 = nominal).
        sd: one-sigma uncertainty per rotor, or None.
        status: one of :data:`STATUSES`.
        diagnostics: estimator-specific details (iterations, KKT histories, weights, ...).
    """

    t: float
    eta: np.ndarray
    sd: np.ndarray | None = None
    status: str = STATUS_OK
    diagnostics: Any = None


@dataclass(frozen=True)
class EstimateSeries:
    """Estimates over a recording: one row per update."""

    t: np.ndarray
    eta: np.ndarray
    sd: np.ndarray | None
    status: np.ndarray
    estimator: str
    config: dict = field(default_factory=dict)
    seconds: float = float("nan")  # wall time of the run [s]
    #: post-processing of ``eta``: ``"none"`` or ``"median:N"`` (causal running median of the
    #: last N estimates, :mod:`estimators.median`)
    postprocess: str = "none"


#: Sidecar key saying whether the flight's plant limited each rotor's thrust to the vehicle's
#: ``max_thrust`` (``true``) or had no upper limit (``false``); ``quadfault simulate`` writes it.
SATURATED_KEY = "saturated"


def command_limit(recording: Recording, vehicle) -> float:
    """The upper clip of the commanded rotor thrust [N] an estimator applies over
    ``recording``: ``vehicle.rotor_max_thrust`` unless the recording says its flight was not
    saturated (sidecar ``"saturated": false``), then none (``inf``). A recording without the
    key keeps the vehicle's limit. Commands are always clipped below at 0."""
    flag = recording.meta.get(SATURATED_KEY)
    if flag is None or flag is True:
        return float(vehicle.rotor_max_thrust)
    if flag is False:
        return float("inf")
    raise ConfigError(
        f"{recording.path or 'recording'}: sidecar key {SATURATED_KEY!r} must be "
        f"true or false, got {flag!r}"
    )


def sample_arrays(sample: Sample, n_rotors: int, who: str) -> tuple:
    """``(t, p, v, R, w, f)`` of one online ``sample`` as a float and contiguous float64
    arrays, for the compiled ``update`` of estimator ``who`` (its name in the error); a
    sample that is not one, or has the wrong shapes, is a one-line ``ConfigError``."""
    try:
        t = float(sample.t)
        arrays = [np.asarray(a, dtype=np.float64) for a in sample[1:6]]
    except (AttributeError, TypeError, ValueError, IndexError):
        raise ConfigError(
            f"{who}: {sample!r} is not a sample (t, p, v, R, w, f of numbers)"
        ) from None
    shapes = [a.shape for a in arrays]
    if shapes != [(3,), (3,), (3, 3), (3,), (n_rotors,)]:
        raise ConfigError(
            f"{who}: sample at t = {sample.t} has shapes {shapes}; expected "
            f"p, v, w (3,), R (3, 3), f ({n_rotors},)"
        )
    return (t, *(np.ascontiguousarray(a) for a in arrays))


def sample_accel(sample, who: str) -> np.ndarray | None:
    """The accelerometer reading of one online ``sample`` (its ``accel``, body FRD
    [m/s^2]) as a contiguous float64 (3,) array, or None where the sample has none; a
    reading of another shape is a one-line ``ConfigError`` naming estimator ``who``."""
    accel = sample[6] if len(sample) > 6 else None
    if accel is None:
        return None
    a = np.asarray(accel, dtype=np.float64)
    if a.shape != (3,):
        raise ConfigError(
            f"{who}: sample at t = {sample[0]} has an accelerometer reading of shape "
            f"{a.shape}; expected (3,) or None"
        )
    return np.ascontiguousarray(a)


def batch_accel(num: int, accel) -> np.ndarray | None:
    """The accelerometer readings of one batched sample (``accel`` (num, 3), body FRD
    [m/s^2]) as a contiguous float64 array, or None (no accelerometer); checked for shape."""
    if accel is None:
        return None
    a = np.ascontiguousarray(accel, dtype=np.float64)
    if a.shape != (num, 3):
        raise ConfigError(
            f"batched accelerometer readings must have shape {(num, 3)}, got {a.shape}"
        )
    return a


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


def batch_arrays(num: int, n: int, t, p, v, R, w, f):
    """The arrays of one batched sample (one row per estimator), float64 and contiguous,
    checked for shape."""
    t = np.ascontiguousarray(np.asarray(t, dtype=np.float64).reshape(-1))
    arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in (p, v, R, w, f)]
    shapes = [(num, 3), (num, 3), (num, 3, 3), (num, 3), (num, n)]
    if t.shape != (num,) or [a.shape for a in arrays] != shapes:
        raise ConfigError(
            f"batched sample must have t {(num,)}, p, v {(num, 3)}, R "
            f"{(num, 3, 3)}, w {(num, 3)}, f {(num, n)}; got "
            f"{[t.shape] + [a.shape for a in arrays]}"
        )
    return (t, *arrays)


def batch_eta0(eta, num: int, n: int) -> np.ndarray:
    """``eta0`` given as (n,) or (num, n), broadcast to (num, n) and checked finite."""
    try:
        eta = np.broadcast_to(np.asarray(eta, dtype=float), (num, n))
    except ValueError:
        raise ConfigError(f"eta0 must be {n} or ({num}, {n}) numbers") from None
    if not np.all(np.isfinite(eta)):
        raise ConfigError("eta0 must be finite")
    return np.ascontiguousarray(eta)


def reset_rows(num: int, mask) -> np.ndarray:
    """The rows selected by a reset mask (default: all)."""
    if mask is None:
        return np.arange(num, dtype=np.int64)
    mask = np.asarray(mask, dtype=bool).reshape(-1)
    if mask.shape != (num,):
        raise ConfigError(f"reset mask must have {num} booleans, got shape {mask.shape}")
    return np.flatnonzero(mask).astype(np.int64)


def check_num(num) -> int:
    """``num``, the number of estimators of a batch, as an int >= 1 (clean error otherwise)."""
    if isinstance(num, bool) or not isinstance(num, (int, np.integer)) or num < 1:
        raise ConfigError(f"number of estimators must be an integer >= 1, got {num!r}")
    return int(num)


@runtime_checkable
class OnlineEstimator(Protocol):
    name: str

    def reset(self, eta0=None) -> None: ...

    def update(self, sample: Sample) -> Estimate: ...

    def run(self, recording: Recording, progress: bool = False) -> EstimateSeries: ...


def run_rows(kernel, arrays, args: tuple, n: int, name: str, progress: bool, chunk: int = 50000):
    """An estimator's compiled ``run`` kernel over the rows of a recording's ``arrays``
    ``(t, p, v, R, w, f)``, in chunks of ``chunk`` rows with a progress bar (``name``):
    ``kernel(t, p, v, R, w, f, *args, eta, sd, code)``. Returns ``(eta, sd, code)``: the
    estimate and its sd (N, n) and the status code (N,) of every row."""
    t = arrays[0]
    N = len(t)
    eta, sd, code = np.empty((N, n)), np.empty((N, n)), np.empty(N, dtype=np.int64)
    bar = progress_bar(total=N, desc=name, unit="sample", disable=None if progress else True)
    for k0 in range(0, N, chunk):
        k = slice(k0, min(k0 + chunk, N))
        kernel(*(a[k] for a in arrays), *args, eta[k], sd[k], code[k])
        bar.update(k.stop - k0)
    bar.close()
    return eta, sd, code


__all__ = [
    "run_rows",
    "SATURATED_KEY",
    "STATUSES",
    "STATUS_BAD_SAMPLE",
    "STATUS_ILL_CONDITIONED",
    "STATUS_MAX_ITER",
    "STATUS_NO_EXCITATION",
    "STATUS_OK",
    "STATUS_REJECTED",
    "STATUS_WARMUP",
    "BatchedEstimate",
    "Estimate",
    "EstimateSeries",
    "OnlineEstimator",
    "batch_accel",
    "batch_arrays",
    "batch_eta0",
    "check_num",
    "reset_rows",
    "sample_accel",
    "sample_arrays",
    "Sample",
    "command_limit",
    "samples",
]
