"""Fixed channel weights and the held-out scores of the diagnosis.

**Weights are fixed before any candidate is fitted** and shared by the nominal model and every
candidate (fits, cross-validation, acceptance tests, reported improvements):

* the noise scale ``s_j`` of channel ``j`` is the smaller of two robust estimates of its
  block-to-block noise -- the MAD of the second differences at lag 2 (``x[k+2] - 2 x[k] +
  x[k-2]``) of the *measured* channel and of the *nominal model's* residual, each divided by
  sqrt(6) (white noise) -- floored
  (``Replay.floors``). Both contain the noise; the first is blind to any model, the second to
  the trajectory, so an unmodelled effect cannot inflate the smaller one much (an unmodelled
  lag makes the nominal residual of roll/pitch fast, not the measured body motion);
* channels measuring the same quantity share one total weight: translation (``acc_*`` and
  ``sf_*`` together), rotation (``alpha_*``) and rotor speeds (``rotor_*``) each count as
  three channels, so adding a sensor does not tilt the pooled score towards it. The divisor
  of channel ``j`` is ``s_j / sqrt(w_j)`` with ``w_j = 3 / (channels in its group)``.

**Outliers cannot dominate a score**: every normalised block residual is winsorised at
``CLIP`` (5) robust standard deviations (1.4826 MAD) of the nominal model's normalised residual
in that channel, and never below ``CLIP`` noise units -- fixed once, before any candidate.

Scores: ``improvement = 1 - RMS(after) / RMS(before)`` of the winsorised, weighted held-out
residuals over all channels (or one channel: there the weight cancels and the figures are
in the channel's own unit). A channel's 95 % interval is a moving-block bootstrap over
contiguous segments of about ``SEGMENT_SECONDS`` (1 s; at least 10 segments) of the scored
blocks, ``BOOTSTRAP`` (2000) resamples from a fixed ``numpy.random.Generator`` (seed 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadfault.diagnosis.residuals import Replay, channel_group

CLIP = 5.0
SEGMENT_SECONDS = 1.0
BOOTSTRAP = 2000
GROUP_WEIGHT = 3.0


def _second_difference_scale(rp: Replay, x: np.ndarray) -> np.ndarray:
    """Robust scale of white noise in ``x`` (B, C) from second differences at lag 2 within
    runs, ``x[k+2] - 2 x[k] + x[k-2]``: blind to linear trends and to the lag-1 correlation
    of block-mean accelerations that share their end samples."""
    same = rp.block_run[4:] == rp.block_run[:-4]
    d = (x[4:] - 2.0 * x[2:-2] + x[:-4])[same]
    if len(d) < 5:
        d = x - np.median(x, axis=0)
        return 1.4826 * np.median(np.abs(d), axis=0)
    return 1.4826 * np.median(np.abs(d - np.median(d, axis=0)), axis=0) / math.sqrt(6.0)


@dataclass(frozen=True, eq=False)
class Scoring:
    """The fixed weights of one recording.

    Attributes:
        noise: noise scale per channel (channel units).
        weight: relative weight per channel (group share).
        divisor: ``noise / sqrt(weight)``: residuals are divided by this everywhere.
        clip: winsorising level per channel, in divided (normalised) units.
        rows: scored blocks (B,) bool.
        channels: channel names.
    """

    noise: np.ndarray
    weight: np.ndarray
    divisor: np.ndarray
    clip: np.ndarray
    rows: np.ndarray
    channels: tuple

    def normalised(self, residual: np.ndarray) -> np.ndarray:
        """Winsorised normalised residual of the scored blocks."""
        z = residual[self.rows] / self.divisor
        return np.clip(z, -self.clip, self.clip)

    def sse(self, residual: np.ndarray) -> float:
        z = self.normalised(residual)
        return float(np.sum(z * z))

    def channel_sse(self, residual: np.ndarray) -> np.ndarray:
        z = self.normalised(residual)
        return np.sum(z * z, axis=0)

    def improvement(self, before: np.ndarray, after: np.ndarray) -> float:
        b = self.sse(before)
        return 1.0 - math.sqrt(self.sse(after) / b) if b > 0 else 0.0

    def channel_rms(self, residual: np.ndarray) -> np.ndarray:
        """Winsorised RMS per channel, in the channel's own unit."""
        z = self.normalised(residual) * self.divisor
        return np.sqrt(np.mean(z * z, axis=0))

    def channel_table(self, before: np.ndarray, after: np.ndarray, block_dur) -> tuple:
        """``({channel: {"rmse_before", "rmse_after", "improvement", "ci95"}}, ci95 of the
        pooled improvement)``: per-channel held-out figures with bootstrap intervals."""
        zb, za = self.normalised(before), self.normalised(after)
        n = len(zb)
        per = max(1, int(round(SEGMENT_SECONDS / float(np.median(block_dur)))))
        n_seg = max(min(n // per, 200), min(10, n))
        edges = np.linspace(0, n, n_seg + 1).astype(int)
        sb = np.add.reduceat(zb * zb, edges[:-1], axis=0)  # (n_seg, C) sums of squares
        sa = np.add.reduceat(za * za, edges[:-1], axis=0)
        idx = np.random.default_rng(0).integers(0, n_seg, size=(BOOTSTRAP, n_seg))
        Bb, Ba = sb[idx].sum(axis=1), sa[idx].sum(axis=1)  # (BOOTSTRAP, C)
        with np.errstate(divide="ignore", invalid="ignore"):
            imp = 1.0 - np.sqrt(Ba / Bb)
            pooled = 1.0 - np.sqrt(Ba.sum(axis=1) / Bb.sum(axis=1))
        rb = np.sqrt(np.mean(zb * zb, axis=0)) * self.divisor
        ra = np.sqrt(np.mean(za * za, axis=0)) * self.divisor
        out = {}
        for j, ch in enumerate(self.channels):
            ok = np.isfinite(imp[:, j])
            ci = np.percentile(imp[ok, j], [2.5, 97.5]) if ok.any() else [np.nan, np.nan]
            out[ch] = {
                "rmse_before": float(rb[j]),
                "rmse_after": float(ra[j]),
                "improvement": float(1.0 - ra[j] / rb[j]) if rb[j] > 0 else 0.0,
                "ci95": [float(ci[0]), float(ci[1])],
            }
        ok = np.isfinite(pooled)
        ci = np.percentile(pooled[ok], [2.5, 97.5]) if ok.any() else [np.nan, np.nan]
        return out, [float(ci[0]), float(ci[1])]


def channel_weights(channels) -> np.ndarray:
    """Group share of each channel: every group counts as ``GROUP_WEIGHT`` channels."""
    groups = [channel_group(c) for c in channels]
    return np.array([GROUP_WEIGHT / groups.count(g) for g in groups])


def fixed_scoring(rp: Replay, nominal_residual: np.ndarray, rows=None) -> Scoring:
    """The weights of ``rp`` from its measured channels and the nominal model's residual
    (never from a fitted model; module docstring)."""
    noise = np.minimum(
        _second_difference_scale(rp, rp.measured), _second_difference_scale(rp, nominal_residual)
    )
    noise = np.maximum(noise, rp.floors())
    weight = channel_weights(rp.channels)
    divisor = noise / np.sqrt(weight)
    rows = np.ones(rp.n_blocks, dtype=bool) if rows is None else rows
    z = nominal_residual[rows] / divisor
    spread = 1.4826 * np.median(np.abs(z - np.median(z, axis=0)), axis=0)
    clip = np.maximum(CLIP * spread, CLIP * np.sqrt(weight))
    return Scoring(noise, weight, divisor, clip, rows, tuple(rp.channels))
