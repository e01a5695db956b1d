"""Fresh samples only: which streams of a sample are new, read from the data itself.

A real vehicle's streams come at their own rates (an on-board pose estimate at 100 Hz, a gyro
at 500 Hz) and a log, or an importer that puts them on one time base, repeats each stream's
last value until the next one arrives. A repeated value carries no new information: a filter
that takes it as a fresh measurement counts one noisy sample many times, and a regression
that differences it at the row rate sees "nothing moved" for several rows, then the whole
interval's motion in one.

Detection needs no flag from the simulator or the importer: a stream whose sample is
bit-identical to the previous sample's is held (:func:`fresh_streams`). Sensor noise, even
the position's quantisation, never repeats a value to the last bit between two fresh samples
of a moving vehicle; a noise-free recording of a moving vehicle has every stream fresh on
every row, and every estimator then runs exactly as without this module. A repeat that is
what the physics says is not a hold: a velocity (rate) of exactly zero that repeats, and the
position (attitude) beside it, are fresh -- a vehicle standing still, which is information
(hover through the allocation), not a stream waiting for its next sample.

How each estimator uses it (one implementation, these functions):

* the Kalman filters (EKF, UKF) still predict on every row; a held stream's measurement rows
  get the variance :data:`HELD_VARIANCE` for that update (:func:`measurement_variances_into`),
  so the filter learns nothing from the repeat;
* the regressions (IRLS, RLS) form each stream's differenced rows over the interval between
  its fresh samples (:func:`fresh_rows_into`): the velocity rows
  ``v_b - v_a - sum_k (g e3 - T_k R_k e3 / m) dt_k`` and the rate rows the same way, the sum
  of the per-row residuals of the rows in between (the measured parts telescope), divided by
  their number (the units of one row, whatever the stream's rate); a segment is used only
  when the velocity or the rate is fresh, its duration the time since the last one used,
  and the residual prefilter runs on each stream's rows over the time they span
  (:func:`prefilter_fresh_into`). The position and rotation rows, which need the
  velocity and the rate inside the segment, are kept only on a segment whose every stream
  was fresh at both ends (every segment of a noise-free recording; their weight next to the
  velocity and rate rows is tiny).
"""

from __future__ import annotations

import math

from estimators.residuals import RESIDUAL, prefilter_into
from estimators.state import fields
from quadfault.jit import jit

#: the streams of a sample, as bits of the mask :func:`fresh_streams` returns
POSITION, VELOCITY, ATTITUDE, RATE = 1, 2, 4, 8
#: every stream fresh
ALL_FRESH = POSITION | VELOCITY | ATTITUDE | RATE
#: the variance [unit^2] a held stream's measurement row gets in a Kalman update: 1e10 times
#: or more any variance the filters use, so that the update moves nothing by more than
#: rounding
HELD_VARIANCE = 1e10
#: the int counters of :func:`fresh_rows_into` (an estimator keeps them in its int state, all
#: zero after a reset, :func:`restart_into`): the streams held at the previous sample (a
#: mask), the segments summed into the pending velocity and rate rows, and 1 when the last
#: segment was used as it came (every stream fresh)
COUNTERS = ("held_prev", "held_v", "held_w", "whole")
N_COUNTERS = len(COUNTERS)
HELD_PREV, HELD_V, HELD_W, WHOLE = range(N_COUNTERS)
#: the float times [s] of :func:`fresh_rows_into` (kept with the counters): the time since
#: the last segment used, the pending velocity and rate rows' time, and the time the
#: velocity and rate rows of the segment just used span (0: held)
TIMES = ("pending", "pending_v", "pending_w", "span_v", "span_w")
N_TIMES = len(TIMES)
PENDING, PENDING_V, PENDING_W, SPAN_V, SPAN_W = range(N_TIMES)


@jit(inline="always")
def _same3(a, b) -> bool:
    return a[0] == b[0] and a[1] == b[1] and a[2] == b[2]


@jit(inline="always")
def _zero3(a) -> bool:
    return a[0] == 0.0 and a[1] == 0.0 and a[2] == 0.0


@jit(inline="always")
def _same33(R, last_R) -> bool:
    same = True
    for i in range(3):
        for j in range(3):
            same = same and R[i, j] == last_R[i, j]
    return same


@jit(inline="always")
def _mask(still, turning, same_p, same_v, same_R, same_w) -> int:
    """The mask of :func:`fresh_streams` from what it compares: the velocity exactly zero
    (``still``), the rate not (``turning``), and whether each stream repeats its last
    sample (``same_*``)."""
    mask = 0
    if still or not same_p:
        mask |= POSITION
    if still or not same_v:
        mask |= VELOCITY
    if not turning or not same_R:
        mask |= ATTITUDE
    if not turning or not same_w:
        mask |= RATE
    return mask


