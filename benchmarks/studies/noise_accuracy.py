"""Every estimator's accuracy under sensor noise, against the targets an estimator must meet
with real sensors.

    python benchmarks/studies/noise_accuracy.py [--noise none] [--noise PRESET|P,V,A,G,ACC ...]
                                                [--seeds 0-4] [--duration 80]
                                                [--weak-duration 20] [--json OUT.json]
                                                [--mixer yaw-release|plain]

For each sensor noise (``--noise``, repeatable: ``none``, a preset name of
``quadfault simulate --sensor-noise`` or the white-noise stds ``P,V,A,G,ACC``) and each seed,
it flies the four scenarios of ``quadfault reproduce`` (degradation, abrupt, combined,
clipping; sigma_f = 0.07, the clipping flight saturated) and runs every estimator as
``quadfault estimate`` runs it by default (``irls``: the paper's; ``irls --improved``; ``ekf``,
``rls``, ``ukf``), the IRLS and the RLS with their thrust rows from the accelerometer
(``--accelerometer on``; ``irls --improved`` uses it by default) and the EKF and the UKF with
its measurement row (``--accelerometer on``). It prints, as means over the
seeds:

* RMSE: the motor-averaged RMSE of :func:`estimators.metrics.score` (warm-up excluded), per
  scenario; target <= 0.04;
* healthy bias: the mean error of the rotors outside their own fault windows (the band and
  padding of :func:`estimators.metrics.window_masks`), over the four scenarios; target
  within +-0.02;
* FDI: the abrupt faults (abrupt, combined, clipping) detected and isolated by
  :mod:`estimators.fdi` (the ``fdi`` entry of ``metrics.json``), the largest latency and the
  false alarms; target every fault within 0.05 s, no false alarm;
* weak rotor: flights of ``--weak-duration`` on the Lissajous curve and on the circle with one
  rotor at 0.7, 0.8 or 0.9 (rotor and level from the seed); the rotor named weakest (lowest
  mean estimate after 2 s) must be the weak one; target every flight.

Every flight is checked first (:func:`estimators.paper.reproduce.flight_check`: rotor
commands beyond 5x hover thrust on more than 1 % of the rows, or more than 10 m from the
start): a flight that lost control is counted in ``flights lost`` and scored by no estimator
(its numbers would say nothing about the estimators); the means are over the flights that
held. A figure that misses its target is marked with ``*``. Speed is not measured here
(``benchmarks/bench_irls.py``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

ESTIMATORS = {
    "irls": ("irls", {}),
    "irls --accelerometer on": ("irls", {"accelerometer": "on"}),
    "irls --improved": ("irls", {"improved": True}),
    "ekf": ("ekf", {}),
    "ekf --accelerometer on": ("ekf", {"accelerometer": "on"}),
    "rls": ("rls", {}),
    "rls --accelerometer on": ("rls", {"accelerometer": "on"}),
    "ukf": ("ukf", {}),
    "ukf --accelerometer on": ("ukf", {"accelerometer": "on"}),
}
SCENARIOS = ("degradation", "abrupt", "combined", "clipping")
LEVELS = (0.7, 0.8, 0.9)
TARGET = {"rmse": 0.04, "bias": 0.02, "latency": 0.05}


def seeds_of(text: str) -> list[int]:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(x) for x in text.split(",")]


def sensor_noise(text: str):
    """``none``, a preset name or ``P,V,A,G[,ACC]``: a SensorNoise."""
    from quadfault.model.sensors import SensorNoise

    if text == "none":
        return SensorNoise()
    try:
        from quadfault.model.sensor_presets import as_sensor_noise
    except ImportError:  # white noise only
        return SensorNoise(*(float(x) for x in text.split(",")))
    return as_sensor_noise(text)


#: the controller's mixer (``--mixer``): True gives up yaw first at the rotors' bounds
YAW_RELEASE = {"yaw-release": True, "plain": False}


def fly(scenario, noise, seed: int, saturate: bool, yaw_release: bool = True):
    from quadfault.model.controller import ControllerConfig
    from quadfault.sim.simulator import SimConfig, simulate

    controller = ControllerConfig(yaw_release=yaw_release)
    config = SimConfig(saturate=saturate, sensor_noise=noise, controller=controller)
    return simulate(scenario, config=config, seed=seed, thrust_noise=0.07)


def healthy_errors(rec, series) -> np.ndarray:
    """The errors of every rotor outside its own fault windows (warm-up excluded)."""
    from estimators.base import STATUS_WARMUP
    from estimators.metrics import aligned_truth, fault_windows, window_masks

    t, truth = aligned_truth(rec, series, "end", None)
    keep = np.asarray(series.status) != STATUS_WARMUP
    e = series.eta - truth
    windows = fault_windows(rec)
    own = (
        window_masks(t, truth, windows)
        if windows
        else np.zeros((truth.shape[1], len(t)), dtype=bool)
    )
    return np.concatenate([e[keep & ~own[m], m] for m in range(truth.shape[1])])


def scenario_runs(noise, seed: int, duration: float, yaw_release: bool = True) -> dict:
    """Every estimator on the four scenarios of one seed."""
    from estimators.cli import estimate_series
    from estimators.fdi import detect, evaluate
    from estimators.metrics import fault_windows, score
    from estimators.paper.reproduce import flight_check
    from quadfault.model.scenarios import named_scenario

    out = {
        key: {"rmse": {}, "healthy": [], "latency": [], "missed": 0, "false": 0}
        for key in ESTIMATORS
    }
    lost = []
    for name in SCENARIOS:
        scenario = named_scenario(name, duration)
        rec = fly(scenario, noise, seed, saturate=name == "clipping", yaw_release=yaw_release)
        if flight_check(rec)["diverged"]:
            lost.append(name)
            for r in out.values():
                r["rmse"][name] = math.nan
            continue
        windows = fault_windows(rec)
        for key, (est, options) in ESTIMATORS.items():
            series = estimate_series(rec, est, **options)
            r = out[key]
            r["rmse"][name] = float(np.mean(score(rec, series).rmse))
            r["healthy"].append(healthy_errors(rec, series))
            if windows:
                fdi = evaluate(detect(series), windows)
                r["latency"] += [math.inf if x is None else x for x in fdi.latencies]
                r["missed"] += fdi.missed
                r["false"] += fdi.false_alarms
    for r in out.values():
        r["healthy"] = float(np.mean(np.concatenate(r["healthy"]))) if r["healthy"] else math.nan
    return {"estimators": out, "lost": lost}


def weak_runs(noise, seed: int, duration: float, yaw_release: bool = True) -> dict:
    """Is the weak rotor named weakest, on the Lissajous curve and on the circle?"""
    from estimators.cli import estimate_series
    from quadfault.model.scenarios import (
        AbruptFault,
        ConstantEfficiency,
        EfficiencySchedule,
        Scenario,
    )
    from quadfault.model.trajectory import Circle, Lissajous

    motor, level = seed % 4 + 1, LEVELS[seed % len(LEVELS)]
    sched = EfficiencySchedule(
        ConstantEfficiency(), (AbruptFault(motor=motor, onset=0.0, level=level),)
    )
    from estimators.paper.reproduce import flight_check

    out: dict = {key: [] for key in ESTIMATORS}
    lost = []
    for traj in (Lissajous(), Circle()):
        scenario = Scenario("weak", duration, sched, traj)
        rec = fly(scenario, noise, seed, saturate=False, yaw_release=yaw_release)
        if flight_check(rec)["diverged"]:
            lost.append(type(traj).__name__.lower())
            continue
        for key, (est, options) in ESTIMATORS.items():
            s = estimate_series(rec, est, **options)
            mean = s.eta[s.t >= 2.0].mean(axis=0)
            out[key].append(int(np.argmin(mean)) + 1 == motor)
    return {"estimators": out, "lost": lost}


def mark(ok: bool) -> str:
    return "" if ok else "*"


def table(label: str, runs_in: list, weak_in: list) -> tuple[str, dict]:
    lost = [f"{name} seed {k}" for k, r in runs_in for name in r["lost"]]
    lost += [f"weak {name} seed {k}" for k, w in weak_in for name in w["lost"]]
    flights = sum(len(SCENARIOS) + 2 for _ in runs_in)
    runs = [r["estimators"] for _, r in runs_in]
    weak = [w["estimators"] for _, w in weak_in]
    lines = [
        f"\nsensor noise: {label}  (means over {len(runs)} seeds, over the flights that held; "
        f"* misses its target)\n",
        f"flights lost: {len(lost)} of {flights}" + (f" ({', '.join(lost)})" if lost else ""),
        "",
        "| estimator | "
        + " | ".join(f"RMSE {s}" for s in SCENARIOS)
        + " | healthy bias | FDI detected | max latency [s] | false alarms | weak rotor named |",
        "|---" * (len(SCENARIOS) + 6) + "|",
    ]
    summary = {}
    for key in ESTIMATORS:
        rmse = {s: _mean([r[key]["rmse"][s] for r in runs]) for s in SCENARIOS}
        bias = _mean([r[key]["healthy"] for r in runs])
        lat = [x for r in runs for x in r[key]["latency"]]
        detected = sum(math.isfinite(x) for x in lat)
        worst = max(lat) if lat else math.nan
        false = sum(r[key]["false"] for r in runs)
        named = [x for w in weak for x in w[key]]
        cells = [
            f"{rmse[s]:.4f}{mark(rmse[s] <= TARGET['rmse'])}" if math.isfinite(rmse[s]) else "lost"
            for s in SCENARIOS
        ]
        lines.append(
            f"| {key} | "
            + " | ".join(cells)
            + f" | {bias:+.4f}{mark(abs(bias) <= TARGET['bias'])}"
            + f" | {detected}/{len(lat)}{mark(detected == len(lat))}"
            + f" | {worst:.3f}{mark(worst <= TARGET['latency'])}"
            + f" | {false}{mark(false == 0)}"
            + f" | {sum(named)}/{len(named)}{mark(all(named))} |"
        )
        summary[key] = {
            "rmse": rmse,
            "healthy_bias": bias,
            "fdi_detected": detected,
            "fdi_faults": len(lat),
            "fdi_max_latency": worst,
            "false_alarms": false,
            "weak_named": sum(named),
            "weak_flights": len(named),
        }
    summary["flights_lost"] = lost
    summary["flights"] = flights
    return "\n".join(lines), summary


def _mean(values) -> float:
    """The mean of the finite values (NaN: a lost flight), NaN when none is."""
    finite = [v for v in values if math.isfinite(v)]
    return float(np.mean(finite)) if finite else math.nan


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--noise", action="append", help="none, a preset or P,V,A,G,ACC (repeatable)")
    p.add_argument("--seeds", default="0-4")
    p.add_argument("--duration", type=float, default=80.0, help="scenario flights [s]")
    p.add_argument("--weak-duration", type=float, default=20.0, help="weak-rotor flights [s]")
    p.add_argument("--json", help="write the summary here")
    p.add_argument(
        "--mixer",
        choices=sorted(YAW_RELEASE),
        default="yaw-release",
        help="the controller's mixer: yaw given up first at the rotors' bounds (default) or "
        "the plain allocation inverse",
    )
    args = p.parse_args(argv)
    yaw_release = YAW_RELEASE[args.mixer]
    seeds = seeds_of(args.seeds)
    doc = {"seeds": seeds, "duration": args.duration, "results": {}}
    start = time.process_time()
    for label in args.noise or ["none"]:
        noise = sensor_noise(label)
        runs = [(k, scenario_runs(noise, k, args.duration, yaw_release)) for k in seeds]
        weak = [(k, weak_runs(noise, k, args.weak_duration, yaw_release)) for k in seeds]
        text, summary = table(label, runs, weak)
        print(text, flush=True)
        doc["results"][label] = summary
    print(f"\n{time.process_time() - start:.0f} CPU-s", file=sys.stderr)
    if args.json:
        from pathlib import Path

        from quadfault.fileio import atomic_write_text

        atomic_write_text(Path(args.json), json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
