"""Resampling of a log's streams onto one time base (pure numpy).

Continuous signals by linear interpolation, unit quaternions by normalised linear
interpolation (signs aligned), commands and flags by zero-order hold (the value held since
its last message, as the recording format defines for commands).
"""

from __future__ import annotations

import numpy as np


def interp_linear(t_src: np.ndarray, x_src: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Linear interpolation of each column of ``x_src`` at ``t`` (NaN outside the source)."""
    x_src = np.asarray(x_src, dtype=float)
    x2 = x_src if x_src.ndim == 2 else x_src[:, None]
    out = np.stack([np.interp(t, t_src, c, left=np.nan, right=np.nan) for c in x2.T], axis=1)
    return out if x_src.ndim == 2 else out[:, 0]


def zero_order_hold(t_src: np.ndarray, x_src: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The most recent source sample at or before each ``t`` (NaN before the first)."""
    x_src = np.asarray(x_src, dtype=float)
    idx = np.searchsorted(t_src, t, side="right") - 1
    out = x_src[np.clip(idx, 0, len(t_src) - 1)].astype(float)
    out[idx < 0] = np.nan
    return out


def interp_quaternion(t_src: np.ndarray, q_src: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Normalised linear interpolation of unit quaternions, after flipping signs so that
    consecutive samples lie in one hemisphere (q and -q are the same rotation)."""
    q = np.array(q_src, dtype=float)
    dots = np.sum(q[1:] * q[:-1], axis=1)
    flips = np.cumprod(np.where(dots < 0, -1.0, 1.0))
    q[1:] *= flips[:, None]
    out = interp_linear(t_src, q, t)
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    return out * np.where(out[:, :1] < 0, -1.0, 1.0)


def merge_topics(t: np.ndarray, streams: dict) -> dict:
    """Resample ``{name: (t_src [s], x_src, kind)}`` onto ``t``; ``kind`` is "linear",
    "quaternion" or "hold"."""
    out = {}
    for name, (ts, xs, kind) in streams.items():
        order = np.argsort(ts, kind="stable")
        ts, xs = np.asarray(ts)[order], np.asarray(xs)[order]
        uniq = np.r_[True, np.diff(ts) > 0]
        ts, xs = ts[uniq], xs[uniq]
        if kind == "linear":
            out[name] = interp_linear(ts, xs, t)
        elif kind == "quaternion":
            out[name] = interp_quaternion(ts, xs, t)
        elif kind == "hold":
            out[name] = zero_order_hold(ts, xs, t)
        else:
            raise ValueError(f"unknown resampling kind {kind!r}")
    return out