@jit(inline="always")
def fresh_streams(p, v, R, w, last_p, last_v, last_R, last_w) -> int:
    """The mask of the streams of the sample ``(p, v, R, w)`` that are fresh (bits
    :data:`POSITION`, :data:`VELOCITY`, :data:`ATTITUDE`, :data:`RATE`): a stream is held when
    its sample is bit-identical to the previous sample's ``(last_p, last_v, last_R,
    last_w)``, unless the repeat is the physics of a vehicle at rest: the velocity (rate)
    exactly zero, which keeps the velocity and the position (the rate and the attitude)
    fresh."""
    return _mask(
        _zero3(v),
        not _zero3(w),
        _same3(p, last_p),
        _same3(v, last_v),
        _same33(R, last_R),
        _same3(w, last_w),
    )


@jit(inline="always")
def accel_fresh(a, last_a, v) -> bool:
    """Whether the accelerometer's reading ``a`` is fresh: not bit-identical to the previous
    reading ``last_a``, or the vehicle at rest (the velocity ``v`` exactly zero: a still
    vehicle's specific force repeats)."""
    return _zero3(v) or not _same3(a, last_a)


@jit(inline="always")
def measurement_variances_into(r, fresh, rows_p, rows_v, rows_R, rows_w, out) -> bool:
    """The measurement variances of one Kalman update into ``out``: ``r`` where the row's
    stream is fresh in the mask ``fresh``, :data:`HELD_VARIANCE` where it is held. ``rows_*``:
    the first of the three rows of each stream in ``r`` (-1: the filter does not measure
    it). Returns False when every measured stream is held (``out`` is then all held)."""
    for k in range(r.shape[0]):
        out[k] = r[k]
    any_fresh = False
    for start, bit in ((rows_p, POSITION), (rows_v, VELOCITY), (rows_R, ATTITUDE), (rows_w, RATE)):
        if start < 0:
            continue
        if fresh & bit:
            any_fresh = True
        else:
            for a in range(3):
                out[start + a] = HELD_VARIANCE
    return any_fresh


@jit(inline="always")
def _pending_rows_into(r0, J, acc_r0, acc_J, start, held, fresh) -> None:
    """Add the segment's rows ``start .. start + 3`` to the pending sum (starting it when
    ``held`` is 0); then write into the segment, when ``fresh``, the sum's mean over its
    ``held + 1`` segments, zeros otherwise."""
    scale = 1.0 / (held + 1)
    for a in range(3):
        r = start + a
        if held == 0:
            acc_r0[r] = r0[r]
            for j in range(J.shape[1]):
                acc_J[r, j] = J[r, j]
        else:
            acc_r0[r] += r0[r]
            for j in range(J.shape[1]):
                acc_J[r, j] += J[r, j]
        r0[r] = acc_r0[r] * scale if fresh else 0.0
        for j in range(J.shape[1]):
            J[r, j] = acc_J[r, j] * scale if fresh else 0.0


@jit(inline="always")
def _zero_rows(r0, J, start, count) -> None:
    for r in range(start, start + count):
        r0[r] = 0.0
        for j in range(J.shape[1]):
            J[r, j] = 0.0


@jit(inline="always")
def fresh_rows_into(r0, J, dt, fresh, counters, acc_r0, acc_J, times) -> float:
    """Turn the residual model ``r(eta) = r0 + J eta`` of the segment from the previous sample
    to this one (:func:`estimators.residuals.segment_model_into`, ``dt`` [s]) into the rows of
    fresh information (module docstring), in place. ``fresh``: :func:`fresh_streams` of this
    sample; ``counters`` (:data:`N_COUNTERS`,) int, ``acc_r0`` (10,), ``acc_J`` (10, n),
    ``times`` (:data:`N_TIMES`,): the pending sums, kept by the estimator between samples
    (zeros after a reset, :func:`restart_into`).

    A stream's rows, when fresh, are the mean of the per-row residuals over the rows since
    its last fresh sample (the interval's residual divided by its rows: a constant factor of
    an affine row, exact for a constant ``eta``, and in the units of one row whatever the
    stream's rate). Returns the duration [s] of the segment to use (the time since the last
    one used), or 0.0 when neither the velocity nor the rate is fresh (nothing to use yet:
    the rows are pending). With every stream fresh now and before, the segment is left as
    it is and ``dt`` returned (``counters[WHOLE]`` = 1): bit for bit the estimator without
    this module."""
    prev = ALL_FRESH & ~counters[HELD_PREV]
    counters[HELD_PREV] = ALL_FRESH & ~fresh
    if (
        fresh == ALL_FRESH
        and prev == ALL_FRESH
        and counters[HELD_V] == 0
        and counters[HELD_W] == 0
        and times[PENDING] == 0.0
    ):
        counters[WHOLE] = 1
        return dt
    counters[WHOLE] = 0
    times[PENDING] += dt
    times[PENDING_V] = dt if counters[HELD_V] == 0 else times[PENDING_V] + dt
    times[PENDING_W] = dt if counters[HELD_W] == 0 else times[PENDING_W] + dt
    fv, fw = (fresh & VELOCITY) != 0, (fresh & RATE) != 0
    _pending_rows_into(r0, J, acc_r0, acc_J, RESIDUAL.v, counters[HELD_V], fv)
    _pending_rows_into(r0, J, acc_r0, acc_J, RESIDUAL.w, counters[HELD_W], fw)
    counters[HELD_V] = 0 if fv else counters[HELD_V] + 1
    counters[HELD_W] = 0 if fw else counters[HELD_W] + 1
    times[SPAN_V] = times[PENDING_V] if fv else 0.0
    times[SPAN_W] = times[PENDING_W] if fw else 0.0
    # the position and rotation rows need every stream inside the segment: never here
    _zero_rows(r0, J, RESIDUAL.x, 3)
    _zero_rows(r0, J, RESIDUAL.R, 1)
    if not (fv or fw):
        return 0.0
    used = times[PENDING]
    times[PENDING] = 0.0
    return used


