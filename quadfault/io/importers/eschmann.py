"""Eschmann et al. (2024) Crazyflie 2.1 logs: 1 kHz IMU + PWM motor commands, IMU-only.

Raw columns (``eschmann-cf21-sysid/README.md``): ``timestamp_ms`` [ms, firmware clock],
``acc.x/y/z`` [g, body FLU], ``gyro.x/y/z`` [deg/s, body FLU], ``motor.m1..m4`` [0..65535].

The recording keeps the firmware clock (``t = timestamp_ms / 1000``) so the authors'
manoeuvre segments (thrust 35-65 s of log10, ...) apply unchanged. It is IMU-only: there is
no position, velocity, attitude, rotor speed or battery voltage in these logs.

Thrust curve: Foerster's PWM curve (see :mod:`quadfault.io.importers.crazyflie`) times one scale
factor fitted on a declared calibration segment (mean summed thrust = m times the mean
specific force along -z_FRD); scoring must use the rest of the recording.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfault.io.importers import (
    gap_stats,
    read_raw_table,
    require_columns,
    require_finite,
    trim_to_flight,
)
from quadfault.io.importers.crazyflie import (
    CF21_BRUSHED,
    FOERSTER_THRUST_CURVE,
    G_CRAZYFLIE,
    calibration_mask,
    scale_curve_on_segment,
)
from quadfault.io.recording import Recording, enu_flu_to_ned_frd
from quadfault.model.effects import curve_thrust

DATASET = "eschmann-cf21-sysid"
LICENCE = "MIT (c) 2024 Jonas Eschmann; github.com/arplaboratory/data-driven-system-identification"
TIME = "timestamp_ms"
ACC = ("acc.x", "acc.y", "acc.z")
GYRO = ("gyro.x", "gyro.y", "gyro.z")
MOTORS = ("motor.m1", "motor.m2", "motor.m3", "motor.m4")
PWM_FULL_SCALE = 65536.0
#: Default calibration window as fractions of the motors-running span (skips take-off).
DEFAULT_CALIBRATION_FRACTION = (0.10, 0.35)
#: The authors' manoeuvre segments [firmware s] (README), kept in the sidecar for reference.
AUTHOR_SEGMENTS = {
    "log10": {"thrust": [35.0, 65.0]},
    "log15": {"roll_pitch_inertia": [55.0, 90.0]},
    "log16": {"yaw": [[32.0, 38.0], [45.0, 49.0]]},
}


def import_eschmann(
    path, *, keep_all: bool = False, calibration=None, mass: float | None = None, **_ignored
) -> Recording:
    """Import one Eschmann log (``logNN.csv[.gz]``) as an IMU-only recording.

    Args:
        path: the gzip CSV.
        keep_all: keep the rows before/after the motors run (default: trim to them).
        calibration: ``(t0, t1)`` [firmware s] of the thrust-scale calibration segment;
            default 10 %..35 % of the motors-running span.
        mass: take-off mass [kg] (default 0.027, the authors').
    """
    path = Path(path)
    table = read_raw_table(path)
    require_columns(path, table, (TIME, *ACC, *GYRO, *MOTORS))
    require_finite(path, table, (TIME, *ACC, *GYRO, *MOTORS))
    arrays = {
        "t": table[TIME] / 1000.0,  # ms -> s
        "acc": np.stack([table[c] for c in ACC], axis=1) * G_CRAZYFLIE,  # g -> m/s^2
        "gyro": np.radians(np.stack([table[c] for c in GYRO], axis=1)),  # deg/s -> rad/s
        "u": np.stack([table[c] for c in MOTORS], axis=1) / PWM_FULL_SCALE,
    }
    arrays, t_run, dropped = trim_to_flight(
        path, arrays, arrays["u"], keep_all, never="the motors never run (all motor.m* are 0)"
    )
    t = arrays["t"]

    _, _, _, omega, accel = enu_flu_to_ned_frd(None, None, None, arrays["gyro"], arrays["acc"])
    if calibration is None:
        f0, f1 = DEFAULT_CALIBRATION_FRACTION
        calibration = (t_run[0] + f0 * (t_run[1] - t_run[0]), t_run[0] + f1 * (t_run[1] - t_run[0]))
    calibration = tuple(float(x) for x in calibration)
    m = CF21_BRUSHED.mass if mass is None else float(mass)
    # collective thrust measured by the accelerometer: T = -m a_z (FRD), plus rotor drag in z
    measured = -m * accel[:, 2]
    cal = calibration_mask(t, calibration)
    curve, scale = scale_curve_on_segment(FOERSTER_THRUST_CURVE, arrays["u"], measured, cal)
    vehicle = CF21_BRUSHED.vehicle(mass=m, max_thrust=float(curve_thrust(curve, 1.0)))

    stem = path.name.split(".")[0]
    meta = {
        "dataset": DATASET,
        "file": path.name,
        "licence": LICENCE,
        "time_origin": "Crazyflie firmware clock (timestamp_ms / 1000), as the authors' segments",
        "author_segments": AUTHOR_SEGMENTS.get(stem, {}),
        "constants": dict(
            CF21_BRUSHED.sources, mass="given" if mass is not None else CF21_BRUSHED.sources["mass"]
        ),
        "calibration": {
            "segment": list(calibration),
            "fitted": {"thrust_scale": scale, "thrust_curve": list(curve)},
            "method": "Foerster PWM curve x scale so that mean(sum f_i) = mean(-m a_z) on the "
            "segment",
            "score_on": "the rest of the recording; exclude this segment when scoring",
        },
        "import": {
            "importer": "eschmann",
            "segment": [float(t[0]), float(t[-1])],
            "motors_running": list(t_run),
            "trimmed": not keep_all,
            "dropped_duplicate_times": dropped,
            **gap_stats(t),
            "missing": [
                "position, velocity, attitude (IMU-only log)",
                "rotor speed",
                "battery voltage",
            ],
            "commands": "u = motor.m* / 65536 (firmware motor power command)",
        },
    }
    thrust_cmd = curve_thrust(curve, arrays["u"])
    return Recording(
        t=t,
        omega=omega,
        accel=accel,
        thrust_cmd=thrust_cmd,
        commands_u=arrays["u"],
        thrust_curve=curve,
        vehicle=vehicle,
        frame="NED",
        source=f"{DATASET}/{path.name}: Crazyflie 2.1 on-board log (Eschmann et al. "
        "2024, arXiv:2404.07837), imported by quadfault",
        meta=meta,
    )
