"""Calibrated EKF uncertainty: fit ``calibrate_sd_scale`` on a calibration flight, report the
one-sigma coverage of the raw and the scaled ``sd`` on held-out seeds and scenarios.

    python benchmarks/studies/ekf_sd_calibration.py                      # 20 s flights, Q_eta 0.5
    python benchmarks/studies/ekf_sd_calibration.py --q-eta 1.778 --duration 80
"""

from __future__ import annotations

import argparse

import numpy as np

from estimators.ekf import EKFConfig, MotorEfficiencyEKF
from estimators.metrics import score
from estimators.paper.calibration import calibrate_sd_scale
from quadfault.model.scenarios import named_scenario
from quadfault.sim.simulator import simulate


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--q-eta", type=float, default=0.5)
    p.add_argument("--duration", type=float, default=20.0)
    p.add_argument("--calibration", default="combined", help="scenario of the calibration flight")
    p.add_argument("--calibration-seed", type=int, default=1000)
    p.add_argument("--scenarios", default="combined,abrupt,degradation")
    p.add_argument("--seeds", default="0,1,2")
    args = p.parse_args()
    cfg = EKFConfig(q_eta=args.q_eta)
    cal_rec = simulate(named_scenario(args.calibration, args.duration), seed=args.calibration_seed)
    cal = calibrate_sd_scale(cal_rec, cfg)
    print(
        f"Q_eta {args.q_eta:g}: scale {cal.scale:.5f} fitted on {args.calibration} seed "
        f"{args.calibration_seed} ({args.duration:g} s, {cal.samples} samples; raw coverage "
        f"{cal.raw_coverage:.3f})"
    )
    print(f"{'scenario':12s} {'seed':>5s} {'raw cov':>8s} {'scaled cov':>10s} {'median sd':>10s}")
    covs = []
    for name in args.scenarios.split(","):
        for seed in map(int, args.seeds.split(",")):
            rec = simulate(named_scenario(name, args.duration), seed=seed)
            raw = MotorEfficiencyEKF(rec.vehicle, cfg).run(rec.without_truth())
            scaled = cal.apply(raw)
            c_raw, c_scaled = (float(np.mean(score(rec, s).coverage)) for s in (raw, scaled))
            covs.append(c_scaled)
            print(
                f"{name:12s} {seed:5d} {c_raw:8.3f} {c_scaled:10.3f} "
                f"{np.median(scaled.sd[1:]):10.4f}"
            )
    print(
        f"held-out scaled coverage: {min(covs):.3f} - {max(covs):.3f} (target {cal.coverage:.4f})"
    )


if __name__ == "__main__":
    main()