@jit(inline="always")
def _filter_rows(r0, J, r0f, Jf, start, span, tau, first) -> None:
    """The prefilter of rows ``start .. start + 3`` over their ``span`` [s]; rows not used
    (``span`` 0) keep their filter state and stay zero."""
    if span <= 0.0:
        return
    b = 0.0 if first else math.exp(-span / tau)
    for r in range(start, start + 3):
        r0f[r] = b * r0f[r] + (1.0 - b) * r0[r]
        r0[r] = r0f[r]
        for j in range(J.shape[1]):
            Jf[r, j] = b * Jf[r, j] + (1.0 - b) * J[r, j]
            J[r, j] = Jf[r, j]


@jit(inline="always")
def prefilter_fresh_into(r0, J, r0f, Jf, dt, tau, first, counters, times) -> None:
    """The residual prefilter (:func:`estimators.residuals.prefilter_into`, time constant
    ``tau`` [s], ``first``: start it) on the segment :func:`fresh_rows_into` returned
    (``dt`` [s]): the whole segment as it came, or each stream's rows over the time they
    span, so that a held stream's zero rows do not pull its filter towards zero."""
    if counters[WHOLE] == 1:
        prefilter_into(r0, J, r0f, Jf, math.exp(-dt / tau), first)
        return
    _filter_rows(r0, J, r0f, Jf, RESIDUAL.v, times[SPAN_V], tau, first)
    _filter_rows(r0, J, r0f, Jf, RESIDUAL.w, times[SPAN_W], tau, first)


@jit(inner=True)
def restart_into(counters, times) -> None:
    """Drop the pending sums of :func:`fresh_rows_into` (a window that restarts after a bad
    sample: no segment spans the gap)."""
    for k in range(N_COUNTERS):
        counters[k] = 0
    for k in range(N_TIMES):
        times[k] = 0.0


#: rows of the previous sample as a filter keeps it, (SAMPLE.size, 3): p, v, Omega, then R
SAMPLE = fields("FreshnessSample", "p", "v", "w", ("R", 3))


@jit(inline="always")
def _same_row(a, last, row) -> bool:
    return a[0] == last[row, 0] and a[1] == last[row, 1] and a[2] == last[row, 2]


@jit(inline="always")
def fresh_since(p, v, R, w, last) -> int:
    """:func:`fresh_streams` against the previous sample ``last`` (:data:`SAMPLE` rows), read
    entry by entry (no views of ``last``: the Kalman filters run it on every update)."""
    same_R = True
    for i in range(3):
        for j in range(3):
            same_R = same_R and R[i, j] == last[SAMPLE.R + i, j]
    return _mask(
        _zero3(v),
        not _zero3(w),
        _same_row(p, last, SAMPLE.p),
        _same_row(v, last, SAMPLE.v),
        same_R,
        _same_row(w, last, SAMPLE.w),
    )


@jit(inline="always")
def remember_into(last, p, v, R, w) -> None:
    """Keep the sample ``(p, v, R, w)`` in ``last`` (:data:`SAMPLE` rows) for the next
    :func:`fresh_since`."""
    for a in range(3):
        last[SAMPLE.p, a], last[SAMPLE.v, a], last[SAMPLE.w, a] = p[a], v[a], w[a]
        for b in range(3):
            last[SAMPLE.R + a, b] = R[a, b]
