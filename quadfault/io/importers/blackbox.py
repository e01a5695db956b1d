"""Betaflight / INDIflight blackbox importer: ``.bfl``/``.bbl`` files (decoded by
:mod:`quadfault.io.importers.blackbox_format`) and the CSV that ``blackbox_decode`` or Blackbox
Explorer exports.

- ``time``: us -> time [s]
- ``gyroADC[0..2]``: deg/s x ``gyro_scale`` (INDIflight: 0.1 deg/s) -> body rates; the
  Betaflight body axes are x forward, y left, z up, so FRD = (x, -y, -z)
- ``accSmooth[0..2]`` (else ``accUnfiltered``): ``acc_1G`` per g -> specific force FRD [m/s^2]
- ``motor[0..3]``: ``motorOutput`` low..high -> ``u1..u4`` = (motor - low) / (high - low)
- ``eRPM[0..3]``: 100 eRPM -> ``omega1..4`` = eRPM x 100 / (``motor_poles`` / 2) x 2 pi / 60
  [rad/s]
- ``omegaUnfiltered[0..3]`` (else ``omega[0..3]``, INDIflight): rad/s -> ``omega1..4``
- ``quat[0..3]``, ``pos[0..2]``, ``vel[0..2]`` (INDIflight): scaled unit quaternion FRD -> NED,
  mm, cm/s -> attitude, position, velocity (NED)
- ``vbatLatest``, ``amperageLatest``: 0.01 V, 0.01 A (Betaflight 4+, INDIflight; older firmware
  logs ADC counts: left out) -> ``vbat``, ``current``

Motor order and spin directions are Betaflight's quad X mixer (0 rear-right, 1 front-right,
2 rear-left, 3 front-left; 0 and 3 clockwise, reversed with ``yaw_motors_reversed``); no arm
length is logged. Thrust model: with measured rotor speeds, omega^2 fitted as a quadratic in
u over the running rows; else thrust ~ x^2 with x the throttle fraction of the protocol's full
range (DShot 48..2047, PWM 1000..2000).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from quadfault.errors import RecordingError
from quadfault.io.importers.blackbox_format import PRODUCT, decode_log, split_logs
from quadfault.io.importers.field_log import RUNNING, FieldLog, Geometry, build_recording
from quadfault.io.recording import Recording

G0 = 9.80665
FLU_TO_FRD = np.array([1.0, -1.0, -1.0])
#: Betaflight quad X: (x, y) FRD in unit offsets and reaction-torque sign (CW rotor: -1)
BF_QUAD_X = (((-1.0, 1.0), -1.0), ((1.0, 1.0), 1.0), ((-1.0, -1.0), 1.0), ((1.0, -1.0), -1.0))
DSHOT_RANGE, PWM_RANGE = (48.0, 2047.0), (1000.0, 2000.0)
DEFAULT_ACC_1G = 2048.0
DEFAULT_POLES = 14


def _number_list(text) -> list:
    try:
        return [float(x) for x in str(text).split(",") if x.strip()]
    except ValueError:
        return []


def _scale_hex(text, default=1.0) -> float:
    """``gyro_scale`` is a float's bits in hex (0x3f800000 = 1.0)."""
    try:
        return float(np.frombuffer(int(str(text), 16).to_bytes(4, "little"), "<f4")[0])
    except (ValueError, OverflowError):
        return default


def _centivolt_firmware(revision: str) -> bool:
    """Betaflight 4 and later (and INDIflight) log ``vbatLatest`` in 0.01 V; older
    firmware logs ADC counts."""
    text = revision.lower()
    if text.startswith("indiflight"):
        return True
    parts = text.split()
    if len(parts) >= 2 and parts[0] == "betaflight":
        try:
            return int(parts[1].split(".")[0]) >= 4
        except ValueError:
            return False
    return False


class _Fields:
    """Named columns with their units: a decoded log or a CSV export."""

    def __init__(self, columns: dict, units: dict, header: dict, source: str, skipped=None):
        self.columns, self.units, self.header, self.source = columns, units, header, source
        self.skipped = skipped  # what the decoder skipped of a cut or corrupt log, or None
        self.others = None  # a note on the file's other logs (one of them cut), or None

    def get(self, *names):
        for name in names:
            if name in self.columns:
                return np.asarray(self.columns[name], dtype=float)
        return None

    def stack(self, base: str, n: int):
        cols = [self.get(f"{base}[{i}]") for i in range(n)]
        return None if any(c is None for c in cols) else np.stack(cols, axis=1)


