"""The measurement record every estimator consumes: one row of a recording.

:class:`Sample` is what flows from the plant (or a recording) to an estimator: the measured
state and the commanded rotor thrusts, never the true efficiency. It lives in the core so
that the simulator, the environment and the estimators share it without importing each
other; :func:`samples` iterates a :class:`~quadfault.io.recording.Recording` as samples.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from quadfault.errors import ConfigError


class Sample(NamedTuple):
    """One measurement row (internal NED/FRD convention).

    Attributes:
        t: time [s].
        p: position, world [m] (3,).
        v: velocity, world [m/s] (3,).
        R: rotation body->world (3, 3).
        w: body rate [rad/s] (3,).
        f: commanded rotor thrusts [N] (n,), held from ``t`` until the next sample.
        accel: the accelerometer's specific force at ``t``, body FRD [m/s^2] (3,), or None
            where the source has no accelerometer (then the estimators use the velocity).
    """

    t: float
    p: np.ndarray
    v: np.ndarray
    R: np.ndarray
    w: np.ndarray
    f: np.ndarray
    accel: np.ndarray | None = None


def samples(recording):
    """Iterate the measurement rows of a recording as :class:`Sample` (no truth columns);
    ``accel`` is the accelerometer row where the recording has the columns, else None."""
    if not recording.has_pose:
        raise ConfigError(
            f"{recording.path or 'recording'}: the estimators need position, "
            "velocity and attitude columns (px..pz, vx..vz, qw..qz); this "
            "recording is IMU-only"
        )
    # each column once as a contiguous array: its rows are then contiguous views, which the
    # compiled estimators take without a copy
    p, v, R, w, f = (
        np.ascontiguousarray(a, dtype=float)
        for a in (
            recording.position,
            recording.velocity,
            recording.rotation,
            recording.omega,
            recording.thrust_cmd,
        )
    )
    acc = None if recording.accel is None else np.ascontiguousarray(recording.accel, dtype=float)
    for k in range(len(recording)):
        yield Sample(
            float(recording.t[k]), p[k], v[k], R[k], w[k], f[k], None if acc is None else acc[k]
        )


__all__ = ["Sample", "samples"]
