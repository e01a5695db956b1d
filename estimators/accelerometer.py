"""The accelerometer in the regressions (IRLS, RLS): the thrust rows measured by the specific
force instead of differenced velocity.

The velocity rows of a segment's residual (:mod:`estimators.residuals`, eq. 17) difference
the velocity stream: ``r_v = v1 - v0 - g e3 dt + (T(eta) / m) R0 e3 dt``. A real velocity is
an on-board estimator's output, coloured and delayed, and its noise differenced at the row
rate dominates the thrust the rows should measure. An accelerometer measures the same
quantity directly: its specific force ``a`` (body FRD) is ``R^T (dv/dt - g e3)``, so over the
segment ``v1 - v0 - g e3 dt`` is ``R0 a0 dt`` and::

    r_v = R0 a0 dt + (T(eta) / m) R0 e3 dt

with the model's Jacobian unchanged (:func:`accelerometer_rows_into`). The row is affine in
``eta`` as before, so the prefilter and the window solve take it as they are; it no longer
reads the velocity stream at all. The position rows would still difference the position and
the velocity streams (``p1 - p0 - v0 dt``) with a Jacobian ``dt / 2`` times the velocity
rows': they carry noise and almost no information, and are not used. The rate and rotation
rows are unchanged.

Holds (:mod:`estimators.freshness`): the velocity rows follow the accelerometer's stream
(:func:`accelerometer_rows`). A reading bit-identical to the one before is held; it measured
the acceleration at its own time, not over the rows it is held for (the thrust changes at
every row), so only the segment that starts at a fresh reading has velocity rows, each
standing for the time since the previous fresh reading. The velocity and position streams no
longer gate anything.

The option (``IRLSConfig.accelerometer``, ``RLSConfig.accelerometer``; :data:`MODES`):
``"off"`` the velocity rows (the paper), ``"auto"`` the accelerometer wherever a sample has
one, the velocity rows elsewhere, ``"on"`` the same, and a recording or sample without an
accelerometer is said once (:func:`warn_missing`), not passed over silently.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from estimators.freshness import HELD_V, POSITION, VELOCITY
from estimators.residuals import RESIDUAL
from quadfault.errors import ConfigError
from quadfault.jit import jit

#: the values of the ``accelerometer`` option (module docstring)
MODES = ("off", "auto", "on")
#: a sample without an accelerometer, as the kernels take it
NO_ACCEL = np.full(3, np.nan)


def check_mode(owner: str, value) -> str:
    """``value`` as one of :data:`MODES` (True is ``"on"``, False ``"off"``); anything else
    is a one-line ``ConfigError`` naming ``owner``'s setting."""
    if value is True:
        return "on"
    if value is False:
        return "off"
    if value not in MODES:
        raise ConfigError(f"{owner}.accelerometer must be one of {', '.join(MODES)}, got {value!r}")
    return value


class AccelerometerMissing(UserWarning):
    """An estimator asked for the accelerometer (``accelerometer="on"``) got data without
    one and uses the velocity rows instead."""


def warn_missing(who: str, where: str) -> None:
    """Say that estimator ``who``, asked for the accelerometer, falls back to the velocity
    rows on ``where`` (a recording or a sample without one)."""
    warnings.warn(
        f"{who}: {where} has no accelerometer (ax, ay, az); the thrust rows use the "
        "velocity instead",
        AccelerometerMissing,
        stacklevel=3,
    )


def recording_accel(recording, mode: str, who: str) -> np.ndarray:
    """The accelerometer rows of ``recording`` for a regression in ``mode``: its ``accel``
    (N, 3), contiguous float64, or NaN rows (none, or the option off); says so once when
    ``mode`` is ``"on"`` and the recording has none."""
    n = len(recording)
    if mode == "off":
        return np.full((n, 3), np.nan)
    if recording.accel is None:
        if mode == "on":
            warn_missing(who, recording.path or "the recording")
        return np.full((n, 3), np.nan)
    return np.ascontiguousarray(recording.accel, dtype=np.float64)


@jit(inner=True)
def accelerometer_rows_into(dt, R0, a0, scale, r0, J):
    """The velocity rows of the residual model ``r(eta) = r0 + J eta`` of a segment of ``dt``
    [s] measured by the accelerometer (module docstring): ``r0_v = R0 a0 dt``, ``a0`` the
    specific force [m/s^2] (body FRD) at the segment's start, ``R0`` its attitude (body to
    world), and ``J_v`` the model's, both times ``scale`` (0: a held reading, no rows). The
    position rows are zeroed (not used)."""
    V, X = RESIDUAL.v, RESIDUAL.x
    for a in range(3):
        r0[V + a] = (R0[a, 0] * a0[0] + R0[a, 1] * a0[1] + R0[a, 2] * a0[2]) * dt * scale
        r0[X + a] = 0.0
        for j in range(J.shape[1]):
            J[V + a, j] *= scale
            J[X + a, j] = 0.0


@jit(inline="always")
def accelerometer_rows(dt, R0, a0, a0_held, fresh, counters, r0, J) -> int:
    """The segment's velocity rows from the accelerometer reading ``a0`` at its start
    (:func:`accelerometer_rows_into`; ``a0_held``: ``a0`` repeats the reading before it),
    ready for :func:`estimators.freshness.fresh_rows_into` (``counters``: its counters, read
    only); returns the freshness mask to give it, ``fresh`` with the velocity bit the
    accelerometer's and the position bit set (the position rows are not used).

    A reading measures the acceleration at its own time, not over the rows it is held for:
    a held reading's segment has no velocity rows (zeros, left pending), and a fresh one's
    rows are scaled by the rows pending before them, so that the mean
    :func:`~estimators.freshness.fresh_rows_into` emits is this segment's rows, spanning the
    time since the last fresh reading (the prefilter's step)."""
    scale = 0.0 if a0_held else counters[HELD_V] + 1.0
    accelerometer_rows_into(dt, R0, a0, scale, r0, J)
    out = fresh | POSITION
    return out & ~VELOCITY if a0_held else out | VELOCITY


@jit(inline="always")
def finite3(a) -> bool:
    """Every entry of the reading ``a`` (3 numbers, an array or a tuple) is finite."""
    return math.isfinite(a[0]) and math.isfinite(a[1]) and math.isfinite(a[2])


@jit(inline="always")
def repeats(a, last_a) -> bool:
    """The accelerometer reading ``a`` repeats ``last_a`` bit for bit (a held stream)."""
    return a[0] == last_a[0] and a[1] == last_a[1] and a[2] == last_a[2]


__all__ = [
    "MODES",
    "AccelerometerMissing",
    "NO_ACCEL",
    "accelerometer_rows",
    "accelerometer_rows_into",
    "check_mode",
    "finite3",
    "recording_accel",
    "repeats",
    "warn_missing",
]
