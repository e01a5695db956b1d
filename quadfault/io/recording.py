"""The ``quadfault-recording/1`` format: a CSV file plus a JSON sidecar (docs/formats.md).

On load everything is converted to the internal convention (world NED, body FRD, rotor
thrust commands in newtons); on save the caller chooses NED or ENU. The command in row k is
held from ``t[k]`` until ``t[k+1]``; the state in row k is measured at ``t[k]``.

Errors name the file, the column or key, and the row (1-based data rows, header excluded).
"""

from __future__ import annotations

import csv
import gzip
import io
import json
import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from quadfault.errors import ConfigError, RecordingError
from quadfault.fileio import atomic_write_files, check_writable
from quadfault.model.effects.thrust_curve import curve_thrust
from quadfault.model.frames import enu_flu_to_ned_frd, vehicle_flu_to_frd  # noqa: F401 (re-exported)
from quadfault.model.rotation import FLU_TO_FRD, quat_to_rot
from quadfault.model.sidecar import FORMAT, parse_sidecar, sidecar_path, vehicle_from_sidecar
from quadfault.model.vehicle import Vehicle

POSE_COLUMNS = ("px", "py", "pz", "vx", "vy", "vz", "qw", "qx", "qy", "qz")
RATE_COLUMNS = ("wx", "wy", "wz")
ACC_COLUMNS = ("ax", "ay", "az")
F_COLUMNS = ("f1", "f2", "f3", "f4")
U_COLUMNS = ("u1", "u2", "u3", "u4")
OMEGA_COLUMNS = ("omega1", "omega2", "omega3", "omega4")
ETA_COLUMNS = ("eta1", "eta2", "eta3", "eta4")
QUAT_NORM_TOL = 1e-3
#: Every column the contract defines; other columns are extras, kept and ignored.
KNOWN_COLUMNS = frozenset(
    ("t", "vbat")
    + POSE_COLUMNS
    + RATE_COLUMNS
    + ACC_COLUMNS
    + F_COLUMNS
    + U_COLUMNS
    + OMEGA_COLUMNS
    + ETA_COLUMNS
)


@dataclass(frozen=True, eq=False)
class Recording:
    """A flight, in the internal convention (world NED, body FRD).

    Attributes:
        t: sample times [s], strictly increasing, shape (N,).
        position, velocity: world NED [m], [m/s], (N, 3), or None for an IMU-only log.
        quaternion: body->world (w, x, y, z), (N, 4), or None.
        omega: body rate [rad/s], (N, 3).
        thrust_cmd: commanded rotor thrusts [N], (N, n) (from ``f`` or converted ``u``).
        vehicle: the nominal vehicle in FRD.
        accel: accelerometer specific force, body FRD [m/s^2], or None.
        vbat: battery voltage [V], or None.
        rotor_speed: measured rotor speeds [rad/s], or None.
        eta_true: true efficiency (simulation only; never read by estimators), or None.
        commands_u: the raw ``u`` commands when the file had them, else None.
        thrust_curve: ``(a, b, c)`` with f = a + b u + c u^2 for ``u`` commands, else None.
        frame: the world frame of the original file ("NED" or "ENU").
        source: free text.
        meta: any other sidecar keys (scenario, seed, effect truth, ...).
        extra: unknown CSV columns, kept and ignored.
    """

    t: np.ndarray
    omega: np.ndarray
    thrust_cmd: np.ndarray
    vehicle: Vehicle
    position: np.ndarray | None = None
    velocity: np.ndarray | None = None
    quaternion: np.ndarray | None = None
    accel: np.ndarray | None = None
    vbat: np.ndarray | None = None
    rotor_speed: np.ndarray | None = None
    eta_true: np.ndarray | None = None
    commands_u: np.ndarray | None = None
    thrust_curve: tuple | None = None
    frame: str = "NED"
    source: str = ""
    meta: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)
    path: str | None = None

    def __post_init__(self):
        n = len(self.t)
        for name in (
            "omega",
            "thrust_cmd",
            "position",
            "velocity",
            "quaternion",
            "accel",
            "vbat",
            "rotor_speed",
            "eta_true",
            "commands_u",
        ):
            value = getattr(self, name)
            if value is not None and len(value) != n:
                raise ConfigError(f"recording field {name} has {len(value)} rows, t has {n}")
        if self.position is None and self.accel is None:
            raise ConfigError("a recording needs pose columns or accelerometer columns")

    def __len__(self) -> int:
        return len(self.t)

    @property
    def has_pose(self) -> bool:
        return (
            self.position is not None and self.velocity is not None and self.quaternion is not None
        )

    @cached_property
    def rotation(self) -> np.ndarray:
        """Body->world rotation matrices (N, 3, 3)."""
        if self.quaternion is None:
            raise ConfigError("this recording has no attitude (IMU-only)")
        return quat_to_rot(self.quaternion)

    @property
    def dt(self) -> np.ndarray:
        return np.diff(self.t)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if len(self.t) > 1 else 0.0

    def without_truth(self) -> Recording:
        """A copy with the true efficiency and any effect truth removed (what estimators and
        the diagnosis may see)."""
        meta = {k: v for k, v in self.meta.items() if k not in ("truth", "effects", "scenario")}
        return replace(self, eta_true=None, meta=meta)

    def slice(self, start: int, stop: int) -> Recording:
        """Rows ``start:stop``."""
        sl = slice(start, stop)

        def cut(a):
            return None if a is None else a[sl]

        return replace(
            self,
            t=self.t[sl],
            omega=self.omega[sl],
            thrust_cmd=self.thrust_cmd[sl],
            position=cut(self.position),
            velocity=cut(self.velocity),
            quaternion=cut(self.quaternion),
            accel=cut(self.accel),
            vbat=cut(self.vbat),
            rotor_speed=cut(self.rotor_speed),
            eta_true=cut(self.eta_true),
            commands_u=cut(self.commands_u),
            extra={k: v[sl] for k, v in self.extra.items()},
        )


