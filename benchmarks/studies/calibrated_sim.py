"""Does a simulator calibrated on one part of a flight predict the rest better than nominal?

For each recording (pose logs, e.g. written by ``quadfault import``): the first ``--split``
of it (by time) is written to a file and diagnosed with ``quadfault diagnose`` (defaults, or
``--effects``); the diagnosis JSON is loaded with ``quadfault.model.effects.from_diagnosis`` (the
loader of ``quadfault simulate --model``); then the held-out rest of the flight is replayed
open loop through the simulator's plant (``quadfault.diagnosis.replay.replay_errors``: from
``--starts`` recorded states, the recorded commands over 0.05-0.5 s), once with the nominal
vehicle and once with the calibrated model. Printed: the effects found and the RMS position,
velocity and attitude errors at each horizon, nominal -> calibrated.

    python benchmarks/studies/calibrated_sim.py FLIGHT.csv ... [--split 0.6] [--effects a,b]
    python benchmarks/studies/calibrated_sim.py --nanodrone ../shared/data/real/nanodrone-cf21bl

``--nanodrone DIR`` imports every flight of that data set first (``quadfault import
nanodrone``). A diagnosis JSON without ``format``/``vehicle`` (older ``quadfault diagnose``)
gets them from the recording's sidecar.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from quadfault.cli import main as cli
from quadfault.diagnosis.replay import replay_errors
from quadfault.fileio import atomic_write_text
from quadfault.io.recording import read_recording, sidecar_path, write_recording
from quadfault.model.effects import from_diagnosis

HORIZONS = (0.05, 0.1, 0.2, 0.5)


def calibrate(path: Path, split: float, effects, work: Path):
    """``(recording, model, diagnosis JSON, split time)``: diagnose the first ``split``."""
    rec = read_recording(path)
    t_split = rec.t[0] + split * (rec.t[-1] - rec.t[0])
    head = rec.slice(0, int(np.searchsorted(rec.t, t_split)))
    fit_csv = work / f"{path.stem}_fit.csv"
    write_recording(head, fit_csv, frame=rec.frame, force=True)
    out = work / f"{path.stem}_diag.json"
    args = ["diagnose", str(fit_csv), "--json", str(out), "--force", "--quiet"]
    if effects:
        args += ["--effects", effects]
    if cli(args) != 0:
        raise SystemExit(f"calibrated_sim: quadfault diagnose failed on {fit_csv}")
    doc = json.loads(out.read_text())
    side = json.loads(sidecar_path(fit_csv).read_text())
    for key in ("frame", "gravity", "vehicle"):
        doc.setdefault(key, side[key])
    doc.setdefault("format", "quadfault-diagnosis/2")
    return rec, from_diagnosis(doc), doc, float(t_split)


def run(paths, split: float, effects, starts: int) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for path in paths:
            rec, model, _, t_split = calibrate(Path(path), split, effects, Path(tmp))
            span = (t_split, float(rec.t[-1]))
            nominal = replay_errors(rec, model.vehicle, (), HORIZONS, starts=starts, span=span)
            calibrated = replay_errors(
                rec, model.vehicle, model.effects, HORIZONS, starts=starts, span=span
            )
            rows.append(
                {
                    "flight": Path(path).stem,
                    "effects": [e.describe() for e in model.effects],
                    "nominal": nominal,
                    "calibrated": calibrated,
                }
            )
            report(rows[-1])
    return rows


def report(row: dict) -> None:
    names = ", ".join(e["name"] for e in row["effects"]) or "none"
    print(f"\n{row['flight']}: calibrated with {names}; {row['nominal']['starts']} held-out starts")
    print(f"{'horizon [s]':<24}" + "".join(f"{h:>16.2f}" for h in row["nominal"]["horizons_s"]))
    for key, unit in (
        ("position_rmse_m", "m"),
        ("velocity_rmse_m_per_s", "m/s"),
        ("attitude_rmse_deg", "deg"),
    ):
        cells = "".join(
            f"{a:>8.3f} ->{b:>6.3f}" for a, b in zip(row["nominal"][key], row["calibrated"][key])
        )
        print(f"{key.split('_')[0] + ' [' + unit + ']':<24}{cells}")


def summary(rows) -> None:
    print(
        "\ncalibrated / nominal RMS error (median over flights; < 1: the calibrated simulator "
        "predicts better)"
    )
    print(f"{'horizon [s]':<24}" + "".join(f"{h:>8.2f}" for h in HORIZONS))
    for key in ("position_rmse_m", "velocity_rmse_m_per_s", "attitude_rmse_deg"):
        ratio = np.array(
            [np.array(r["calibrated"][key]) / np.array(r["nominal"][key]) for r in rows]
        )
        better = np.sum(ratio < 1, axis=0)
        print(
            f"{key.split('_')[0]:<24}"
            + "".join(f"{x:>8.2f}" for x in np.median(ratio, 0))
            + f"   better on {', '.join(map(str, better))} of {len(rows)} flights"
        )


def import_nanodrone(directory: Path, work: Path) -> list[Path]:
    out = []
    for raw in sorted(directory.glob("*.csv.gz")):
        csv = work / (raw.name[: -len(".csv.gz")] + ".csv")
        if cli(["import", "nanodrone", str(raw), "--out", str(csv), "--force", "--quiet"]) != 0:
            raise SystemExit(f"calibrated_sim: quadfault import failed on {raw}")
        out.append(csv)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("recordings", nargs="*", help="pose recordings (quadfault-recording/1)")
    ap.add_argument(
        "--nanodrone",
        default=None,
        metavar="DIR",
        help="import and use every flight of the nano-drone data set in DIR",
    )
    ap.add_argument(
        "--split",
        type=float,
        default=0.6,
        help="fraction of each flight (by time) used to calibrate (default 0.6)",
    )
    ap.add_argument("--effects", default=None, help="restrict the diagnosis' library")
    ap.add_argument("--starts", type=int, default=40, help="held-out starts per flight")
    ap.add_argument("--out", default=None, help="also write the rows to this JSON file")
    args = ap.parse_args(argv)
    if not 0.2 <= args.split <= 0.9:
        print("calibrated_sim: --split must be in [0.2, 0.9]", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        paths = list(args.recordings)
        if args.nanodrone:
            directory = Path(args.nanodrone)
            if not directory.is_dir():
                print(f"calibrated_sim: {directory}: not a directory (skipped)", file=sys.stderr)
                return 0
            paths += import_nanodrone(directory, Path(tmp))
        if not paths:
            print("calibrated_sim: give recordings or --nanodrone DIR", file=sys.stderr)
            return 2
        rows = run(paths, args.split, args.effects, args.starts)
    summary(rows)
    if args.out:
        atomic_write_text(args.out, json.dumps(rows, indent=1) + "\n", force=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
