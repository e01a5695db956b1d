"""IRLS against its EKF partner over several seeds: the ratios of ``quadfault reproduce``
with means and 95 % intervals.

    python benchmarks/fair_comparison.py --out DIR [--seeds 0-4] [--quick] [--workers 2]

For every seed K it runs ``quadfault reproduce --seed K --no-reference-mode --out DIR/seed-K``
(skipped when ``DIR/seed-K/metrics.json`` exists, so an interrupted study resumes), then
prints, per scenario and variant, the IRLS / EKF ratios of the motor-averaged raw spike,
excess spike and RMSE: each seed's value, the mean and the 95 % Student-t interval of the mean,
and the motor-averaged numbers behind them. ``DIR/summary.json`` holds the same. Every ratio
is against the EKF given the identical post-processing (docs/reproduce.md).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
from scipy import stats

from quadfault.fileio import atomic_write_text

METRICS = ("spike", "excess_spike", "rmse")


def seeds_of(text: str) -> list[int]:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(x) for x in text.split(",")]


def run_seed(out: Path, seed: int, quick: bool, workers: int) -> dict:
    path = out / f"seed-{seed}"
    if not (path / "metrics.json").exists():
        cmd = [sys.executable, "-m", "quadfault.cli", "reproduce", "--seed", str(seed),
               "--no-reference-mode", "--out", str(path), "--workers", str(workers),
               "--quiet", "--force"] + (["--quick"] if quick else [])
        print("$ quadfault " + " ".join(cmd[3:]), flush=True)
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return json.loads((path / "metrics.json").read_text())


def interval(values) -> tuple[float, float, float]:
    """Mean and 95 % Student-t interval of the mean."""
    x = np.asarray(values, dtype=float)
    m = float(x.mean())
    if len(x) < 2:
        return m, math.nan, math.nan
    h = float(stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / math.sqrt(len(x)))
    return m, m - h, m + h


def _mean(values):
    return None if any(v is None for v in values) else float(np.mean(values))


def summarise(docs: dict) -> dict:
    """``{scenario: {variant: {metric: {"per_seed", "mean", "ci95"}, "irls": {...},
    "ekf": {...}, "q_eta": [...]}}}`` over the seeds' metrics.json."""
    from estimators.metrics import mean_or_none
    from estimators.paper.pairing import VARIANTS

    out: dict = {}
    first = next(iter(docs.values()))
    for name in first["ratios"]:
        for v in VARIANTS:
            if v.name not in first["ratios"][name]:
                continue
            block = {}
            for metric in METRICS + ("excess_spike_difference",):
                vals = [d["ratios"][name][v.name].get(metric) for d in docs.values()]
                if metric == "excess_spike" and all(
                        d["ratios"][name][v.name].get("excess_spike_difference") is not None
                        for d in docs.values()) and any(x is None for x in vals):
                    # the EKF's excess is within its noise on some seed (pairing.MIN_EXCESS)
                    block[metric] = {"per_seed": vals, "mean": None, "ci95": [None, None]}
                    continue
                if any(x is None for x in vals):
                    continue
                m, lo, hi = interval(vals)
                block[metric] = {"per_seed": vals, "mean": m, "ci95": [lo, hi]}
            for key, label in ((v.irls_key, "irls"), (v.ekf_key, "ekf")):
                per = [d["scenarios"][name][key] for d in docs.values()]
                block[label] = {
                    "rmse": _mean([float(np.mean(p["rmse"])) for p in per]),
                    "spike": _mean([mean_or_none(p["spike"]) for p in per]),
                    "excess_spike": _mean([mean_or_none(p["excess_spike"]) for p in per]),
                    "cli": per[0]["cli"]}
            block["q_eta"] = [d["scenarios"][name][v.ekf_key]["q_eta"] for d in docs.values()]
            out.setdefault(name, {})[v.name] = block
    return out


def _cell(b, d=2) -> str:
    if b is None:
        return "-"
    if b["mean"] is None:
        return "n/a (EKF excess ~0)"
    return f"{b['mean']:.{d}f} [{b['ci95'][0]:.{d}f}, {b['ci95'][1]:.{d}f}]"


def print_summary(summary: dict, seeds: list[int]) -> None:
    print(f"\nIRLS / EKF partner (identical post-processing), seeds {seeds[0]}-{seeds[-1]}: "
          "mean [95 % interval] of the per-seed ratio")
    print(f"{'scenario':<10} {'variant':<9} " + " ".join(f"{m + ' ratio':>26}" for m in METRICS)
          + f" {'excess IRLS - EKF':>26}")
    for name, per in summary.items():
        for v, b in per.items():
            cells = [_cell(b.get(m)) for m in METRICS]
            if "excess_spike_difference" in b:
                cells.append(_cell(b["excess_spike_difference"], 4))
            print(f"{name:<10} {v:<9} " + " ".join(f"{c:>26}" for c in cells))
    print("\nmotor averages over the seeds (mean of IRLS / EKF)")
    print(f"{'scenario':<10} {'variant':<9} {'RMSE':>15} {'spike':>15} {'excess':>17}  Q_eta")
    for name, per in summary.items():
        for v, b in per.items():
            i, e = b["irls"], b["ekf"]
            if i["spike"] is None:
                spikes = f"{'-':>15} {'-':>17}"
            else:
                spikes = (f"{i['spike']:.4f}/{e['spike']:.4f} {i['excess_spike']:+.4f}/"
                          f"{e['excess_spike']:+.4f}")
            print(f"{name:<10} {v:<9} {i['rmse']:.4f}/{e['rmse']:.4f} {spikes}  "
                  + ", ".join(f"{q:.3g}" for q in b["q_eta"]))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, help="folder of the per-seed runs and summary.json")
    p.add_argument("--seeds", default="0-4", help="seeds, e.g. 0-4 or 0,2,3 (default 0-4)")
    p.add_argument("--quick", action="store_true", help="reproduce --quick (12 s flights)")
    p.add_argument("--workers", type=int, default=2)
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    seeds = seeds_of(args.seeds)
    docs = {k: run_seed(out, k, args.quick, args.workers) for k in seeds}
    summary = summarise(docs)
    # summary.json is derived from the per-seed runs: rewritten on every call
    atomic_write_text(out / "summary.json", json.dumps(
        {"seeds": seeds, "quick": args.quick, "ratios": summary}, indent=2) + "\n", force=True)
    print_summary(summary, seeds)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