# ----------------------------------------------------------------------------------------
# reading
def _open_text(path: Path):
    if path.suffix == ".gz":
        return io.TextIOWrapper(gzip.open(path, "rb"), encoding="utf-8-sig", newline="")
    return open(path, encoding="utf-8-sig", newline="")  # a BOM (Excel) is not a column name


#: rows converted to numbers at a time (the reader streams: memory ~ the numeric table)
_CHUNK_ROWS = 5_000


def _rows_to_array(path, header, rows, first_row):
    """``rows`` (lists of cells) as a float array; the error names the first bad cell of a
    contract column. Non-numeric cells of unknown extra columns become NaN (they are kept as
    columns and ignored, docs/formats.md)."""
    try:
        return np.array(rows, dtype=float).reshape(len(rows), len(header))
    except ValueError:
        pass
    out = np.empty((len(rows), len(header)))
    for j, name in enumerate(header):
        known = name in KNOWN_COLUMNS
        for i, r in enumerate(rows):
            try:
                out[i, j] = float(r[j])
            except ValueError:
                if known:
                    raise RecordingError(
                        path, f"not a number: {r[j]!r}", column=name, row=first_row + i
                    ) from None
                out[i, j] = np.nan
    return out


def _read_table(path: Path) -> tuple[list[str], np.ndarray]:
    chunks, rows, blank, n = [], [], [], 0  # blank: trailing empty rows (dropped at the end)
    try:
        with _open_text(path) as fh:
            reader = csv.reader(fh)
            try:
                header = next(reader)
            except StopIteration:
                raise RecordingError(path, "file is empty (no header row)") from None
            header = [h.strip() for h in header]
            seen = set()
            for h in header:
                if not h:
                    raise RecordingError(path, "empty column name in the header")
                if h in seen:
                    raise RecordingError(path, "duplicated column", column=h)
                seen.add(h)
            width = len(header)
            for r in reader:
                if not any(c.strip() for c in r):
                    blank.append(r)
                    continue
                for row in (*blank, r):  # empty rows followed by data are errors
                    n += 1
                    if len(row) != width:
                        raise RecordingError(
                            path, f"has {len(row)} fields, the header has {width}", row=n
                        )
                    rows.append(row)
                blank = []
                if len(rows) >= _CHUNK_ROWS:
                    chunks.append(_rows_to_array(path, header, rows, n - len(rows) + 1))
                    rows = []
    except UnicodeDecodeError:
        raise RecordingError(path, "not UTF-8 text") from None
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        raise RecordingError(path, f"cannot read: {exc}") from None
    except csv.Error as exc:
        raise RecordingError(path, f"malformed CSV: {exc}") from None
    if rows:
        chunks.append(_rows_to_array(path, header, rows, n - len(rows) + 1))
    if not chunks:
        raise RecordingError(path, "no data rows")
    return header, chunks[0] if len(chunks) == 1 else np.concatenate(chunks)


