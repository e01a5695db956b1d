"""``quadfault import``: convert a real flight log into a recording (docs/formats.md).

    quadfault import LOG --out FILE.csv [--format px4|ardupilot|blackbox|crazyflie-usd]
                     [--log N] [--preset NAME]
    quadfault import DATASET INPUT --out FILE.csv
                     [--force] [--keep-all] [--vehicle VEHICLE.json] [--calibration T0,T1]
                     [--mass KG] [--arm D] [--torque-coefficient C] [--inertia JXX,JYY,JZZ]

Writes FILE.csv + FILE.json atomically (never overwriting without ``--force``) and prints one
summary line: rows, duration, rate, gaps, dropped samples and what the log is missing.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

from quadfault.errors import ConfigError, RecordingError

#: importers of autopilot logs (the rest are data sets with known vehicles)
AUTOPILOTS = ("px4", "ardupilot", "blackbox")
#: formats read from the file itself (--format)
FORMATS = AUTOPILOTS + ("crazyflie-usd",)


def add_arguments(p: argparse.ArgumentParser) -> None:
    from quadfault.io.importers import IMPORTERS

    p.add_argument(
        "source",
        metavar="LOG|DATASET",
        help="the log (PX4 .ulg, ArduPilot .bin/.log, Betaflight/INDIflight "
        ".bfl/.bbl or its decoded CSV, Crazyflie uSD-deck log: the format is read from "
        "the file), "
        f"or a data set name ({', '.join(IMPORTERS)}) followed by its file",
    )
    p.add_argument("input", nargs="?", metavar="INPUT", help="the file, after a data set name")
    p.add_argument("--out", required=True, help="output recording FILE.csv (+ FILE.json)")
    p.add_argument(
        "--format",
        choices=FORMATS,
        default=None,
        help="the log's format, instead of reading it from the file",
    )
    p.add_argument(
        "--preset",
        default=None,
        metavar="NAME",
        help="crazyflie-usd: the vehicle's named constants (crazyflie21, "
        "crazyflie21-brushless; default crazyflie21, said so)",
    )
    p.add_argument(
        "--log",
        type=int,
        default=None,
        metavar="N",
        help="blackbox: which of several logs in one file (1-based; default the longest)",
    )
    p.add_argument("--force", action="store_true", help="overwrite existing files")
    p.add_argument(
        "--keep-all",
        action="store_true",
        help="keep the rows outside the flight (default: trim to the free-flight "
        "span; see docs/importers.md)",
    )
    p.add_argument(
        "--vehicle",
        default=None,
        metavar="VEHICLE.json",
        help="vehicle description (the sidecar's 'vehicle' object: mass, inertia, "
        "allocation or arm + torque_coefficient, thrust_curve or "
        "thrust_coefficient; optional 'frame': NED|ENU)",
    )
    p.add_argument(
        "--calibration",
        default=None,
        metavar="T0,T1",
        help="calibration segment [s, in the log's clock] for constants fitted by "
        "the importer (default: see docs/importers.md)",
    )
    p.add_argument("--mass", type=float, default=None, help="take-off mass [kg]")
    p.add_argument(
        "--arm",
        type=float,
        default=None,
        help="per-axis rotor offset d [m] of a quad X (autopilot logs)",
    )
    p.add_argument(
        "--torque-coefficient",
        type=float,
        default=None,
        help="yaw torque per newton of thrust [m] (autopilot logs)",
    )
    p.add_argument(
        "--inertia",
        default=None,
        metavar="JXX,JYY,JZZ",
        help="diagonal inertia [kg m^2] (autopilot logs)",
    )
    p.add_argument(
        "--time-base",
        choices=("attitude", "imu"),
        default=None,
        help="px4 only: resample every topic onto the attitude or the IMU time "
        "stamps (default: the faster)",
    )
    p.add_argument(
        "--frame",
        choices=("NED", "ENU"),
        default="NED",
        help="world frame of the written file (default NED)",
    )


def load_vehicle_file(path) -> tuple:
    """``(Vehicle in FRD, thrust curve (a, b, c) or None)`` from a vehicle JSON file."""
    from quadfault.model.sidecar import vehicle_from_sidecar

    path = Path(path)
    if not path.exists():
        raise RecordingError(path, "file not found")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RecordingError(path, f"not valid JSON: {exc}") from None
    except RecursionError:
        raise RecordingError(path, "not valid JSON: nested too deeply") from None
    if not isinstance(data, dict):
        raise RecordingError(path, "must be a JSON object")
    if isinstance(data.get("vehicle"), dict):  # a whole sidecar is fine too
        data = dict(
            data["vehicle"], frame=data.get("frame", "NED"), gravity=data.get("gravity", 9.81)
        )
    frame = data.get("frame", "NED")
    if frame not in ("NED", "ENU"):
        raise RecordingError(path, f"must be 'NED' or 'ENU', got {frame!r}", key="frame")
    has_curve = "thrust_curve" in data or "thrust_coefficient" in data
    meta = {"frame": frame, "gravity": data.get("gravity", 9.81), "vehicle": data}
    vehicle, curve = vehicle_from_sidecar(path, meta, has_curve)
    return vehicle, curve


def _calibration(text):
    if text is None:
        return None
    try:
        t0, t1 = (float(x) for x in text.split(","))
    except ValueError:
        raise ConfigError(f"--calibration expects T0,T1 in seconds, got {text!r}") from None
    if not (math.isfinite(t0) and math.isfinite(t1) and t1 > t0):
        raise ConfigError(f"--calibration needs finite T0 < T1, got {text!r}")
    return (t0, t1)


def _inertia(text):
    if text is None:
        return None
    try:
        J = [float(x) for x in text.split(",")]
    except ValueError:
        raise ConfigError(f"--inertia expects JXX,JYY,JZZ, got {text!r}") from None
    if len(J) != 3 or not all(math.isfinite(j) and j > 0 for j in J):
        raise ConfigError(f"--inertia expects 3 positive numbers, got {text!r}")
    return J


def _positive(name, value):
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ConfigError(f"--{name} must be a positive number, got {value}")


def _kind_and_input(args) -> tuple:
    from quadfault.io.importers import IMPORTERS, detect_format

    if args.input is not None:
        if args.source not in IMPORTERS:
            raise ConfigError(
                f"unknown data set {args.source!r}; choose one of "
                f"{', '.join(IMPORTERS)} or give only the log file"
            )
        return args.source, args.input
    return (args.format or detect_format(args.source)), args.source


def with_vehicle(rec, vehicle, curve, source: str):
    """``rec`` with its nominal vehicle (and thrust curve) replaced by a user's file."""
    from quadfault.model.effects import curve_thrust

    changes = {"vehicle": vehicle}
    meta = dict(rec.meta)
    meta["constants"] = {"vehicle": f"from {source}"}
    if curve is not None and rec.commands_u is not None:
        changes.update(thrust_curve=curve, thrust_cmd=curve_thrust(curve, rec.commands_u))
        meta.pop("calibration", None)
    changes["meta"] = meta
    return replace(rec, **changes)