# ----------------------------------------------------------------------------------------
def _from_binary(path: Path, data: bytes, log_index: int | None) -> tuple:
    spans = split_logs(data)
    if not spans:
        raise RecordingError(path, "not a blackbox log (no 'H Product:Blackbox' header)")
    logs = []
    for a, b in spans:
        try:
            logs.append(decode_log(data, a, b))
        except ValueError as exc:
            logs.append(exc)
    good = [
        (i, lg) for i, lg in enumerate(logs) if not isinstance(lg, Exception) and len(lg.main) > 1
    ]
    if log_index is not None:
        if not 1 <= log_index <= len(logs):
            raise RecordingError(path, f"--log {log_index}: the file holds {len(logs)} log(s)")
        chosen = logs[log_index - 1]
        if isinstance(chosen, Exception) or len(chosen.main) < 2:
            raise RecordingError(path, f"log {log_index} has no readable frames")
        index = log_index
    else:
        if not good:
            raise RecordingError(path, "no log in the file has readable frames")

        def length(item):
            t = item[1].field("time")
            return float(t[-1] - t[0]) if t is not None else len(item[1].main)

        index, chosen = max(good, key=length)
        index += 1
    cols = {n: chosen.main[:, k] for k, n in enumerate(chosen.main_names)}
    note = f"log {index} of {len(logs)}" + (
        f", {chosen.corrupt} corrupt frames dropped" if chosen.corrupt else ""
    )
    skipped = None
    lost = chosen.skipped_bytes + (0 if chosen.ended else chosen.tail_bytes)
    if lost or chosen.corrupt:
        t = chosen.field("time")
        what = []
        if chosen.corrupt:
            what.append(f"{chosen.corrupt} corrupt frames")
        if not chosen.ended:
            what.append("the log ends without its end-of-log event (cut)")
        skipped = {
            "what": " and ".join(what),
            "bytes": int(lost),
            "truncated": not chosen.ended,
            "corrupt": int(chosen.corrupt),
            "after_t": None if chosen.ended or t is None else float(t[-1] * 1e-6),
        }
    fields = _Fields(cols, {}, chosen.header, note, skipped)
    cut = [
        k + 1
        for k, lg in enumerate(logs)
        if k + 1 != index and not isinstance(lg, Exception) and not lg.ended
    ]
    if cut:
        fields.others = (
            f"log{'s' if len(cut) > 1 else ''} {', '.join(map(str, cut))} of {len(logs)} in the "
            f"file {'are' if len(cut) > 1 else 'is'} cut short (no end-of-log event); imported "
            f"log {index} (--log N picks another)"
        )
    return fields, len(logs)


def _from_csv(path: Path, text: str) -> _Fields:
    """A ``blackbox_decode`` / Blackbox Explorer CSV: optional ``"name","value"`` header
    rows, then the column header (its first column ``loopIteration``), then the frames."""
    rows = csv.reader(text.splitlines())
    header, names = {}, None
    for row in rows:
        cells = [c.strip() for c in row]
        if cells and cells[0] == "loopIteration":
            names = cells
            break
        if len(cells) >= 2 and cells[0]:
            header[cells[0]] = ",".join(cells[1:]).strip()
    if names is None:
        raise RecordingError(path, "no column header starting with 'loopIteration'")
    data = []
    for k, row in enumerate(rows):
        if not any(c.strip() for c in row):
            continue
        try:
            data.append([float(c) if c.strip() else np.nan for c in row[: len(names)]])
        except ValueError:
            raise RecordingError(path, "not a number", row=k + 1) from None
        if len(data[-1]) != len(names):
            raise RecordingError(
                path, f"has {len(data[-1])} fields, the header has {len(names)}", row=k + 1
            )
    if len(data) < 2:
        raise RecordingError(path, "fewer than 2 data rows")
    arr = np.asarray(data, dtype=float)
    cols, units = {}, {}
    for j, name in enumerate(names):
        base, _, unit = name.partition(" (")
        cols[base.strip()] = arr[:, j]
        if unit:
            units[base.strip()] = unit.rstrip(")").strip()
    return _Fields(cols, units, header, "decoded CSV")


# ----------------------------------------------------------------------------------------
def _geometry(header: dict) -> Geometry:
    reverse = str(header.get("yaw_motors_reversed", "0")).strip() not in ("0", "", "OFF")
    xy = tuple(p for p, _ in BF_QUAD_X)
    yaw = tuple(-s if reverse else s for _, s in BF_QUAD_X)
    return Geometry(
        xy,
        yaw,
        None,
        "Betaflight quad X mixer (motor 0 rear-right, 1 "
        "front-right, 2 rear-left, 3 front-left"
        + (", yaw reversed)" if reverse else ")")
        + "; blackbox logs no arm length",
        placeholder=True,
    )


