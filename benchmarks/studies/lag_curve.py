"""Motor lag with the importer's thrust curve vs fitted jointly with a free curve.

A fixed command-to-thrust curve biases the lag: the time constant also absorbs the curve's
error. For each recording, ``quadfault diagnose`` runs twice on the same rows, with
``--effects motor_lag``, with ``--effects thrust_curve,motor_lag`` (the curve's hover
thrust, slope and curvature fitted jointly with the lag) and with ``inertia`` added (a
curve's slope also scales the rotor moments, so without it an inertia error leaks into the
slope); the lag, the curve and the inertia are printed. ``--segment T0,T1`` [s] restricts the rows; ``--author-segments`` takes the
segments the importer lists in the sidecar (``meta.author_segments``: the data set authors'
manoeuvres) -- whole logs also hold take-off, ground and landing rows, which the lag and the
curve do not describe.

    python benchmarks/studies/lag_curve.py FLIGHT.csv ... [--segment T0,T1 | --author-segments]
    python benchmarks/studies/lag_curve.py --eschmann ../shared/data/real/eschmann-cf21-sysid

``--eschmann DIR`` imports log10, log15 and log16 (``quadfault import eschmann``) and uses
their author segments.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from quadfault.cli import main as cli
from quadfault.fileio import atomic_write_text
from quadfault.io.recording import read_recording, write_recording

LIBRARIES = ("motor_lag", "thrust_curve,motor_lag", "thrust_curve,motor_lag,inertia")


def segments(rec, segment, author: bool) -> list[tuple[str, float, float]]:
    if segment is not None:
        return [("segment", *segment)]
    if not author:
        return [("all", float(rec.t[0]), float(rec.t[-1]))]
    out = []
    for name, seg in (rec.meta.get("author_segments") or {}).items():
        spans = seg if isinstance(seg[0], list) else [seg]
        out += [
            (name if len(spans) == 1 else f"{name}{k + 1}", float(a), float(b))
            for k, (a, b) in enumerate(spans)
        ]
    return out


def diagnose(rec, t0, t1, effects, work: Path) -> dict:
    rows = np.flatnonzero((rec.t >= t0) & (rec.t <= t1))
    part = rec.slice(int(rows[0]), int(rows[-1]) + 1)
    csv = work / "part.csv"
    write_recording(part, csv, frame=rec.frame, force=True)
    out = work / "part.diag.json"
    if (
        cli(["diagnose", str(csv), "--json", str(out), "--force", "--quiet", "--effects", effects])
        != 0
    ):
        raise SystemExit(f"lag_curve: quadfault diagnose failed on {t0}-{t1} s")
    return json.loads(out.read_text())


def describe(doc) -> str:
    found = {e["name"]: e for e in doc["effects"]}
    if "motor_lag" not in found:
        return "no lag accepted"
    lag = found["motor_lag"]
    text = f"tau {lag['params']['tau_s']:.3f} +- {lag['uncertainty']['tau_s']:.3f} s"
    if "thrust_curve" in found:
        p = found["thrust_curve"]["params"]
        text += (
            f"; curve: hover {p['hover_thrust_change']:+.3f}, slope "
            f"{p['slope_change']:+.3f}, curvature {p['curvature_change']:+.3f}"
        )
    if "inertia" in found:
        text += "; inertia x" + ", ".join(f"{s:.2f}" for s in found["inertia"]["params"]["scale"])
    return text + f"; model improvement {doc['model']['improvement']:.2f}"


def run(paths, segment, author: bool) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for path in paths:
            rec = read_recording(path)
            for name, t0, t1 in segments(rec, segment, author):
                print(f"\n{Path(path).stem} {name} {t0:.1f}-{t1:.1f} s")
                row = {"flight": Path(path).stem, "segment": [name, t0, t1]}
                for effects in LIBRARIES:
                    doc = diagnose(rec, t0, t1, effects, Path(tmp))
                    row[effects] = doc["effects"]
                    print(f"  --effects {effects:<32} {describe(doc)}")
                rows.append(row)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("recordings", nargs="*")
    ap.add_argument("--segment", default=None, metavar="T0,T1")
    ap.add_argument("--author-segments", action="store_true")
    ap.add_argument("--eschmann", default=None, metavar="DIR")
    ap.add_argument("--out", default=None, help="also write the rows to this JSON file")
    args = ap.parse_args(argv)
    segment = None
    if args.segment:
        try:
            segment = tuple(float(x) for x in args.segment.split(","))
            assert len(segment) == 2 and segment[0] < segment[1]
        except (ValueError, AssertionError):
            print("lag_curve: --segment expects T0,T1 with T0 < T1", file=sys.stderr)
            return 2
    with tempfile.TemporaryDirectory() as tmp:
        paths = list(args.recordings)
        author = args.author_segments
        if args.eschmann:
            directory = Path(args.eschmann)
            if not directory.is_dir():
                print(f"lag_curve: {directory}: not a directory (skipped)", file=sys.stderr)
                return 0
            for log in ("log10", "log15", "log16"):
                csv = Path(tmp) / f"{log}.csv"
                if (
                    cli(
                        [
                            "import",
                            "eschmann",
                            str(directory / f"{log}.csv.gz"),
                            "--out",
                            str(csv),
                            "--quiet",
                        ]
                    )
                    != 0
                ):
                    raise SystemExit(f"lag_curve: quadfault import failed on {log}")
                paths.append(csv)
            author = True
        if not paths:
            print("lag_curve: give recordings or --eschmann DIR", file=sys.stderr)
            return 2
        rows = run(paths, segment, author)
    if args.out:
        atomic_write_text(args.out, json.dumps(rows, indent=1) + "\n", force=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
