"""ArduPilot DataFlash importer: binary ``.bin`` and text ``.log`` (needs ``pymavlink``:
``pip install 'quadfault[ardupilot]'``).

pymavlink's ``DFReader`` opens the log, reads its self-description (``FMT`` messages) and its
parameters, and indexes the messages; the columns this importer needs are then decoded in
bulk with numpy from that index (binary logs) or collected message by message (text logs).
ArduPilot logs NED world and FRD body frames, like quadfault.

- ``IMU`` (instance 0): ``GyrX..Z`` [rad/s], ``AccX..Z`` [m/s^2] -> body rates, specific force;
  the time base
- ``ATT``: ``Roll, Pitch, Yaw`` [deg] -> attitude (Z-Y-X Euler)
- ``XKF1`` / ``NKF1`` (core 0): ``PN, PE, PD`` [m], ``VN, VE, VD`` [m/s] -> position, velocity
- ``XKF4`` / ``NKF4`` (core 0): ``SS`` (filter status bits) -> validity: velocity needs bits 1,
  2; position bit 3 or 4 and bit 5; bit 7 (constant position mode) invalidates both
- ``RCOU`` (``C1..``, or ``Chan1..``) / ``MOT``: PWM [us] -> motor commands, channels from
  ``SERVOn_FUNCTION`` = Motor 1..4
- ``ESC``: ``Instance``, ``RPM`` -> measured rotor speed [rad/s]
- ``BAT`` / ``CURR``: ``Volt``, ``Curr`` -> ``vbat``, ``current``
- ``EV``: ``Id`` 28 (not landed), 18 (land complete), 17 (land complete maybe), 10/11
  (armed/disarmed) -> flight span

Parameters: ``MOT_PWM_MIN/MAX`` (else ``RC3_MIN/MAX``, else 1000-2000 us) normalise the PWM
to the actuator command u; ``MOT_SPIN_MIN/MAX`` and ``MOT_THST_EXPO`` give ArduPilot's thrust
model: with a = (u - spin_min) / (spin_max - spin_min), thrust ~ (1 - expo) a + expo a^2
(ArduPilot's defaults 0.15, 0.95, 0.65 when a log lacks them); ``FRAME_CLASS``/``FRAME_TYPE``
(or ``FRAME`` in old logs) the motor order and spin directions. ArduPilot has no arm-length
parameter: the positions are unit offsets, flagged as a placeholder unless ``--arm`` is given.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np

from quadfault.errors import ConfigError, QuadfaultError, RecordingError
from quadfault.importers import DATAFLASH_MAGIC
from quadfault.importers.field_log import FieldLog, Geometry, build_recording
from quadfault.recording import Recording
from quadfault.rotation import euler_zyx_to_rot, rot_to_quat

RPM_TO_RAD_S = 2.0 * np.pi / 60.0
MOTOR1_FUNCTION = 33  # SERVOn_FUNCTION of Motor 1 (Motor i is 32 + i)
DEFAULTS = {"MOT_SPIN_MIN": 0.15, "MOT_SPIN_MAX": 0.95, "MOT_THST_EXPO": 0.65}
EV_ARMED, EV_DISARMED, EV_LAND_MAYBE, EV_LANDED, EV_NOT_LANDED = 10, 11, 17, 18, 28
#: quad frames by FRAME_TYPE: per motor (x, y, reaction-torque sign about +z FRD) in unit
#: offsets, ArduPilot's motor numbering (AP_MotorsMatrix); a CCW rotor reacts with +z.
_X = ((1, 1, 1), (-1, -1, 1), (1, -1, -1), (-1, 1, -1))
_R2 = 2 ** 0.5
QUAD_FRAMES = {
    0: ("plus", ((0, _R2, 1), (0, -_R2, 1), (_R2, 0, -1), (-_R2, 0, -1))),
    1: ("X", _X),
    3: ("H", tuple((x, y, -s) for x, y, s in _X)),
    12: ("Betaflight X", ((-1, 1, -1), (1, 1, 1), (-1, -1, 1), (1, -1, -1))),
    13: ("DJI X", ((1, 1, 1), (1, -1, -1), (-1, -1, 1), (-1, 1, -1))),
    14: ("clockwise X", ((1, 1, 1), (-1, 1, -1), (-1, -1, 1), (1, -1, -1))),
    18: ("Betaflight X reversed", ((-1, 1, 1), (1, 1, -1), (-1, -1, -1), (1, -1, 1))),
}
_NUMPY = {"b": "i1", "B": "u1", "h": "<i2", "H": "<u2", "i": "<i4", "I": "<u4", "f": "<f4",
          "d": "<f8", "q": "<i8", "Q": "<u8", "e": "<f2"}


def _open(path: Path):
    try:
        from pymavlink import DFReader
    except ImportError:
        raise QuadfaultError("the ArduPilot importer needs pymavlink: pip install "
                             "'quadfault[ardupilot]'") from None
    if not path.exists():
        raise RecordingError(path, "file not found")
    with open(path, "rb") as fh:
        head = fh.read(8000)
    binary = head.startswith(DATAFLASH_MAGIC)
    if not binary and b"FMT," not in head:
        raise RecordingError(path, "not an ArduPilot DataFlash log (no DataFlash header and no "
                                   "FMT lines)")
    class Binary(DFReader.DFReader_binary):
        def init_clock(self):  # time comes from TimeUS: no pass over the whole log
            self.clock = DFReader.DFReaderClock_usec()

    chatter = io.StringIO()
    try:
        with contextlib.redirect_stderr(chatter), contextlib.redirect_stdout(chatter):
            reader = Binary(str(path)) if binary else DFReader.DFReader_text(str(path))
    except Exception as exc:  # DFReader raises bare Exceptions on corrupt logs
        raise RecordingError(path, f"not a readable DataFlash log: {exc}") from None
    return reader, binary


def _binary_table(reader, name: str) -> dict | None:
    """``{column: array}`` of every ``name`` message, decoded from DFReader's index."""
    tid = reader.name_to_id.get(name)
    if tid is None or not reader.offsets[tid]:
        return None
    fmt = reader.formats[tid]
    from pymavlink.DFReader import FORMAT_TO_STRUCT

    names, types, mults = [], [], []
    for col, ch, mult in zip(fmt.columns, fmt.msg_fmts, fmt.msg_mults):
        code = FORMAT_TO_STRUCT[ch][0]
        names.append(col)
        types.append("S" + code[:-1] if code.endswith("s") else _NUMPY[code])
        mults.append(mult)
    dtype = np.dtype({"names": names, "formats": types})
    if dtype.itemsize != fmt.len - 3:
        return None
    buf = np.frombuffer(reader.data_map, dtype=np.uint8)
    ofs = np.asarray(reader.offsets[tid], dtype=np.int64)
    ofs = ofs[ofs + fmt.len <= len(buf)]  # a truncated last message is dropped
    rows = buf[ofs[:, None] + 3 + np.arange(fmt.len - 3)].copy().view(dtype)[:, 0]
    out = {}
    for col, mult in zip(names, mults):
        if rows[col].dtype.kind == "S":
            out[col] = np.char.decode(rows[col], "latin-1")
        else:
            out[col] = rows[col].astype(float) * (mult if mult else 1.0)
    return out