def _check_finite(path, header, data, columns):
    for name in columns:
        col = data[:, header.index(name)]
        bad = np.flatnonzero(~np.isfinite(col))
        if bad.size:
            raise RecordingError(
                path, f"NaN or inf value ({col[bad[0]]})", column=name, row=int(bad[0]) + 1
            )


def read_recording(csv_path) -> Recording:
    """Load and validate a recording; returns it in the internal NED/FRD convention."""
    path = Path(csv_path)
    if not path.exists():
        raise RecordingError(path, "file not found")
    if path.is_dir():
        raise RecordingError(path, "is a directory, expected a CSV file")
    meta = parse_sidecar(sidecar_path(path))
    header, data = _read_table(path)
    cols = {h: i for i, h in enumerate(header)}

    def need(names, why):
        missing = [c for c in names if c not in cols]
        if missing:
            raise RecordingError(path, f"missing ({why})", column=missing[0])

    need(("t",), "time")
    need(RATE_COLUMNS, "body rates")
    has_pose = all(c in cols for c in POSE_COLUMNS)
    has_acc = all(c in cols for c in ACC_COLUMNS)
    if not has_pose:
        if not has_acc:
            need(POSE_COLUMNS, "pose, or accelerometer columns ax, ay, az for an IMU-only log")
        partial = [c for c in POSE_COLUMNS if c in cols]
        if partial:
            need(POSE_COLUMNS, "pose columns must all be present or all absent")
    has_f = all(c in cols for c in F_COLUMNS)
    has_u = all(c in cols for c in U_COLUMNS)
    if not (has_f or has_u):
        need(F_COLUMNS, "rotor commands: f1..f4 [N] or u1..u4")
    required = ["t", *RATE_COLUMNS]
    required += list(POSE_COLUMNS) if has_pose else list(ACC_COLUMNS)
    required += list(F_COLUMNS) if has_f else list(U_COLUMNS)
    _check_finite(path, header, data, required)
    t = data[:, cols["t"]]
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        raise RecordingError(
            path,
            f"time must be strictly increasing (t={t[bad[0] + 1]!r} after t={t[bad[0]]!r})",
            column="t",
            row=int(bad[0]) + 2,
        )
    if len(t) < 2:
        raise RecordingError(path, "needs at least 2 rows")

    def get(names):
        return data[:, [cols[c] for c in names]]

    vehicle, curve = vehicle_from_sidecar(sidecar_path(path), meta, has_u and not has_f)
    if vehicle.n_rotors != 4:
        raise RecordingError(
            sidecar_path(path),
            f"allocation has {vehicle.n_rotors} rotor columns, but the CSV carries 4",
            key="vehicle.allocation",
        )
    position = velocity = quat = None
    if has_pose:
        position, velocity, quat = (
            get(POSE_COLUMNS[:3]),
            get(POSE_COLUMNS[3:6]),
            get(POSE_COLUMNS[6:]),
        )
        norm = np.linalg.norm(quat, axis=1)
        badq = np.flatnonzero(np.abs(norm - 1.0) > QUAT_NORM_TOL)
        if badq.size:
            raise RecordingError(
                path,
                f"quaternion norm {norm[badq[0]]:.6g} is not within {QUAT_NORM_TOL} of 1",
                column="qw",
                row=int(badq[0]) + 1,
            )
        # renormalise, leaving rows already unit to the last bits untouched (exact round trip)
        off = np.abs(norm - 1.0) > 2.0**-50
        quat[off] = quat[off] / norm[off, None]
    omega = get(RATE_COLUMNS)
    accel = get(ACC_COLUMNS) if has_acc else None
    commands_u = None
    if has_f:
        thrust_cmd = get(F_COLUMNS)
    else:
        commands_u = get(U_COLUMNS)
        thrust_cmd = curve_thrust(curve, commands_u)
    if meta["frame"] == "ENU":
        position, velocity, quat, omega, accel = enu_flu_to_ned_frd(
            position, velocity, quat, omega, accel
        )
    # Optional columns may hold NaN where a stream dropped out; consumers handle that.
    optional = {}
    for name, names in (
        ("vbat", ("vbat",)),
        ("rotor_speed", OMEGA_COLUMNS),
        ("eta_true", ETA_COLUMNS),
    ):
        if all(c in cols for c in names):
            arr = get(names)
            optional[name] = arr[:, 0] if name == "vbat" else arr
    known = (
        set(required)
        | set(ACC_COLUMNS)
        | {"vbat"}
        | set(OMEGA_COLUMNS)
        | set(ETA_COLUMNS)
        | set(F_COLUMNS)
        | set(U_COLUMNS)
        | set(POSE_COLUMNS)
    )
    extra = {h: data[:, i] for h, i in cols.items() if h not in known}
    rest = {
        k: v
        for k, v in meta.items()
        if k not in ("format", "frame", "gravity", "vehicle", "source")
    }
    return Recording(
        t=t,
        omega=omega,
        thrust_cmd=thrust_cmd,
        vehicle=vehicle,
        position=position,
        velocity=velocity,
        quaternion=quat,
        accel=accel,
        commands_u=commands_u,
        thrust_curve=curve,
        frame=meta["frame"],
        source=str(meta.get("source", "")),
        meta=rest,
        extra=extra,
        path=str(path),
        **optional,
    )


