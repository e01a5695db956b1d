"""The four estimators (IRLS, EKF, RLS, UKF) on real flights, per motor, through the user's path.

For each CrazyPAD motor log (Crazyflie 2.1, 100 Hz, on-board state estimate; the source's
``motor_data``) this runs what a user runs -- ``quadfault import crazypad LOG --out
DIR/NAME.csv`` and ``quadfault estimate DIR/NAME.csv --estimator E --out DIR/NAME.E.csv`` for
every estimator with its defaults -- through the console script's entry point, prints each
command, and summarises the estimate files it wrote: per motor, the median of the estimated
efficiency over the rows where every rotor is commanded (status ``ok``; take-off, landing and
the motors-off pause excluded by the estimators' own ``no_excitation`` status) and its
interquartile range over time.

Real logs carry no true efficiency. What the data can tell: the thrust curve the importer
applies is nominal for every rotor, so a common factor is not a fault; on the cut-propeller
flights the defect is on motor 3 (the source's folder name), and an estimator that sees it
puts motor 3 below the other three. The table gives ``eta3 - mean(eta1, eta2, eta4)`` per
flight and estimator, the count of flights where motor 3 is the lowest, and (per airframe,
``E8`` / ``E9``) how far the defect moves that gap from the same airframe's normal flights:
the nominal model does not fit either airframe equally on every rotor, so a gap on the normal
flights is the airframe's, not a defect.

    python benchmarks/studies/real_estimators.py [--data DIR] [--out DIR] [--conditions normal_flight,...]
                                         [--json OUT.json] [--quiet]

Reads ``../shared/data/real`` (never copied into the repository) and prints one line and
exits 0 when it is absent.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

DEFAULT_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real"
ESTIMATORS = ("irls", "ekf", "rls", "ukf")
CONDITIONS = (
    "normal_flight",
    "cut_propeller_M3_1mm",
    "cut_propeller_M3_2mm",
    "cut_propeller_M3_3mm",
)


def quadfault(args: list, quiet: bool) -> None:
    """Run one ``quadfault`` command through the console script's entry point."""
    from quadfault.cli import main

    if not quiet:
        print("$ quadfault " + " ".join(str(a) for a in args), flush=True)
    code = main([str(a) for a in args] + ["--quiet"])
    if code != 0:
        raise SystemExit(f"real_estimators: quadfault {args[0]} failed on {args[1]}")


def summarise_estimate(path: Path) -> dict:
    """Per motor: median and interquartile range of the estimate over the ``ok`` rows."""
    from estimators.series_io import read_estimate_csv

    est = read_estimate_csv(path)
    ok = np.asarray(est["status"]) == "ok"
    eta = np.asarray(est["eta"], dtype=float)[ok]
    if len(eta) == 0:
        return {"rows": 0, "median": None, "iqr": None}
    q1, med, q3 = np.percentile(eta, [25, 50, 75], axis=0)
    return {"rows": int(ok.sum()), "median": med.tolist(), "iqr": (q3 - q1).tolist()}


def run(data: Path, out: Path, conditions, quiet: bool) -> list:
    rows = []
    for cond in conditions:
        for log in sorted((data / "crazypad-cf21-faults" / "motor_data" / cond).glob("*.csv.gz")):
            name = f"{cond}_{log.name.split('.')[0]}"
            csv = out / f"{name}.csv"
            quadfault(["import", "crazypad", log, "--out", csv, "--force"], quiet)
            row = {"condition": cond, "flight": name, "estimators": {}}
            for est in ESTIMATORS:
                path = out / f"{name}.{est}.csv"
                quadfault(["estimate", csv, "--estimator", est, "--out", path, "--force"], quiet)
                row["estimators"][est] = summarise_estimate(path)
            rows.append(row)
    return rows


def m3_gap(median) -> float | None:
    """``eta3 - mean(eta1, eta2, eta4)``."""
    if median is None:
        return None
    return float(median[2] - np.mean([median[0], median[1], median[3]]))


