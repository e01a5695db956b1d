"""Causal running median of an estimate stream (an output filter beyond the paper).

The reported estimate at a sample is, per motor, the median of the last ``L`` estimates
(the middle value, or the mean of the middle two, as ``np.median``); before ``L`` estimates
exist the first one counts for the missing ones. Only the output is filtered: an estimator
that uses it (``IRLSConfig.output_median``) still anchors its next window to the unfiltered
estimate. It delays a step by about ``L / 2`` samples.

:func:`median_push_into` is one push, plain Python compiled by :func:`quadfault.jit.jit`,
allocation-free: a ring of the last ``L`` values per motor and the same values kept sorted (one
removal and one insertion per push instead of a sort). The online estimators push once per
update; :func:`causal_median` runs it over a whole series, and :func:`median_series` over an
estimator's output (the post-processing ``quadfault estimate --median N`` gives every
estimator).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit


@jit
def median_push_into(buf, srt, k, x, fresh, out) -> None:
    """Push ``x`` (n,) into slot ``k`` of the ring ``buf`` (L, n) and write the running
    median into ``out`` (n,). ``srt`` (L, n) holds each column of the ring sorted; a
    ``fresh`` ring (no value yet) is filled with ``x``."""
    L, n = buf.shape
    h = L // 2
    for j in range(n):
        new = x[j]
        if fresh:
            for s in range(L):
                buf[s, j] = new
                srt[s, j] = new
        else:
            old = buf[k, j]
            buf[k, j] = new
            r = 0
            while r < L - 1 and srt[r, j] != old:  # the old value leaves the ring
                r += 1
            while r > 0 and srt[r - 1, j] > new:  # the new one moves into place
                srt[r, j] = srt[r - 1, j]
                r -= 1
            while r < L - 1 and srt[r + 1, j] < new:
                srt[r, j] = srt[r + 1, j]
                r += 1
            srt[r, j] = new
        out[j] = srt[h, j] if L % 2 else (srt[h - 1, j] + srt[h, j]) / 2.0


@jit
def _causal_median_into(x, buf, srt, out) -> None:
    L = buf.shape[0]
    for k in range(x.shape[0]):
        median_push_into(buf, srt, k % L, x[k], k == 0, out[k])


def causal_median(x, length: int) -> np.ndarray:
    """Running median of the last ``length`` rows of ``x`` (N, n), per column; the first
    rows see the first row repeated before them. ``length <= 1`` returns a copy."""
    x = np.ascontiguousarray(x, dtype=float)
    if length <= 1 or len(x) == 0:
        return x.copy()
    if x.ndim != 2:
        raise ConfigError(f"causal_median needs a (N, n) array, got shape {x.shape}")
    out = np.empty_like(x)
    n = x.shape[1]
    _causal_median_into(x, np.empty((length, n)), np.empty((length, n)), out)
    return out


def postprocess_label(length: int) -> str:
    """How a series was post-processed: ``"none"`` or ``"median:<length>"``."""
    return "none" if length <= 1 else f"median:{int(length)}"


def median_series(series, length: int):
    """``series`` (an :class:`~estimators.base.EstimateSeries` not yet post-processed) with
    ``eta`` replaced by its causal running median over ``length`` rows (``sd`` and ``status``
    kept); ``length <= 1`` returns it unchanged. The same kernel as an estimator's online
    output median (``IRLSConfig.output_median``), so both give identical numbers."""
    if isinstance(length, bool) or not isinstance(length, (int, np.integer)) or length < 1:
        raise ConfigError(f"median length must be an integer >= 1 samples, got {length!r}")
    if length <= 1:
        return series
    if series.postprocess != "none":
        raise ConfigError(
            f"the {series.estimator} series is already post-processed ({series.postprocess})"
        )
    return replace(
        series, eta=causal_median(series.eta, int(length)), postprocess=postprocess_label(length)
    )


__all__ = ["causal_median", "median_push_into", "median_series", "postprocess_label"]
