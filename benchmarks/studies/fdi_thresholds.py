"""Where the fault detector stands under sensor noise, and what its settings buy.

    python benchmarks/studies/fdi_thresholds.py [--noise crazyflie] [--seeds 0-2]
                                               [--duration 20] [--estimator ekf:q_eta=0.002 ...]

For each seed it flies the three scenarios of ``quadfault reproduce`` with abrupt faults
(abrupt, combined, clipping; sigma_f = 0.07, the clipping flight saturated; 4 faults each) with
the sensors ``--noise`` (a preset name, as ``benchmarks/studies/noise_accuracy.py``), runs each
``--estimator`` (``NAME[:option=value,...]``: ``quadfault estimate``'s options, e.g.
``irls:improved=1`` or ``ekf:q_eta=0.002``) once, and scores :mod:`estimators.fdi` on the same
estimates at a grid of detector settings (``threshold``, ``tau_smooth``, ``confirm``; the
others at their defaults). Per estimator and setting it prints the faults detected and isolated,
those within 50 ms (the ``fdi`` target of ``metrics.json``: every abrupt fault within 50 ms, no
false alarm) and the false alarms over every flight.
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from noise_accuracy import fly, seeds_of, sensor_noise  # noqa: E402

SCENARIOS = ("abrupt", "combined", "clipping")
THRESHOLDS = (0.1, 0.15, 0.2, 0.3)
SMOOTHING = (0.01, 0.03)
CONFIRM = (0.01, 0.02)
TARGET_LATENCY = 0.05


def parse_estimator(text: str) -> tuple[str, str, dict]:
    """``NAME[:option=value,...]`` -> (label, name, options)."""
    name, _, rest = text.partition(":")
    options = {}
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        options[key] = True if value in ("1", "true") else _number_or_word(value)
    return text, name, options


def _number_or_word(value: str):
    """An option's value: a number where it reads as one (``q_eta=0.002``), else the word
    (``accelerometer=auto``)."""
    try:
        return float(value)
    except ValueError:
        return value


def main(argv=None) -> int:
    from estimators.cli import estimate_series
    from estimators.fdi import FDIConfig, detect, evaluate
    from estimators.metrics import fault_windows
    from quadfault.model.scenarios import named_scenario

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--noise", default="crazyflie", help="none or a preset")
    p.add_argument("--seeds", default="0-2")
    p.add_argument("--duration", type=float, default=20.0, help="scenario flights [s]")
    p.add_argument(
        "--estimator",
        action="append",
        help="NAME[:option=value,...] (repeatable; default irls:improved=1 and ekf)",
    )
    args = p.parse_args(argv)
    estimators = [parse_estimator(e) for e in (args.estimator or ["irls:improved=1", "ekf"])]
    noise = sensor_noise(args.noise)
    grid = list(itertools.product(THRESHOLDS, SMOOTHING, CONFIRM))
    tally = {(e[0], g): [0, 0, 0, 0] for e in estimators for g in grid}  # det, fast, faults, FA
    for seed in seeds_of(args.seeds):
        for name in SCENARIOS:
            rec = fly(named_scenario(name, args.duration), noise, seed, saturate=name == "clipping")
            windows = fault_windows(rec)
            for label, est, options in estimators:
                series = estimate_series(rec, est, **options)
                for g in grid:
                    th, ts, cf = g
                    fdi = evaluate(
                        detect(series, FDIConfig(threshold=th, tau_smooth=ts, confirm=cf)),
                        windows,
                    )
                    t = tally[(label, g)]
                    lat = [math.inf if x is None else x for x in fdi.latencies]
                    t[0] += sum(math.isfinite(x) for x in lat)
                    t[1] += sum(x <= TARGET_LATENCY for x in lat)
                    t[2] += len(lat)
                    t[3] += fdi.false_alarms
    print(
        f"\nsensor noise: {args.noise}; seeds {args.seeds}; {len(SCENARIOS)} scenarios of "
        f"{args.duration:g} s per seed\n"
    )
    print(
        "| estimator | threshold | tau_smooth [s] | confirm [s] | detected | within 50 ms | false alarms |"
    )
    print("|---|---|---|---|---|---|---|")
    for label, _, _ in estimators:
        for g in grid:
            det, fast, faults, fa = tally[(label, g)]
            print(
                f"| {label} | {g[0]:g} | {g[1]:g} | {g[2]:g} | {det}/{faults} | {fast}/{faults} | {fa} |"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
