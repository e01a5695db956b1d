"""The paper's accuracy metrics (reference ``run.m`` / ``run_all.m``; facts section 6).

Per motor, over the estimates of one run (rows with status ``warmup`` excluded, as the
reference starts scoring at its first full window):

* error ``e = eta_true - eta_hat``;
* ``rmse = sqrt(mean(e^2))``;
* ``std`` = the N-1 sample standard deviation of the signed error;
* ``spike`` = ``max |e_m|`` over the union of the *other* motors' fault windows, each window
  first extended to where the true efficiency re-enters a +-3 % band of its pre-/post-fault
  level, then dilated by +-0.03 s (cross-coupling into healthy motors);
  ``None`` for a run without fault windows;
* ``excess_spike`` (ours) = that spike minus the 99.9th percentile of ``|e_m|`` outside every
  fault window: how much the transient exceeds the estimator's ordinary noise;
* ``coverage`` (ours) = the fraction of scored estimates with ``|e_m| <= sd_m`` (rows with a
  finite ``sd``): about 0.68 for an honest Gaussian one-sigma, near 1 for a pessimistic one,
  lower for an optimistic one; ``None`` when the series has no ``sd``.

Alignment: ``align="end"`` (default) compares each estimate with the truth at its own ``t``,
the newest sample it used. ``align="reference"`` compares with the truth at the window start
(``window - 1`` rows earlier), as the reference code does.

Scoring reads the truth (``eta_true`` and the sidecar's ``fault_windows``); the estimators
never do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimators.base import STATUS_WARMUP, EstimateSeries
from quadfault.errors import ConfigError
from quadfault.io.recording import Recording

BAND = 0.03  # relative band around the pre-/post-fault level
PAD = 0.03  # [s] dilation of each fault window
EXCESS_PERCENTILE = 99.9
ALIGNMENTS = ("end", "reference")
#: Samples per estimate window when the series' config does not say (reference code).
DEFAULT_WINDOWS = {"irls": 10, "ekf": 2}


@dataclass(frozen=True)
class Score:
    """Per-motor accuracy of one estimator on one recording.

    Attributes:
        rmse, std: per motor [1] (efficiency units).
        spike: per motor, or None without fault windows; an entry is None for a motor with
            no other motor's window.
        excess_spike: per motor, like ``spike``.
        seconds: the estimator's wall time [s].
        n: number of scored estimates.
        coverage: per motor, fraction of estimates with ``|e| <= sd`` (None without sd).
    """

    rmse: tuple
    std: tuple
    spike: tuple | None
    excess_spike: tuple | None
    seconds: float
    n: int
    coverage: tuple | None = None

    def to_contract(self) -> dict:
        """The ``metrics.json`` entry (docs/reproduce.md) plus ``excess_spike`` and ``n``."""
        return {
            "rmse": list(self.rmse),
            "std": list(self.std),
            "spike": None if self.spike is None else list(self.spike),
            "seconds": float(self.seconds),
            "excess_spike": None if self.excess_spike is None else list(self.excess_spike),
            "n": self.n,
            "coverage": None if self.coverage is None else list(self.coverage),
        }


def fault_windows(recording: Recording) -> list[tuple[int, float, float]]:
    """``[(motor (1-based), t0, t1), ...]`` from the sidecar meta (``t1`` None -> inf)."""
    raw = recording.meta.get("fault_windows") or []
    out = []
    for i, item in enumerate(raw):
        try:
            motor, t0, t1 = item
            motor, t0 = int(motor), float(t0)
            t1 = math.inf if t1 is None else float(t1)
        except (TypeError, ValueError):
            raise ConfigError(
                f"{recording.path or 'recording'}: meta fault_windows[{i}] must be "
                f"[motor, t0, t1], got {item!r}"
            ) from None
        if not 1 <= motor <= recording.thrust_cmd.shape[1] or not t1 >= t0:
            raise ConfigError(
                f"{recording.path or 'recording'}: meta fault_windows[{i}] = "
                f"{item!r} is not a valid [motor, t0, t1]"
            )
        out.append((motor, t0, t1))
    return out


def window_masks(
    t: np.ndarray, eta_true: np.ndarray, windows, *, band: float = BAND, pad: float = PAD
) -> np.ndarray:
    """``(n_motors, N)`` masks of each motor's own fault windows on the time base ``t``.

    Each window ``[t0, t1]`` is extended backwards to the last sample whose true efficiency is
    within ``+-band`` of the level just before it, forwards to the first sample within
    ``+-band`` of the level just after it, then dilated by ``+-pad`` seconds.
    """
    N, n_motors = eta_true.shape
    masks = np.zeros((n_motors, N), dtype=bool)
    tol = 1e-9
    for motor, t0, t1 in windows:
        m = motor - 1
        inside = np.flatnonzero((t >= t0 - tol) & (t <= t1 + tol))
        if inside.size == 0:
            continue
        s, e = int(inside[0]), int(inside[-1])
        before, after = eta_true[max(s - 1, 0), m], eta_true[min(e + 1, N - 1), m]

        def in_band(k, level, m=m):
            v = abs(eta_true[k, m])
            return (1 - band) * abs(level) <= v <= (1 + band) * abs(level)

        while s > 0 and not in_band(s, before):
            s -= 1
        while e < N - 1 and not in_band(e, after):
            e += 1
        masks[m] |= (t >= t[s] - pad - tol) & (t <= t[e] + pad + tol)
    return masks


def aligned_truth(
    recording: Recording, est: EstimateSeries, align: str = "end", window: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(t_truth, eta_truth)`` for each estimate row, per the alignment rule."""
    if align not in ALIGNMENTS:
        raise ConfigError(f"align must be one of {ALIGNMENTS}, got {align!r}")
    if recording.eta_true is None:
        raise ConfigError(
            f"{recording.path or 'recording'}: no true efficiency (eta1..eta4) to score against"
        )
    idx = np.searchsorted(recording.t, est.t)
    idx = np.clip(idx, 0, len(recording) - 1)
    if not np.allclose(recording.t[idx], est.t, rtol=0, atol=1e-9):
        raise ConfigError("estimate times do not match the recording's sample times")
    if align == "reference":
        if window is None:
            window = int(est.config.get("window", DEFAULT_WINDOWS.get(est.estimator, 1)))
        idx = np.maximum(idx - (window - 1), 0)
    return recording.t[idx], recording.eta_true[idx]