def _motors(path, f: _Fields, notes: list) -> tuple:
    motors = f.stack("motor", 4)
    if motors is None:
        raise RecordingError(path, "no motor outputs (motor[0..3])", column="motor[0]")
    rng = _number_list(f.header.get("motorOutput", ""))
    proto = _number_list(f.header.get("motor_pwm_protocol", ""))
    protocol = int(proto[0]) if proto else -1
    if len(rng) >= 2 and rng[1] > rng[0]:
        lo, hi = rng[0], rng[1]
        how = f"motorOutput {lo:g}-{hi:g}"
    else:
        lo, hi = (
            DSHOT_RANGE
            if np.nanmax(motors) > PWM_RANGE[1] or np.nanmin(motors) < 900
            else PWM_RANGE
        )
        how = f"{lo:g}-{hi:g} (assumed: no motorOutput in the log)"
        notes.append(f"motor range assumed {lo:g}-{hi:g} (no motorOutput header)")
    dshot = protocol >= 5 or hi > PWM_RANGE[1] or (protocol < 0 and hi <= 2047 and lo < 900)
    full = DSHOT_RANGE if dshot else PWM_RANGE
    u = np.clip((motors - lo) / (hi - lo), 0.0, 1.0)
    # throttle fraction of the protocol's full range: x = x0 + k u
    x0, k = (lo - full[0]) / (full[1] - full[0]), (hi - lo) / (full[1] - full[0])
    return (
        u,
        (x0 * x0, 2 * x0 * k, k * k),
        f"u = (motor[0..3] - {lo:g}) / ({hi:g} - {lo:g}) ({how})",
        ("DShot" if dshot else "PWM"),
    )


def _rotor_curve(u: np.ndarray, w: np.ndarray) -> tuple | None:
    """Relative thrust ~ omega^2 as a quadratic in u (running rows, rotors pooled)."""
    run = (u > RUNNING) & np.isfinite(w) & (w > 0)
    if run.sum() < 50:
        return None
    X = np.stack((np.ones(run.sum()), u[run], u[run] ** 2), axis=1)
    coef, *_ = np.linalg.lstsq(X, w[run] ** 2, rcond=None)
    top = coef.sum()
    return tuple(float(c / top) for c in coef) if top > 0 else None


