"""Which rotor losses can be survived at all: hover, one rotor drops abruptly to ``eta``.

Flies :func:`quadfault.model.task_scenarios.rotor_loss_scenario`'s situation with fixed draws
(rotor 1, onset 3 s, 10 s flight, hover at 1 m) through the public API
(:func:`agents.rollout.fly`) for each level, with the plain geometric controller, the
estimate-aware controller fed by the online IRLS estimate, the estimate-aware controller fed
by the true efficiency (the oracle), and the relaxed-hover fallback fed by the IRLS estimate
(estimate-aware until the estimate isolates a rotor below 0.15, then the relaxed hover on
the other three; :class:`agents.fault_tolerant.RelaxedHoverFallback`). It prints, per level
and controller, whether the vehicle survived, the crash time, the largest and final position
error after the loss and the tracking RMSE; then how many flights held the hover point
(within 1 m from 2 s after the loss to the end) and, for the relaxed-hover arm, the time from
the onset to the switch and from the first isolating estimate to the switch.

The vehicle (``--vehicle``): ``paper`` (the paper's F450, thrust-to-weight 2, no rate
damping), ``rotor-loss`` (the complete-loss vehicle of
:func:`quadfault.model.relaxed_hover.rotor_loss_vehicle` with its rate damping and rotor
inertia, :data:`~quadfault.model.relaxed_hover.ROTOR_LOSS_EFFECTS`), or ``auto`` (the
default): ``rotor-loss`` when every level is 0 (a complete loss), else ``paper``.

``--sensor-noise PRESET`` flies every flight with a sensor-noise preset (docs/sensors.md);
``--detect THRESHOLD HOLD`` sets the relaxed-hover switch's threshold and hold [s];
``--improved`` flies the IRLS arms with ``IRLSConfig.improved()`` (the residual prefilter that
noisy sensors call for) instead of the paper's IRLS.

``--rotors 1 2 3 4 --onset-range 3 6`` flies every listed rotor with the onset drawn per seed
from that range (the complete-loss target: 10 seeds x 4 rotors).

    python benchmarks/rotor_loss_survival.py [--levels 0 0.1 0.2 0.3 0.4 0.5] [--seeds 0 1 2]
    python benchmarks/rotor_loss_survival.py --levels 0 --seeds 0 1 2 3 4 5 6 7 8 9 \\
        --rotors 1 2 3 4 --onset-range 3 6 --arms relaxed-hover:irls [--sensor-noise px4]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from agents.fault_tolerant import FaultTolerantConfig
from agents.metrics import held_after_loss
from agents.rollout import FlightConfig, fly
from estimators.irls_config import IRLSConfig
from estimators.registry import make_estimator
from quadfault.model.relaxed_hover import ROTOR_LOSS_EFFECTS, rotor_loss_vehicle
from quadfault.model.relaxed_hover_control import RotorLossDetector
from quadfault.model.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Hover
from quadfault.model.vehicle import Vehicle

ARMS = (
    ("geometric", "none"),
    ("estimate-aware", "irls"),
    ("estimate-aware", "truth"),
    ("relaxed-hover", "irls"),
)


def scenario(level: float, onset: float, duration: float, motor: int = 1) -> Scenario:
    fault = AbruptFault(motor=motor, onset=onset, level=level)
    return Scenario(
        f"rotor_loss_{level:g}",
        duration,
        EfficiencySchedule(ConstantEfficiency(), (fault,)),
        Hover(),
    )


def vehicle_of(name: str, levels) -> tuple[Vehicle, tuple]:
    """``(vehicle, effects)`` of ``--vehicle``."""
    if name == "auto":
        name = "rotor-loss" if max(levels) == 0 else "paper"
    if name == "rotor-loss":
        return rotor_loss_vehicle(), ROTOR_LOSS_EFFECTS
    return Vehicle(), ()


def onsets(args) -> list[float]:
    """The onset of each seed: ``--onset``, or drawn from ``--onset-range`` (seeded)."""
    if args.onset_range is None:
        return [args.onset] * len(args.seeds)
    lo, hi = args.onset_range
    return [float(np.random.default_rng(1000 + s).uniform(lo, hi)) for s in args.seeds]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=float, nargs="+", default=[0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--onset", type=float, default=3.0)
    ap.add_argument("--onset-range", type=float, nargs=2, default=None, metavar=("LO", "HI"))
    ap.add_argument("--rotors", type=int, nargs="+", default=[1], choices=[1, 2, 3, 4])
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--vehicle", choices=("auto", "paper", "rotor-loss"), default="auto")
    ap.add_argument(
        "--detect",
        type=float,
        nargs=2,
        default=None,
        metavar=("THRESHOLD", "HOLD"),
        help="the relaxed-hover switch's threshold [-] and hold [s] (default 0.15 and 0.004, "
        "0.05 with sensor noise)",
    )
    ap.add_argument(
        "--sensor-noise",
        default=None,
        help="a sensor-noise preset (docs/sensors.md) for every flight (default: noise-free)",
    )
    ap.add_argument(
        "--improved",
        action="store_true",
        help="the IRLS arms fly IRLSConfig.improved() (its residual prefilter; "
        "quadfault estimate --improved) instead of the paper's IRLS",
    )
    ap.add_argument(
        "--arms",
        nargs="+",
        default=[f"{c}:{e}" for c, e in ARMS],
        help="controller:estimator pairs (default: %(default)s)",
    )
    args = ap.parse_args(argv)
    arms = [tuple(a.split(":")) for a in args.arms]
    veh, effects = vehicle_of(args.vehicle, args.levels)
    t_on = onsets(args)
    ft = FaultTolerantConfig()
    if args.detect is not None:
        ft = FaultTolerantConfig(
            detector=RotorLossDetector(threshold=args.detect[0], hold=args.detect[1])
        )
    cfg = FlightConfig(fault_tolerant=ft)
    if args.sensor_noise is not None:
        cfg = FlightConfig(fault_tolerant=ft, sensor_noise=args.sensor_noise)
    start = time.process_time()
    label = lambda e: "irls, improved" if e == "irls" and args.improved else e  # noqa: E731
    detector = ft.detector or RotorLossDetector.for_sensors(cfg.sensor_noise)
    print(
        f"vehicle: {veh.name} (thrust-to-weight {veh.thrust_to_weight:g}), effects: "
        f"{' '.join(effects) or 'none'}; rotors {args.rotors}; sensor noise "
        f"{args.sensor_noise or 'none'}; switch {detector}\n"
    )
    print(
        "| eta after loss | controller (estimate) | survived | crash time [s] | "
        "max error after loss [m] | final error [m] | RMSE [m] | held within 1 m | "
        "onset to switch [ms] | first isolating estimate to switch [ms] |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for level in args.levels:
        for ctrl, est in arms:
            fl, on = [], []
            for rotor in args.rotors:
                for seed, onset in zip(args.seeds, t_on):
                    sc = scenario(level, onset, args.duration, rotor)
                    e = est
                    if est == "irls" and args.improved:
                        e = make_estimator("irls", veh, IRLSConfig.improved())
                    fl.append(fly(sc, ctrl, e, seed, vehicle=veh, effects=effects, config=cfg))
                    on.append(onset)
            ok = sum(not f.metrics.crashed for f in fl)
            crash = [f.metrics.crash_time - o for f, o in zip(fl, on) if f.metrics.crashed]
            after = [f.pos_error[f.t >= o] for f, o in zip(fl, on)]
            peak = max(float(np.max(a)) if a.size else math.nan for a in after)
            final = max(float(f.pos_error[-1]) for f in fl)
            rmse = float(np.mean([f.metrics.rmse for f in fl]))
            held = sum(held_after_loss(f.t, f.pos_error, o, args.duration) for f, o in zip(fl, on))
            crash_s = "-" if not crash else f"{min(crash):.2f}-{max(crash):.2f} after onset"
            sw = [(f.switch, o) for f, o in zip(fl, on) if f.switch is not None]
            to_switch = [1e3 * (s["switched"] - o) for s, o in sw if s["switched"] is not None]
            confirm = [
                1e3 * (s["switched"] - s["first_seen"]) for s, _ in sw if s["switched"] is not None
            ]
            span = lambda xs: "-" if not xs else f"{min(xs):.0f}-{max(xs):.0f}"  # noqa: E731
            print(
                f"| {level:g} | {ctrl} ({label(est)}) | {ok}/{len(fl)} | {crash_s} | {peak:.3f} | "
                f"{final:.3f} | {rmse:.3f} | {held}/{len(fl)} | {span(to_switch)} | "
                f"{span(confirm)} |"
            )
    print(f"\n{time.process_time() - start:.0f} CPU-s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
