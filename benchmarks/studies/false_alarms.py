"""False alarms of the diagnosis on effect-free flights flown with the simulator's defaults.

``quadfault simulate`` writes 1 kHz recordings with the controller at every physics step and
the scenario's thrust noise (sigma_f = 0.07) and no sensor noise: the thrust noise is process
noise the controller reacts to within milliseconds, the case where least squares fits that
reaction as a motor lag, delay or inertia (closed-loop feedback bias, docs/diagnosis.md). This
flies ``--n`` such flights without any effect -- trajectory (circle, hover, Lissajous), thrust
noise (0.02-0.1) and sensor noise (off or on) drawn per flight from ``--seed`` -- and reports
how many the diagnosis calls a mismatch. With ``--reference REV`` the diagnosis package of git
revision ``REV`` diagnoses the same recordings in the same run.

    python benchmarks/studies/false_alarms.py --n 12 --reference ec394f0
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benchmarks/
from bench_diagnosis import describe, reference_package  # noqa: E402

from quadfault.model.scenarios import named_scenario
from quadfault.model.trajectory import Circle, Hover, Lissajous
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate


def draw(rng: np.random.Generator) -> dict:
    kind = str(rng.choice(["circle", "hover", "lissajous"]))
    traj = {
        "circle": Circle(
            radius=float(rng.uniform(1.0, 3.0)), frequency=float(rng.uniform(0.05, 0.2))
        ),
        "hover": Hover(),
        "lissajous": Lissajous(
            amplitude=(float(rng.uniform(0.5, 2.0)), float(rng.uniform(0.5, 2.0)), 0.2),
            frequency=float(rng.uniform(0.1, 0.2)),
        ),
    }[kind]
    noise = SensorNoise(0.002, 0.005, 0.001, 0.001) if rng.random() < 0.5 else SensorNoise()
    return {
        "kind": kind,
        "traj": traj,
        "sigma_f": float(rng.uniform(0.02, 0.1)),
        "sensor": noise,
        "seed": int(rng.integers(2**31)),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=12, help="flights (default 12)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--duration", type=float, default=20.0, help="[s] (default 20)")
    ap.add_argument(
        "--reference",
        default=None,
        metavar="REV",
        help="also diagnose with the diagnosis package of this git revision",
    )
    args = ap.parse_args(argv)
    import quadfault.diagnosis as new

    ref = reference_package(args.reference) if args.reference else None
    rng = np.random.default_rng(args.seed)
    alarms = {"new": 0, "ref": 0, "flown": 0}
    print(
        f"{args.n} effect-free flights, {args.duration:g} s at 1 kHz; load "
        f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"
    )
    for i in range(args.n):
        c = draw(rng)
        sc = named_scenario("nominal", args.duration, 1e-3).replace(trajectory=c["traj"])
        rec = simulate(
            sc,
            config=SimConfig(dt=1e-3, sensor_noise=c["sensor"]),
            seed=c["seed"],
            thrust_noise=c["sigma_f"],
        ).without_truth()
        f_max = rec.vehicle.rotor_max_thrust
        if not np.all(np.abs(rec.thrust_cmd) <= 1.5 * f_max):  # lost vehicle: not a test
            print(f"{i:3d} {c['kind']:9s} the controller lost the vehicle: skipped", flush=True)
            continue
        t0 = time.perf_counter()
        res = new.Diagnosis().fit(rec)
        line = (
            f"{i:3d} {c['kind']:9s} sigma_f {c['sigma_f']:.3f} sensor noise "
            f"{'on ' if c['sensor'].any else 'off'} | new: {res.verdict:10s} "
            f"{describe(res)} ({time.perf_counter() - t0:.1f} s)"
        )
        alarms["new"] += res.verdict != "consistent"
        alarms["flown"] += 1
        if ref is not None:
            res0 = ref.Diagnosis().fit(rec)
            alarms["ref"] += res0.verdict != "consistent"
            line += f" | ref: {res0.verdict:10s} {describe(res0)}"
        print(line, flush=True)
    n = alarms["flown"]
    print(
        f"false alarms: new {alarms['new']}/{n}"
        + (f", reference {args.reference} {alarms['ref']}/{n}" if ref is not None else "")
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
