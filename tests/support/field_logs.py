"""Small synthetic autopilot flights for the importer tests, and a minimal ULog writer
(file format: docs.px4.io "ULog File Format"; pyulog reads ULogs but does not write them).

The flight (:func:`flight_profile`): disarmed on the ground, armed idle on the ground, a
take-off, a hover with small per-rotor differences, a landing and idle again; the
accelerometer reads -g along z throughout (the ground supports the vehicle at idle).
"""

from __future__ import annotations

import struct

import numpy as np

G = 9.81
HOVER = 0.5  # normalised hover command
IDLE = 0.08  # armed idle command
T_ARM, T_TAKEOFF, T_LAND, T_DISARM, T_END = 2.0, 4.0, 16.0, 18.0, 19.0
OMEGA_PER_U = 2000.0  # measured rotor speed per unit command [rad/s]


def flight_profile(t: np.ndarray) -> dict:
    """Commands (n, 4) 0..1, landed flag, position, velocity of the synthetic flight."""
    u = np.zeros((len(t), 4))
    idle = (t >= T_ARM) & (t < T_DISARM)
    u[idle] = IDLE
    air = (t >= T_TAKEOFF) & (t < T_LAND)
    ramp = np.clip(np.minimum(t - T_TAKEOFF, T_LAND - t) / 0.5, 0.0, 1.0)
    level = IDLE + (HOVER - IDLE) * ramp
    wiggle = 0.02 * np.sin(2 * np.pi * 1.3 * t)
    u[air] = (level + np.outer(wiggle, [1.0, 1.0, -1.0, -1.0]).T).T[air]
    landed = ~((t >= T_TAKEOFF + 0.5) & (t < T_LAND - 0.5))
    z = np.where(landed, 0.0, -1.0)
    pos = np.stack([0.1 * np.sin(0.3 * t), np.zeros_like(t), z], axis=1)
    vel = np.stack([0.03 * np.cos(0.3 * t), np.zeros_like(t), np.zeros_like(t)], axis=1)
    return {"u": u, "landed": landed, "pos": pos, "vel": vel}


# ----------------------------------------------------------------------------------------
_TYPES = {"uint64_t": "Q", "float": "f", "uint8_t": "B", "int32_t": "i", "uint16_t": "H"}


def _msg(kind: str, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), ord(kind)) + payload


def write_ulog(path, topics: list, params: dict | None = None, nested: dict | None = None):
    """``topics``: ``[(name, multi_id, fields, rows)]`` with fields ``[(type, name, n)]``
    (n = 0: scalar) and rows of values in field order (arrays for n > 0; a nested type's
    element is a tuple). ``nested``: ``{type: [(type, name, n)]}`` of struct types."""
    nested = nested or {}

    def fmt_of(ftype):
        if ftype in nested:
            return "".join(fmt_of(t) * (n or 1) for t, _, n in nested[ftype])
        return _TYPES[ftype]

    out = bytearray(b"ULog\x01\x12\x35" + bytes([1]) + struct.pack("<Q", 0))
    out += _msg("B", bytes(16) + struct.pack("<QQQ", 0, 0, 0))
    for tname, fields in nested.items():
        spec = "".join(f"{t}[{n}] {f};" if n else f"{t} {f};" for t, f, n in fields)
        out += _msg("F", f"{tname}:{spec}".encode())
    done = set()
    for name, _, fields, _ in topics:
        if name not in done:
            spec = "".join(f"{t}[{n}] {f};" if n else f"{t} {f};" for t, f, n in fields)
            out += _msg("F", f"{name}:{spec}".encode())
            done.add(name)
    for key, value in (params or {}).items():
        if isinstance(value, int):
            k = f"int32_t {key}".encode()
            out += _msg("P", bytes([len(k)]) + k + struct.pack("<i", value))
        else:
            k = f"float {key}".encode()
            out += _msg("P", bytes([len(k)]) + k + struct.pack("<f", value))
    for msg_id, (name, multi_id, _, _) in enumerate(topics):
        out += _msg("A", struct.pack("<BH", multi_id, msg_id) + name.encode())
    events = []
    for msg_id, (_name, _, fields, rows) in enumerate(topics):
        fmt = "<" + "".join(fmt_of(t) * (n or 1) for t, _, n in fields)
        for row in rows:
            flat = []
            for v in row:
                for item in v if isinstance(v, (list, tuple, np.ndarray)) else [v]:
                    flat.extend(item if isinstance(item, tuple) else [item])
            events.append((row[0], _msg("D", struct.pack("<H", msg_id) + struct.pack(fmt, *flat))))
    for _, blob in sorted(events, key=lambda e: e[0]):
        out += blob
    path.write_bytes(bytes(out))


