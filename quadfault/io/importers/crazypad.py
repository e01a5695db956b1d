"""CrazyPAD (Masalimov et al. 2024): Crazyflie 2.1 flights with propeller defects, 100 Hz.

Two kinds of log, from separate flights (``crazypad-cf21-faults/README.md``); the kind is
detected from the columns:

**motor_data** -- ``motor.m1..m4`` [0..65535] motor power command, ``pwm.m*_pwm`` applied PWM,
``pm.vbatMV`` [mV], ``stateEstimate.x,y,z`` [m] and ``vx,vy,vz`` [m/s] (world z-up),
``stateEstimate.ax,ay,az`` world acceleration [g, gravity removed], ``stateEstimate.roll`` and
(not in six older files) ``stateEstimate.yaw`` [deg]. No pitch and no body rates were logged:
the importer *reconstructs* pitch from the direction of the specific force (the thrust axis
of a rotorcraft) with the logged roll and yaw (yaw 0 when absent), and body rates by
differentiating that attitude. The roll that the same reconstruction predicts agrees with the
logged roll to about 1 degree RMS (stored as ``roll_check_rms_deg``).

**controller_data** -- ``stateEstimate.x,y,z`` [m], ``controller.r_roll, r_pitch, r_yaw`` gyro
rates [rad/s] (the firmware's PID controller negates pitch: wy_FLU = -r_pitch),
``controller.accelz`` [g], ``controller.cmd_thrust/roll/pitch/yaw`` PID outputs. No motor
commands, velocity or attitude were logged: the motor commands are *reconstructed* with the
firmware's legacy quadrotor power distribution (m1 = T - r/2 + p/2 + y, m2 = T - r/2 - p/2 - y,
m3 = T + r/2 - p/2 + y, m4 = T + r/2 + p/2 - y, then capped to 0..65535), velocity by
differentiating the smoothed position, attitude by integrating the gyro from level at
take-off (bias from the rest before take-off; yaw drifts by up to ~25 degrees per flight).

Thrust curve: Foerster's PWM curve times one scale factor fitted on the calibration segment
(default: the airborne part, z > 0.3 m, of the first leg, before the pad landing), together
with the unknown mass (0.034 kg assumed; 32-35 g estimated in the README). The condition label
(folder name) goes to ``meta["truth"]`` so :meth:`Recording.without_truth` hides it.
"""

from __future__ import annotations

import re
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
    CF21_BRUSHED,
    FOERSTER_THRUST_CURVE,
    G_CRAZYFLIE,
    calibration_mask,
    scale_curve_on_segment,
)
from quadfault.io.recording import Recording, enu_flu_to_ned_frd
from quadfault.model.effects import curve_thrust
from quadfault.model.rotation import euler_zyx_to_rot, expm_so3, logm_so3, rot_to_quat

DATASET = "crazypad-cf21-faults"
LICENCE = "MIT (c) 2022 Kamil Masalimov, Tagir Muslimov; github.com/AerialRoboticsUUST/CrazyPAD"
#: Take-off mass [kg]: not documented; bare CF2.1 27 g + decks (README estimate 32-35 g).
DEFAULT_MASS = 0.034
AIRBORNE_Z = 0.3  # [m] above the start, "airborne" for the calibration segment
SMOOTH_SAMPLES = 5  # centred moving average (50 ms) before reconstructing attitude/velocity
POS = tuple(f"stateEstimate.{c}" for c in "xyz")
VEL = tuple(f"stateEstimate.v{c}" for c in "xyz")
ACC = tuple(f"stateEstimate.a{c}" for c in "xyz")
MOTORS = tuple(f"motor.m{i}" for i in range(1, 5))
PWM = tuple(f"pwm.m{i}_pwm" for i in range(1, 5))
GYRO = ("controller.r_roll", "controller.r_pitch", "controller.r_yaw")
CMD = ("controller.cmd_thrust", "controller.cmd_roll", "controller.cmd_pitch", "controller.cmd_yaw")
PWM_FULL_SCALE = 65536.0


def _smooth(x: np.ndarray, n: int = SMOOTH_SAMPLES) -> np.ndarray:
    """Centred moving average along axis 0 (edges use the available samples)."""
    if n <= 1 or len(x) < n:
        return x
    k = np.ones(n)
    x2 = x if x.ndim == 2 else x[:, None]
    num = np.stack([np.convolve(c, k, "same") for c in x2.T], axis=1)
    den = np.convolve(np.ones(len(x)), k, "same")[:, None]
    out = num / den
    return out if x.ndim == 2 else out[:, 0]


