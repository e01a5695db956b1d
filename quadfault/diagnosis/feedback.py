"""Closed-loop feedback bias: the instrumental-variable check every accepted effect passes.

Every effect is regressed on closed-loop commands and states: within a block the controller
reacts to the block's own thrust noise, so an effect that reweights commands in time (lag,
delay) or scales the response (inertia, efficiency) can fit that reaction instead of physics.
:func:`iv_slope` regresses the residual on a candidate's fitted signal, instrumented by the
same signal on :func:`frozen_replay` (each block knows only what was known when it began).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from quadfault.diagnosis.library import predict
from quadfault.diagnosis.residuals import Replay

#: On a 1 kHz effect-free flight with thrust noise 0.05, least squares "finds" a 0.07 s motor
#: lag; every candidate must therefore pass the check below.
IV_Z = 2.0  # the IV slope must be this many standard errors above 0
#: least held-out gain of an effect whose signal the instrument cannot predict at all
IV_UNVERIFIED_GAIN = 0.5
IV_MIN = 0.5  # least IV slope (1: the fitted signal is all real, 0: all feedback bias)
#: An effect the check rejects whose IV slope is still this many standard errors above 0 and
#: at least ``PARTLY_MIN`` is partly real: the closed loop inflated its fit (an inertia x1.35
#: on a 250 Hz Lissajous flight fits at its bound 2 with slope 0.35 +- 0.03), but some of its
#: signal is physics. On effect-free simulated flights the slopes stay within 2 se of 0.
PARTLY_Z = 4.0
PARTLY_MIN = 0.15


def partly_real(iv, se) -> bool:
    """An instrumental-variable slope below ``IV_MIN`` that still shows real signal
    (``PARTLY_MIN`` or more, ``PARTLY_Z`` standard errors above 0)."""
    if iv is None or se is None or not (np.isfinite(iv) and np.isfinite(se)):
        return False
    return PARTLY_MIN <= iv < IV_MIN and iv - PARTLY_Z * se > 0.0


def iv_slope(rp: Replay, before, after, scale, residual, channels) -> tuple[float, float]:
    """Instrumental-variable slope of ``residual`` (B, 6, normalised) on the fitted signal
    (the model change from the terms ``before`` to the terms ``after``, e.g. a candidate fitted
    jointly with the accepted effects) over ``channels``, and its standard error.

    The instrument is the same signal on the :func:`frozen_replay`, which knows only what
    happened before each block began, so it is blind to the block's own process noise and to
    the controller's reaction to it: ``sum(z r) / sum(z s)`` is ~1 when the fitted signal is
    real and ~0 when least squares fitted that reaction (closed-loop feedback bias). Only the
    channels of ``channels`` in which the instrument predicts the signal (``sum(z s) > 0``)
    count; NaN when there are none. A fit stopped by a bound leaves part of its own signal in
    the residual: its least-squares slope ``sum(s r) / sum(s s)`` is then above 1 and the
    instrumented slope is divided by it (a feedback-biased inertia clipped at its bound must
    not pass for a real one)."""
    ch = np.asarray(channels, dtype=int)
    if ch.size == 0:
        return float("nan"), float("nan")
    sig = (predict(rp, list(after)) - predict(rp, list(before))) / scale
    fr = frozen_replay(rp)
    z = (predict(fr, list(after)) - predict(fr, list(before))) / scale
    ch = ch[np.sum(z[:, ch] * sig[:, ch], axis=0) > 0]  # channels the instrument predicts
    if ch.size == 0:
        return float("nan"), float("nan")
    den = float(np.sum(z[:, ch] * sig[:, ch]))  # > 0: a sum of positive channel terms
    beta = float(np.sum(z[:, ch] * residual[:, ch])) / den
    u = residual[:, ch] - beta * sig[:, ch]
    se = float(np.sqrt(np.sum((z[:, ch] * u) ** 2))) / den
    # relative to the least-squares slope of the same signal: 1 at an interior optimum, more
    # when the fit stopped at a bound (the residual still holds more of the signal, which
    # would inflate the instrumented slope too)
    ols = float(np.sum(sig[:, ch] * residual[:, ch])) / max(float(np.sum(sig[:, ch] ** 2)), 1e-300)
    scale = max(ols, 1.0)
    return beta / scale, se / scale


def frozen_replay(rp: Replay) -> Replay:
    """``rp`` with every block's inputs replaced by what was known when the block began.

    The state (``p, v, R, w``) of a block's first row holds over the block; the command is
    the first row's command extrapolated linearly with its rate of change over the recording
    row just before the block (no trend at the start of a run). Intervals outside blocks keep
    their inputs. Cached on ``rp``.

    A model signal computed on it depends only on what happened before each block started
    (the first command was chosen from the state at the block's start), so it is blind to the
    block's own process noise and to the controller's reaction to it -- the instrument of
    :func:`iv_slope`. It keeps an effect's memory (a lag's carried-over thrust, a delay's
    earlier commands) and the trajectory-driven part of the commands."""
    fr = rp.__dict__.get("_frozen")
    if fr is not None:
        return fr
    ok = np.flatnonzero(rp.block >= 0)
    blk = rp.block[ok]
    heads = np.r_[0, np.flatnonzero(np.diff(blk)) + 1]
    start = ok[heads]  # first interval of each block (blocks are numbered in time order)
    first = np.arange(len(rp.dt))
    first[ok] = start[blk]
    src = rp.starts or {"f": rp.f, "p": rp.p, "v": rp.v, "R": rp.R, "w": rp.w}
    t0 = rp.t[start]  # time at each block's first row
    cont = np.r_[False, rp.block_run[1:] == rp.block_run[:-1]]
    k0 = rp.knots[start] if rp.raw is not None else start
    # the commands frozen per block: the first row's value plus its trend over the last
    # recording row before the block
    x0 = src["f"][start]
    rows, rows_t = (rp.raw["f"], rp.raw["t"]) if rp.raw is not None else (rp.f, rp.t)
    trend = np.zeros_like(x0)
    kc = k0[cont]
    trend[cont] = (rows[kc] - rows[kc - 1]) / (rows_t[kc] - rows_t[kc - 1])[:, None]

    def commands(t_rows, block_of_row, values):
        out = values.copy()
        inside = block_of_row >= 0
        b = block_of_row[inside]
        out[inside] = x0[b] + (t_rows[inside] - t0[b])[:, None] * trend[b]
        return out

    raw = None
    if rp.raw is not None:
        f_raw = commands(rp.raw["t"][:-1], rp.block[rp.raw["seg"]], rp.raw["f"])
        f = np.asarray(rp.raw["merge"] @ f_raw)
        raw = dict(rp.raw, f=f_raw)
    else:
        f = commands(rp.t[:-1], rp.block, src["f"])

    def take(a):
        return None if a is None else a[first]

    fr = replace(
        rp, f=f, p=take(src["p"]), v=take(src["v"]), R=take(src["R"]), w=take(src["w"]), raw=raw
    )
    object.__setattr__(rp, "_frozen", fr)
    return fr