def px4_flight(
    path,
    *,
    outputs: str = "uavcan",
    invalid_vxy=(8.0, 9.0),
    motor_rate=100.0,
    params: dict | None = None,
    disarmed_value: float = 0.0,
    duration: float = T_END,
    imu_rate: float = 500.0,
    esc_motors=None,
    motor_channels=(1, 2, 3, 4),
    armed: bool | None = None,
) -> dict:
    """Write the synthetic flight as a ULog. ``outputs``: "uavcan" (actuator_outputs
    instance 1, 0-8191, instance 0 all zeros, no actuator_motors), "motors"
    (actuator_motors, ``disarmed_value`` before arming) or "none". Velocity flagged invalid on
    ``invalid_vxy`` [s] (None: never). ``duration`` stretches the flight (phases keep their
    proportions; times in the arguments are in the unstretched flight). Returns the profile at
    the motor stamps. ``esc_motors``: the motor (0-based) each ESC reports, with its
    ``actuator_function`` (default: ESC i is motor i, no function field).
    ``motor_channels``: the UAVCAN outputs (1-based) of motors 1-4; other than 1-4, the
    remaining outputs move like control surfaces. ``armed``: write ``actuator_armed`` (False:
    never armed, and every output stays at zero)."""
    us = 1_000_000
    stretch = duration / T_END
    t_att = np.arange(0.0, duration, 0.004)
    t_imu = np.arange(0.0, duration, 1.0 / imu_rate)
    t_pos = np.arange(0.0, duration, 0.01)
    t_mot = np.arange(0.0, duration, 1.0 / motor_rate)
    prof = flight_profile(t_mot / stretch)
    q = [1.0, 0.0, 0.0, 0.0]
    topics = [
        (
            "vehicle_attitude",
            0,
            [("uint64_t", "timestamp", 0), ("float", "q", 4)],
            [(int(t * us), q) for t in t_att],
        ),
        (
            "sensor_combined",
            0,
            [
                ("uint64_t", "timestamp", 0),
                ("float", "gyro_rad", 3),
                ("float", "accelerometer_m_s2", 3),
            ],
            [(int(t * us), [0.0, 0.0, 0.0], [0.0, 0.0, -G]) for t in t_imu],
        ),
    ]
    pp = flight_profile(t_pos / stretch)
    bad = np.zeros(len(t_pos), dtype=bool)
    if invalid_vxy is not None:
        bad = (t_pos / stretch >= invalid_vxy[0]) & (t_pos / stretch < invalid_vxy[1])
    vel = pp["vel"].copy()
    vel[bad, 0] = 5.0 + t_pos[bad]  # an invalid estimate drifts
    topics.append(
        (
            "vehicle_local_position",
            0,
            [("uint64_t", "timestamp", 0)]
            + [("float", k, 0) for k in ("x", "y", "z", "vx", "vy", "vz")]
            + [("uint8_t", k, 0) for k in ("xy_valid", "z_valid", "v_xy_valid", "v_z_valid")],
            [
                (int(t * us), *pp["pos"][k], *vel[k], 1, 1, int(not bad[k]), 1)
                for k, t in enumerate(t_pos)
            ],
        )
    )
    if outputs == "uavcan":
        fields = [("uint64_t", "timestamp", 0), ("float", "output", 8)]
        zero = [(int(t * us), [0.0] * 8) for t in t_mot]
        moving = tuple(motor_channels) != (1, 2, 3, 4)
        raw = []
        for k, t in enumerate(t_mot):
            out = [4095.5 + (2000.0 * np.sin(2.0 * t + j) if moving else 0.0) for j in range(8)]
            for i, ch in enumerate(motor_channels):
                out[ch - 1] = 0.0 if armed is False else 8191.0 * prof["u"][k, i]
            raw.append((int(t * us), out))
        topics += [("actuator_outputs", 0, fields, zero), ("actuator_outputs", 1, fields, raw)]
    elif outputs == "motors":
        u = prof["u"].copy()
        u[t_mot / stretch < T_ARM] = disarmed_value
        topics.append(
            (
                "actuator_motors",
                0,
                [("uint64_t", "timestamp", 0), ("float", "control", 4)],
                [(int(t * us), list(u[j])) for j, t in enumerate(t_mot)],
            )
        )
    rpm = prof["u"] * OMEGA_PER_U * 60.0 / (2 * np.pi)
    report = [("int32_t", "esc_rpm", 0), ("float", "esc_voltage", 0)]
    if esc_motors is None:
        esc = [
            (int(t * us), 4, [(int(round(r)), 12.0) for r in rpm[k]]) for k, t in enumerate(t_mot)
        ]
    else:
        report.append(("uint8_t", "actuator_function", 0))
        esc = [
            (int(t * us), 4, [(int(round(rpm[k, m])), 12.0, 101 + m) for m in esc_motors])
            for k, t in enumerate(t_mot)
        ]
    topics.append(
        (
            "esc_status",
            0,
            [("uint64_t", "timestamp", 0), ("uint8_t", "esc_count", 0), ("esc_report", "esc", 4)],
            esc,
        )
    )
    t_land = np.arange(0.0, duration, 0.1)
    pl = flight_profile(t_land / stretch)
    topics.append(
        (
            "vehicle_land_detected",
            0,
            [
                ("uint64_t", "timestamp", 0),
                ("uint8_t", "landed", 0),
                ("uint8_t", "maybe_landed", 0),
                ("uint8_t", "ground_contact", 0),
            ],
            [(int(t * us), int(pl["landed"][k]), 0, 0) for k, t in enumerate(t_land)],
        )
    )
    t_bat = np.arange(0.0, duration, 0.1)
    topics.append(
        (
            "battery_status",
            0,
            [("uint64_t", "timestamp", 0), ("float", "voltage_v", 0), ("float", "current_a", 0)],
            [(int(t * us), 16.0 - 0.05 * t, 10.0) for t in t_bat],
        )
    )
    if armed is not None:
        topics.append(
            (
                "actuator_armed",
                0,
                [("uint64_t", "timestamp", 0), ("uint8_t", "armed", 0)],
                [(int(t * us), int(armed and T_ARM <= t < T_DISARM)) for t in t_land],
            )
        )
    base = {"THR_MDL_FAC": 0.3, "CA_ROTOR_COUNT": 4}
    for i, ((x, y), km) in enumerate(
        zip(
            ((0.12, 0.12), (-0.12, -0.12), (0.12, -0.12), (-0.12, 0.12)), (0.02, 0.02, -0.02, -0.02)
        )
    ):
        base.update({f"CA_ROTOR{i}_PX": x, f"CA_ROTOR{i}_PY": y, f"CA_ROTOR{i}_KM": km})
    base.update(params or {})
    base = {k: v for k, v in base.items() if v is not None}  # None: leave the parameter out
    write_ulog(path, topics, base, nested={"esc_report": report})
    return prof


