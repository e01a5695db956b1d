"""IRLS, EKF, RLS and the UKF on one seeded simulated flight, per motor, with their defaults.

Runs what a user runs -- ``quadfault simulate --scenario S --duration D --seed K
--no-saturation --out DIR/flight.csv`` and ``quadfault estimate DIR/flight.csv --estimator E
--out DIR/E.csv`` for every estimator -- through the console script's entry point, then scores
the estimate files against the recording's truth (:func:`estimators.metrics.score`): per motor
the RMSE, the spike (largest error while another motor is in its fault window) and, for each
fault, the detection delay: the time from the onset until the faulted motor's estimate first
drops below 0.75 (``-`` when it never does within the window).

    python benchmarks/studies/four_estimators.py [--scenario abrupt] [--duration 40] [--seed 11]
                                         [--out DIR]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ESTIMATORS = ("irls", "ekf", "rls", "ukf")
THRESHOLD = 0.75


def quadfault(args: list) -> None:
    from quadfault.cli import main

    print("$ quadfault " + " ".join(str(a) for a in args), flush=True)
    if main([str(a) for a in args] + ["--quiet"]) != 0:
        raise SystemExit(f"four_estimators: quadfault {args[0]} failed")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="abrupt")
    p.add_argument("--duration", type=float, default=40.0)
    p.add_argument("--seed", type=int, default=11)
    p.add_argument("--out", type=Path, default=None, help="folder of the files (default: temp)")
    args = p.parse_args(argv)
    from estimators.base import EstimateSeries
    from estimators.metrics import fault_windows, score
    from estimators.series_io import read_estimate_csv
    from quadfault.io.recording import read_recording

    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        flight = out / "flight.csv"
        quadfault(
            [
                "simulate",
                "--scenario",
                args.scenario,
                "--duration",
                args.duration,
                "--seed",
                args.seed,
                "--no-saturation",
                "--out",
                flight,
                "--force",
            ]
        )
        rec = read_recording(flight)
        rows = {}
        for est in ESTIMATORS:
            path = out / f"{est}.csv"
            quadfault(["estimate", flight, "--estimator", est, "--out", path, "--force"])
            d = read_estimate_csv(path)
            series = EstimateSeries(
                t=d["t"], eta=d["eta"], sd=d["sd"], status=d["status"], estimator=est
            )
            rows[est] = (series, score(rec, series))
    windows = fault_windows(rec)
    print(
        f"\n{args.scenario}, {args.duration:g} s, seed {args.seed}, no saturation: per motor "
        "RMSE | spike | detection delay [s] (estimate < 0.75 after the onset)"
    )
    print(
        f"{'est':5s} "
        + " ".join(f"{'M' + str(m + 1) + ' rmse':>8s}" for m in range(4))
        + f" {'mean':>7s}   "
        + " ".join(f"{'M' + str(m + 1) + ' spike':>9s}" for m in range(4))
        + "   delays"
    )
    for est, (s, sc) in rows.items():
        delays = []
        for motor, t0, t1 in windows:
            k = np.flatnonzero((s.t >= t0) & (s.t <= t1) & (s.eta[:, motor - 1] < THRESHOLD))
            delays.append(f"M{motor} {s.t[k[0]] - t0:.3f}" if k.size else f"M{motor} -")
        spikes = sc.spike or [None] * 4
        print(
            f"{est:5s} "
            + " ".join(f"{x:8.4f}" for x in sc.rmse)
            + f" {np.mean(sc.rmse):7.4f}   "
            + " ".join(f"{x:9.4f}" if x is not None else f"{'-':>9s}" for x in spikes)
            + "   "
            + ", ".join(delays)
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
