"""PX4 ULog importer (needs ``pyulog``: ``pip install 'quadfault[ulog]'``).

Topics read (PX4 uses NED world and FRD body frames, like quadfault; nothing is rotated):

| topic | fields | use |
|---|---|---|
| ``vehicle_attitude`` | ``q[0..3]`` (w, x, y, z; FRD -> NED) | attitude, and the time base |
| ``vehicle_local_position`` | ``x, y, z, vx, vy, vz`` [m, m/s], NED | position, velocity |
| ``vehicle_angular_velocity`` | ``xyz[0..2]`` [rad/s] FRD | body rates (or ``gyro_rad``) |
| ``sensor_combined`` | ``accelerometer_m_s2[0..2]``, ``gyro_rad[0..2]`` | specific force FRD |
| ``actuator_motors`` | ``control[0..3]`` normalised 0..1 | commands ``u1..u4`` |
| ``actuator_outputs`` | ``output[0..3]`` PWM [us] | fallback: u = (pwm - 1000) / 1000 |
| ``battery_status`` | ``voltage_v`` (or ``voltage_filtered_v``) [V] | ``vbat`` |

All topics are resampled onto one time base (the attitude stamps, or the IMU stamps with
``time_base="imu"``): continuous signals by linear interpolation, the quaternion by
normalised linear interpolation (nlerp, hemisphere-aligned), commands by zero-order hold
(the command held since its last message). The recording covers the span where every needed
topic has data. Motor order is the log's (``control[i]`` -> ``u{i+1}``); for a PX4 quad X that
is front-right, rear-left, front-left, rear-right, and the vehicle file's allocation columns
must follow it.

ULogs carry no mass or inertia: the vehicle comes from a JSON file (``--vehicle``). If it has
no thrust curve, PX4's own model is used, f = s ((1 - THR_MDL_FAC) u + THR_MDL_FAC u^2), with
THR_MDL_FAC from the log's parameters and the scale s fitted on a calibration segment (mean
summed thrust = -m mean a_z over the first 30 % of the motors-running span by default).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfault.effects import curve_thrust
from quadfault.errors import ConfigError, QuadfaultError, RecordingError
from quadfault.importers import gap_stats, running_span
from quadfault.importers.crazyflie import (calibration_mask, scale_curve_on_segment)
from quadfault.recording import Recording
from quadfault.vehicle import Vehicle, allocation_from_rotors

TOPICS = ("vehicle_attitude", "vehicle_local_position", "vehicle_angular_velocity",
          "sensor_combined", "actuator_motors", "actuator_outputs", "battery_status")
N_MOTORS = 4
DEFAULT_CALIBRATION_FRACTION = (0.0, 0.3)
PWM_MIN_US, PWM_MAX_US = 1000.0, 2000.0


#: PX4 "quad x" geometry, motor order of actuator_motors (FRD, units of the per-axis offset):
#: 1 front-right (CCW), 2 rear-left (CCW), 3 front-left (CW), 4 rear-right (CW). A CCW rotor
#: (seen from above) reacts with a clockwise torque: +z in FRD.
PX4_QUAD_X_XY = ((1.0, 1.0), (-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0))
PX4_QUAD_X_YAW = (1.0, 1.0, -1.0, -1.0)


def px4_quad_x_vehicle(mass: float, inertia, arm: float, torque_coefficient: float) -> Vehicle:
    """A PX4 quad X vehicle in its actuator order.

    Args:
        mass: [kg]; inertia: (Jxx, Jyy, Jzz) [kg m^2]; arm: per-axis rotor offset d [m];
        torque_coefficient: yaw torque per newton of thrust [m].
    """
    if not (arm > 0 and torque_coefficient > 0):
        raise ConfigError("--arm and --torque-coefficient must be positive")
    alloc = allocation_from_rotors(np.asarray(PX4_QUAD_X_XY) * arm, PX4_QUAD_X_YAW,
                                   torque_coefficient)
    return Vehicle(mass=mass, inertia=inertia, allocation=alloc, name="PX4 quad X")


# ----------------------------------------------------------------------------------------
# resampling (pure numpy; the tests exercise these directly)
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


# ----------------------------------------------------------------------------------------
def _load_ulog(path: Path):
    try:
        from pyulog import ULog
    except ImportError:
        raise QuadfaultError("the PX4 importer needs pyulog: pip install 'quadfault[ulog]'") \
            from None
    if not path.exists():
        raise RecordingError(path, "file not found")
    try:
        return ULog(str(path), list(TOPICS))
    except Exception as exc:  # pyulog raises bare Exceptions on corrupt files
        raise RecordingError(path, f"not a readable ULog: {exc}") from None


def _topic(ulog, name):
    sets = [d for d in ulog.data_list if d.name == name]
    if not sets:
        return None
    return min(sets, key=lambda d: d.multi_id).data  # instance 0


def _fields(path, data, topic, names):
    missing = [n for n in names if n not in data]
    if missing:
        raise RecordingError(path, f"topic {topic} lacks field {missing[0]}", column=missing[0])
    return np.stack([np.asarray(data[n], dtype=float) for n in names], axis=1)


def _stamp(data, prefer_sample=False):
    key = "timestamp_sample" if prefer_sample and "timestamp_sample" in data else "timestamp"
    return np.asarray(data[key], dtype=float) * 1e-6  # us -> s


def import_px4_ulog(path, *, vehicle=None, thrust_curve=None, keep_all: bool = False,
                    calibration=None, mass: float | None = None, time_base: str = "attitude",
                    **_ignored) -> Recording:
    """Import a PX4 ``.ulg`` flight log.

    Args:
        path: the ULog file.
        vehicle: nominal :class:`quadfault.vehicle.Vehicle` (FRD, rotors in the log's motor
            order); required, since ULogs carry no mass or inertia.
        thrust_curve: ``(a, b, c)`` with f = a + b u + c u^2 [N]; default PX4's model scaled
            on the calibration segment.
        keep_all: keep rows where no motor runs.
        calibration: ``(t0, t1)`` [s, log clock] for the thrust-scale fit.
        mass: overrides ``vehicle.mass`` [kg].
        time_base: "attitude" (default) or "imu".
    """
    path = Path(path)
    if vehicle is None:
        raise ConfigError("the PX4 importer needs a vehicle file (--vehicle VEHICLE.json): ULogs "
                          "carry no mass, inertia or rotor geometry")
    if vehicle.n_rotors != N_MOTORS:
        raise ConfigError(f"the PX4 importer handles quadrotors; the vehicle has "
                          f"{vehicle.n_rotors} rotors")
    if mass is not None:
        vehicle = vehicle.replace(mass=float(mass))
    ulog = _load_ulog(path)
    att, pos = _topic(ulog, "vehicle_attitude"), _topic(ulog, "vehicle_local_position")
    angv, imu = _topic(ulog, "vehicle_angular_velocity"), _topic(ulog, "sensor_combined")
    motors, outputs = _topic(ulog, "actuator_motors"), _topic(ulog, "actuator_outputs")
    battery = _topic(ulog, "battery_status")
    if att is None:
        raise RecordingError(path, "no vehicle_attitude topic", key="vehicle_attitude")
    if angv is None and imu is None:
        raise RecordingError(path, "no body rates (vehicle_angular_velocity or sensor_combined)",
                             key="vehicle_angular_velocity")
    streams, missing = {}, []
    streams["q"] = (_stamp(att), _fields(path, att, "vehicle_attitude",
                                         [f"q[{i}]" for i in range(4)]), "quaternion")
    if angv is not None:
        streams["w"] = (_stamp(angv, True), _fields(path, angv, "vehicle_angular_velocity",
                                                     [f"xyz[{i}]" for i in range(3)]), "linear")
    else:
        streams["w"] = (_stamp(imu), _fields(path, imu, "sensor_combined",
                                             [f"gyro_rad[{i}]" for i in range(3)]), "linear")
    if imu is not None:
        streams["acc"] = (_stamp(imu), _fields(path, imu, "sensor_combined",
                                               [f"accelerometer_m_s2[{i}]" for i in range(3)]),
                          "linear")
    else:
        missing.append("accelerometer (sensor_combined)")
    if pos is not None:
        streams["pos"] = (_stamp(pos), _fields(path, pos, "vehicle_local_position",
                                               ["x", "y", "z"]), "linear")
        streams["vel"] = (_stamp(pos), _fields(path, pos, "vehicle_local_position",
                                               ["vx", "vy", "vz"]), "linear")
    else:
        missing.append("position and velocity (vehicle_local_position)")
    if motors is not None:
        u_src = np.nan_to_num(_fields(path, motors, "actuator_motors",
                                      [f"control[{i}]" for i in range(N_MOTORS)]), nan=0.0)
        streams["u"] = (_stamp(motors), u_src, "hold")
        cmd_note = "u = actuator_motors.control[0..3] (normalised 0..1)"
    elif outputs is not None:
        pwm = _fields(path, outputs, "actuator_outputs", [f"output[{i}]" for i in range(N_MOTORS)])
        u_src = np.clip((pwm - PWM_MIN_US) / (PWM_MAX_US - PWM_MIN_US), 0.0, 1.0)
        streams["u"] = (_stamp(outputs), u_src, "hold")
        cmd_note = "u = (actuator_outputs.output[0..3] - 1000 us) / 1000 us"
    else:
        raise RecordingError(path, "no motor commands (actuator_motors or actuator_outputs)",
                             key="actuator_motors")
    if battery is not None:
        vkey = "voltage_v" if "voltage_v" in battery else "voltage_filtered_v"
        if vkey in battery:
            streams["vbat"] = (_stamp(battery), np.asarray(battery[vkey], float), "linear")
    if "vbat" not in streams:
        missing.append("battery voltage (battery_status)")
    if "acc" not in streams and "pos" not in streams:
        raise RecordingError(path, "needs vehicle_local_position or sensor_combined: a recording "
                                   "needs a pose or an accelerometer", key="sensor_combined")

    if time_base == "imu" and imu is not None:
        stamps = _stamp(imu)
    elif time_base in ("attitude", "imu"):
        stamps = _stamp(att)
    else:
        raise ConfigError(f"time_base must be 'attitude' or 'imu', got {time_base!r}")
    t = np.unique(stamps)  # sorted, duplicates dropped
    dropped = len(stamps) - len(t)
    res = merge_topics(t, streams)
    need = [k for k in ("q", "w", "acc", "pos", "vel", "u") if k in res]
    ok = np.all(np.stack([np.all(np.isfinite(res[k]), axis=1) for k in need]), axis=0)
    if ok.sum() < 2:
        raise RecordingError(path, "the topics do not overlap in time")
    first, last = np.flatnonzero(ok)[[0, -1]]
    keep = slice(first, last + 1)
    if not keep_all:
        span = running_span(res["u"][keep])
        if span is None:
            raise ConfigError(f"{path}: the motors never run")
        keep = slice(first + span[0], first + span[1])
    t = t[keep]
    res = {k: v[keep] for k, v in res.items()}
    ok = np.all(np.stack([np.all(np.isfinite(res[k]), axis=1) for k in need]), axis=0)
    if not ok.all():  # dropouts inside the span: keep the gap, drop the rows
        t = t[ok]
        res = {k: v[ok] for k, v in res.items()}
    if len(t) < 2:
        raise ConfigError(f"{path}: fewer than 2 usable rows")

    meta_cal = None
    if thrust_curve is None:
        fac = float(ulog.initial_parameters.get("THR_MDL_FAC", 0.0))
        base = (0.0, 1.0 - fac, fac)
        if calibration is None:
            f0, f1 = DEFAULT_CALIBRATION_FRACTION
            calibration = (t[0] + f0 * (t[-1] - t[0]), t[0] + f1 * (t[-1] - t[0]))
        if "acc" not in res:
            raise ConfigError(f"{path}: no thrust curve in the vehicle file and no accelerometer "
                              "to fit one on")
        measured = -vehicle.mass * res["acc"][:, 2]  # collective thrust from the IMU [N]
        thrust_curve, scale = scale_curve_on_segment(base, res["u"], measured,
                                                     calibration_mask(t, calibration))
        meta_cal = {"segment": [float(x) for x in calibration],
                    "fitted": {"thrust_scale": scale, "thrust_curve": list(thrust_curve),
                               "THR_MDL_FAC": fac},
                    "method": "PX4 thrust model x scale so that mean(sum f_i) = mean(-m a_z)",
                    "score_on": "the rest of the recording; exclude this segment when scoring"}
    thrust_curve = tuple(float(c) for c in thrust_curve)
    meta = {"dataset": "px4-ulog", "file": path.name,
            "import": {"importer": "px4", "segment": [float(t[0]), float(t[-1])],
                       "trimmed": not keep_all, "time_base": time_base,
                       "dropped_duplicate_times": dropped, **gap_stats(t), "missing": missing,
                       "commands": cmd_note},
            "constants": {"vehicle": "from the user's vehicle file"}}
    if meta_cal:
        meta["calibration"] = meta_cal
    return Recording(t=t, omega=res["w"], accel=res.get("acc"), position=res.get("pos"),
                     velocity=res.get("vel"), quaternion=res["q"] if "pos" in res else None,
                     vbat=res.get("vbat"), thrust_cmd=curve_thrust(thrust_curve, res["u"]),
                     commands_u=res["u"], thrust_curve=thrust_curve, vehicle=vehicle,
                     frame="NED", source=f"PX4 ULog {path.name}, imported by quadfault",
                     meta=meta)
