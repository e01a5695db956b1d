"""Accuracy, FDI and speed of the EKF baseline beside IRLS, measured side by side in one run.

    python benchmarks/studies/bench_accuracy.py                 # 80 s flights, 5 seeds (~5 min)
    python benchmarks/studies/bench_accuracy.py --duration 20 --seeds 2    # a quick look
    python benchmarks/studies/bench_accuracy.py --improved --no-speed      # + IRLSConfig.improved()

Prints:

1. speed: updates per second of the EKF and IRLS, numpy and numba paths, on the same flight,
   and their ratios (EKF / IRLS);
2. FDI: per scenario (abrupt, combined, nominal, degradation) and estimator, faults detected
   and isolated to the right motor, worst latency, false alarms, summed over the seeds
   (target: every abrupt drop to 0.5 within 0.1 s, no false alarm on nominal / degradation);
3. accuracy: motor-averaged RMSE and spike per scenario, mean over the seeds.

Flights use ``quadfault reproduce``'s settings (``estimators.paper.reproduce.sim_config``: no upper
thrust limit, as in the paper). The EKF's Q_eta is calibrated first (as ``quadfault
reproduce`` does) unless ``--q-eta``.

With ``--improved`` the beyond-the-paper IRLS (``IRLSConfig.improved()``, docs/irls.md) runs
too, with its own EKF calibrated to its RMSE on the same calibration flight (seed 1000), and
the spike ratio IRLS / EKF of both pairs is printed per seed (target <= 0.5 on abrupt and
combined). The calibration flight's seed is never one of the scored seeds (0..seeds-1).
``--ekf-median`` adds a fairness check, ``ekf+m``: the improved IRLS's EKF (same ``Q_eta``)
with the same 21-sample output median. (Calibrating the median-filtered EKF to the improved
IRLS's RMSE is degenerate: with the median its RMSE stays below the target from ~5e-3 up to
``Q_eta`` = 10, so the only crossing is on the slow branch, ~5e-3, a filter that lags every
fault.)
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from estimators.ekf import EKFConfig, MotorEfficiencyEKF
from estimators.fdi import detect, evaluate
from estimators.irls import IRLSConfig, SlidingWindowIRLS
from estimators.median import median_series
from estimators.metrics import fault_windows, mean_or_none, score
from estimators.paper.calibration import calibrate_q_eta
from estimators.paper.reproduce import flight_check, sim_config
from quadfault.model.scenarios import named_scenario
from quadfault.sim.simulator import simulate

SCENARIOS = ("abrupt", "combined", "nominal", "degradation")


def speed(duration: float) -> None:
    rec = simulate(
        named_scenario("combined", duration), config=sim_config("rk4", "combined"), seed=0
    ).without_truth()
    rows = {}
    veh = rec.vehicle
    for label, est in (("EKF", MotorEfficiencyEKF(veh)), ("IRLS", SlidingWindowIRLS(veh))):
        est.run(rec.slice(0, 50))  # compile / warm up
        t0 = time.perf_counter()
        est.run(rec)
        rows[label] = len(rec) / (time.perf_counter() - t0)
    print("speed [updates/s]")
    for k, v in rows.items():
        print(f"  {k:<5} {v:10.0f}")
    print(f"  ratio EKF/IRLS {rows['EKF'] / rows['IRLS']:.2f}")


def flight(
    name: str,
    seed: int,
    duration: float,
    q_eta: float,
    q_improved: float | None = None,
    q_median: float | None = None,
) -> dict:
    rec = simulate(named_scenario(name, duration), config=sim_config("rk4", name), seed=seed)
    blind = rec.without_truth()
    out = {"diverged": flight_check(rec)["diverged"]}
    runs = [
        ("irls", SlidingWindowIRLS(rec.vehicle)),
        ("ekf", MotorEfficiencyEKF(rec.vehicle, EKFConfig(q_eta=q_eta))),
    ]
    if q_improved is not None:
        runs += [
            ("irls+", SlidingWindowIRLS(rec.vehicle, IRLSConfig.improved())),
            ("ekf+", MotorEfficiencyEKF(rec.vehicle, EKFConfig(q_eta=q_improved))),
        ]
    if q_median is not None:
        runs += [("ekf+m", MotorEfficiencyEKF(rec.vehicle, EKFConfig(q_eta=q_median)))]
    for key, est in runs:
        s = est.run(blind)
        if key == "ekf+m":
            s = median_series(s, IRLSConfig.improved().output_median)
        sc = score(rec, s)
        out[key] = {
            "rmse": float(np.mean(sc.rmse)),
            "spike": mean_or_none(sc.spike),
            "excess": mean_or_none(sc.excess_spike),
            "fdi": evaluate(detect(s), fault_windows(rec)),
        }
    return out


def calibrate(duration: float, irls_config: IRLSConfig, post_median: int = 1):
    """The EKF's Q_eta matching ``irls_config``'s RMSE on the combined flight of seed 1000
    (the EKF's output median-filtered over ``post_median`` rows when > 1)."""
    cal_rec = simulate(
        named_scenario("combined", min(duration, 40.0)),
        config=sim_config("rk4", "combined"),
        seed=1000,
    )
    target = float(
        np.mean(
            score(
                cal_rec,
                SlidingWindowIRLS(cal_rec.vehicle, irls_config).run(cal_rec.without_truth()),
            ).rmse
        )
    )
    return calibrate_q_eta(
        cal_rec, target, q_range=(1e-4, 10.0), bisection_steps=6, post_median=post_median
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=80.0)
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--q-eta", type=float, default=None)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument(
        "--improved",
        action="store_true",
        help="also IRLSConfig.improved() and an EKF calibrated to it",
    )
    p.add_argument("--no-speed", action="store_true", help="skip the speed section")
    p.add_argument(
        "--ekf-median",
        action="store_true",
        help="with --improved: also the improved IRLS's EKF with the same output "
        "median (fairness check)",
    )
    p.add_argument(
        "--scenarios",
        default=",".join(SCENARIOS),
        help="comma-separated subset of " + ", ".join(SCENARIOS),
    )
    args = p.parse_args()
    if not args.no_speed:
        speed(min(args.duration, 20.0))
    q = args.q_eta
    if q is None:
        cal = calibrate(args.duration, IRLSConfig())
        q = cal.q_eta
        print(f"calibration: {cal.message}")
    q_plus = q_med = None
    if args.improved:
        cal = calibrate(args.duration, IRLSConfig.improved())
        q_plus = cal.q_eta
        print(f"calibration (improved IRLS): {cal.message}")
        if args.ekf_median:
            q_med = q_plus
    scenarios = [n for n in SCENARIOS if n in args.scenarios.split(",")]
    jobs = [(n, s) for n in scenarios for s in range(args.seeds)]
    with ProcessPoolExecutor(args.workers) as pool:
        res = list(
            pool.map(
                flight,
                [j[0] for j in jobs],
                [j[1] for j in jobs],
                [args.duration] * len(jobs),
                [q] * len(jobs),
                [q_plus] * len(jobs),
                [q_med] * len(jobs),
            )
        )
    lost = [j for j, r in zip(jobs, res) if r["diverged"]]
    if lost:
        print(f"WARNING: flights that lost control: {lost}")
    print(
        f"\nFDI and accuracy over {args.seeds} seeds, {args.duration:g} s flights, "
        f"EKF Q_eta = {q:.4g}"
    )
    print(
        f"{'scenario':<12} {'est':<5} {'detected':>9} {'worst lat [s]':>14} {'false':>6} "
        f"{'RMSE':>7} {'spike':>7} {'excess':>7}"
    )
    keys = ("irls", "ekf", "irls+", "ekf+") if args.improved else ("irls", "ekf")
    keys += ("ekf+m",) if q_med is not None else ()
    for name in scenarios:
        for est in keys:
            rs = [r[est] for (n, _), r in zip(jobs, res) if n == name]
            det = sum(r["fdi"].detected for r in rs)
            tot = sum(len(r["fdi"].latencies) for r in rs)
            lat = [x for r in rs for x in r["fdi"].latencies if x is not None]
            false = sum(r["fdi"].false_alarms for r in rs)
            spikes = [r["spike"] for r in rs if r["spike"] is not None]
            excess = [r["excess"] for r in rs if r["excess"] is not None]
            worst = max(lat) if lat else float("nan")
            print(
                f"{name:<12} {est:<5} {det:>4}/{tot:<4} {worst:>14.3f} {false:>6}"
                f" {np.mean([r['rmse'] for r in rs]):>7.4f} "
                f"{(np.mean(spikes) if spikes else float('nan')):>7.4f} "
                f"{(np.mean(excess) if excess else float('nan')):>7.4f}"
            )
    pairs = [("paper", "irls", "ekf")] + ([("improved", "irls+", "ekf+")] if args.improved else [])
    pairs += [("vs ekf+m", "irls+", "ekf+m")] if q_med is not None else []
    print(
        "\nper seed: IRLS spike / EKF spike = ratio (motor averages; target <= 0.5), "
        "IRLS RMSE (target <= 0.025)"
    )
    for name in [n for n in ("abrupt", "combined") if n in scenarios]:
        for label, a, b in pairs:
            cells = [
                f"{r[a]['spike']:.3f}/{r[b]['spike']:.3f}={r[a]['spike'] / r[b]['spike']:.2f}"
                f" ({r[a]['rmse']:.4f})"
                for (n, _), r in zip(jobs, res)
                if n == name
            ]
            print(f"  {name:<9} {label:<9} " + "  ".join(cells))


if __name__ == "__main__":
    main()