# ----------------------------------------------------------------------------------------
# ArduPilot DataFlash (binary: 0xA3 0x95 type payload; the FMT messages describe the rest)
_DF = {  # name: (type id, format, columns)
    "PARM": (129, "QNf", "TimeUS,Name,Value"),
    "IMU": (130, "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),
    "ATT": (131, "Qfff", "TimeUS,Roll,Pitch,Yaw"),
    "XKF1": (132, "QBffffff", "TimeUS,C,VN,VE,VD,PN,PE,PD"),
    "XKF4": (133, "QBI", "TimeUS,C,SS"),
    "RCOU": (134, "QHHHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8"),
    "ESC": (135, "QBi", "TimeUS,Instance,RPM"),
    "BAT": (136, "QBff", "TimeUS,Instance,Volt,Curr"),
    "EV": (137, "QB", "TimeUS,Id"),
}
_STRUCT = {
    "Q": "Q",
    "B": "B",
    "f": "f",
    "I": "I",
    "H": "H",
    "i": "i",
    "N": "16s",
    "n": "4s",
    "Z": "64s",
}
SS_OK = 0b111111  # attitude, velocities, positions valid


def _df_messages(
    *, rcou_rate, invalid_vxy, params, motor_channels, imu_rate=400.0, duration=T_END, armed=True
):
    """``[(t, name, values)]`` of the synthetic flight (``armed`` False: a bench log, outputs
    at their minimum, no ARMED event)."""
    s = duration / T_END
    msgs = [(0.0, "PARM", (k.encode(), float(v))) for k, v in params.items()]
    for t in np.arange(0.0, duration, 1.0 / imu_rate):
        msgs.append((t, "IMU", (0, 0.0, 0.0, 0.0, 0.0, 0.0, -G)))
        msgs.append((t, "IMU", (1, 9.0, 9.0, 9.0, 9.0, 9.0, 9.0)))  # a second, broken IMU
    t_pos = np.arange(0.0, duration, 0.04)
    pp = flight_profile(t_pos / s)
    for k, t in enumerate(t_pos):
        bad = invalid_vxy is not None and invalid_vxy[0] <= t / s < invalid_vxy[1]
        vel = pp["vel"][k] + (np.array([5.0 + t, 0.0, 0.0]) if bad else 0.0)
        msgs.append((t, "ATT", (0.0, 0.0, 30.0)))
        msgs.append((t, "XKF1", (0, *vel, *pp["pos"][k])))
        msgs.append((t, "XKF1", (1, 99.0, 99.0, 99.0, 99.0, 99.0, 99.0)))
        msgs.append((t, "XKF4", (0, SS_OK & ~0b10 if bad else SS_OK)))
    t_mot = np.arange(0.0, duration, 1.0 / rcou_rate)
    pm = flight_profile(t_mot / s)
    if not armed:
        pm["u"][:] = 0.0
    for k, t in enumerate(t_mot):
        pwm = [1000] * 8
        for i, ch in enumerate(motor_channels):
            pwm[ch - 1] = int(round(1000 + 1000 * pm["u"][k, i]))
        msgs.append((t, "RCOU", tuple(pwm)))
        for i, ch in enumerate(motor_channels):
            rpm = int(round(pm["u"][k, i] * OMEGA_PER_U * 60 / (2 * np.pi)))
            msgs.append((t, "ESC", (ch - 1, rpm)))
    for t in np.arange(0.0, duration, 0.1):
        msgs.append((t, "BAT", (0, 16.0 - 0.05 * t / s, 10.0)))
    events = ((2.0, 10), (T_TAKEOFF + 0.5, 28), (T_LAND - 0.5, 18), (T_DISARM, 11))
    for t, ev in events if armed else ((2.0, 18),):
        msgs.append((t * s, "EV", (ev,)))
    return sorted(msgs, key=lambda m: m[0])


def dataflash_flight(
    path,
    *,
    text: bool = False,
    rcou_rate: float = 100.0,
    invalid_vxy=(8.0, 9.0),
    params: dict | None = None,
    motor_channels=(5, 6, 7, 8),
    imu_rate: float = 400.0,
    duration: float = T_END,
    renames: dict | None = None,
    armed: bool = True,
) -> None:
    """Write the synthetic flight as an ArduPilot DataFlash log: binary, or text with
    ``text=True``. Motors on ``motor_channels`` (``SERVOn_FUNCTION``), ESC telemetry on
    the same instances, a broken second IMU and EKF core, velocity flagged invalid on
    ``invalid_vxy`` [s], land events. ``renames``: ``{message: (name, {column: new name
    or None})}`` writes a message as an older firmware named it; a column renamed to None is
    left out, with the rows whose value in it is not 0 (an instance or core column: only
    instance 0 is written)."""
    base = {
        "FRAME_CLASS": 1,
        "FRAME_TYPE": 1,
        "MOT_PWM_MIN": 1000,
        "MOT_PWM_MAX": 2000,
        "MOT_SPIN_MIN": 0.1,
        "MOT_SPIN_MAX": 0.95,
        "MOT_THST_EXPO": 0.5,
    }
    for i, ch in enumerate(motor_channels):
        base[f"SERVO{ch}_FUNCTION"] = 33 + i
    base.update(params or {})
    base = {k: v for k, v in base.items() if v is not None}  # None: leave the parameter out
    msgs = _df_messages(
        rcou_rate=rcou_rate,
        invalid_vxy=invalid_vxy,
        params=base,
        motor_channels=motor_channels,
        imu_rate=imu_rate,
        duration=duration,
        armed=armed,
    )
    defs = dict(_DF)
    for old_name, (new_name, cols) in (renames or {}).items():
        tid, fmt, columns = defs.pop(old_name)
        names = columns.split(",")
        drop = [i for i, c in enumerate(names) if cols.get(c, c) is None]
        fmt = "".join(ch for i, ch in enumerate(fmt) if i not in drop)
        names = [cols.get(c, c) for i, c in enumerate(names) if i not in drop]
        defs[new_name] = (tid, fmt, ",".join(names))
        renamed = []
        for t, name, vals in msgs:
            if name == old_name:
                if any(vals[i - 1] != 0 for i in drop):
                    continue
                name = new_name
                vals = tuple(v for i, v in enumerate(vals) if i + 1 not in drop)
            renamed.append((t, name, vals))
        msgs = renamed
    if text:
        lines = ["FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format,Columns"]
        for name, (tid, fmt, cols) in defs.items():
            size = 3 + struct.calcsize("<" + "".join(_STRUCT[c] for c in fmt))
            lines.append(f"FMT, {tid}, {size}, {name}, {fmt}, {cols}")
        for t, name, vals in msgs:
            cells = [str(int(round(t * 1e6)))] + [
                v.decode() if isinstance(v, bytes) else f"{v:g}" if isinstance(v, float) else str(v)
                for v in vals
            ]
            lines.append(f"{name}, " + ", ".join(cells))
        path.write_text("\n".join(lines) + "\n")
        return
    out = bytearray()

    def fmt_msg(tid, name, fmt, cols):
        size = 3 + struct.calcsize("<" + "".join(_STRUCT[c] for c in fmt))
        return b"\xa3\x95\x80" + struct.pack(
            "<BB4s16s64s", tid, size, name.encode(), fmt.encode(), cols.encode()
        )

    out += fmt_msg(128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns")
    for name, (tid, fmt, cols) in defs.items():
        out += fmt_msg(tid, name, fmt, cols)
    for t, name, vals in msgs:
        tid, fmt, _ = defs[name]
        pack = "<" + "".join(_STRUCT[c] for c in fmt)
        out += b"\xa3\x95" + bytes([tid]) + struct.pack(pack, int(round(t * 1e6)), *vals)
    path.write_bytes(bytes(out))


OLD_TEXT_FMT = {  # ArduCopter 3.x text logs: no time stamp in most messages
    "PARM": ("Nf", "Name,Value"),
    "GPS": ("BIHBcLLeeEefI", "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs,VZ,T"),
    "GPS_TOW": ("BIBcLLeeEe", "Status,Time,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs"),
    "IMU": ("ffffff", "GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),
    "ATT": ("cccccCC", "RollIn,Roll,PitchIn,Pitch,YawIn,Yaw,NavYaw"),
    "MOT": ("hhhh", "Mot1,Mot2,Mot3,Mot4"),
    "CURR": ("hIhhhf", "ThrOut,ThrInt,Volt,Curr,Vcc,CurrTot"),
}
LAT0, LNG0, ALT0 = -39.49503, 176.74835, 46.8  # [deg], [deg], [m]
BOARD_T0 = 66.937  # board clock at the start of the old text log [s]


def old_text_log(
    path,
    *,
    gps: str | None = "board",
    imu: str | None = "IMU",
    rate: float = 50.0,
    gps_every: int = 10,
) -> None:
    """An ArduCopter 3.x-style text log of the synthetic flight: IMU (named ``imu``; None
    leaves it out), ATT and MOT once per loop at ``rate`` without time stamps, CURR, and a GPS
    fix every ``gps_every`` loops: ``gps="board"`` with GPS week, time of week and the board
    clock ``T``; ``"tow"`` with the time of week only (no week, no board clock, no vertical
    speed); None: no GPS (nothing times the log)."""
    R = 6378137.0
    lines = ["FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format,Columns"]
    kinds = {"PARM": "PARM", "ATT": "ATT", "MOT": "MOT", "CURR": "CURR"}
    if imu:
        kinds[imu] = "IMU"
    if gps:
        kinds["GPS"] = "GPS" if gps == "board" else "GPS_TOW"
    for tid, (name, kind) in enumerate(kinds.items(), start=129):
        fmt, cols = OLD_TEXT_FMT[kind]
        lines.append(f"FMT, {tid}, 0, {name}, {fmt}, {cols}")
    for k, v in {"FRAME": 1, "RC3_MIN": 1000, "RC3_MAX": 2000}.items():
        lines.append(f"PARM, {k}, {v}")
    t = np.arange(0.0, T_END, 1.0 / rate)
    p = flight_profile(t)
    for k, tk in enumerate(t):
        if gps and k % gps_every == 0:
            n, e, d = p["pos"][k]
            lat = LAT0 + np.degrees(n / R)
            lng = LNG0 + np.degrees(e / (R * np.cos(np.radians(LAT0))))
            vn, ve, vd = p["vel"][k]
            spd, crs = np.hypot(vn, ve), np.degrees(np.arctan2(ve, vn)) % 360.0
            tow = 109206800 + int(round(1000 * tk))
            fix = f"3, {tow}, 1774" if gps == "board" else f"3, {tow}"
            tail = f", {vd:.6f}, {int(round(1000 * (BOARD_T0 + tk)))}" if gps == "board" else ""
            lines.append(
                f"GPS, {fix}, 9, 2.42, {lat:.7f}, {lng:.7f}, 0.00, {ALT0 - d:.2f}, "
                f"{spd:.3f}, {crs:.2f}" + tail
            )
        if imu:
            lines.append(f"{imu}, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000, {-G:.4f}")
        lines.append("ATT, 0.00, 0.00, 0.00, 0.00, 0.00, 30.00, 30.00")
        pwm = ", ".join(str(int(round(1000 + 1000 * u))) for u in p["u"][k])
        lines.append(f"MOT, {pwm}")
        if k % 25 == 0:
            lines.append(f"CURR, 0, 0, {int(1600 - 5 * tk)}, 1000, 4962, 0.000000")
    path.write_text("\n".join(lines) + "\n")


# ----------------------------------------------------------------------------------------
# Betaflight blackbox: an encoder of the format (the inverse of the importer's decoder)
def _uvb(v: int) -> bytes:
    v &= 0xFFFFFFFF
    out = bytearray()
    while v >= 0x80:
        out.append((v & 0x7F) | 0x80)
        v >>= 7
    out.append(v)
    return bytes(out)


def _svb(v: int) -> bytes:
    return _uvb((v << 1) ^ (v >> 31))


def _fits(v: int, bits: int) -> bool:
    return -(1 << (bits - 1)) <= v < (1 << (bits - 1))


def _tag2_3s32(vals) -> bytes:
    if all(_fits(v, 2) for v in vals):
        return bytes([((vals[0] & 3) << 4) | ((vals[1] & 3) << 2) | (vals[2] & 3)])
    if all(_fits(v, 4) for v in vals):
        return bytes([0x40 | (vals[0] & 0xF), ((vals[1] & 0xF) << 4) | (vals[2] & 0xF)])
    if all(_fits(v, 6) for v in vals):
        return bytes([0x80 | (vals[0] & 0x3F), vals[1] & 0x3F, vals[2] & 0x3F])
    sel, body = 0, bytearray()
    for i, v in enumerate(vals):
        n = next(n for n in (1, 2, 3, 4) if _fits(v, 8 * n))
        sel |= (n - 1) << (2 * i)
        body += (v & ((1 << (8 * n)) - 1)).to_bytes(n, "little")
    return bytes([0xC0 | sel]) + bytes(body)


def _tag8_4s16(vals) -> bytes:
    sel, nibbles = 0, []
    for i, v in enumerate(vals):
        if v == 0:
            code = 0
        elif _fits(v, 4):
            code, nibbles = 1, nibbles + [v & 0xF]
        elif _fits(v, 8):
            code, nibbles = 2, nibbles + [(v >> 4) & 0xF, v & 0xF]
        else:
            code, nibbles = 3, nibbles + [(v >> s) & 0xF for s in (12, 8, 4, 0)]
        sel |= code << (2 * i)
    if len(nibbles) % 2:
        nibbles.append(0)
    return bytes([sel]) + bytes((a << 4) | b for a, b in zip(nibbles[::2], nibbles[1::2]))


def _tag8_8svb(vals) -> bytes:
    if len(vals) == 1:
        return _svb(vals[0])
    head = sum(1 << i for i, v in enumerate(vals) if v != 0)
    return bytes([head]) + b"".join(_svb(v) for v in vals if v != 0)


def encode_fields(values, encodings) -> bytes:
    """One frame's field values (after prediction) in the given encodings."""
    out, i, n = bytearray(), 0, len(values)
    while i < n:
        e = encodings[i]
        if e == 0:
            out += _svb(values[i])
            i += 1
        elif e == 1:
            out += _uvb(values[i])
            i += 1
        elif e == 3:
            out += _uvb((-values[i]) & 0x3FFF)
            i += 1
        elif e == 9:
            i += 1
        elif e == 6:
            c = 1
            while c < 8 and i + c < n and encodings[i + c] == 6:
                c += 1
            out += _tag8_8svb(values[i : i + c])
            i += c
        elif e == 7:
            out += _tag2_3s32(values[i : i + 3])
            i += 3
        elif e == 8:
            out += _tag8_4s16(values[i : i + 4])
            i += 4
        else:
            raise ValueError(e)
    return bytes(out)


BB_FIELDS = (
    ["loopIteration", "time"]
    + [f"gyroADC[{i}]" for i in range(3)]
    + [f"accSmooth[{i}]" for i in range(3)]
    + [f"motor[{i}]" for i in range(4)]
    + [f"eRPM[{i}]" for i in range(4)]
    + ["vbatLatest"]
)
#                    it  t  gyro     acc      motors       eRPM         vbat
BB_I_PRED = [0, 0, 0, 0, 0, 0, 0, 0, 11, 5, 5, 5, 0, 0, 0, 0, 9]
BB_I_ENC = [1, 1, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1, 3]
BB_P_PRED = [6, 2, 1, 1, 1, 3, 3, 3, 1, 1, 1, 1, 1, 1, 1, 1, 1]
BB_P_ENC = [9, 0, 7, 7, 7, 8, 8, 8, 8, 6, 6, 6, 6, 6, 6, 6, 0]
BB_MOTOR_OUTPUT = (158, 2047)
BB_POLES, BB_ACC_1G, BB_VBATREF = 14, 2048, 1600


def _bb_rows(duration: float, rate: float) -> np.ndarray:
    """Integer field rows of the synthetic flight (times from 0)."""
    t = np.arange(0.0, duration, 1.0 / rate)
    prof = flight_profile(t * (T_END / duration))
    u = np.maximum(prof["u"], IDLE)  # the log starts at arming: idle, never off
    lo, hi = BB_MOTOR_OUTPUT
    motor = np.round(lo + (hi - lo) * u).astype(int)
    omega = u * OMEGA_PER_U
    erpm = np.round(omega * 60 / (2 * np.pi) * (BB_POLES / 2) / 100).astype(int)
    rows = np.zeros((len(t), len(BB_FIELDS)), dtype=np.int64)
    rows[:, 0] = np.arange(len(t)) * 2
    rows[:, 1] = np.round(t * 1e6).astype(int) + 1_000_000
    rows[:, 2] = np.round(20 * np.sin(2 * np.pi * 0.7 * t)).astype(int)  # deg/s, roll
    rows[:, 7] = BB_ACC_1G  # +1 g along the FLU z axis
    rows[:, 8:12] = motor
    rows[:, 12:16] = erpm
    rows[:, 16] = np.round(1600 - 20 * t / duration).astype(int)  # 0.01 V
    return rows


def _predict(row, prev, prev2, preds, motor0):
    out = []
    for i, (v, p) in enumerate(zip(row, preds)):
        base = {
            0: 0,
            1: prev[i] if prev is not None else 0,
            2: 2 * prev[i] - prev2[i] if prev is not None else 0,
            3: int((prev[i] + prev2[i]) / 2) if prev is not None else 0,
            5: row[motor0],
            6: v,
            9: BB_VBATREF,
            11: BB_MOTOR_OUTPUT[0],
        }[p]
        out.append(int(v - base))
    return out


def blackbox_log(
    duration: float, rate: float = 500.0, *, i_interval: int = 32, corrupt_at: int | None = None
) -> bytes:
    """One log of the synthetic flight: header, I frames every ``i_interval`` frames, P
    frames between, slow frames, a sync-beep event and the log-end event. ``corrupt_at``:
    damage the frame with that index."""
    header = [
        "Product:Blackbox flight data recorder by Nicholas Sherlock",
        "Data version:2",
        "I interval:" + str(2 * i_interval),
        "P interval:2",
        "Field I name:" + ",".join(BB_FIELDS),
        "Field I signed:" + ",".join(["0", "0"] + ["1"] * 6 + ["0"] * 9),
        "Field I predictor:" + ",".join(map(str, BB_I_PRED)),
        "Field I encoding:" + ",".join(map(str, BB_I_ENC)),
        "Field P predictor:" + ",".join(map(str, BB_P_PRED)),
        "Field P encoding:" + ",".join(map(str, BB_P_ENC)),
        "Field S name:flightModeFlags,stateFlags",
        "Field S signed:0,0",
        "Field S predictor:0,0",
        "Field S encoding:1,1",
        "Firmware type:Cleanflight",
        "Firmware revision:Betaflight 4.4.0 (test) STM32F7X2",
        f"motorOutput:{BB_MOTOR_OUTPUT[0]},{BB_MOTOR_OUTPUT[1]}",
        f"acc_1G:{BB_ACC_1G}",
        "gyro_scale:0x3f800000",
        f"vbatref:{BB_VBATREF}",
        f"motor_poles:{BB_POLES}",
        "motor_pwm_protocol:7",
        "minthrottle:1070",
    ]
    out = bytearray("".join(f"H {h}\n" for h in header).encode())
    out += b"E" + bytes([0]) + _uvb(1234)  # sync beep
    rows = _bb_rows(duration, rate)
    motor0 = BB_FIELDS.index("motor[0]")
    prev = prev2 = None
    for k, row in enumerate(rows):
        row = [int(v) for v in row]
        if k % i_interval == 0:
            frame = b"I" + encode_fields(_predict(row, None, None, BB_I_PRED, motor0), BB_I_ENC)
            prev = prev2 = row
        else:
            frame = b"P" + encode_fields(_predict(row, prev, prev2, BB_P_PRED, motor0), BB_P_ENC)
            prev2, prev = prev, row
        if corrupt_at is not None and k == corrupt_at:
            frame = frame[:1] + b"\xff\xff\xff" + frame[4:]
        out += frame
        if k % 100 == 0:
            out += b"S" + _uvb(1) + _uvb(k)
    out += b"E" + bytes([255]) + b"End of log\x00"
    return bytes(out)


def blackbox_csv(duration: float, rate: float = 500.0) -> str:
    """The same flight as ``blackbox_decode`` writes it (units in the column names)."""
    rows = _bb_rows(duration, rate)
    names = [
        ("time (us)" if n == "time" else "vbatLatest (V)" if n == "vbatLatest" else n)
        for n in BB_FIELDS
    ]
    lines = [",".join(names)]
    for r in rows:
        cells = [str(v) for v in r[:-1]] + [f"{r[-1] / 100:.2f}"]
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------
# a simulated flight written in each format (frames, units and motor order as each autopilot
# logs them), for cross-checks of the importers against the simulator's truth
SIM_CURVE = 9.8  # f = SIM_CURVE u^2 [N]: the commands written for thrusts f
PX4_ORDER = (0, 2, 1, 3)  # PX4/ArduPilot quad X rotor i is the paper's rotor ORDER[i]
BF_ORDER = (3, 0, 2, 1)  # Betaflight: rear-right, front-right, rear-left, front-left


def _commands(rec, order):
    return np.sqrt(np.clip(rec.thrust_cmd[:, list(order)], 0.0, None) / SIM_CURVE)


def sim_to_px4(rec, path, every: int = 2) -> None:
    """ULog of a simulated (NED/FRD) recording: attitude, rates, IMU, pose, actuator_motors,
    airborne land detector, CA_ROTOR* from the vehicle, THR_MDL_FAC 1."""
    us = 1_000_000
    sel = np.arange(0, len(rec.t), every)
    t = rec.t[sel]
    u = _commands(rec, PX4_ORDER)[sel]
    ts = [int(round(x * us)) + us for x in t]
    topics = [
        (
            "vehicle_attitude",
            0,
            [("uint64_t", "timestamp", 0), ("float", "q", 4)],
            [(s, list(rec.quaternion[k])) for s, k in zip(ts, sel)],
        ),
        (
            "vehicle_angular_velocity",
            0,
            [("uint64_t", "timestamp", 0), ("float", "xyz", 3)],
            [(s, list(rec.omega[k])) for s, k in zip(ts, sel)],
        ),
        (
            "sensor_combined",
            0,
            [("uint64_t", "timestamp", 0), ("float", "accelerometer_m_s2", 3)],
            [(s, list(rec.accel[k])) for s, k in zip(ts, sel)],
        ),
        (
            "vehicle_local_position",
            0,
            [("uint64_t", "timestamp", 0)]
            + [("float", c, 0) for c in ("x", "y", "z", "vx", "vy", "vz")],
            [(s, *rec.position[k], *rec.velocity[k]) for s, k in zip(ts, sel)],
        ),
        (
            "actuator_motors",
            0,
            [("uint64_t", "timestamp", 0), ("float", "control", 4)],
            [(s, list(u[j])) for j, s in enumerate(ts)],
        ),
        (
            "vehicle_land_detected",
            0,
            [("uint64_t", "timestamp", 0), ("uint8_t", "landed", 0)],
            [(ts[0], 0)],
        ),
    ]
    A = rec.vehicle.allocation[:, list(PX4_ORDER)]
    params = {"THR_MDL_FAC": 1.0, "CA_ROTOR_COUNT": 4}
    for i in range(4):
        params.update(
            {
                f"CA_ROTOR{i}_PX": float(A[2, i]),
                f"CA_ROTOR{i}_PY": float(-A[1, i]),
                f"CA_ROTOR{i}_KM": float(A[3, i]),
            }
        )
    write_ulog(path, topics, params)


def sim_to_dataflash(rec, path, every: int = 2) -> None:
    """DataFlash binary of a simulated recording (IMU, ATT, XKF1, RCOU PWM 1000-2000 with a
    pure square thrust model, a not-landed event); the frame type (X, or H when rotor 1 spins
    clockwise) from the vehicle's spin directions."""
    from quadfault.model.rotation import quat_to_rot, rot_to_euler_zyx

    sel = np.arange(0, len(rec.t), every)
    u = _commands(rec, PX4_ORDER)[sel]
    eul = np.degrees(rot_to_euler_zyx(quat_to_rot(rec.quaternion[sel])))
    frame = 1 if rec.vehicle.allocation[3, PX4_ORDER[0]] > 0 else 3
    params = {
        "FRAME_CLASS": 1,
        "FRAME_TYPE": frame,
        "MOT_PWM_MIN": 1000,
        "MOT_PWM_MAX": 2000,
        "MOT_SPIN_MIN": 0.0,
        "MOT_SPIN_MAX": 1.0,
        "MOT_THST_EXPO": 1.0,
    }
    msgs = [(0.0, "PARM", (k.encode(), float(v))) for k, v in params.items()]
    msgs.append((rec.t[0] + 0.5, "EV", (28,)))
    for j, k in enumerate(sel):
        t = rec.t[k] + 1.0
        msgs.append((t, "IMU", (0, *rec.omega[k], *rec.accel[k])))
        msgs.append((t, "ATT", tuple(float(x) for x in eul[j])))
        msgs.append((t, "XKF1", (0, *rec.velocity[k], *rec.position[k])))
        msgs.append((t, "XKF4", (0, SS_OK)))
        pwm = [int(round(1000 + 1000 * x)) for x in u[j]] + [1000] * 4
        msgs.append((t, "RCOU", tuple(pwm)))
    out = bytearray()
    for name, (tid, fmt, cols) in [
        ("FMT", (128, "BBnNZ", "Type,Length,Name,Format,Columns"))
    ] + list(_DF.items()):
        size = 3 + struct.calcsize("<" + "".join(_STRUCT[c] for c in fmt))
        out += b"\xa3\x95\x80" + struct.pack(
            "<BB4s16s64s", tid, size, name.encode(), fmt.encode(), cols.encode()
        )
    for t, name, vals in sorted(msgs, key=lambda m: m[0]):
        tid, fmt, _ = _DF[name]
        pack = "<" + "".join(_STRUCT[c] for c in fmt)
        out += b"\xa3\x95" + bytes([tid]) + struct.pack(pack, int(round(t * 1e6)), *vals)
    path.write_bytes(bytes(out))


def sim_to_blackbox(rec, path, every: int = 2) -> None:
    """Blackbox log of a simulated recording: gyro [deg/s] and accelerometer [acc_1G per g]
    in Betaflight's axes (x forward, y left, z up), motors 48-2047 (DShot; thrust ~ u^2),
    Betaflight's motor order (``yaw_motors_reversed`` when rotor 0 spins counter-clockwise);
    I frames only (every field unsigned/signed variable byte)."""
    sel = np.arange(0, len(rec.t), every)
    u = _commands(rec, BF_ORDER)[sel]
    flu = np.array([1.0, -1.0, -1.0])
    names = (
        ["loopIteration", "time"]
        + [f"gyroADC[{i}]" for i in range(3)]
        + [f"accSmooth[{i}]" for i in range(3)]
        + [f"motor[{i}]" for i in range(4)]
    )
    enc = [1, 1, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1]
    head = [
        "Product:Blackbox flight data recorder by Nicholas Sherlock",
        "Data version:2",
        "I interval:1",
        "P interval:1",
        "Field I name:" + ",".join(names),
        "Field I signed:0,0,1,1,1,1,1,1,0,0,0,0",
        "Field I predictor:" + ",".join("0" * len(names)),
        "Field I encoding:" + ",".join(map(str, enc)),
        "Firmware revision:Betaflight 4.4.0 (test)",
        "motorOutput:48,2047",
        f"acc_1G:{BB_ACC_1G}",
        "gyro_scale:0x3f800000",
        "motor_pwm_protocol:7",
        f"yaw_motors_reversed:{int(rec.vehicle.allocation[3, BF_ORDER[0]] > 0)}",
    ]
    out = bytearray("".join(f"H {h}\n" for h in head).encode())
    for j, k in enumerate(sel):
        gyro = np.round(np.degrees(rec.omega[k] * flu)).astype(int)  # deg/s, as Betaflight
        acc = np.round(rec.accel[k] * flu / 9.80665 * BB_ACC_1G).astype(int)
        motor = np.round(48 + 1999 * u[j]).astype(int)
        row = [j, int(round((rec.t[k] + 1.0) * 1e6)), *gyro, *acc, *motor]
        out += b"I" + encode_fields([int(v) for v in row], enc)
    path.write_bytes(bytes(out))


# ----------------------------------------------------------------------------------------
# Crazyflie uSD-deck event log (header 0xBC, version, event definitions, records, CRC32)
def usd_log(
    path,
    *,
    version: int = 2,
    crc: bool = True,
    mocap: bool = False,
    gyro: bool = True,
    vbat: float = 3.9,
    duration: float = T_END,
) -> None:
    """The synthetic flight as a Crazyflie uSD event log with several event types at
    different rates: ``fixedFrequency`` (500 Hz: gyro [deg/s], acc [g], motor.m1..m4),
    ``estimate`` (100 Hz: stateEstimate position, velocity, quaternion; with ``mocap`` the
    motion-capture pose ``locSrv`` instead), ``rpm`` (250 Hz, the RPM deck) and ``power``
    (10 Hz, pm.vbat). World z up, body FLU, as the firmware logs. ``crc``: append the CRC32
    that stopping the logging writes."""
    import zlib

    fast = ["gyro.x(f)", "gyro.y(f)", "gyro.z(f)", "acc.x(f)", "acc.y(f)", "acc.z(f)"]
    fast += [f"motor.m{i}(H)" for i in range(1, 5)]
    if not gyro:
        fast = fast[3:]
    est = [f"stateEstimate.{k}(f)" for k in ("x", "y", "z", "vx", "vy", "vz")]
    est += [f"stateEstimate.q{k}(f)" for k in "xyzw"]
    if mocap:
        est = [f"locSrv.{k}(f)" for k in ("x", "y", "z", "qx", "qy", "qz", "qw")]
    events = [
        (1, "fixedFrequency", fast, 500.0),
        (7, "estimate", est, 100.0),
        (9, "rpm", [f"rpm.m{i}(H)" for i in range(1, 5)], 250.0),
        (12, "power", ["pm.vbat(f)"], 10.0),
    ]
    out = bytearray(struct.pack("<BHH", 0xBC, version, len(events)))
    for eid, name, variables, _ in events:
        out += struct.pack("<H", eid) + name.encode() + b"\x00" + struct.pack("<H", len(variables))
        out += b"".join(v.encode() + b"\x00" for v in variables)
    stamp, per_s = ("<Q", 1e6) if version == 2 else ("<I", 1e3)
    records = []
    for eid, name, variables, rate in events:
        fmt = "<" + "".join(v[-2] for v in variables)
        t = np.arange(0.0, duration, 1.0 / rate) + 0.01
        p = flight_profile(t * T_END / duration)
        for k, tk in enumerate(t):
            u = p["u"][k]
            if name == "fixedFrequency":
                vals = [0.0, 0.0, 0.0, 0.0, 0.0, 1.0] + [int(round(65535 * x)) for x in u]
                vals = vals if gyro else vals[3:]
            elif name == "estimate":
                pos = [p["pos"][k, 0], -p["pos"][k, 1], -p["pos"][k, 2]]  # NED -> z up
                vel = [p["vel"][k, 0], -p["vel"][k, 1], -p["vel"][k, 2]]
                vals = pos + [0.0, 0.0, 0.0, 1.0] if mocap else pos + vel + [0.0, 0.0, 0.0, 1.0]
            elif name == "rpm":
                vals = [int(round(x * OMEGA_PER_U * 60 / (2 * np.pi))) for x in u]
            else:
                vals = [vbat - 0.01 * tk]
            stamp_v = int(round(tk * per_s))
            records.append(
                (tk, struct.pack("<H", eid) + struct.pack(stamp, stamp_v) + struct.pack(fmt, *vals))
            )
    for _, blob in sorted(records, key=lambda r: r[0]):
        out += blob
    if crc:
        out += struct.pack("<I", zlib.crc32(bytes(out)))
    path.write_bytes(bytes(out))
