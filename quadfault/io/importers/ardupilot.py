"""ArduPilot DataFlash importer: binary ``.bin`` and text ``.log`` (needs ``pymavlink``:
``pip install 'quadfault[ardupilot]'``).

:mod:`quadfault.io.importers.dataflash` reads the log into tables (one per message type, from
the log's own message definitions) and times them; this module turns them into streams.
ArduPilot logs NED world and FRD body frames, like quadfault. Sources are chosen by their
columns, so old and new logs alike give what they have:

- body rates and specific force, the time base: ``IMU`` (instance 0; else ``IMU2``,
  ``IMU3``, else any message with ``GyrX..Z``) ``GyrX..Z`` [rad/s], ``AccX..Z`` [m/s^2]; else
  delta angles and velocities over their intervals (``IMT``: ``DelAngX..Z / DelAT``,
  ``DelVelX..Z / DelVT``)
- ``ATT`` (else ``AHR2``): ``Roll, Pitch, Yaw`` [deg] -> attitude (Z-Y-X Euler)
- ``XKF1`` / ``NKF1`` / ``EKF1`` (core 0; any message with ``PN..PD``, ``VN..VD``) [m], [m/s]
  -> position, velocity; without an EKF, the GPS (``Lat``, ``Lng``, ``Alt``, ``Status``):
  position NED about the first 3D fix, velocity from ``Spd``, ``GCrs``, ``VZ`` (or the
  position's slope), invalid without a 3D fix
- ``XKF4`` / ``NKF4`` / ``EKF4`` (core 0): ``SS`` (filter status bits) -> validity: velocity needs bits 1,
  2; position bit 3 or 4 and bit 5; bit 7 (constant position mode) invalidates both
- ``RCOU`` (``C1..``, ``Chan1..`` or ``Ch1..``: :data:`RCOU_PREFIXES`) / ``MOT``: PWM [us] -> motor commands, channels from
  ``SERVOn_FUNCTION`` = Motor 1..4
- ``ESC``: ``Instance``, ``RPM`` -> measured rotor speed [rad/s]
- ``BAT`` / ``CURR``: ``Volt``, ``Curr`` -> ``vbat``, ``current``
- ``EV``: ``Id`` 28 (not landed), 18 (land complete), 17 (land complete maybe), 10/11
  (armed/disarmed) -> flight span

A log without body rates or without motor outputs fails with one line naming what is missing
and the messages the log does have.

Parameters: ``MOT_PWM_MIN/MAX`` (else ``RC3_MIN/MAX``, else 1000-2000 us) normalise the PWM
to the actuator command u; ``MOT_SPIN_MIN/MAX`` and ``MOT_THST_EXPO`` give ArduPilot's thrust
model: with a = (u - spin_min) / (spin_max - spin_min), thrust ~ (1 - expo) a + expo a^2
(ArduPilot's defaults 0.15, 0.95, 0.65 when a log lacks them); ``FRAME_CLASS``/``FRAME_TYPE``
(or ``FRAME`` in old logs) the motor order and spin directions. ArduPilot has no arm-length
parameter: the positions are unit offsets, flagged as a placeholder unless ``--arm`` is given.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfault.errors import ConfigError, RecordingError
from quadfault.io.importers.dataflash import read_tables, set_times
from quadfault.io.importers.field_log import FieldLog, Geometry, build_recording
from quadfault.io.recording import Recording
from quadfault.model.rotation import euler_zyx_to_rot, rot_to_quat

RPM_TO_RAD_S = 2.0 * np.pi / 60.0
MOTOR1_FUNCTION = 33  # SERVOn_FUNCTION of Motor 1 (Motor i is 32 + i)
DEFAULTS = {"MOT_SPIN_MIN": 0.15, "MOT_SPIN_MAX": 0.95, "MOT_THST_EXPO": 0.65}
EV_ARMED, EV_DISARMED, EV_LAND_MAYBE, EV_LANDED, EV_NOT_LANDED = 10, 11, 17, 18, 28
#: quad frames by FRAME_TYPE: per motor (x, y, reaction-torque sign about +z FRD) in unit
#: offsets, ArduPilot's motor numbering (AP_MotorsMatrix); a CCW rotor reacts with +z.
_X = ((1, 1, 1), (-1, -1, 1), (1, -1, -1), (-1, 1, -1))
_R2 = 2**0.5
QUAD_FRAMES = {
    0: ("plus", ((0, _R2, 1), (0, -_R2, 1), (_R2, 0, -1), (-_R2, 0, -1))),
    1: ("X", _X),
    3: ("H", tuple((x, y, -s) for x, y, s in _X)),
    12: ("Betaflight X", ((-1, 1, -1), (1, 1, 1), (-1, -1, 1), (1, -1, -1))),
    13: ("DJI X", ((1, 1, 1), (1, -1, -1), (-1, -1, 1), (-1, 1, -1))),
    14: ("clockwise X", ((1, 1, 1), (-1, 1, -1), (-1, -1, 1), (1, -1, -1))),
    18: ("Betaflight X reversed", ((-1, 1, 1), (1, 1, -1), (-1, -1, -1), (1, -1, 1))),
}


def _instance(table: dict, key: str) -> dict:
    """Rows of instance (or core) 0 when the message has an instance column."""
    if key in table:
        sel = table[key] == np.min(table[key])
        return {k: v[sel] for k, v in table.items()}
    return table


#: ArduPilot's ``FRAME_CLASS`` (and a QuadPlane's ``Q_FRAME_CLASS``) values
FRAME_CLASSES = {
    0: "undefined",
    1: "quad",
    2: "hexa",
    3: "octa",
    4: "octaquad",
    5: "Y6",
    6: "heli",
    7: "tri",
    8: "single copter",
    9: "coax copter",
    10: "bicopter",
    11: "heli dual",
    12: "dodecahexa",
    13: "heli quad",
    14: "deca",
    15: "scripting matrix",
    16: "6DoF scripting",
    17: "dynamic scripting matrix",
}
#: the last ``SERVOn_FUNCTION`` of a motor (Motor 1..12 are 33..44 and 82..)
MOTOR_FUNCTIONS = set(range(33, 45)) | set(range(82, 86))


def frame_check(params: dict, messages=(), path="log") -> str | None:
    """A one-line error naming the frame and its parameters when the log's vehicle is not a
    quadrotor (``FRAME_CLASS``, a QuadPlane's ``Q_FRAME_CLASS``, a fifth motor among the
    ``SERVOn_FUNCTION``, or an old log's ``Frame:`` message); else None, or a note for a
    QuadPlane (its four lift motors are imported)."""
    note = None
    key = "FRAME_CLASS"
    if int(params.get("Q_ENABLE", 0)) == 1:
        key = "Q_FRAME_CLASS"
        note = (
            "QuadPlane: its four lift motors (Motor 1-4) imported; fixed-wing flight not modelled"
        )
    frame_class = params.get(key)
    if frame_class is not None and int(frame_class) != 1:
        name = FRAME_CLASSES.get(int(frame_class), "unknown")
        raise RecordingError(
            path,
            f"{key} is {int(frame_class)} ({name}): quadfault flies quadrotors ({key} 1)",
            key=key,
        )
    extra = sorted(
        (k, int(v))
        for k, v in params.items()
        if k.startswith("SERVO")
        and k.endswith("_FUNCTION")
        and int(v) in MOTOR_FUNCTIONS
        and int(v) > MOTOR1_FUNCTION + 3
    )
    if extra:
        k, v = extra[0]
        raise RecordingError(
            path,
            f"{k} is {v} (Motor {v - 32 if v < 82 else v - 73}): more than four motors, "
            "quadfault flies quadrotors",
            key=k,
        )
    for text in messages:
        if text.startswith("Frame:"):
            frame = text.split(":", 1)[1].strip().split()[0].upper() if text[6:].strip() else ""
            if frame and not frame.startswith(("QUAD", "X", "+")):
                raise RecordingError(
                    path,
                    f"the log's message {text!r}: quadfault flies quadrotors",
                    key="MSG",
                )
    return note


def geometry(params: dict, path="log") -> Geometry:
    """Motor order and spin directions from ``FRAME_CLASS``/``FRAME_TYPE`` (``FRAME``)."""
    frame_check(params, (), path)
    key = "FRAME_TYPE" if "FRAME_TYPE" in params else "FRAME"
    if int(params.get("Q_ENABLE", 0)) == 1:
        key = "Q_FRAME_TYPE"
    ftype = int(params.get(key, 1))
    name, rotors = QUAD_FRAMES.get(ftype, QUAD_FRAMES[1])
    note = (
        f"{key} {ftype} ({name})"
        if ftype in QUAD_FRAMES
        else f"{key} {ftype} not modelled: quad X assumed"
    )
    return Geometry(
        tuple((float(x), float(y)) for x, y, _ in rotors),
        tuple(float(s) for _, _, s in rotors),
        None,
        note + "; ArduPilot logs no arm length",
        placeholder=True,
    )


def thrust_model(params: dict) -> tuple:
    """``((a, b, c), note)``: ArduPilot's thrust model as a quadratic in u (module doc)."""
    got = {k: float(params.get(k, v)) for k, v in DEFAULTS.items()}
    s0, s1, e = got["MOT_SPIN_MIN"], got["MOT_SPIN_MAX"], got["MOT_THST_EXPO"]
    if not s1 > s0:
        raise ConfigError(f"MOT_SPIN_MAX ({s1}) must exceed MOT_SPIN_MIN ({s0})")
    d = s1 - s0
    curve = (-(1 - e) * s0 / d + e * s0**2 / d**2, (1 - e) / d - 2 * e * s0 / d**2, e / d**2)
    assumed = [k for k in DEFAULTS if k not in params]
    note = (
        f"ArduPilot thrust model (1 - MOT_THST_EXPO) a + MOT_THST_EXPO a^2, a = (u - "
        f"MOT_SPIN_MIN) / (MOT_SPIN_MAX - MOT_SPIN_MIN); MOT_THST_EXPO = {e:g}, "
        f"MOT_SPIN_MIN = {s0:g}, MOT_SPIN_MAX = {s1:g}"
    )
    if assumed:
        note += f" ({', '.join(assumed)}: ArduPilot's default, not in the log)"
    return curve, note


def _pwm_range(params: dict) -> tuple:
    for lo_key, hi_key in (("MOT_PWM_MIN", "MOT_PWM_MAX"), ("RC3_MIN", "RC3_MAX")):
        lo, hi = params.get(lo_key, 0), params.get(hi_key, 0)
        if lo and hi and hi > lo:
            return float(lo), float(hi), f"{lo_key}/{hi_key}"
    return 1000.0, 2000.0, "1000-2000 us (assumed: no MOT_PWM_MIN/MAX or RC3_MIN/MAX)"


def _landed(tables: dict) -> tuple | None:
    ev = tables.get("EV")
    if ev is None or "Id" not in ev:
        return None
    ids, t = ev["Id"].astype(int), ev["_t"]
    if not np.any(ids == EV_NOT_LANDED):
        return None
    keep = np.isin(ids, (EV_ARMED, EV_DISARMED, EV_LAND_MAYBE, EV_LANDED, EV_NOT_LANDED))
    ids, t = ids[keep], t[keep]
    return np.r_[t[0] - 1.0, t], np.r_[True, ids != EV_NOT_LANDED]


def _validity(table: dict) -> dict:
    ss = table["SS"].astype(np.int64)
    bit = [(ss >> k) & 1 for k in range(8)]
    const = bit[7] == 1
    vel_ok = (bit[1] == 1) & (bit[2] == 1) & ~const
    pos_ok = ((bit[3] == 1) | (bit[4] == 1)) & (bit[5] == 1) & ~const
    return {"pos": (table["_t"], ~pos_ok), "vel": (table["_t"], ~vel_ok)}


MESSAGES = (
    "IMU",
    "IMU2",
    "IMU3",
    "ATT",
    "AHR2",
    "XKF1",
    "NKF1",
    "EKF1",
    "XKF4",
    "NKF4",
    "EKF4",
    "RCOU",
    "MOT",
    "ESC",
    "BAT",
    "CURR",
    "EV",
    "MSG",
)
#: The names each quantity had in ArduPilot's eras, newest first; a log's own FMT columns
#: choose one (``RCOU``: ``C1..`` from Copter 3.5, ``Chan1..`` and ``Ch1..`` before).
RCOU_PREFIXES = ("C", "Chan", "Ch")
#: column sets that make a message a source of its kind, whatever its name (module doc)
GYRO, DELTA_ANGLE = ("GyrX", "GyrY", "GyrZ"), ("DelAngX", "DelAngY", "DelAngZ", "DelAT")
ACCEL, DELTA_VEL = ("AccX", "AccY", "AccZ"), ("DelVelX", "DelVelY", "DelVelZ", "DelVT")
EKF_STATE = ("PN", "PE", "PD", "VN", "VE", "VD")
FIX = ("Lat", "Lng", "Alt")
GPS_FIX_3D = 3
EARTH_RADIUS = 6_378_137.0  # [m]


def _pick(tables: dict, columns, prefer=()) -> tuple:
    """``(name, table)`` of the message with all ``columns``: the first of ``prefer`` that
    has them, else the one with the most rows; ``(None, None)`` when none has."""
    have = [n for n, tb in tables.items() if all(c in tb for c in columns)]
    if not have:
        return None, None
    name = next((n for n in prefer if n in have), None) or max(
        sorted(have), key=lambda n: len(tables[n]["_t"])
    )
    return name, tables[name]


def _imu(tables: dict) -> tuple:
    """``(name, t, rates (n, 3) [rad/s], specific force (n, 3) or None)`` of the IMU-like
    message (gyro columns, or delta angles over their interval), or None."""
    name, imu = _pick(tables, GYRO, ("IMU", "IMU2", "IMU3"))
    if imu is None:
        name, imu = _pick(tables, DELTA_ANGLE, ("IMT",))
    if imu is None:
        return None
    imu = _instance(imu, "I")
    if "GyrX" in imu:
        w = np.stack([imu[f"Gyr{a}"] for a in "XYZ"], axis=1)
    else:
        w = np.stack([imu[f"DelAng{a}"] for a in "XYZ"], axis=1) / imu["DelAT"][:, None]
    acc = None
    if all(c in imu for c in ACCEL):
        acc = np.stack([imu[f"Acc{a}"] for a in "XYZ"], axis=1)
    elif all(c in imu for c in DELTA_VEL):
        acc = np.stack([imu[f"DelVel{a}"] for a in "XYZ"], axis=1) / imu["DelVT"][:, None]
    ok = np.all(np.isfinite(w), axis=1)
    return name, imu["_t"][ok], w[ok], None if acc is None else acc[ok]


def _gps_pose(gps: dict) -> tuple:
    """``(t, pos NED [m] about the first 3D fix, vel NED [m/s], invalid flags)`` of a GPS
    message: ``Lat``, ``Lng`` [deg], ``Alt`` [m]; velocity from ``Spd`` [m/s], ``GCrs``
    [deg] and ``VZ`` [m/s, down] (without them, from the position's slope); rows without a
    3D fix (``Status``) are flagged invalid."""
    gps = _instance(gps, "I")
    t = gps["_t"]
    fix = gps["Status"] >= GPS_FIX_3D if "Status" in gps else np.ones(len(t), dtype=bool)
    fix &= np.isfinite(gps["Lat"]) & np.isfinite(gps["Lng"]) & (gps["Lat"] != 0)
    if not fix.any():
        return None
    i0 = int(np.flatnonzero(fix)[0])
    lat0, lng0, alt0 = (float(gps[k][i0]) for k in FIX)
    north = np.radians(gps["Lat"] - lat0) * EARTH_RADIUS
    east = np.radians(gps["Lng"] - lng0) * EARTH_RADIUS * np.cos(np.radians(lat0))
    pos = np.stack([north, east, -(gps["Alt"] - alt0)], axis=1)
    order = np.argsort(t, kind="stable")
    slope = np.full_like(pos, np.nan)
    if len(t) > 2:
        slope[order] = np.gradient(pos[order], t[order], axis=0)
    if "Spd" in gps and "GCrs" in gps:
        crs = np.radians(gps["GCrs"])
        vd = gps["VZ"] if "VZ" in gps else slope[:, 2]
        vel = np.stack([gps["Spd"] * np.cos(crs), gps["Spd"] * np.sin(crs), vd], axis=1)
    else:
        vel = slope
    bad = ~fix
    return t, pos, vel, {"pos": (t, bad), "vel": (t, bad)}


def _fail(path, missing: list, logged: list):
    raise RecordingError(
        path, "cannot import: " + "; ".join(missing) + " (the log has " + ", ".join(logged) + ")"
    )


def read_ardupilot(path) -> FieldLog:
    """The streams of an ArduPilot DataFlash log (module docstring)."""
    path = Path(path)
    tables, params, logged, skipped = read_tables(
        path, MESSAGES, also=(GYRO, DELTA_ANGLE, EKF_STATE, FIX + ("Status",))
    )
    texts = [str(m) for m in tables.get("MSG", {}).get("Message", [])]
    frame_note = frame_check(params, texts, path)
    armed = _ever_armed(tables)
    lacking = _missing_outputs(tables)
    if lacking and armed is False:
        lacking = ["the vehicle was never armed (no ARMED event) and the log has no motor outputs"]
    if not any(
        all(c in tb for c in GYRO) or all(c in tb for c in DELTA_ANGLE) for tb in tables.values()
    ):
        lacking.insert(0, "no body rates (no message with GyrX, GyrY, GyrZ or delta angles)")
    if lacking:
        _fail(path, lacking, logged)
    set_times(tables, path)
    streams, missing, invalid, notes = {}, [], {}, []
    imu = _imu(tables)
    if len(imu[1]) < 2:
        raise RecordingError(path, f"fewer than two {imu[0]} messages with body rates")
    imu_name, t_imu, w, acc = imu
    if skipped and skipped["bytes"]:
        skipped = _skipped_times(skipped, tables[imu_name])
    else:
        skipped = None
    if frame_note:
        notes.append(frame_note)
    streams["w"] = (t_imu, w, "linear")
    if acc is not None:
        streams["acc"] = (t_imu, acc, "linear")
    else:
        missing.append(f"accelerometer ({imu_name} has none)")
    if imu_name != "IMU":
        notes.append(f"body rates from {imu_name} (no IMU message)")
    att_name, att = _pick(tables, ("Roll", "Pitch", "Yaw"), ("ATT", "AHR2"))
    ekf_name, ekf = _pick(tables, EKF_STATE, ("XKF1", "NKF1", "EKF1"))
    gps_name, gps = _pick(tables, FIX + ("Status",), ("GPS",))
    pose = None
    if ekf is not None:
        ekf = _instance(ekf, "C")
        pose = (
            ekf["_t"],
            np.stack([ekf[k] for k in ("PN", "PE", "PD")], 1),
            np.stack([ekf[k] for k in ("VN", "VE", "VD")], 1),
        )
        status = next(
            (
                _instance(tables[n], "C")
                for n in ("XKF4", "NKF4", "EKF4")
                if n in tables and "SS" in tables[n]
            ),
            None,
        )
        if status is not None:
            invalid = _validity(status)
    elif gps is not None and (got := _gps_pose(gps)) is not None:
        pose, invalid = got[:3], got[3]
        notes.append(
            f"position and velocity from {gps_name} (no EKF position): NED about "
            "its first 3D fix, invalid without a 3D fix"
        )
    if pose is not None and att is not None:
        R = euler_zyx_to_rot(*(np.radians(att[k]) for k in ("Roll", "Pitch", "Yaw")))
        streams["q"] = (att["_t"], rot_to_quat(R), "quaternion")
        streams["pos"] = (pose[0], pose[1], "linear")
        streams["vel"] = (pose[0], pose[2], "linear")
    else:
        invalid = {}
        missing.append(
            "position and velocity (no EKF or GPS position)" if pose is None else "attitude (ATT)"
        )
    t_out, u, chans, note = _outputs(tables, params, path)
    streams["u"] = (t_out, u, "hold")
    rotor = _rotor_speeds(tables, chans)
    if rotor is not None:
        streams["rotor"] = rotor
    else:
        missing.append("rotor speed (ESC)")
    bat = tables.get("BAT") or tables.get("CURR")
    if bat is not None and "Volt" in bat:
        bat = _instance(bat, "Instance" if "Instance" in bat else "Inst")
        scale = 0.01 if np.nanmax(bat["Volt"]) > 100 else 1.0  # old logs: centivolts
        v = bat["Volt"] * scale
        streams["vbat"] = (bat["_t"], np.where(v > 0, v, np.nan), "linear")
        if "Curr" in bat:
            c = bat["Curr"] * (0.01 if scale != 1.0 else 1.0)
            streams["current"] = (bat["_t"], c, "linear")
    else:
        missing.append("battery voltage (BAT)")
    curve, curve_note = thrust_model(params)
    recorded = {
        k: v
        for k, v in params.items()
        if k in DEFAULTS
        or k.startswith(("FRAME", "Q_FRAME", "Q_ENABLE", "MOT_PWM", "MOT_BAT", "RC3_M"))
    }
    return FieldLog(
        path=path,
        importer="ardupilot",
        streams=streams,
        time_base=t_imu,
        thrust_model=curve,
        thrust_note=curve_note,
        geometry=geometry(params, path),
        landed=_landed(tables),
        landed_source="EV (NOT_LANDED, LAND_COMPLETE)",
        invalid=invalid,
        commands=note,
        missing=missing,
        params=recorded,
        source=f"ArduPilot DataFlash log {path.name}, imported by quadfault",
        warnings=notes,
        armed=armed,
        armed_source="no ARMED event in the log",
        cells=_cells(params),
        skipped=skipped,
    )


def _ever_armed(tables: dict) -> bool | None:
    """From the ``EV`` messages (ARMED, id 10), or None when the log has no events."""
    ev = tables.get("EV")
    if ev is None or "Id" not in ev:
        return None
    return bool(np.any(ev["Id"].astype(int) == EV_ARMED))


def _cells(params: dict) -> tuple | None:
    """Cell count from ``MOT_BAT_VOLT_MAX`` (the voltage of a full pack, 4.2 V per cell)."""
    vmax = float(params.get("MOT_BAT_VOLT_MAX", 0.0))
    if vmax > 0:
        return max(1, int(round(vmax / 4.2))), f"MOT_BAT_VOLT_MAX {vmax:g} V / 4.2 V per cell"
    return None


def _skipped_times(skipped: dict, imu: dict) -> dict:
    """The reader's skipped bytes (:func:`quadfault.io.importers.dataflash.skipped_bytes`)
    with the times around each gap (from the IMU messages' place in the log)."""
    seq, t = imu["_seq"], imu["_t"]
    spans = []
    for at, _ in skipped["gaps"]:
        i = int(np.searchsorted(seq, at))
        if 0 < i < len(seq):
            spans.append((float(t[i - 1]), float(t[i])))
    what = "corrupt or cut data" if skipped["gaps"] else "the log ends mid-message (cut)"
    return {
        "what": what,
        "bytes": int(skipped["bytes"]),
        "truncated": bool(skipped["tail"]),
        "corrupt": len(skipped["gaps"]),
        "after_t": float(t[-1]) if skipped["tail"] else None,
        "spans": spans,
    }


def rcou_prefix(table: dict) -> str | None:
    """The channel columns' prefix of an ``RCOU`` message (:data:`RCOU_PREFIXES`), or None."""
    return next((p for p in RCOU_PREFIXES if f"{p}1" in table), None)


def _missing_outputs(tables: dict) -> list:
    have = ("RCOU" in tables and rcou_prefix(tables["RCOU"]) is not None) or (
        "MOT" in tables and "Mot1" in tables["MOT"]
    )
    return [] if have else ["no motor outputs (no RCOU or MOT messages)"]


def _outputs(tables: dict, params: dict, path) -> tuple:
    """``(t, u (n, 4) 0..1, channels, note)`` from RCOU (else MOT; one of them is there)."""
    lo, hi, how = _pwm_range(params)
    out = tables.get("RCOU")
    if out is not None and rcou_prefix(out) is None:
        out = None
    if out is not None:
        prefix = rcou_prefix(out)
        chans = [
            next(
                (
                    k
                    for k in range(1, 33)
                    if params.get(f"SERVO{k}_FUNCTION") == MOTOR1_FUNCTION + i
                ),
                i + 1,
            )
            for i in range(4)
        ]
        if not all(f"{prefix}{k}" in out for k in chans):
            have = [c for c in out if c.startswith(prefix) and c[len(prefix) :].isdigit()]
            raise RecordingError(
                path,
                f"RCOU lacks the motor channels {[f'{prefix}{k}' for k in chans]} "
                f"(it has {', '.join(have)})",
                key="RCOU",
            )
        pwm = np.stack([out[f"{prefix}{k}"] for k in chans], axis=1)
        note = f"u = (RCOU {prefix}{chans} - {lo:g}) / ({hi:g} - {lo:g}) us ({how})"
    else:
        out = tables["MOT"]
        chans = [1, 2, 3, 4]
        pwm = np.stack([out[f"Mot{k}"] for k in chans], axis=1)
        note = f"u = (MOT Mot1..4 - {lo:g}) / ({hi:g} - {lo:g}) us ({how})"
    return out["_t"], np.clip((pwm - lo) / (hi - lo), 0.0, 1.0), chans, note


def _rotor_speeds(tables: dict, chans) -> tuple | None:
    """ESC telemetry of the motors' channels as a ``rotor`` stream [rad/s], or None."""
    esc = tables.get("ESC")
    if esc is None or "RPM" not in esc or "Instance" not in esc:
        return None
    cols = []
    for i, k in enumerate(chans):
        inst = k - 1 if np.any(esc["Instance"] == k - 1) else i
        sel = esc["Instance"] == inst
        cols.append((esc["_t"][sel], np.abs(esc["RPM"][sel]) * RPM_TO_RAD_S))
    if not all(len(c[0]) > 1 for c in cols):
        return None
    t_esc = np.unique(np.concatenate([c[0] for c in cols]))
    w = np.stack([np.interp(t_esc, tc, wc) for tc, wc in cols], axis=1)
    return t_esc, w, "linear"


def import_ardupilot(
    path,
    *,
    vehicle=None,
    thrust_curve=None,
    keep_all: bool = False,
    calibration=None,
    mass=None,
    inertia=None,
    arm=None,
    torque_coefficient=None,
    **_ignored,
) -> Recording:
    """Import an ArduPilot DataFlash ``.bin`` or text ``.log``; arguments as
    :func:`quadfault.io.importers.px4_ulog.import_px4_ulog`."""
    log = read_ardupilot(path)
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