# ----------------------------------------------------------------------------------------
# writing
def recording_columns(rec: Recording, frame: str = "NED") -> tuple[list[str], np.ndarray]:
    """Header and data matrix of ``rec`` expressed in ``frame``."""
    if frame not in ("NED", "ENU"):
        raise ConfigError(f"frame must be 'NED' or 'ENU', got {frame!r}")
    pos, vel, quat, om, acc = rec.position, rec.velocity, rec.quaternion, rec.omega, rec.accel
    if frame == "ENU":
        pos, vel, quat, om, acc = enu_flu_to_ned_frd(pos, vel, quat, om, acc)
    names: list[str] = ["t"]
    blocks = [rec.t[:, None]]
    if pos is not None and vel is not None and quat is not None:  # rec.has_pose
        names += list(POSE_COLUMNS)
        blocks += [pos, vel, quat]
    names += list(RATE_COLUMNS)
    blocks.append(om)
    if acc is not None:
        names += list(ACC_COLUMNS)
        blocks.append(acc)
    if rec.commands_u is not None:
        names += list(U_COLUMNS)
        blocks.append(rec.commands_u)
    else:
        names += list(F_COLUMNS)
        blocks.append(rec.thrust_cmd)
    if rec.vbat is not None:
        names.append("vbat")
        blocks.append(rec.vbat[:, None])
    if rec.rotor_speed is not None:
        names += list(OMEGA_COLUMNS)
        blocks.append(rec.rotor_speed)
    if rec.eta_true is not None:
        names += list(ETA_COLUMNS)
        blocks.append(rec.eta_true)
    for k, v in rec.extra.items():
        names.append(k)
        blocks.append(np.asarray(v, dtype=float)[:, None])
    return names, np.hstack(blocks)


def recording_sidecar(rec: Recording, frame: str = "NED") -> dict:
    veh = rec.vehicle
    if frame == "ENU":
        B = FLU_TO_FRD
        J = B @ veh.inertia @ B
        A = np.diag([1.0, 1.0, -1.0, -1.0]) @ veh.allocation
    else:
        J, A = veh.inertia, veh.allocation
    vd = {"mass": veh.mass, "inertia": J.tolist(), "allocation": A.tolist()}
    if math.isfinite(veh.rotor_max_thrust):
        vd["max_thrust"] = veh.rotor_max_thrust
    if rec.commands_u is not None:
        if rec.thrust_curve is None:
            raise ConfigError("a recording with u commands needs its thrust_curve (a, b, c)")
        a, b, c = rec.thrust_curve
        if a == 0 and b == 0:
            vd["thrust_coefficient"] = c
        else:
            vd["thrust_curve"] = [a, b, c]
    out = {
        "format": FORMAT,
        "frame": frame,
        "gravity": veh.gravity,
        "vehicle": vd,
        "source": rec.source,
    }
    out.update(rec.meta)
    return out


def _format_table(names, data) -> str:
    buf = io.StringIO()
    buf.write(",".join(names) + "\n")
    # repr() of a Python float is the shortest string that round-trips exactly.
    for row in data.tolist():
        buf.write(",".join(map(repr, row)))
        buf.write("\n")
    return buf.getvalue()


def write_recording(rec: Recording, csv_path, *, frame: str = "NED", force: bool = False) -> Path:
    """Write ``rec`` as CSV + JSON sidecar, atomically; refuse to overwrite unless ``force``."""
    path = Path(csv_path)
    if path.suffix != ".csv":
        raise ConfigError(f"{path}: a recording must be written to a .csv path")
    side = sidecar_path(path)
    check_writable([path, side], force=force)
    names, data = recording_columns(rec, frame)
    atomic_write_files(
        {
            side: json.dumps(recording_sidecar(rec, frame), indent=2) + "\n",
            path: _format_table(names, data),
        },
        force=True,
    )
    return path