def tilt_from_specific_force(f_world: np.ndarray, roll: np.ndarray, yaw: np.ndarray):
    """Pitch (and a roll check) [rad] from the thrust axis: z_body (FLU) is along the specific
    force in a z-up world. With Z-Y-X angles, Rz(-yaw) z_body = (cos r sin p, -sin r, cos r cos p).
    """
    s = f_world / np.linalg.norm(f_world, axis=1, keepdims=True)
    cy, sy = np.cos(yaw), np.sin(yaw)
    zx = cy * s[:, 0] + sy * s[:, 1]
    zy = -sy * s[:, 0] + cy * s[:, 1]
    pitch = np.arctan2(zx * np.sign(np.cos(roll)), s[:, 2] * np.sign(np.cos(roll)))
    roll_check = np.arctan2(-zy, np.hypot(zx, s[:, 2]))
    return pitch, roll_check


def rates_from_attitude(t: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Body rates [rad/s] by central differences on SO(3): log(R_{k-1}^T R_{k+1}) / (2 dt)."""
    w = np.zeros((len(t), 3))
    if len(t) < 3:
        return w
    rel = np.einsum("nji,njk->nik", R[:-2], R[2:])
    w[1:-1] = logm_so3(rel) / (t[2:] - t[:-2])[:, None]
    w[0], w[-1] = w[1], w[-2]
    return w


def attitude_from_gyro(t: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Integrate body rates (trapezoidal, on SO(3)) from level, yaw 0."""
    R = np.empty((len(t), 3, 3))
    R[0] = np.eye(3)
    for k in range(len(t) - 1):
        R[k + 1] = R[k] @ expm_so3(0.5 * (w[k] + w[k + 1]) * (t[k + 1] - t[k]))
    return R


def power_distribution_legacy(cmd: np.ndarray) -> np.ndarray:
    """Motor commands [0..65535] from the PID outputs (thrust, roll, pitch, yaw), as the
    Crazyflie firmware's legacy quadrotor mixer, with its cap (lower all when one exceeds the
    range) and clip at 0."""
    T, r, p, y = cmd[:, 0], cmd[:, 1] / 2.0, cmd[:, 2] / 2.0, cmd[:, 3]
    m = np.stack((T - r + p + y, T - r - p - y, T + r - p + y, T + r + p - y), axis=1)
    excess = np.maximum(m.max(axis=1) - (PWM_FULL_SCALE - 1), 0.0)
    m = m - excess[:, None]
    m[T <= 0] = 0.0  # motors stop when the thrust command is 0
    return np.clip(m, 0.0, PWM_FULL_SCALE - 1)


def _condition(path: Path) -> dict:
    name = path.parent.name
    truth = {"condition": name}
    hit = re.match(r"cut_propeller_M(\d)_(\d)mm", name)
    if hit:
        truth.update(damaged_motor=int(hit.group(1)), cut_mm=int(hit.group(2)))
    elif name.startswith("tape_on_propeller"):
        truth["taped_motors"] = [int(x) for x in re.findall(r"M(\d)", name)]
    return truth


def _first_leg_airborne(t, z, running) -> tuple[float, float]:
    """The airborne rows of the first motors-on stretch (before the pad landing)."""
    on = running.astype(int)
    starts = np.flatnonzero(np.diff(np.r_[0, on]) == 1)
    stops = np.flatnonzero(np.diff(np.r_[on, 0]) == -1)
    if starts.size == 0:
        raise ConfigError("the motors never run")
    leg = slice(starts[0], stops[0] + 1)
    air = np.flatnonzero(z[leg] - z[0] > AIRBORNE_Z)
    if air.size < 10:
        raise ConfigError(
            "no airborne stretch (z > 0.3 m) in the first leg to calibrate on; "
            "pass --calibration T0,T1"
        )
    return float(t[leg][air[0]]), float(t[leg][air[-1]])


def import_crazypad(
    path, *, keep_all: bool = False, calibration=None, mass: float | None = None, **_ignored
) -> Recording:
    """Import one CrazyPAD log (motor_data or controller_data kind, detected by columns).

    Args:
        path: the gzip CSV.
        keep_all: keep the rows before the first / after the last motors-on sample.
        calibration: ``(t0, t1)`` [firmware s] of the thrust-scale calibration segment.
        mass: take-off mass [kg] (default 0.034, an estimate).
    """
    path = Path(path)
    table = read_raw_table(path)
    if "motor.m1" in table:
        return _import_motor_log(path, table, keep_all, calibration, mass)
    if "controller.cmd_thrust" in table:
        return _import_controller_log(path, table, keep_all, calibration, mass)
    raise RecordingError(
        path,
        "neither a motor_data log (motor.m1..m4) nor a controller_data "
        "log (controller.cmd_thrust, ...)",
        column="motor.m1",
    )


def _finish(path, kind, t, arrays, cal_segment, mass, measured, extra_meta, **rec_fields):
    m = DEFAULT_MASS if mass is None else float(mass)
    cal = calibration_mask(t, cal_segment)
    curve, scale = scale_curve_on_segment(FOERSTER_THRUST_CURVE, arrays["u"], m * measured, cal)
    vehicle = CF21_BRUSHED.vehicle(mass=m, max_thrust=float(curve_thrust(curve, 1.0)))
    rel = path.parent.parent.name + "/" + path.parent.name + "/" + path.name
    meta = {
        "dataset": DATASET,
        "file": rel,
        "licence": LICENCE,
        "log_kind": kind,
        "time_origin": "Crazyflie firmware clock (timestamp_ms / 1000)",
        "constants": dict(
            CF21_BRUSHED.sources,
            mass="given"
            if mass is not None
            else "0.034 kg assumed (README: 32-35 g estimated, undocumented)",
        ),
        "calibration": {
            "segment": list(cal_segment),
            "fitted": {"thrust_scale": scale, "thrust_curve": list(curve)},
            "method": "Foerster PWM curve x scale so that mean(sum f_i) = m mean(|specific "
            "force|) on the airborne segment (absorbs the unknown mass)",
            "score_on": "the rest of the recording; exclude this segment when scoring",
        },
        "truth": _condition(path),
        "import": extra_meta,
    }
    return Recording(
        t=t,
        thrust_cmd=curve_thrust(curve, arrays["u"]),
        commands_u=arrays["u"],
        thrust_curve=curve,
        vehicle=vehicle,
        frame="NED",
        source=f"{DATASET}/{rel}: Crazyflie 2.1 on-board log (Masalimov et al. "
        "2024, Data 9, 79), imported by quadfault",
        meta=meta,
        **rec_fields,
    )


def _import_motor_log(path, table, keep_all, calibration, mass):
    need = ("timestamp_ms", *MOTORS, *POS, *VEL, *ACC, "stateEstimate.roll")
    require_columns(path, table, need)
    require_finite(path, table, need)
    has_yaw = "stateEstimate.yaw" in table
    n = len(table["timestamp_ms"])
    arrays = {
        "t": table["timestamp_ms"] / 1000.0,
        "u": np.stack([table[c] for c in MOTORS], axis=1) / PWM_FULL_SCALE,
        "pos": np.stack([table[c] for c in POS], axis=1),
        "vel": np.stack([table[c] for c in VEL], axis=1),
        "acc": np.stack([table[c] for c in ACC], axis=1) * G_CRAZYFLIE,  # g -> m/s^2
        "roll": np.radians(table["stateEstimate.roll"]),
        "yaw": np.radians(table["stateEstimate.yaw"]) if has_yaw else np.zeros(n),
        "pwm": (
            np.stack([table[c] for c in PWM], axis=1) / PWM_FULL_SCALE
            if all(c in table for c in PWM)
            else None
        ),
        "vbat": table["pm.vbatMV"] / 1000.0 if "pm.vbatMV" in table else None,
    }
    if calibration is None:
        calibration = _first_leg_airborne(
            arrays["t"], arrays["pos"][:, 2], arrays["u"].max(axis=1) > 0
        )
    arrays, _, dropped = trim_to_flight(path, arrays, arrays["u"], keep_all)
    t = arrays["t"]
    f_world = _smooth(arrays["acc"]) + np.array([0.0, 0.0, G_CRAZYFLIE])  # specific force, z-up
    pitch, roll_check = tilt_from_specific_force(f_world, arrays["roll"], arrays["yaw"])
    R = euler_zyx_to_rot(arrays["roll"], pitch, arrays["yaw"])  # body FLU -> world z-up
    w_flu = rates_from_attitude(t, R)
    airborne = (arrays["pos"][:, 2] - arrays["pos"][0, 2] > AIRBORNE_Z) & (arrays["u"].max(1) > 0)
    roll_rms = (
        float(np.degrees(np.sqrt(np.mean((roll_check - arrays["roll"])[airborne] ** 2))))
        if airborne.any()
        else None
    )
    pos, vel, quat, omega, _ = enu_flu_to_ned_frd(
        arrays["pos"], arrays["vel"], rot_to_quat(R), w_flu, None
    )
    extra = {}
    if arrays["pwm"] is not None:
        extra = {f"pwm{i + 1}": arrays["pwm"][:, i] for i in range(4)}
    missing = [
        "pitch (reconstructed from the specific-force direction)",
        "body rates (differentiated from the reconstructed attitude)",
        "accelerometer (only the EKF's world acceleration)",
    ]
    if not has_yaw:
        missing.append("yaw (assumed 0)")
    meta = {
        "importer": "crazypad",
        "segment": [float(t[0]), float(t[-1])],
        "trimmed": not keep_all,
        "dropped_duplicate_times": dropped,
        **gap_stats(t),
        "missing": missing,
        "roll_check_rms_deg": roll_rms,
        "commands": "u = motor.m* / 65536 (before the firmware's battery compensation; the "
        "applied PWM is in pwm1..pwm4)",
        "reconstructed": {
            "pitch": "thrust axis = specific-force direction, 50 ms smoothing",
            "omega": "central differences of the attitude on SO(3)",
        },
    }
    return _finish(
        path,
        "motor_data",
        t,
        arrays,
        calibration,
        mass,
        np.linalg.norm(f_world, axis=1),
        meta,
        position=pos,
        velocity=vel,
        quaternion=quat,
        omega=omega,
        vbat=arrays["vbat"],
        extra=extra,
    )


def _import_controller_log(path, table, keep_all, calibration, mass):
    need = ("timestamp_ms", *POS, *GYRO, *CMD, "controller.accelz")
    require_columns(path, table, need)
    require_finite(path, table, need)
    cmd = np.stack([table[c] for c in CMD], axis=1)
    gyro = np.stack([table[c] for c in GYRO], axis=1) * np.array([1.0, -1.0, 1.0])  # -> FLU
    arrays = {
        "t": table["timestamp_ms"] / 1000.0,
        "u": power_distribution_legacy(cmd) / PWM_FULL_SCALE,
        "pos": np.stack([table[c] for c in POS], axis=1),
        "gyro": gyro,
        "accz": table["controller.accelz"] * G_CRAZYFLIE,  # body z specific force, FLU [m/s^2]
    }
    running = arrays["u"].max(axis=1) > 0
    first = int(np.argmax(running))
    bias = arrays["gyro"][:first].mean(axis=0) if first >= 10 else np.zeros(3)
    arrays["gyro"] = arrays["gyro"] - bias
    if calibration is None:
        calibration = _first_leg_airborne(arrays["t"], arrays["pos"][:, 2], running)
    arrays, _, dropped = trim_to_flight(path, arrays, arrays["u"], keep_all)
    t = arrays["t"]
    R = attitude_from_gyro(t, arrays["gyro"])
    vel_enu = np.gradient(_smooth(arrays["pos"]), t, axis=0)
    pos, vel, quat, omega, _ = enu_flu_to_ned_frd(
        arrays["pos"], vel_enu, rot_to_quat(R), arrays["gyro"], None
    )
    meta = {
        "importer": "crazypad",
        "segment": [float(t[0]), float(t[-1])],
        "trimmed": not keep_all,
        "dropped_duplicate_times": dropped,
        **gap_stats(t),
        "gyro_bias_rad_s": bias.tolist(),
        "missing": [
            "motor commands (reconstructed from the PID outputs)",
            "velocity (differentiated from position)",
            "attitude (integrated gyro from level; yaw drifts)",
            "accelerometer x, y (only body z, in column az_frd)",
        ],
    }
    return _finish(
        path,
        "controller_data",
        t,
        arrays,
        calibration,
        mass,
        arrays["accz"],
        meta,
        position=pos,
        velocity=vel,
        quaternion=quat,
        omega=omega,
        extra={"az_frd": -arrays["accz"]},
    )