def print_tables(rows: list) -> None:
    print("\nper flight: median eta1..eta4 over the ok rows, and eta3 - mean(others)")
    print(
        f"{'flight':34s} {'est':5s} {'eta1':>6s} {'eta2':>6s} {'eta3':>6s} {'eta4':>6s} "
        f"{'m3 gap':>7s} {'IQR (mean)':>10s}"
    )
    for r in rows:
        for est, s in r["estimators"].items():
            if s["median"] is None:
                print(f"{r['flight']:34s} {est:5s} (no ok rows)")
                continue
            m = s["median"]
            print(
                f"{r['flight']:34s} {est:5s} "
                + " ".join(f"{x:6.3f}" for x in m)
                + f" {m3_gap(m):+7.3f} {np.mean(s['iqr']):10.3f}"
            )
    print(
        "\nper airframe, condition and estimator: mean [min, max] of the m3 gap over the "
        "flights, its shift from the same airframe's normal flights, flights with motor 3 "
        "the lowest"
    )
    print(
        f"{'airframe':8s} {'condition':22s} {'est':5s} {'m3 gap':>26s} {'vs normal':>10s} "
        f"{'M3 lowest':>10s}"
    )
    groups = dict.fromkeys((airframe(r), r["condition"]) for r in rows)
    for frame, cond in sorted(
        groups, key=lambda g: (g[0], CONDITIONS.index(g[1]) if g[1] in CONDITIONS else 99)
    ):
        for est in ESTIMATORS:
            gaps, lowest = _gaps(rows, frame, cond, est)
            if not gaps:
                continue
            normal, _ = _gaps(rows, frame, "normal_flight", est)
            shift = f"{np.mean(gaps) - np.mean(normal):+10.3f}" if normal else f"{'-':>10s}"
            print(
                f"{frame:8s} {cond:22s} {est:5s} {np.mean(gaps):+8.3f} [{min(gaps):+.3f}, "
                f"{max(gaps):+.3f}] {shift} {lowest:>6d}/{len(gaps)}"
            )


def airframe(row: dict) -> str:
    """The CrazyPAD airframe of a flight (``E8`` or ``E9``, the log's name prefix)."""
    return row["flight"][len(row["condition"]) + 1 :].split("_")[0]


def _gaps(rows, frame, cond, est):
    meds = [
        r["estimators"][est]["median"]
        for r in rows
        if airframe(r) == frame
        and r["condition"] == cond
        and r["estimators"][est]["median"] is not None
    ]
    return [m3_gap(m) for m in meds], sum(int(np.argmin(m)) == 2 for m in meds)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=DEFAULT_DATA)
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="folder for the recordings and estimates (default: a temporary one)",
    )
    p.add_argument(
        "--conditions",
        default=",".join(CONDITIONS),
        help=f"CrazyPAD motor_data conditions (default {','.join(CONDITIONS)})",
    )
    p.add_argument("--json", type=Path, default=None, help="also write the rows as JSON")
    p.add_argument("--quiet", action="store_true", help="do not print the commands")
    p.add_argument(
        "--from-json",
        type=Path,
        default=None,
        help="re-print the tables of a --json file (runs nothing)",
    )
    args = p.parse_args(argv)
    if args.from_json:
        print_tables(json.loads(args.from_json.read_text()))
        return 0
    if not (args.data / "crazypad-cf21-faults").is_dir():
        print(f"real_estimators: no CrazyPAD data under {args.data}; nothing to do")
        return 0
    conditions = [c.strip() for c in args.conditions.split(",") if c.strip()]
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        rows = run(args.data, out, conditions, args.quiet)
    if args.json:
        from quadfault.fileio import atomic_write_text

        atomic_write_text(args.json, json.dumps(rows, indent=2) + "\n", force=True)
    print_tables(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
