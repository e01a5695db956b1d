"""Which rotor losses can be survived at all: hover, one rotor drops abruptly to ``eta``.

Flies :func:`quadfault.model.task_scenarios.rotor_loss_scenario`'s situation with fixed draws (rotor
1, onset 3 s, 10 s flight, hover at 1 m) through the public API (:func:`agents.rollout.fly`)
for each level, with the plain geometric controller, the estimate-aware controller fed by
the online IRLS estimate, and the estimate-aware controller fed by the true efficiency (the
oracle). It prints, per level and controller, whether the vehicle survived, the crash time,
the largest and final position error after the loss and the tracking RMSE.

    python benchmarks/rotor_loss_survival.py [--levels 0 0.1 0.2 0.3 0.4 0.5] [--seeds 0 1 2]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from agents.rollout import fly
from quadfault.model.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Hover

ARMS = (("geometric", "none"), ("estimate-aware", "irls"), ("estimate-aware", "truth"))


def scenario(level: float, onset: float, duration: float, motor: int = 1) -> Scenario:
    fault = AbruptFault(motor=motor, onset=onset, level=level)
    return Scenario(
        f"rotor_loss_{level:g}",
        duration,
        EfficiencySchedule(ConstantEfficiency(), (fault,)),
        Hover(),
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=float, nargs="+", default=[0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--onset", type=float, default=3.0)
    ap.add_argument("--duration", type=float, default=10.0)
    args = ap.parse_args(argv)
    start = time.process_time()
    print(
        "| eta after loss | controller (estimate) | survived | crash time [s] | "
        "max error after loss [m] | final error [m] | RMSE [m] |"
    )
    print("|---|---|---|---|---|---|---|")
    for level in args.levels:
        sc = scenario(level, args.onset, args.duration)
        for ctrl, est in ARMS:
            fl = [fly(sc, ctrl, est, seed) for seed in args.seeds]
            ok = sum(not f.metrics.crashed for f in fl)
            crash = [f.metrics.crash_time for f in fl if f.metrics.crashed]
            after = [f.pos_error[f.t >= args.onset] for f in fl]
            peak = max(float(np.max(a)) if a.size else math.nan for a in after)
            final = max(float(f.pos_error[-1]) for f in fl)
            rmse = float(np.mean([f.metrics.rmse for f in fl]))
            crash_s = "-" if not crash else f"{min(crash):.2f}-{max(crash):.2f}"
            print(
                f"| {level:g} | {ctrl} ({est}) | {ok}/{len(fl)} | {crash_s} | {peak:.3f} | "
                f"{final:.3f} | {rmse:.3f} |"
            )
    print(f"\n{time.process_time() - start:.0f} CPU-s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