def _text_tables(reader, names) -> dict:
    """``{name: {column: array}}`` of a text log, message by message."""
    rows = {n: [] for n in names}
    cols = {}
    while True:
        try:
            m = reader.recv_match(type=list(names))
        except Exception:  # a malformed line ends what can be read
            break
        if m is None:
            break
        kind = m.get_type()
        if kind not in cols:
            cols[kind] = [c for c in m.get_fieldnames() if c not in ("Name", "Message")]
        vals = []
        for c in cols[kind]:
            v = getattr(m, c, np.nan)
            vals.append(float(v) if isinstance(v, (int, float)) else np.nan)
        rows[kind].append(vals + [m._timestamp])
    out = {}
    for n, r in rows.items():
        if r:
            arr = np.asarray(r, dtype=float)
            out[n] = {c: arr[:, i] for i, c in enumerate(cols[n] + ["_timestamp"])}
    return out


def _time(table: dict, path, name) -> np.ndarray:
    if "TimeUS" in table:
        return table["TimeUS"] * 1e-6
    if "TimeMS" in table:
        return table["TimeMS"] * 1e-3
    if "_timestamp" in table:
        return table["_timestamp"]
    raise RecordingError(path, f"message {name} has no time stamp", key=name)


def _instance(table: dict, key: str) -> dict:
    """Rows of instance (or core) 0 when the message has an instance column."""
    if key in table:
        sel = table[key] == np.min(table[key])
        return {k: v[sel] for k, v in table.items()}
    return table


