"""The JSON sidecar of a ``quadfault-recording/1`` file: where it is, and its vehicle.

Errors name the file and the key (:class:`~quadfault.errors.RecordingError`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from quadfault.errors import ConfigError, RecordingError
from quadfault.model.frames import vehicle_flu_to_frd
from quadfault.model.vehicle import Vehicle, paper_allocation

FORMAT = "quadfault-recording/1"


def sidecar_path(csv_path) -> Path:
    p = Path(csv_path)
    name = p.name
    for suf in (".csv.gz", ".csv"):
        if name.endswith(suf):
            return p.with_name(name[: -len(suf)] + ".json")
    return p.with_suffix(".json")


def _number(path, key, value, *, positive=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RecordingError(path, f"must be a number, got {value!r}", key=key)
    if not math.isfinite(value):
        raise RecordingError(path, f"must be finite, got {value!r}", key=key)
    if positive and value <= 0:
        raise RecordingError(path, f"must be positive, got {value!r}", key=key)
    return float(value)


def _matrix(path, key, value, shape_ok):
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise RecordingError(path, "must be a list of numbers", key=key) from None
    if not shape_ok(arr.shape):
        raise RecordingError(path, f"has the wrong shape {arr.shape}", key=key)
    if not np.all(np.isfinite(arr)):
        raise RecordingError(path, "contains NaN or inf", key=key)
    return arr


def parse_sidecar(path: Path) -> dict:
    if not path.exists():
        raise RecordingError(
            path, "sidecar JSON not found (every recording needs FILE.json beside FILE.csv)"
        )
    try:
        text = path.read_text(encoding="utf-8")
        meta = json.loads(text)
    except UnicodeDecodeError:
        raise RecordingError(path, "sidecar is not UTF-8 text") from None
    except json.JSONDecodeError as exc:
        raise RecordingError(
            path, f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}"
        ) from None
    except RecursionError:
        raise RecordingError(path, "invalid JSON: nested too deeply") from None
    if not isinstance(meta, dict):
        raise RecordingError(path, "sidecar must be a JSON object")
    fmt = meta.get("format")
    if fmt != FORMAT:
        raise RecordingError(path, f"expected {FORMAT!r}, got {fmt!r}", key="format")
    frame = meta.get("frame")
    if frame not in ("NED", "ENU"):
        raise RecordingError(path, f"must be 'NED' or 'ENU', got {frame!r}", key="frame")
    if not isinstance(meta.get("vehicle"), dict):
        raise RecordingError(path, "missing or not an object", key="vehicle")
    return meta


def vehicle_from_sidecar(path: Path, meta: dict, has_u: bool):
    vd = meta["vehicle"]
    frame = meta["frame"]
    gravity = _number(path, "gravity", meta.get("gravity", 9.81), positive=True)
    mass = _number(path, "vehicle.mass", vd.get("mass"), positive=True) if "mass" in vd else None
    if mass is None:
        raise RecordingError(path, "missing", key="vehicle.mass")
    if "inertia" not in vd:
        raise RecordingError(path, "missing", key="vehicle.inertia")
    J = _matrix(path, "vehicle.inertia", vd["inertia"], lambda s: s in ((3,), (3, 3)))
    if J.shape == (3,):
        J = np.diag(J)
    if "allocation" in vd:
        A = _matrix(
            path,
            "vehicle.allocation",
            vd["allocation"],
            lambda s: len(s) == 2 and s[0] == 4 and s[1] >= 4,
        )
    elif "arm" in vd and "torque_coefficient" in vd:
        d = _number(path, "vehicle.arm", vd["arm"], positive=True)
        c = _number(path, "vehicle.torque_coefficient", vd["torque_coefficient"], positive=True)
        A = paper_allocation(d, c)
        if frame == "ENU":
            # the arm/torque layout is defined in FRD; express it in FLU for the common path
            A = np.diag([1.0, 1.0, -1.0, -1.0]) @ A
    else:
        raise RecordingError(
            path, "needs 'allocation' or both 'arm' and 'torque_coefficient'", key="vehicle"
        )
    kw = {"gravity": gravity}
    if "max_thrust" in vd:
        kw["max_thrust"] = _number(path, "vehicle.max_thrust", vd["max_thrust"], positive=True)
    try:
        if frame == "ENU":
            vehicle = vehicle_flu_to_frd(mass, J, A, **kw)
        else:
            vehicle = Vehicle(mass=mass, inertia=J, allocation=A, **kw)
    except ConfigError as exc:
        raise RecordingError(path, str(exc), key="vehicle") from None
    curve = None
    if has_u:
        if "thrust_curve" in vd:
            c3 = _matrix(path, "vehicle.thrust_curve", vd["thrust_curve"], lambda s: s == (3,))
            curve = tuple(float(x) for x in c3)
        elif "thrust_coefficient" in vd:
            k = _number(path, "vehicle.thrust_coefficient", vd["thrust_coefficient"], positive=True)
            curve = (0.0, 0.0, k)
        else:
            raise RecordingError(
                path, "u1..u4 commands need 'thrust_coefficient' or 'thrust_curve'", key="vehicle"
            )
    return vehicle, curve