def score(
    recording: Recording,
    est: EstimateSeries,
    *,
    align: str = "end",
    window: int | None = None,
    band: float = BAND,
    pad: float = PAD,
) -> Score:
    """Score ``est`` against the truth of ``recording`` (see the module docstring)."""
    t_true, eta_true = aligned_truth(recording, est, align, window)
    keep = np.asarray(est.status) != STATUS_WARMUP
    if keep.sum() < 2:
        raise ConfigError("fewer than two scored estimates; the recording is too short")
    e = (eta_true - est.eta)[keep]
    t_true, eta_true = t_true[keep], eta_true[keep]
    rmse = np.sqrt(np.mean(e * e, axis=0))
    std = np.std(e, axis=0, ddof=1)
    windows = fault_windows(recording)
    spike = excess = None
    if windows:
        own = window_masks(t_true, eta_true, windows, band=band, pad=pad)
        any_window = own.any(axis=0)
        spike, excess = [], []
        for m in range(e.shape[1]):
            others = np.delete(own, m, axis=0).any(axis=0)
            if not others.any():
                spike.append(None)
                excess.append(None)
                continue
            peak = float(np.max(np.abs(e[others, m])))
            quiet = np.abs(e[~any_window, m])
            base = float(np.percentile(quiet, EXCESS_PERCENTILE)) if quiet.size else 0.0
            spike.append(peak)
            excess.append(peak - base)
        spike, excess = tuple(spike), tuple(excess)
    return Score(
        tuple(map(float, rmse)),
        tuple(map(float, std)),
        spike,
        excess,
        float(est.seconds),
        int(keep.sum()),
        _coverage(est, e, keep),
    )


def _coverage(est: EstimateSeries, e: np.ndarray, keep: np.ndarray) -> tuple | None:
    """Per motor, the fraction of rows with a finite ``sd`` where ``|e| <= sd``."""
    if est.sd is None:
        return None
    sd = np.asarray(est.sd, dtype=float)[keep]
    out = []
    for m in range(e.shape[1]):
        ok = np.isfinite(sd[:, m])
        out.append(float(np.mean(np.abs(e[ok, m]) <= sd[ok, m])) if ok.any() else None)
    return tuple(out)


def mean_or_none(values) -> float | None:
    """Mean over motors ignoring None (the reference's nanmean), None if all are None."""
    if values is None:
        return None
    vals = [v for v in values if v is not None]
    return float(np.mean(vals)) if vals else None