def geometry(params: dict, path="log") -> Geometry:
    """Motor order and spin directions from ``FRAME_CLASS``/``FRAME_TYPE`` (``FRAME``)."""
    frame_class = params.get("FRAME_CLASS")
    if frame_class is not None and int(frame_class) != 1:
        raise RecordingError(path, f"FRAME_CLASS is {int(frame_class)}: quadfault imports "
                                   "quadrotors (FRAME_CLASS 1)", key="FRAME_CLASS")
    key = "FRAME_TYPE" if "FRAME_TYPE" in params else "FRAME"
    ftype = int(params.get(key, 1))
    name, rotors = QUAD_FRAMES.get(ftype, QUAD_FRAMES[1])
    note = f"{key} {ftype} ({name})" if ftype in QUAD_FRAMES else \
        f"{key} {ftype} not modelled: quad X assumed"
    return Geometry(tuple((float(x), float(y)) for x, y, _ in rotors),
                    tuple(float(s) for _, _, s in rotors), None,
                    note + "; ArduPilot logs no arm length", placeholder=True)


def thrust_model(params: dict) -> tuple:
    """``((a, b, c), note)``: ArduPilot's thrust model as a quadratic in u (module doc)."""
    got = {k: float(params.get(k, v)) for k, v in DEFAULTS.items()}
    s0, s1, e = got["MOT_SPIN_MIN"], got["MOT_SPIN_MAX"], got["MOT_THST_EXPO"]
    if not s1 > s0:
        raise ConfigError(f"MOT_SPIN_MAX ({s1}) must exceed MOT_SPIN_MIN ({s0})")
    d = s1 - s0
    curve = (-(1 - e) * s0 / d + e * s0 ** 2 / d ** 2, (1 - e) / d - 2 * e * s0 / d ** 2,
             e / d ** 2)
    assumed = [k for k in DEFAULTS if k not in params]
    note = (f"ArduPilot thrust model (1 - MOT_THST_EXPO) a + MOT_THST_EXPO a^2, a = (u - "
            f"MOT_SPIN_MIN) / (MOT_SPIN_MAX - MOT_SPIN_MIN); MOT_THST_EXPO = {e:g}, "
            f"MOT_SPIN_MIN = {s0:g}, MOT_SPIN_MAX = {s1:g}")
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


MESSAGES = ("IMU", "ATT", "XKF1", "NKF1", "XKF4", "NKF4", "RCOU", "MOT", "ESC", "BAT", "CURR",
            "EV")


