"""Which part of a sensor preset costs the EKF its accuracy, and whether its measurement noise
``R`` taken from the preset buys it back.

    python benchmarks/studies/ekf_noise_sources.py [--preset crazyflie] [--seeds 0-2]
                                                   [--scenario abrupt] [--duration 20]
                                                   [--accel-scatter S]

For each seed it flies the scenario (sigma_f = 0.07, no thrust limit, as ``noise_accuracy.py``) with the
preset's sensors taken apart: the whole preset; its noise at every physics step (no rate, no
latency); its rate and latency alone (no noise); its noise at its rate (no latency). On each
flight it runs the EKF at its default ``Q_eta`` (0.5) and at 0.03 (near what the fair
comparison's tuning rule picks under ``crazyflie``), the EKF with ``R`` from the preset (each
stream's per-sample variance, white + coloured + bias, the information a recording's declared
noise gives), the EKF with the accelerometer's row (``EKFConfig(accelerometer="on")``, its
defaults, or ``--accel-scatter``; at both ``Q_eta``) and the improved IRLS for reference. It prints the motor-averaged RMSE
(:func:`estimators.metrics.score`), mean over the seeds. Nothing here is tuned on the scored
flights: every setting is fixed above.
"""

from __future__ import annotations

import argparse

import numpy as np

#: the preset's parts: name -> the changes to the preset (``None``: no sensor noise at all)
PARTS = {
    "no sensor noise": None,
    "the preset": {},
    "its noise, every step, no latency": {"rate": [0.0] * 5, "latency": [0.0] * 5},
    "its rate and latency, no noise": "timing",
    "its noise at its rate, no latency": {"latency": [0.0] * 5},
}
STREAMS = ("position", "velocity", "attitude", "gyro")


def seeds_of(text: str) -> list[int]:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(x) for x in text.split(",")]


def part_noise(preset: str, part):
    """The sensor noise of one part of ``preset`` (a value ``sensor_noise`` takes)."""
    from quadfault.model.sensor_presets import as_sensor_noise

    if part is None:
        return "none"
    if part == "timing":
        full = as_sensor_noise(preset)
        return {"rate": list(full.rate), "latency": list(full.latency)}
    return {"preset": preset, **part}


def preset_r(preset: str) -> dict:
    """The EKF's measurement noise from the preset: each stream's per-sample variance."""
    from quadfault.model.sensor_presets import as_sensor_noise

    noise = as_sensor_noise(preset)
    var = {}
    for s in STREAMS:
        x = noise.stream(s)
        var[s] = x["white"] ** 2 + x["markov"] ** 2 + x["bias"] ** 2
    return {
        "r_position": var["position"],
        "r_velocity": var["velocity"],
        "r_attitude": var["attitude"],
        "r_rate": var["gyro"],
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--preset", default="crazyflie")
    p.add_argument("--seeds", default="0-2")
    p.add_argument("--scenario", default="abrupt")
    p.add_argument("--duration", type=float, default=20.0)
    p.add_argument(
        "--accel-scatter", type=float, help="EKFConfig.accel_scatter of the accelerometer rows"
    )
    args = p.parse_args(argv)

    from estimators.ekf import EKFConfig, MotorEfficiencyEKF
    from estimators.irls import SlidingWindowIRLS
    from estimators.irls_config import IRLSConfig
    from estimators.metrics import score
    from quadfault.model.scenarios import named_scenario
    from quadfault.sim.simulator import SimConfig, simulate

    r = preset_r(args.preset)
    acc = {"accelerometer": "on"}
    if args.accel_scatter is not None:
        acc["accel_scatter"] = args.accel_scatter
    estimators = {
        "ekf": lambda v: MotorEfficiencyEKF(v, EKFConfig()),
        "ekf Q_eta 0.03": lambda v: MotorEfficiencyEKF(v, EKFConfig(q_eta=0.03)),
        "ekf R of the preset": lambda v: MotorEfficiencyEKF(v, EKFConfig(**r)),
        "ekf Q_eta 0.03, R of the preset": lambda v: MotorEfficiencyEKF(
            v, EKFConfig(q_eta=0.03, **r)
        ),
        "ekf accelerometer": lambda v: MotorEfficiencyEKF(v, EKFConfig(**acc)),
        "ekf Q_eta 0.03, accelerometer": lambda v: MotorEfficiencyEKF(
            v, EKFConfig(q_eta=0.03, **acc)
        ),
        "irls --improved": lambda v: SlidingWindowIRLS(v, IRLSConfig.improved()),
    }
    seeds = seeds_of(args.seeds)
    print(
        f"{args.preset}: {args.scenario}, {args.duration:g} s, seeds {args.seeds}; "
        "R of the preset: " + ", ".join(f"{k} {v:.3g}" for k, v in r.items())
    )
    print("| sensors | " + " | ".join(estimators) + " |")
    print("|---" * (len(estimators) + 1) + "|")
    for label, part in PARTS.items():
        noise = part_noise(args.preset, part)
        rmse = {k: [] for k in estimators}
        for seed in seeds:
            config = SimConfig(saturate=False, sensor_noise=noise)
            rec = simulate(
                named_scenario(args.scenario, args.duration),
                config=config,
                seed=seed,
                thrust_noise=0.07,
            )
            for k, make in estimators.items():
                series = make(rec.vehicle).run(rec)
                rmse[k].append(float(np.mean(score(rec, series).rmse)))
        print(f"| {label} | " + " | ".join(f"{np.mean(v):.4f}" for v in rmse.values()) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
