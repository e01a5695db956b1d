"""IDSIA nano-drone benchmark (Busetto et al. 2026): Crazyflie 2.1 Brushless, 100 Hz, full state.

Raw columns (``nanodrone-cf21bl/README.md``; world z-up, body FLU): ``t`` [s]; ``x,y,z``
[m]; ``vx,vy,vz`` [m/s]; ``qx,qy,qz,qw`` (body->world, scalar last); ``wx,wy,wz`` [rad/s];
``ax,ay,az`` specific force **in the world frame** [m/s^2]; ``m1..m4_thrust`` normalised
command 0..1; ``m1..m4_erpm`` measured electrical RPM; ``Vbat`` [V]; ``is_flying`` 0/1.

Conversions: the world specific force is rotated into the body (``R(q)^T a``, as the
authors do) and everything goes ENU/FLU -> NED/FRD. eRPM -> rad/s with 6 pole pairs; values
above 3e5 eRPM or jumps above 1e5 eRPM are telemetry spikes and become NaN (the authors'
rule). Commands are written as ``u1..u4`` with a thrust curve f = a + b u + c u^2 fitted on a
declared calibration segment to k_F omega^2 of the measured rotor speeds (k_F = 3.72e-8, the
authors'), all four rotors pooled; scoring must use the rest.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfault.errors import ConfigError, RecordingError
from quadfault.io.importers import (
    gap_stats,
    read_raw_table,
    require_columns,
    require_finite,
    trim_to_flight,
)
from quadfault.io.importers.crazyflie import (
    BRUSHLESS_KF,
    CF21_BRUSHLESS,
    ERPM_TO_RAD_S,
    calibration_mask,
)
from quadfault.io.recording import QUAT_NORM_TOL, Recording, enu_flu_to_ned_frd
from quadfault.model.effects import curve_thrust
from quadfault.model.rotation import quat_to_rot

DATASET = "nanodrone-cf21bl"
LICENCE = (
    "not stated (no LICENSE file; the paper calls data and scripts open-source): "
    "research use inside this project only, do not redistribute"
)
POS, VEL, RATE, ACC = ("x", "y", "z"), ("vx", "vy", "vz"), ("wx", "wy", "wz"), ("ax", "ay", "az")
QUAT = ("qw", "qx", "qy", "qz")
CMD = tuple(f"m{i}_thrust" for i in range(1, 5))
ERPM = tuple(f"m{i}_erpm" for i in range(1, 5))
ERPM_SPIKE, ERPM_JUMP = 3e5, 1e5
DEFAULT_CALIBRATION_FRACTION = (0.0, 0.3)


def clean_erpm(erpm: np.ndarray) -> np.ndarray:
    """NaN where the telemetry spikes (> 3e5 eRPM, or a jump > 1e5 from the previous sample)."""
    out = np.array(erpm, dtype=float)
    out[~(out <= ERPM_SPIKE)] = np.nan
    jump = np.zeros_like(out, dtype=bool)
    jump[1:] = np.abs(np.diff(out, axis=0)) > ERPM_JUMP
    out[jump] = np.nan
    return out


def fit_command_curve(u: np.ndarray, rotor_thrust: np.ndarray) -> tuple:
    """Least-squares (a, b, c) of f = a + b u + c u^2 over all rotors and rows (NaN skipped)."""
    uu, ff = u.ravel(), rotor_thrust.ravel()
    ok = np.isfinite(uu) & np.isfinite(ff)
    if ok.sum() < 30:
        raise ConfigError("calibration segment has fewer than 30 valid rotor-speed samples")
    X = np.stack((np.ones(ok.sum()), uu[ok], uu[ok] ** 2), axis=1)
    coef, *_ = np.linalg.lstsq(X, ff[ok], rcond=None)
    return tuple(float(c) for c in coef)


def stale_fraction(x: np.ndarray) -> float:
    """Fraction of rows identical to the previous one (repeated Wi-Fi samples)."""
    if len(x) < 2:
        return 0.0
    return float(np.mean(np.all(np.diff(x, axis=0) == 0, axis=1)))


def import_nanodrone(
    path, *, keep_all: bool = False, calibration=None, mass: float | None = None, **_ignored
) -> Recording:
    """Import one flight (``<name>.csv[.gz]``) with pose, IMU, commands, rotor speeds, Vbat.

    Args:
        path: the gzip CSV.
        keep_all: keep rows where ``is_flying`` is 0 (default: trim to the flying span).
        calibration: ``(t0, t1)`` [s] of the thrust-curve calibration segment (default: the
            first 30 % of the kept span).
        mass: take-off mass [kg] (default 0.045, the authors').
    """
    path = Path(path)
    table = read_raw_table(path)
    needed = ("t", *POS, *VEL, *QUAT, *RATE, *ACC, *CMD)
    require_columns(path, table, needed)
    require_finite(path, table, needed)
    q = np.stack([table[c] for c in QUAT], axis=1)
    norm = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > QUAT_NORM_TOL)
    if bad.size:
        raise RecordingError(
            path, f"quaternion norm {norm[bad[0]]:.6g} is not 1", column="qw", row=int(bad[0]) + 1
        )
    arrays = {
        "t": table["t"],
        "pos": np.stack([table[c] for c in POS], axis=1),
        "vel": np.stack([table[c] for c in VEL], axis=1),
        "q": q / norm[:, None],
        "w": np.stack([table[c] for c in RATE], axis=1),
        "acc_world": np.stack([table[c] for c in ACC], axis=1),
        "u": np.stack([table[c] for c in CMD], axis=1),
        "omega_rotor": (
            clean_erpm(np.stack([table[c] for c in ERPM], axis=1)) * ERPM_TO_RAD_S
            if all(c in table for c in ERPM)
            else None
        ),
        "vbat": table.get("Vbat"),
        "flying": table.get("is_flying"),
    }
    flying = arrays["flying"]
    arrays, t_run, dropped = trim_to_flight(
        path,
        arrays,
        arrays["u"] if flying is None else flying[:, None],
        keep_all,
        threshold=0.0 if flying is None else 0.5,
        never="no rows with the vehicle flying",
        rows="while flying",
    )
    t = arrays["t"]

    # world specific force -> body FLU (R^T a), then ENU/FLU -> NED/FRD
    R = quat_to_rot(arrays["q"])
    acc_body = np.einsum("nji,nj->ni", R, arrays["acc_world"])
    pos, vel, quat, omega, accel = enu_flu_to_ned_frd(
        arrays["pos"], arrays["vel"], arrays["q"], arrays["w"], acc_body
    )
    if calibration is None:
        f0, f1 = DEFAULT_CALIBRATION_FRACTION
        calibration = (t[0] + f0 * (t[-1] - t[0]), t[0] + f1 * (t[-1] - t[0]))
    calibration = tuple(float(x) for x in calibration)
    cal = calibration_mask(t, calibration)
    missing = []
    if arrays["omega_rotor"] is None:
        raise ConfigError(f"{path}: columns m1_erpm..m4_erpm are needed to fit the thrust curve")
    curve = fit_command_curve(arrays["u"][cal], BRUSHLESS_KF * arrays["omega_rotor"][cal] ** 2)
    m = CF21_BRUSHLESS.mass if mass is None else float(mass)
    vehicle = CF21_BRUSHLESS.vehicle(mass=m, max_thrust=float(curve_thrust(curve, 1.0)))
    if arrays["vbat"] is None:
        missing.append("battery voltage")
    thrust_cmd = curve_thrust(curve, arrays["u"])
    check = -m * accel[:, 2]
    rest = ~cal
    meta = {
        "dataset": DATASET,
        "file": path.name,
        "licence": LICENCE,
        # thrust per squared measured rotor speed [N/(rad/s)^2]: the diagnosis' rotor_*
        # channels compare k omega_i^2 with the commanded thrust (docs/importers.md)
        "rotor_thrust_coefficient": BRUSHLESS_KF,
        "constants": dict(CF21_BRUSHLESS.sources),
        "calibration": {
            "segment": list(calibration),
            "fitted": {"thrust_curve": list(curve)},
            "method": "least squares of k_F omega_i^2 (measured eRPM) on u_i, rotors pooled",
            "score_on": "the rest of the recording; exclude this segment when scoring",
            "thrust_ratio_on_rest": float(np.mean(check[rest]) / np.mean(thrust_cmd[rest].sum(1)))
            if rest.any()
            else None,
        },
        "import": {
            "importer": "nanodrone",
            "segment": [float(t[0]), float(t[-1])],
            "flying": list(t_run),
            "trimmed": not keep_all,
            "dropped_duplicate_times": dropped,
            **gap_stats(t),
            "stale_rate_fraction": stale_fraction(arrays["w"]),
            "rotor_speed_nan_fraction": float(np.mean(~np.isfinite(arrays["omega_rotor"]))),
            "missing": missing,
            "notes": "pose is the on-board estimate (mocap-aided); accelerometer rotated to body "
            "with R(q)^T; motor telemetry is not shifted (the authors found ~30 ms "
            "offset to the IMU)",
        },
    }
    return Recording(
        t=t,
        position=pos,
        velocity=vel,
        quaternion=quat,
        omega=omega,
        accel=accel,
        thrust_cmd=thrust_cmd,
        commands_u=arrays["u"],
        thrust_curve=curve,
        vbat=arrays["vbat"],
        rotor_speed=arrays["omega_rotor"],
        vehicle=vehicle,
        frame="NED",
        source=f"{DATASET}/{path.name}: Crazyflie 2.1 Brushless flight (Busetto et "
        "al. 2026, arXiv:2512.14450), imported by quadfault",
        meta=meta,
    )
