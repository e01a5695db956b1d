"""Measure the noise of every stream of real flight logs, and derive a sensor preset from them.

Each log goes through the project's own importers (``quadfault import``: the format is read
from the file, ``--dataset`` names a Crazyflie data set) or is a recording already (CSV + JSON
sidecar); :func:`quadfault.diagnosis.sensor_noise.measure_noise` measures its position,
velocity, attitude, gyro and accelerometer at their own rates: white noise, the high-passed
residual and its spectrum's peak, the estimator outputs' coloured inconsistency and its
correlation time, latency and bias (docs/sensors.md says how).

    python benchmarks/sensor_noise.py LOG [LOG ...]            # a table, one row per stream
    python benchmarks/sensor_noise.py --data DIR               # every log the importers read
    python benchmarks/sensor_noise.py --dataset nanodrone DIR/*.csv.gz --preset crazyflie

``--preset NAME`` prints the SensorNoise the logs give (the median over the logs of each
number) in the form of ``quadfault/model/sensor_presets.py``; ``--json OUT`` writes every
measurement.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from quadfault.errors import QuadfaultError
from quadfault.fileio import atomic_write_text
from quadfault.model.sensors import STREAMS, UNITS


def load(path: Path, dataset: str | None = None):
    """The recording of ``path``: a recording's CSV (with its sidecar) as it is, else the log
    through its importer (``dataset``: a Crazyflie data set name)."""
    from quadfault.io.importers import detect_format, get_importer
    from quadfault.io.recording import read_recording, sidecar_path

    path = Path(path)
    if path.suffix == ".csv" and sidecar_path(path).exists():
        return read_recording(path)
    kind = dataset or detect_format(path)
    return get_importer(kind)(path)


def measure_files(paths, dataset: str | None = None, quiet: bool = True):
    """``[(path, measurement)]`` of the logs that import; the others are named on stderr."""
    from quadfault.diagnosis.sensor_noise import measure_noise

    out = []
    for p in paths:
        try:
            rec = load(p, dataset)
        except QuadfaultError as e:
            print(f"skipped {Path(p).name}: {e}", file=sys.stderr)
            continue
        out.append((Path(p), measure_noise(rec)))
    return out


#: a stream logged slower than this [Hz] was decimated by the logger: its onboard rate (what
#: the controller flies on) is not in the log, and the preset samples it every physics step
ONBOARD_HZ = 50.0


def preset_numbers(measurements) -> dict:
    """Per stream, the median over the logs of each number the sensor model takes:
    ``{stream: {white, markov, tau, bias, rate, latency}}`` (3 significant digits; a number
    no log gave is 0, a latency below 0 is 0, a rate below :data:`ONBOARD_HZ` is 0)."""
    out = {}
    for s in STREAMS:
        got = [m[s] for _, m in measurements if s in m]
        row = {}
        for key in ("white", "markov", "tau", "bias", "rate", "latency"):
            vals = [g[key] for g in got if g.get(key) is not None and np.isfinite(g[key])]
            x = float(np.median(vals)) if vals else 0.0
            if key == "latency":
                x = max(0.0, x)
            if key == "rate" and x < ONBOARD_HZ:
                x = 0.0  # the logger's decimation, not the onboard rate: every physics step
            if key == "tau" and not vals:
                x = 1.0
            row[key] = float(f"{x:.3g}")
        out[s] = row
    return out


def preset_text(name: str, numbers: dict) -> str:
    """The preset as a call of ``sensor_presets._preset`` (to paste into that module)."""
    lines = [f'    "{name}": _preset(', f'        "{name}",']
    for s in STREAMS:
        items = ", ".join(f'"{k}": {v!r}' for k, v in numbers[s].items())
        lines.append(f"        {s}={{{items}}},")
    lines.append("    ),")
    return "\n".join(lines)


def _fmt(x, scale=1.0):
    return "-" if x is None or not np.isfinite(x) else f"{x * scale:.3g}"


def table(measurements) -> str:
    head = (
        "| log | stream | unit | rate Hz | white | white check | high-passed | peak Hz | "
        "coloured (markov) | tau s | latency ms | bias |"
    )
    rows = [head, "|" + "---|" * 12]
    for path, m in measurements:
        for s, unit in zip(STREAMS, UNITS):
            if s not in m:
                continue
            r = m[s]
            if r["rate"] is None:  # derived by the importer: not a measurement
                rows.append(f"| {path.name} | {s} | {unit} | {r['notes'][0]} |" + " |" * 8)
                continue
            rows.append(
                f"| {path.name} | {s} | {unit} | {_fmt(r['rate'])} | {_fmt(r['white'])} | "
                f"{_fmt(r['white_check'])} | {_fmt(r['highpass'])} | {_fmt(r['peak_hz'])} | "
                f"{_fmt(r['markov'])} | {_fmt(r['tau'])} | {_fmt(r['latency'], 1e3)} | "
                f"{_fmt(r['bias'])} |"
            )
    return "\n".join(rows)


def _files(args) -> list[Path]:
    paths = [Path(p) for p in args.logs]
    if args.data is not None:
        root = Path(args.data)
        if not root.is_dir():
            raise SystemExit(f"sensor_noise: --data {root}: not a folder")
        paths += sorted(p for p in root.rglob("*") if p.is_file() and p.suffix != ".md")
        paths = [p for p in paths if not (p.suffix == ".json" and p.with_suffix(".csv").exists())]
    return paths


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("logs", nargs="*", help="flight logs or recordings (CSV + sidecar)")
    ap.add_argument("--data", default=None, help="also every file under this folder")
    ap.add_argument(
        "--dataset",
        default=None,
        help="the logs are files of this Crazyflie data set (eschmann, nanodrone, crazypad)",
    )
    ap.add_argument("--preset", default=None, metavar="NAME", help="print the preset they give")
    ap.add_argument("--json", default=None, metavar="OUT", help="write the measurements")
    args = ap.parse_args(argv)
    paths = _files(args)
    if not paths:
        ap.error("give logs or --data DIR")
    got = measure_files(paths, args.dataset)
    if not got:
        print("sensor_noise: no log could be imported", file=sys.stderr)
        return 2
    print(table(got))
    if args.preset:
        print()
        print(preset_text(args.preset, preset_numbers(got)))
    if args.json:
        out = Path(args.json)
        if out.exists():
            raise SystemExit(f"sensor_noise: {out} exists (not overwritten)")
        atomic_write_text(out, json.dumps({str(p): m for p, m in got}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