def read_blackbox(path, log: int | None = None) -> FieldLog:
    """The streams of a blackbox log (module docstring); ``log`` is 1-based."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(path, "file not found")
    data = path.read_bytes()
    head = data[: 1 << 16]
    if PRODUCT in head:
        f, n_logs = _from_binary(path, data, log)
    else:
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            raise RecordingError(
                path, "not a blackbox log (no 'H Product:Blackbox' header) nor its decoded CSV"
            ) from None
        f, _n_logs = _from_csv(path, text), 1
        if log not in (None, 1):
            raise RecordingError(path, f"--log {log}: a decoded CSV holds one log")
    notes, missing = ([f.others] if f.others else []), []
    h = f.header
    firmware = str(h.get("Firmware revision", ""))
    t_raw = f.get("time")
    if t_raw is None:
        raise RecordingError(path, "no time column", column="time")
    t = t_raw * (1e-3 if f.units.get("time") == "ms" else 1e-6)
    streams = {}
    gyro = f.stack("gyroADC", 3)
    if gyro is None:
        raise RecordingError(path, "no gyro (gyroADC[0..2])", column="gyroADC[0]")
    gunit = f.units.get("gyroADC[0]", "")
    if gunit == "rad/s":
        w = gyro
    else:
        per = 0.1 if firmware.lower().startswith("indiflight") and not gunit else 1.0
        w = np.radians(gyro * per * (_scale_hex(h.get("gyro_scale", "")) if not gunit else 1.0))
    streams["w"] = (t, w * FLU_TO_FRD, "linear")
    acc = f.stack("accSmooth", 3)
    if acc is None:
        acc = f.stack("accUnfiltered", 3)
    if acc is not None:
        aunit = f.units.get("accSmooth[0]", f.units.get("accUnfiltered[0]", ""))
        if aunit in ("m/s/s", "m/s^2", "m/s2"):
            sf = acc
        elif aunit == "g":
            sf = acc * G0
        else:
            one_g = _number_list(h.get("acc_1G", ""))
            if not one_g:
                notes.append(f"acc_1G assumed {DEFAULT_ACC_1G:g} (not in the log)")
            sf = acc / (one_g[0] if one_g else DEFAULT_ACC_1G) * G0
        streams["acc"] = (t, sf * FLU_TO_FRD, "linear")
    else:
        missing.append("accelerometer (accSmooth)")
    u, dshot_curve, cmd_note, protocol = _motors(path, f, notes)
    streams["u"] = (t, u, "hold")
    # INDIflight [rad/s]: the telemetry as received; "omega" is the firmware's filtered copy,
    # which lags the rotor by its filter
    omega, rotor_note = f.stack("omegaUnfiltered", 4), "omegaUnfiltered[0..3] [rad/s]"
    if omega is None:
        omega, rotor_note = f.stack("omega", 4), "omega[0..3] [rad/s]"
    if omega is None:
        erpm = f.stack("eRPM", 4)
        if erpm is not None:
            poles = _number_list(h.get("motor_poles", ""))
            if not poles:
                notes.append(f"motor_poles assumed {DEFAULT_POLES} (not in the log)")
            pairs = (poles[0] if poles else DEFAULT_POLES) / 2.0
            omega = erpm * 100.0 / pairs * 2.0 * np.pi / 60.0
            rotor_note = f"eRPM[0..3] x 100 / {pairs:g} pole pairs"
    curve, curve_note = dshot_curve, f"thrust ~ (throttle fraction of {protocol}'s full range)^2"
    if omega is not None:
        streams["rotor"] = (t, np.where(omega > 0, omega, np.nan), "linear")
        fitted = _rotor_curve(u, omega)
        if fitted is not None:
            curve, curve_note = (
                fitted,
                f"thrust ~ omega^2, omega^2 fitted as a quadratic in u ({rotor_note})",
            )
    else:
        missing.append("rotor speed (eRPM)")
    quat, pos, vel = f.stack("quat", 4), f.stack("pos", 3), f.stack("vel", 3)
    if quat is not None and pos is not None and vel is not None:
        norm = np.linalg.norm(quat, axis=1, keepdims=True)
        ok = norm[:, 0] > 0
        streams["q"] = (t[ok], quat[ok] / norm[ok], "quaternion")
        streams["pos"] = (t, pos * 1e-3, "linear")
        streams["vel"] = (t, vel * 1e-2, "linear")
    else:
        missing.append("position, velocity and attitude")
    vbat = f.get("vbatLatest")
    centivolts = _centivolt_firmware(firmware)
    if vbat is not None and (f.units.get("vbatLatest") == "V" or centivolts):
        v = vbat if f.units.get("vbatLatest") == "V" else vbat * 0.01
        if 2.0 < np.nanmedian(v) < 70.0:
            streams["vbat"] = (t, np.where(v > 0, v, np.nan), "linear")
    if "vbat" not in streams:
        missing.append(
            "battery voltage (vbatLatest)"
            if vbat is None or centivolts
            else f"battery voltage (vbatLatest of {firmware or 'this firmware'} is in ADC units)"
        )
    amps = f.get("amperageLatest")
    if amps is not None and "vbat" in streams:
        streams["current"] = (
            t,
            amps if f.units.get("amperageLatest") == "A" else amps * 0.01,
            "linear",
        )
    recorded = {
        k: h[k]
        for k in (
            "Firmware revision",
            "motorOutput",
            "motor_poles",
            "acc_1G",
            "gyro_scale",
            "motor_pwm_protocol",
            "looptime",
            "pid_process_denom",
            "yaw_motors_reversed",
        )
        if k in h
    }
    return FieldLog(
        path=path,
        importer="blackbox",
        streams=streams,
        time_base=t,
        thrust_model=curve,
        thrust_note=curve_note,
        geometry=_geometry(h),
        commands=f"{cmd_note}; {f.source}",
        missing=missing,
        params=recorded,
        warnings=notes,
        source=f"blackbox log {path.name} ({f.source}), imported by quadfault",
        skipped=f.skipped,
    )


def import_blackbox(
    path,
    *,
    log: int | None = None,
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
    """Import a Betaflight / INDIflight blackbox log or its decoded CSV; ``log`` picks one of
    several logs in a file (1-based, default the longest); other arguments as
    :func:`quadfault.io.importers.px4_ulog.import_px4_ulog`."""
    fl = read_blackbox(path, log)
    return build_recording(
        fl,
        vehicle=vehicle,
        thrust_curve=thrust_curve,
        mass=mass,
        inertia=inertia,
        arm=arm,
        torque_coefficient=torque_coefficient,
        keep_all=keep_all,
        calibration=calibration,
    )