def run(args) -> int:
    from quadfault.io.importers import get_importer, summary_line
    from quadfault.io.recording import write_recording

    out = Path(args.out)
    if out.suffix != ".csv":
        raise ConfigError(f"{out}: --out must name a .csv file")
    for name in ("mass", "arm", "torque_coefficient"):
        _positive(name.replace("_", "-"), getattr(args, name))
    if args.log is not None and args.log < 1:
        raise ConfigError(f"--log counts from 1, got {args.log}")
    kind, source = _kind_and_input(args)
    given = [
        f
        for f in ("arm", "torque_coefficient", "inertia", "time_base")
        if getattr(args, f) is not None
    ]
    if given and kind not in AUTOPILOTS:
        raise ConfigError(
            f"--{given[0].replace('_', '-')} applies to autopilot logs; the {kind} "
            "data set's vehicle is known (give --vehicle VEHICLE.json to replace "
            "it)"
        )
    if args.preset is not None and kind != "crazyflie-usd":
        raise ConfigError("--preset applies to Crazyflie uSD logs (crazyflie-usd)")
    if args.time_base is not None and kind != "px4":
        raise ConfigError("--time-base applies to PX4 logs")
    if args.log is not None and kind != "blackbox":
        raise ConfigError(
            f"--log picks one of several logs in a blackbox file; a {kind} log holds one"
        )
    vehicle = curve = None
    if args.vehicle is not None:
        vehicle, curve = load_vehicle_file(args.vehicle)
    importer = get_importer(kind)
    kwargs = {
        "keep_all": args.keep_all,
        "calibration": _calibration(args.calibration),
        "mass": args.mass,
    }
    if kind in AUTOPILOTS:
        kwargs.update(
            vehicle=vehicle,
            thrust_curve=curve,
            inertia=_inertia(args.inertia),
            arm=args.arm,
            torque_coefficient=args.torque_coefficient,
            time_base=args.time_base,
            log=args.log,
        )
    if kind == "crazyflie-usd":
        kwargs.update(vehicle=vehicle, thrust_curve=curve, preset=args.preset)
    rec = importer(source, **kwargs)
    if vehicle is not None and kind not in FORMATS:
        rec = with_vehicle(rec, vehicle, curve, args.vehicle)
    write_recording(rec, out, frame=args.frame, force=args.force)
    warns = (rec.meta.get("import") or {}).get("warnings")
    if warns:
        print(f"warning: {Path(source).name}: " + "; ".join(warns), file=sys.stderr)
    if not args.quiet:
        print(f"{out}: {summary_line(rec)}")
    return 0
