"""PX4 ULog importer (needs ``pyulog``: ``pip install 'quadfault[ulog]'``).

Topics read (PX4 uses NED world and FRD body frames, like quadfault; nothing is rotated):

- ``vehicle_attitude``: ``q[0..3]`` (w, x, y, z; FRD -> NED) -> attitude
- ``vehicle_local_position``: ``x, y, z, vx, vy, vz``, ``xy_valid, z_valid, v_xy_valid,
  v_z_valid`` -> pose; invalid rows never used
- ``vehicle_angular_velocity``: ``xyz[0..2]`` [rad/s] FRD -> body rates (else
  ``vehicle_attitude.rollspeed..yawspeed``, else ``sensor_combined.gyro_rad``)
- ``sensor_combined``: ``accelerometer_m_s2[0..2]``, ``gyro_rad[0..2]`` -> specific force FRD
- ``actuator_motors``: ``control[0..3]`` normalised 0..1 -> commands ``u1..u4``
- ``actuator_outputs`` (any instance): ``output[k]`` -> else: the instance that drives the
  motors, normalised with its range
- ``esc_status``: ``esc[i].esc_rpm`` -> measured rotor speed ``omega1..4`` [rad/s]
- ``battery_status``: ``voltage_v``, ``current_a`` -> ``vbat`` [V], ``current`` [A]
- ``vehicle_land_detected``: ``landed, maybe_landed, ground_contact`` -> flight span

Parameters: ``CA_ROTOR{i}_PX/PY/KM`` (geometry, motor order, spin direction, yaw torque per
newton), ``THR_MDL_FAC`` (thrust model f ~ (1 - fac) u + fac u^2), the output ranges
(``PWM_MAIN_MIN{k}/MAX{k}``, ``PWM_MIN/MAX``, ``UAVCAN_EC_MIN{k}/MAX{k}``, the ``*_FUNC{k}``
motor assignment). The time base is the IMU's or the attitude's stamps, whichever is faster
(``time_base`` chooses). The rest is :func:`quadfault.io.importers.field_log.build_recording`.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np

from quadfault.errors import ConfigError, QuadfaultError, RecordingError
from quadfault.io.importers.field_log import (
    QUAD_X_XY,
    QUAD_X_YAW,
    RUNNING,
    FieldLog,
    Geometry,
    build_recording,
    quad_x,
)
from quadfault.io.recording import Recording
from quadfault.model.vehicle import Vehicle, allocation_from_rotors

TOPICS = (
    "vehicle_attitude",
    "vehicle_local_position",
    "vehicle_angular_velocity",
    "sensor_combined",
    "actuator_motors",
    "actuator_outputs",
    "battery_status",
    "esc_status",
    "vehicle_land_detected",
    "actuator_armed",
)
N_MOTORS = 4
RPM_TO_RAD_S = 2.0 * np.pi / 60.0
#: output ranges by driver when the log's parameters do not give them
PWM_RANGE, UAVCAN_RANGE, DSHOT_RANGE = (1000.0, 2000.0), (0.0, 8191.0), (1.0, 1999.0)
#: the ``*_FUNC{k}`` value of Motor 1 (Motor i is 100 + i)
MOTOR1_FUNCTION = 101
#: ``MAV_TYPE`` values of PX4 vehicles (MAVLink's MAV_TYPE enumeration)
MAV_TYPES = {
    1: "fixed wing",
    2: "quadrotor",
    3: "coaxial helicopter",
    4: "helicopter",
    13: "hexarotor",
    14: "octorotor",
    15: "tricopter",
    19: "VTOL tailsitter (two rotors)",
    20: "VTOL tailsitter (four rotors)",
    21: "VTOL tiltrotor",
    22: "VTOL with fixed lift rotors",
    23: "VTOL tailsitter",
    29: "dodecarotor",
}
MAV_TYPE_QUAD, MAV_TYPE_STANDARD_VTOL = 2, 22
#: ``CA_AIRFRAME`` values (PX4's control allocation)
CA_AIRFRAMES = {
    0: "multirotor",
    1: "fixed wing",
    2: "standard VTOL",
    3: "tiltrotor VTOL",
    4: "tailsitter VTOL",
    5: "rover (Ackermann)",
    6: "rover (differential)",
    7: "motors only",
    8: "custom",
    9: "helicopter (tail ESC)",
    10: "helicopter (tail servo)",
    11: "helicopter (coaxial)",
}
CA_MULTIROTOR, CA_STANDARD_VTOL = 0, 2
#: ``SYS_AUTOSTART`` ranges of airframes the model does not fly (PX4's airframe numbering)
AUTOSTART_FRAMES = (
    (2000, 3999, "fixed wing"),
    (6000, 7999, "hexarotor"),
    (8000, 9999, "octorotor"),
    (11000, 11999, "coaxial hexarotor"),
    (12000, 12999, "coaxial octorotor"),
    (13000, 13999, "VTOL"),
    (14000, 15999, "tricopter"),
    (16000, 16999, "helicopter"),
)


def px4_quad_x_vehicle(mass: float, inertia, arm: float, torque_coefficient: float) -> Vehicle:
    """A PX4 quad X vehicle in its actuator order (front-right, rear-left, front-left,
    rear-right; rotors 1 and 2 counter-clockwise).

    Args:
        mass: [kg]; inertia: (Jxx, Jyy, Jzz) [kg m^2]; arm: per-axis rotor offset d [m];
        torque_coefficient: yaw torque per newton of thrust [m].
    """
    if not (arm > 0 and torque_coefficient > 0):
        raise ConfigError("--arm and --torque-coefficient must be positive")
    alloc = allocation_from_rotors(np.asarray(QUAD_X_XY) * arm, QUAD_X_YAW, torque_coefficient)
    return Vehicle(mass=mass, inertia=inertia, allocation=alloc, name="PX4 quad X")


class _CutWatch(io.BufferedReader):
    """The log file as pyulog reads it, noting the first read that the file's end cut short
    (pyulog stops there without saying so): ``cut_at`` is the offset where the cut-off
    message starts (its 3-byte header precedes a cut body)."""

    cut_at = None
    SYNC_CHUNK = 512  # pyulog's resync search reads this much; a short one is not a cut

    def read(self, n=-1):
        data = super().read(n)
        if self.cut_at is None and n is not None and 0 < n != self.SYNC_CHUNK and len(data) < n:
            start = self.tell() - len(data)
            if n > 3:  # a message body: its header was read just before
                self.cut_at = start - 3
            elif data:  # a header cut short
                self.cut_at = start
        return data


def _load_ulog(path: Path, topics=TOPICS):
    """``(ulog, skipped)``: pyulog's reading of ``topics`` (None: all), and what was
    skipped of a cut or corrupt log (:class:`quadfault.io.importers.field_log.FieldLog`)."""
    try:
        from pyulog import ULog
    except ImportError:
        raise QuadfaultError(
            "the PX4 importer needs pyulog: pip install 'quadfault[ulog]'"
        ) from None
    if not path.exists():
        raise RecordingError(path, "file not found")
    with open(path, "rb") as fh:
        if fh.read(7) != b"ULog\x01\x12\x35":
            raise RecordingError(path, "not a ULog file (no ULog header)")
    size = path.stat().st_size
    fh = _CutWatch(io.FileIO(path, "rb"))
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # pyulog prints its corruption notes
            ulog = ULog(fh, None if topics is None else list(topics))
    except Exception as exc:  # pyulog raises bare Exceptions on corrupt files
        raise RecordingError(path, f"not a readable ULog: {exc}") from None
    finally:
        fh.close()
    skipped = None
    last = ulog.last_timestamp * 1e-6 if ulog.last_timestamp else None
    if fh.cut_at is not None and fh.cut_at < size:
        skipped = {
            "what": "the log ends mid-message (cut)",
            "bytes": int(size - fh.cut_at),
            "truncated": True,
            "corrupt": 0,
            "after_t": last,
        }
    if ulog.file_corruption:
        skipped = skipped or {"bytes": 0, "truncated": False, "after_t": None}
        skipped["corrupt"] = 1
        skipped["what"] = (
            "corrupt data (pyulog resynchronised past it; it does not report how many bytes)"
            + (" and the log ends mid-message" if skipped.get("truncated") else "")
        )
    return ulog, skipped


def _instances(ulog, name) -> list:
    return sorted((d for d in ulog.data_list if d.name == name), key=lambda d: d.multi_id)


def _topic(ulog, name):
    sets = _instances(ulog, name)
    return sets[0].data if sets else None


def _fields(path, data, topic, names):
    missing = [n for n in names if n not in data]
    if missing:
        raise RecordingError(path, f"topic {topic} lacks field {missing[0]}", column=missing[0])
    return np.stack([np.asarray(data[n], dtype=float) for n in names], axis=1)


def _stamp(data, prefer_sample=False):
    key = "timestamp_sample" if prefer_sample and "timestamp_sample" in data else "timestamp"
    return np.asarray(data[key], dtype=float) * 1e-6  # us -> s


# ----------------------------------------------------------------------------------------
# geometry and motor outputs
def _autostart_frame(params: dict) -> str | None:
    auto = int(params.get("SYS_AUTOSTART", 0))
    return next((name for lo, hi, name in AUTOSTART_FRAMES if lo <= auto <= hi), None)


def lift_rotors(params: dict, path="log") -> tuple:
    """``(rotors, note)``: the 0-based indices of the four lift rotors the model flies, in
    the autopilot's motor order (Motor i+1 is rotor i), and what says so; a one-line error
    naming the frame and its parameters when the log's vehicle is not a quadrotor whose
    lift rotors the parameters identify.

    With control allocation (``CA_ROTOR_COUNT``): a multirotor with four rotors, or a
    standard VTOL whose rotors pointing up (``CA_ROTOR{i}_AZ`` -1, the default) are four;
    before it: ``MAV_TYPE`` quadrotor, or a standard VTOL with four multicopter outputs in
    ``VT_MOT_ID`` (its quad X mixer on those outputs); anything else is refused."""
    mav = params.get("MAV_TYPE")
    mav_name = MAV_TYPES.get(int(mav), f"type {int(mav)}") if mav is not None else None
    if "CA_ROTOR_COUNT" in params:
        count = int(params["CA_ROTOR_COUNT"])
        airframe = int(params.get("CA_AIRFRAME", CA_MULTIROTOR))
        lift = [
            i
            for i in range(count)
            if float(params.get(f"CA_ROTOR{i}_AZ", -1.0)) <= -0.9
            and abs(float(params.get(f"CA_ROTOR{i}_AX", 0.0))) < 0.3
            and abs(float(params.get(f"CA_ROTOR{i}_AY", 0.0))) < 0.3
        ]
        frame = CA_AIRFRAMES.get(airframe, f"airframe {airframe}")
        if airframe == CA_MULTIROTOR and count == N_MOTORS and len(lift) == N_MOTORS:
            return tuple(range(N_MOTORS)), "CA_ROTOR_COUNT 4"
        if airframe == CA_STANDARD_VTOL and len(lift) == N_MOTORS:
            others = [i for i in range(count) if i not in lift]
            return tuple(lift), (
                f"standard VTOL (CA_AIRFRAME 2): the four lift rotors {[i + 1 for i in lift]} "
                f"(CA_ROTOR*_AZ = -1) imported, rotor{'s' if len(others) > 1 else ''} "
                f"{[i + 1 for i in others]} (pusher) and fixed-wing flight not modelled"
            )
        raise RecordingError(
            path,
            f"the vehicle is a {frame} with {count} rotors, {len(lift)} of them lifting "
            f"(CA_AIRFRAME {airframe}, CA_ROTOR_COUNT {count}"
            + (f", MAV_TYPE {int(mav)} {mav_name}" if mav is not None else "")
            + "): quadfault flies quadrotors (or a standard VTOL's four lift rotors)",
            key="CA_AIRFRAME",
        )
    auto = _autostart_frame(params)
    is_vtol = (mav is not None and 19 <= int(mav) <= 23) or auto == "VTOL"
    if is_vtol:
        digits = str(int(params.get("VT_MOT_ID", 0)))
        outputs = [int(c) for c in digits if c != "0"]
        standard = mav is None or int(mav) == MAV_TYPE_STANDARD_VTOL
        if standard and len(outputs) == N_MOTORS and len(set(outputs)) == N_MOTORS:
            return tuple(k - 1 for k in outputs), (
                f"standard VTOL: multicopter motors on outputs {outputs} (VT_MOT_ID "
                f"{digits}), PX4's quad X order assumed; fixed-wing flight not modelled"
            )
    if (mav is not None and int(mav) != MAV_TYPE_QUAD) or auto is not None:
        name = mav_name if mav is not None and int(mav) != MAV_TYPE_QUAD else auto
        raise RecordingError(
            path,
            f"the vehicle is a {name} (MAV_TYPE {int(mav) if mav is not None else 'not set'}, "
            f"SYS_AUTOSTART {int(params.get('SYS_AUTOSTART', 0))}"
            + (f", VT_MOT_ID {int(params['VT_MOT_ID'])}" if "VT_MOT_ID" in params else "")
            + "): quadfault flies quadrotors; the log's lift motors cannot be told from "
            "its parameters",
            key="MAV_TYPE",
        )
    return tuple(range(N_MOTORS)), "PX4 quad X"


def geometry(params: dict, rotors=tuple(range(N_MOTORS)), path="log") -> Geometry | None:
    """Layout of ``rotors`` from ``CA_ROTOR{i}_PX/PY/KM`` (None without them). Placeholder
    positions (all at unit or zero offsets) are flagged."""
    if "CA_ROTOR0_PX" not in params:
        return None
    xy = [
        (float(params.get(f"CA_ROTOR{i}_PX", 0.0)), float(params.get(f"CA_ROTOR{i}_PY", 0.0)))
        for i in rotors
    ]
    km = [float(params.get(f"CA_ROTOR{i}_KM", 0.05)) for i in rotors]
    a = np.abs(np.asarray(xy))
    placeholder = bool(np.any(a.max(axis=1) == 0) or np.allclose(a, 1.0))
    return Geometry(
        tuple(xy),
        tuple(float(np.sign(k) or 1.0) for k in km),
        float(np.mean(np.abs(km))),
        "CA_ROTOR*_PX/PY/KM",
        placeholder,
    )


def _output_range(params: dict, channel: int, values: np.ndarray) -> tuple:
    """``(lo, hi, how)`` of an ``actuator_outputs`` channel (1-based ``channel``): the driver
    is told by the values (UAVCAN above 2100, DShot below 900 with ``DSHOT_CONFIG``, else
    PWM), the range by its parameters."""
    top = float(np.nanmax(values)) if values.size else 0.0
    run = values[values > 0]
    if top > PWM_RANGE[1] + 100:
        keys, default, name = ("UAVCAN_EC_MIN", "UAVCAN_EC_MAX"), UAVCAN_RANGE, "UAVCAN"
    elif params.get("DSHOT_CONFIG", 0) and run.size and np.nanmin(run) < 900:
        keys, default, name = ("DSHOT_MIN", "DSHOT_MAX"), DSHOT_RANGE, "DShot"
    else:
        keys, default, name = ("PWM_MAIN_MIN", "PWM_MAIN_MAX"), PWM_RANGE, "PWM"
    candidates = [(f"{keys[0]}{channel}", f"{keys[1]}{channel}"), keys]
    if name == "PWM":
        candidates.append(("PWM_MIN", "PWM_MAX"))
    for lo_key, hi_key in candidates:
        lo, hi = params.get(lo_key), params.get(hi_key)
        if lo is not None and hi is not None and hi > lo:
            return float(lo), float(hi), f"{name} {lo_key}/{hi_key}"
    return (*default, f"{name} {default[0]:g}-{default[1]:g} (assumed)")


def motor_outputs(path, ulog, params: dict, motors=tuple(range(N_MOTORS)), channels=None):
    """``(t [s], u (n, 4) normalised 0..1, note)`` of the lift motors ``motors`` (0-based:
    Motor i+1) from ``actuator_motors`` or the ``actuator_outputs`` instance that drives
    them; ``channels``: their outputs (1-based) when the log says so otherwise (VT_MOT_ID).
    Other motors than the first four are never replaced by outputs 1-4."""
    motors = tuple(motors)
    default = motors == tuple(range(N_MOTORS)) and channels is None
    for inst in _instances(ulog, "actuator_motors"):
        if channels is not None:
            break
        u = _fields(path, inst.data, "actuator_motors", [f"control[{i}]" for i in motors])
        if np.nanmax(np.nan_to_num(u, nan=0.0)) > RUNNING:
            return (
                _stamp(inst.data),
                np.nan_to_num(u, nan=0.0),
                f"u = actuator_motors (instance {inst.multi_id}).control"
                f"{list(motors) if not default else '[0..3]'}",
            )
    best = None
    funcs = {
        pre: [k for k in range(1, 17) if params.get(f"{pre}_FUNC{k}") == MOTOR1_FUNCTION]
        for pre in ("PWM_MAIN", "PWM_AUX", "UAVCAN_EC", "DSHOT", "PCA9685")
    }
    for inst in _instances(ulog, "actuator_outputs"):
        data = inst.data
        n_out = int(np.max(data.get("noutputs", [16])))
        chans = list(channels) if channels is not None else None
        for pre, first in funcs.items():  # motor functions assigned by parameter
            if first and chans is None:
                assigned = [
                    next(
                        (
                            k
                            for k in range(1, 17)
                            if params.get(f"{pre}_FUNC{k}") == MOTOR1_FUNCTION + i
                        ),
                        None,
                    )
                    for i in motors
                ]
                if None not in assigned and max(assigned) <= n_out:
                    chans = assigned
        if chans is None and default:
            chans = list(range(1, N_MOTORS + 1))
        if chans is None or max(chans) > n_out or f"output[{max(chans) - 1}]" not in data:
            continue
        raw = _fields(path, data, "actuator_outputs", [f"output[{k - 1}]" for k in chans])
        spread = float(np.nanmin(np.nanstd(raw, axis=0)))  # every motor must move
        if spread > 0 and (best is None or spread > best[0]):
            best = (spread, inst, raw, chans)
    if best is None:
        if not default:
            raise RecordingError(
                path,
                f"no outputs of the lift motors {[i + 1 for i in motors]} (no actuator_motors, "
                "and no *_FUNCn parameter assigns them an output): quadfault flies quadrotors "
                "and does not guess a VTOL's lift outputs",
                key="actuator_outputs",
            )
        raise RecordingError(
            path,
            "no motor outputs (actuator_motors, or an actuator_outputs "
            "instance whose first four outputs vary)",
            key="actuator_outputs",
        )
    _, inst, raw, channels = best
    u = np.empty_like(raw)
    ranges = []
    for i, k in enumerate(channels):
        lo, hi, how = _output_range(params, k, raw[:, i])
        u[:, i] = np.clip((raw[:, i] - lo) / (hi - lo), 0.0, 1.0)
        ranges.append(how)
    note = (
        f"u = actuator_outputs (instance {inst.multi_id}) outputs {channels} normalised "
        f"with {ranges[0] if len(set(ranges)) == 1 else '; '.join(ranges)}"
    )
    return _stamp(inst.data), np.nan_to_num(u, nan=0.0), note


def rotor_speeds(esc, motors=tuple(range(N_MOTORS))) -> tuple | None:
    """``(t [s], omega (n, 4) [rad/s])`` of the motors ``motors`` (0-based) from
    ``esc_status``: motor i is the ESC whose ``actuator_function`` is Motor i where the log
    has that field (PX4 1.14 and later), else ESC i."""
    motors = list(motors)
    if esc is None or f"esc[{max(motors)}].esc_rpm" not in esc:
        return None
    index = motors
    n_esc = sum(1 for k in range(16) if f"esc[{k}].esc_rpm" in esc)
    if "esc[0].actuator_function" in esc:
        funcs = [int(np.median(esc[f"esc[{k}].actuator_function"])) for k in range(n_esc)]
        found = [
            funcs.index(MOTOR1_FUNCTION + i) if MOTOR1_FUNCTION + i in funcs else None
            for i in motors
        ]
        if None not in found:
            index = found
    rpm = np.abs(np.stack([np.asarray(esc[f"esc[{k}].esc_rpm"], float) for k in index], axis=1))
    if not np.any(rpm > 0):
        return None
    return _stamp(esc), rpm * RPM_TO_RAD_S


# ----------------------------------------------------------------------------------------
def read_px4(path, time_base: str | None = None) -> FieldLog:
    """The streams of a PX4 ULog (module docstring)."""
    path = Path(path)
    ulog, skipped = _load_ulog(path)
    params = dict(ulog.initial_parameters)
    motors, frame_note = lift_rotors(params, path)
    att, pos = _topic(ulog, "vehicle_attitude"), _topic(ulog, "vehicle_local_position")
    angv, imu = _topic(ulog, "vehicle_angular_velocity"), _topic(ulog, "sensor_combined")
    if att is None:
        _lacks(path, "no vehicle_attitude topic", skipped)
    if angv is None and imu is None:
        _lacks(path, "no body rates (vehicle_angular_velocity or sensor_combined)", skipped)
    armed = _ever_armed(_topic(ulog, "actuator_armed"))
    notes = [] if frame_note in ("CA_ROTOR_COUNT 4", "PX4 quad X") else [frame_note]
    streams, missing, invalid = {}, [], {}
    streams["q"] = (
        _stamp(att),
        _fields(path, att, "vehicle_attitude", [f"q[{i}]" for i in range(4)]),
        "quaternion",
    )
    if angv is not None:
        streams["w"] = (
            _stamp(angv, True),
            _fields(path, angv, "vehicle_angular_velocity", [f"xyz[{i}]" for i in range(3)]),
            "linear",
        )
    elif "rollspeed" in att:  # PX4 before 1.10 logs the rates with the attitude
        streams["w"] = (
            _stamp(att),
            _fields(path, att, "vehicle_attitude", ["rollspeed", "pitchspeed", "yawspeed"]),
            "linear",
        )
    else:
        streams["w"] = (
            _stamp(imu),
            _fields(path, imu, "sensor_combined", [f"gyro_rad[{i}]" for i in range(3)]),
            "linear",
        )
    if imu is not None:
        streams["acc"] = (
            _stamp(imu),
            _fields(path, imu, "sensor_combined", [f"accelerometer_m_s2[{i}]" for i in range(3)]),
            "linear",
        )
    else:
        missing.append("accelerometer (sensor_combined)")
    if pos is not None:
        tp = _stamp(pos)
        streams["pos"] = (
            tp,
            _fields(path, pos, "vehicle_local_position", ["x", "y", "z"]),
            "linear",
        )
        streams["vel"] = (
            tp,
            _fields(path, pos, "vehicle_local_position", ["vx", "vy", "vz"]),
            "linear",
        )
        for key, flags in (("pos", ("xy_valid", "z_valid")), ("vel", ("v_xy_valid", "v_z_valid"))):
            present = [f for f in flags if f in pos]
            if present:
                invalid[key] = (tp, ~np.all([np.asarray(pos[f]) > 0 for f in present], axis=0))
    else:
        missing.append("position and velocity (vehicle_local_position)")
    vt_channels = [k + 1 for k in motors] if "VT_MOT_ID" in frame_note else None
    try:
        tu, u, note = motor_outputs(path, ulog, params, motors, vt_channels)
    except RecordingError:
        if armed is False:
            raise RecordingError(
                path,
                "the vehicle was never armed (actuator_armed.armed is never set): a bench "
                "or ground log has no flight to import",
            ) from None
        raise
    streams["u"] = (tu, u, "hold")
    rotor = rotor_speeds(_topic(ulog, "esc_status"), motors)
    if rotor is not None:
        streams["rotor"] = (*rotor, "linear")
    else:
        missing.append("rotor speed (esc_status)")
    battery = _topic(ulog, "battery_status")
    if battery is not None:
        vkey = "voltage_v" if "voltage_v" in battery else "voltage_filtered_v"
        if vkey in battery:
            v = np.asarray(battery[vkey], float)
            streams["vbat"] = (_stamp(battery), np.where(v > 0, v, np.nan), "linear")
        if "current_a" in battery:
            c = np.asarray(battery["current_a"], float)
            streams["current"] = (_stamp(battery), np.where(c >= 0, c, np.nan), "linear")
    if "vbat" not in streams:
        missing.append("battery voltage (battery_status)")
    if "acc" not in streams and "pos" not in streams:
        raise RecordingError(
            path,
            "needs vehicle_local_position or sensor_combined: a recording "
            "needs a pose or an accelerometer",
            key="sensor_combined",
        )
    land = _topic(ulog, "vehicle_land_detected")
    landed = None
    if land is not None and "landed" in land:
        flags = [
            np.asarray(land[k]) > 0
            for k in ("landed", "maybe_landed", "ground_contact")
            if k in land
        ]
        landed = (_stamp(land), np.any(flags, axis=0))
    if time_base is None:
        stamps = (
            _stamp(imu)
            if imu is not None and len(imu["timestamp"]) > len(att["timestamp"])
            else _stamp(att)
        )
    elif time_base == "imu" and imu is not None:
        stamps = _stamp(imu)
    elif time_base in ("attitude", "imu"):
        stamps = _stamp(att)
    else:
        raise ConfigError(f"time_base must be 'attitude' or 'imu', got {time_base!r}")
    fac = float(params.get("THR_MDL_FAC", 0.0))
    geo = geometry(params, motors, path)
    if geo is None:
        geo = quad_x(
            "no CA_ROTOR* parameters: PX4 quad X order assumed "
            f"(SYS_AUTOSTART {int(params.get('SYS_AUTOSTART', 0))})"
        )
    keep = (
        "THR_MDL_FAC",
        "CA_ROTOR_COUNT",
        "CA_AIRFRAME",
        "SYS_AUTOSTART",
        "MAV_TYPE",
        "VT_MOT_ID",
        "BAT1_N_CELLS",
        "MPC_THR_HOVER",
    )
    recorded = {
        k: float(v)
        for k, v in params.items()
        if k in keep or k.startswith(("CA_ROTOR", "PWM_MAIN_M", "UAVCAN_EC_M"))
    }
    return FieldLog(
        path=path,
        importer="px4",
        streams=streams,
        time_base=stamps,
        thrust_model=(0.0, 1.0 - fac, fac),
        thrust_note=f"PX4 thrust model (1 - THR_MDL_FAC) u + THR_MDL_FAC u^2, "
        f"THR_MDL_FAC = {fac:g}",
        geometry=geo,
        landed=landed,
        landed_source="vehicle_land_detected (landed, maybe_landed, ground_contact)",
        invalid=invalid,
        commands=note,
        missing=missing,
        params=recorded,
        source=f"PX4 ULog {path.name}, imported by quadfault",
        warnings=notes,
        armed=armed,
        armed_source="actuator_armed.armed is never set",
        cells=_cells(params),
        skipped=skipped,
    )


def _ever_armed(armed) -> bool | None:
    if armed is None or "armed" not in armed:
        return None
    return bool(np.any(np.asarray(armed["armed"]) > 0))


def _cells(params: dict) -> tuple | None:
    for key in ("BAT1_N_CELLS", "BAT_N_CELLS"):
        if params.get(key, 0) and int(params[key]) > 0:
            return int(params[key]), key
    return None


def _lacks(path, what: str, skipped) -> None:
    """Fail naming what the log lacks and the topics it has (read again, all of them)."""
    try:
        ulog, _ = _load_ulog(path, None)
        names = sorted({d.name for d in ulog.data_list})
    except RecordingError:
        names = []
    has = f" (the log has {', '.join(names)})" if names else " (the log has no data messages)"
    cut = ""
    if skipped and skipped.get("truncated"):
        cut = f"; {skipped['what']}, {skipped['bytes']} bytes after the last whole message"
    raise RecordingError(path, f"{what}{has}{cut}: not a PX4 flight log, or nothing valid")


def import_px4_ulog(
    path,
    *,
    vehicle=None,
    thrust_curve=None,
    keep_all: bool = False,
    calibration=None,
    mass: float | None = None,
    time_base: str | None = None,
    inertia=None,
    arm=None,
    torque_coefficient=None,
    **_ignored,
) -> Recording:
    """Import a PX4 ``.ulg`` flight log.

    Args:
        path: the ULog file.
        vehicle: nominal :class:`quadfault.model.vehicle.Vehicle` (FRD, rotors in the log's motor
            order); default: the log's ``CA_ROTOR*`` geometry with ``mass``, ``inertia``,
            ``arm`` and ``torque_coefficient`` where given and stated assumptions elsewhere.
        thrust_curve: ``(a, b, c)`` with f = a + b u + c u^2 [N]; default PX4's model scaled
            on the calibration segment.
        keep_all: keep rows outside the flight span.
        calibration: ``(t0, t1)`` [s, log clock] for the thrust-scale fit.
        mass: [kg]; inertia: (Jxx, Jyy, Jzz) [kg m^2]; arm: per-axis rotor offset [m];
        torque_coefficient: yaw torque per newton [m].
        time_base: "attitude", "imu" or None (the faster of the two).
    """
    log = read_px4(path, time_base)
    return build_recording(
        log,
        vehicle=vehicle,
        thrust_curve=thrust_curve,
        mass=mass,
        inertia=inertia,
        arm=arm,
        torque_coefficient=torque_coefficient,
        keep_all=keep_all,
        calibration=calibration,
    )