def read_ardupilot(path) -> FieldLog:
    """The streams of an ArduPilot DataFlash log (module docstring)."""
    path = Path(path)
    reader, binary = _open(path)
    if binary:
        tables = {n: t for n in MESSAGES if (t := _binary_table(reader, n)) is not None}
        parm = _binary_table(reader, "PARM") or {"Name": [], "Value": []}
        params = {}
        for k, v in zip(parm["Name"], parm["Value"]):
            params.setdefault(str(k), float(v))  # the values at the start of the log
    else:
        tables = _text_tables(reader, MESSAGES)
        params = {k: float(v) for k, v in reader.params.items() if isinstance(v, (int, float))}
    for name, table in tables.items():
        table["_t"] = _time(table, path, name)
    streams, missing, invalid = {}, [], {}
    imu = tables.get("IMU")
    if imu is None or "GyrX" not in imu:
        raise RecordingError(path, "no IMU message (body rates and accelerometer)", key="IMU")
    imu = _instance(imu, "I")
    streams["w"] = (imu["_t"], np.stack([imu[f"Gyr{a}"] for a in "XYZ"], axis=1), "linear")
    streams["acc"] = (imu["_t"], np.stack([imu[f"Acc{a}"] for a in "XYZ"], axis=1), "linear")
    ekf = next((_instance(tables[n], "C") for n in ("XKF1", "NKF1") if n in tables
                and "PN" in tables[n]), None)
    att = tables.get("ATT")
    if ekf is not None and att is not None:
        R = euler_zyx_to_rot(*(np.radians(att[k]) for k in ("Roll", "Pitch", "Yaw")))
        streams["q"] = (att["_t"], rot_to_quat(R), "quaternion")
        streams["pos"] = (ekf["_t"], np.stack([ekf[k] for k in ("PN", "PE", "PD")], 1), "linear")
        streams["vel"] = (ekf["_t"], np.stack([ekf[k] for k in ("VN", "VE", "VD")], 1), "linear")
        status = next((_instance(tables[n], "C") for n in ("XKF4", "NKF4") if n in tables
                       and "SS" in tables[n]), None)
        if status is not None:
            invalid = _validity(status)
    else:
        missing.append("position and velocity (XKF1/NKF1)" if ekf is None else "attitude (ATT)")
    lo, hi, how = _pwm_range(params)
    out = tables.get("RCOU")
    if out is not None:
        prefix = "C" if "C1" in out else "Chan"
        chans = [next((k for k in range(1, 33) if params.get(f"SERVO{k}_FUNCTION")
                       == MOTOR1_FUNCTION + i), i + 1) for i in range(4)]
        if not all(f"{prefix}{k}" in out for k in chans):
            raise RecordingError(path, f"RCOU lacks the motor channels {chans}", key="RCOU")
        pwm = np.stack([out[f"{prefix}{k}"] for k in chans], axis=1)
        note = f"u = (RCOU {prefix}{chans} - {lo:g}) / ({hi:g} - {lo:g}) us ({how})"
    elif "MOT" in tables and "Mot1" in tables["MOT"]:
        out = tables["MOT"]
        chans = [1, 2, 3, 4]
        pwm = np.stack([out[f"Mot{k}"] for k in chans], axis=1)
        note = f"u = (MOT Mot1..4 - {lo:g}) / ({hi:g} - {lo:g}) us ({how})"
    else:
        raise RecordingError(path, "no motor outputs (RCOU or MOT messages)", key="RCOU")
    streams["u"] = (out["_t"], np.clip((pwm - lo) / (hi - lo), 0.0, 1.0), "hold")
    esc = tables.get("ESC")
    if esc is not None and "RPM" in esc and "Instance" in esc:
        cols = []
        for i, k in enumerate(chans):
            inst = k - 1 if np.any(esc["Instance"] == k - 1) else i
            sel = esc["Instance"] == inst
            cols.append((esc["_t"][sel], np.abs(esc["RPM"][sel]) * RPM_TO_RAD_S))
        if all(len(c[0]) > 1 for c in cols):
            t_esc = np.unique(np.concatenate([c[0] for c in cols]))
            w = np.stack([np.interp(t_esc, tc, wc) for tc, wc in cols], axis=1)
            streams["rotor"] = (t_esc, w, "linear")
    if "rotor" not in streams:
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
    recorded = {k: v for k, v in params.items()
                if k in DEFAULTS or k.startswith(("FRAME", "MOT_PWM", "MOT_BAT", "RC3_M"))}
    return FieldLog(path=path, importer="ardupilot", streams=streams, time_base=imu["_t"],
                    thrust_model=curve, thrust_note=curve_note, geometry=geometry(params, path),
                    landed=_landed(tables), landed_source="EV (NOT_LANDED, LAND_COMPLETE)",
                    invalid=invalid, commands=note, missing=missing, params=recorded,
                    source=f"ArduPilot DataFlash log {path.name}, imported by quadfault")


def import_ardupilot(path, *, vehicle=None, thrust_curve=None, keep_all: bool = False,
                     calibration=None, mass=None, inertia=None, arm=None,
                     torque_coefficient=None, **_ignored) -> Recording:
    """Import an ArduPilot DataFlash ``.bin`` or text ``.log``; arguments as
    :func:`quadfault.importers.px4_ulog.import_px4_ulog`."""
    log = read_ardupilot(path)
    return build_recording(log, vehicle=vehicle, thrust_curve=thrust_curve, mass=mass,
                           inertia=inertia, arm=arm, torque_coefficient=torque_coefficient,
                           keep_all=keep_all, calibration=calibration)
