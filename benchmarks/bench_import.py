"""Import (and diagnosis) time of a long autopilot log, per format, through the user's path.

For each format this writes a synthetic flight of ``--minutes`` minutes (the one the importer
tests use, stretched: armed idle, take-off, hover, landing) at ``--rate`` Hz -- a PX4 ULog
(IMU at the rate, attitude at 250 Hz, UAVCAN outputs and ESC rpm at 100 Hz), an ArduPilot
DataFlash binary (IMU at the rate, a second IMU, RCOU and ESC at the rate) and a Betaflight
blackbox log (every main field at the rate) -- then times ``quadfault import LOG --out
X.csv`` and ``quadfault diagnose X.csv --json X.json`` (defaults) through the console
script's entry point, in this process, after one warm-up import and diagnosis of a short log
of the same format (numba's compiled kernels are then loaded or compiled, as for a user's
second run: the times are warm). It prints the seconds (wall and CPU) and their share of the
30 s budget for import + diagnose, and the load average before and after (on a shared
machine the CPU seconds are the measure; the wall time grows with the load).

    python benchmarks/bench_import.py [--minutes 10] [--rate 500] [--formats px4,ardupilot,blackbox]
                                      [--no-diagnose]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

BUDGET_S = 30.0


def write(fmt: str, path: Path, minutes: float, rate: float) -> Path:
    from quadfault.fileio import atomic_write_bytes
    from tests.support.field_logs import blackbox_log, dataflash_flight, px4_flight

    seconds = 60.0 * minutes
    if fmt == "px4":
        path = path.with_suffix(".ulg")
        px4_flight(path, duration=seconds, imu_rate=rate, invalid_vxy=None)
    elif fmt == "ardupilot":
        path = path.with_suffix(".bin")
        dataflash_flight(path, duration=seconds, imu_rate=rate, rcou_rate=rate, invalid_vxy=None)
    else:
        path = path.with_suffix(".bbl")
        atomic_write_bytes(path, blackbox_log(seconds, rate), force=True)
    return path


def timed(args: list) -> tuple:
    """``(wall s, CPU s)`` of one command (CPU time is what a loaded shared machine does
    not inflate)."""
    from quadfault.cli import main

    t0, c0 = time.perf_counter(), time.process_time()
    code = main([str(a) for a in args] + ["--quiet", "--force"])
    if code != 0:
        raise SystemExit(f"bench_import: quadfault {args[0]} failed")
    return time.perf_counter() - t0, time.process_time() - c0


def load() -> str:
    """The 1-minute load average (``/proc/loadavg``), or "?"."""
    p = Path("/proc/loadavg")
    return p.read_text().split()[0] if p.exists() else "?"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=500.0)
    ap.add_argument("--formats", default="px4,ardupilot,blackbox")
    ap.add_argument("--no-diagnose", action="store_true")
    args = ap.parse_args()
    rows = []
    load0 = load()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for fmt in args.formats.split(","):
            warm = write(fmt, tmp / f"warm_{fmt}", 0.5, args.rate)
            timed(["import", warm, "--out", tmp / "warm.csv"])
            if not args.no_diagnose:  # loads (or compiles) the diagnosis' kernels too
                timed(["diagnose", tmp / "warm.csv", "--json", tmp / "warm.diagnosis.json"])
            log = write(fmt, tmp / f"long_{fmt}", args.minutes, args.rate)
            t_imp = timed(["import", log, "--out", tmp / f"{fmt}.csv"])
            t_diag = None
            if not args.no_diagnose:
                t_diag = timed(
                    ["diagnose", tmp / f"{fmt}.csv", "--json", tmp / f"{fmt}.diagnosis.json"]
                )
            rows.append((fmt, log.stat().st_size / 1e6, t_imp, t_diag))
    print(
        f"\n{args.minutes:g}-minute logs at {args.rate:g} Hz (budget {BUDGET_S:g} s for import "
        f"+ diagnose; load average {load0} before, {load()} after)"
    )
    print("seconds as wall (CPU); share: import + diagnose over the budget, wall (CPU)")
    print(f"{'format':<10} {'MB':>7} {'import s':>14} {'diagnose s':>14} {'share':>13}")
    for fmt, mb, t_imp, t_diag in rows:
        wall = t_imp[0] + (t_diag[0] if t_diag else 0.0)
        cpu = t_imp[1] + (t_diag[1] if t_diag else 0.0)
        diag = f"{t_diag[0]:6.1f} ({t_diag[1]:5.1f})" if t_diag else f"{'-':>14}"
        print(
            f"{fmt:<10} {mb:7.1f} {t_imp[0]:6.1f} ({t_imp[1]:5.1f}) {diag} "
            f"{wall / BUDGET_S:5.2f} ({cpu / BUDGET_S:4.2f})"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
