"""IRLS against its partners (the EKF, RLS, the UKF) over several seeds: the ratios of
``quadfault reproduce`` with means and 95 % intervals.

    python benchmarks/fair_comparison.py --out DIR [--seeds 0-4] [--quick] [--workers 2]
                                                 [--sensor-noise PRESET]

For every seed K it runs ``quadfault reproduce --seed K --no-reference-mode --out DIR/seed-K``
(skipped when ``DIR/seed-K/metrics.json`` exists, so an interrupted study resumes), then
prints, per baseline, scenario and variant, the IRLS / partner ratios of the motor-averaged raw
spike, excess spike and RMSE: each seed's value, the mean and the 95 % Student-t interval of
the mean, and the motor-averaged numbers behind them. ``DIR/summary.json`` holds the same
(``ratios``: against the EKF; ``baselines``: every baseline). Every ratio is against a partner
given the identical post-processing and tuned on the calibration flight (docs/reproduce.md).
With ``--sensor-noise`` every flight, the calibration flight's too, has those sensors
(``quadfault reproduce --sensor-noise``), so each partner is tuned with the same noise.
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


def run_seed(out: Path, seed: int, quick: bool, workers: int, noise: str | None = None) -> dict:
    path = out / f"seed-{seed}"
    if not (path / "metrics.json").exists():
        cmd = [
            sys.executable,
            "-m",
            "quadfault.cli",
            "reproduce",
            "--seed",
            str(seed),
            "--no-reference-mode",
            "--out",
            str(path),
            "--workers",
            str(workers),
            "--quiet",
            "--force",
        ] + (["--quick"] if quick else [])
        cmd += ["--sensor-noise", noise] if noise else []
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


def _ratios(doc: dict, baseline: str) -> dict:
    return doc.get("baseline_ratios", {}).get(baseline) or (
        doc["ratios"] if baseline == "ekf" else {}
    )


def summarise(docs: dict, baseline: str = "ekf") -> dict:
    """``{scenario: {variant: {metric: {"per_seed", "mean", "ci95"}, "irls": {...},
    "ekf": {...}, "tuning": [...]}}}`` over the seeds' metrics.json, against the partners of
    ``baseline`` (the ``"ekf"`` key holds that partner's numbers whatever it is)."""
    from estimators.metrics import mean_or_none
    from estimators.paper.pairing import BASELINES, VARIANTS

    out: dict = {}
    option = BASELINES[baseline].option
    first = _ratios(next(iter(docs.values())), baseline)
    for name in first:
        for v in VARIANTS:
            if v.name not in first[name]:
                continue
            block = {}
            ratios = [_ratios(d, baseline)[name][v.name] for d in docs.values()]
            for metric in METRICS + ("excess_spike_difference",):
                vals = [r.get(metric) for r in ratios]
                if (
                    metric == "excess_spike"
                    and all(r.get("excess_spike_difference") is not None for r in ratios)
                    and any(x is None for x in vals)
                ):
                    # the partner's excess is within its noise on some seed (pairing.MIN_EXCESS)
                    block[metric] = {"per_seed": vals, "mean": None, "ci95": [None, None]}
                    continue
                if any(x is None for x in vals):
                    continue
                m, lo, hi = interval(vals)
                block[metric] = {"per_seed": vals, "mean": m, "ci95": [lo, hi]}
            for key, label in ((v.irls_key, "irls"), (v.key(baseline), "ekf")):
                per = [d["scenarios"][name][key] for d in docs.values()]
                block[label] = {
                    "rmse": _mean([float(np.mean(p["rmse"])) for p in per]),
                    "spike": _mean([mean_or_none(p["spike"]) for p in per]),
                    "excess_spike": _mean([mean_or_none(p["excess_spike"]) for p in per]),
                    "cli": per[0]["cli"],
                }
            block["tuning"] = [d["scenarios"][name][v.key(baseline)][option] for d in docs.values()]
            if baseline == "ekf":
                block["q_eta"] = block["tuning"]
            out.setdefault(name, {})[v.name] = block
    return out


def _cell(b, d=2) -> str:
    if b is None:
        return "-"
    if b["mean"] is None:
        return "n/a (EKF excess ~0)"
    return f"{b['mean']:.{d}f} [{b['ci95'][0]:.{d}f}, {b['ci95'][1]:.{d}f}]"


def print_summary(summary: dict, seeds: list[int], baseline: str = "ekf") -> None:
    B = baseline.upper()
    print(
        f"\nIRLS / {B} partner (identical post-processing), seeds {seeds[0]}-{seeds[-1]}: "
        "mean [95 % interval] of the per-seed ratio"
    )
    print(
        f"{'scenario':<10} {'variant':<9} "
        + " ".join(f"{m + ' ratio':>26}" for m in METRICS)
        + f" {'excess IRLS - ' + B:>26}"
    )
    for name, per in summary.items():
        for v, b in per.items():
            cells = [_cell(b.get(m)) for m in METRICS]
            if "excess_spike_difference" in b:
                cells.append(_cell(b["excess_spike_difference"], 4))
            print(f"{name:<10} {v:<9} " + " ".join(f"{c:>26}" for c in cells))
    print(f"\nmotor averages over the seeds (mean of IRLS / {B})")
    knob = "forgetting" if baseline == "rls" else "Q_eta"
    print(f"{'scenario':<10} {'variant':<9} {'RMSE':>15} {'spike':>15} {'excess':>17}  {knob}")
    for name, per in summary.items():
        for v, b in per.items():
            i, e = b["irls"], b["ekf"]
            if i["spike"] is None:
                spikes = f"{'-':>15} {'-':>17}"
            else:
                spikes = (
                    f"{i['spike']:.4f}/{e['spike']:.4f} {i['excess_spike']:+.4f}/"
                    f"{e['excess_spike']:+.4f}"
                )
            print(
                f"{name:<10} {v:<9} {i['rmse']:.4f}/{e['rmse']:.4f} {spikes}  "
                + ", ".join(f"{q:.4g}" for q in b["tuning"])
            )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, help="folder of the per-seed runs and summary.json")
    p.add_argument("--seeds", default="0-4", help="seeds, e.g. 0-4 or 0,2,3 (default 0-4)")
    p.add_argument("--quick", action="store_true", help="reproduce --quick (12 s flights)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument(
        "--sensor-noise",
        metavar="PRESET",
        help="the sensors of every flight (a preset or P,V,A,G[,ACC]; default none)",
    )
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    seeds = seeds_of(args.seeds)
    docs = {k: run_seed(out, k, args.quick, args.workers, args.sensor_noise) for k in seeds}
    from estimators.paper.pairing import BASELINES

    first = next(iter(docs.values()))
    baselines = [b for b in BASELINES if b == "ekf" or first.get("baseline_ratios", {}).get(b)]
    summaries = {b: summarise(docs, b) for b in baselines}
    # summary.json is derived from the per-seed runs: rewritten on every call
    atomic_write_text(
        out / "summary.json",
        json.dumps(
            {
                "seeds": seeds,
                "quick": args.quick,
                "sensor_noise": args.sensor_noise or "none",
                "ratios": summaries["ekf"],
                "baselines": summaries,
            },
            indent=2,
        )
        + "\n",
        force=True,
    )
    for b, summary in summaries.items():
        print_summary(summary, seeds, b)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
