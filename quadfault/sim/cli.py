"""``quadfault simulate``: fly a scenario and write a recording (docs/formats.md)."""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

from quadfault.errors import ConfigError

#: Thrust coefficient [N/(rad/s)^2] used when ``--commands u`` is asked without one.
DEFAULT_THRUST_COEFFICIENT = 1.0e-5


def _floats(text: str, n: int, flag: str) -> list[float]:
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        raise ConfigError(f"{flag} expects {n} comma-separated numbers, got {text!r}") from None
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise ConfigError(f"{flag} expects {n} comma-separated finite numbers, got {text!r}")
    return vals


def add_arguments(p: argparse.ArgumentParser) -> None:
    from quadfault.model.scenarios import SCENARIO_NAMES

    p.add_argument(
        "--scenario",
        default=None,
        choices=SCENARIO_NAMES,
        help="efficiency schedule and trajectory (default: combined, the paper's faults and "
        "battery sag; nominal when --effect is given)",
    )
    p.add_argument(
        "--trajectory",
        choices=("circle", "lissajous", "hover"),
        default=None,
        help="fly this reference instead of the scenario's: the paper's circle, a "
        "Lissajous figure-eight exciting all axes, or hover (their default "
        "shapes in quadfault.model.trajectory)",
    )
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        help="flight time [s] (default 80, the reference schedule)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--out", required=True, help="output recording FILE.csv (+ FILE.json)")
    p.add_argument("--force", action="store_true", help="overwrite existing files")
    p.add_argument(
        "--integrator",
        choices=("rk4", "reference"),
        default="rk4",
        help="rk4 (default; RKMK4 on SO(3)) or reference (the authors' Euler step "
        "with its one-sample input lag, no upper saturation, a_d = 0)",
    )
    p.add_argument("--dt", type=float, default=1e-3, help="physics step [s] (default 0.001)")
    p.add_argument(
        "--control-rate",
        type=float,
        default=None,
        help="controller rate [Hz] (default: every physics step)",
    )
    p.add_argument(
        "--mixer",
        choices=("yaw-release", "plain"),
        default="yaw-release",
        help="the controller's mixer: yaw-release (default) gives up yaw first where it would "
        "push a rotor's command below zero or above the thrust limit; plain: the allocation "
        "inverse alone (eq. 12)",
    )
    p.add_argument(
        "--thrust-noise",
        type=float,
        default=None,
        help="sigma_f of the multiplicative thrust noise (default: scenario's, 0.07)",
    )
    p.add_argument(
        "--sensor-noise",
        default=None,
        metavar="PRESET|POS,VEL,ATT,GYRO[,ACC]",
        help="the sensors: a preset measured on real logs (crazyflie, px4, ...: "
        "docs/sensors.md; coloured noise, bias, rate and latency) or the white noise std "
        "of position [m], velocity [m/s], attitude [rad], gyro [rad/s], accelerometer "
        "[m/s^2] (default: none)",
    )
    p.add_argument(
        "--no-saturation",
        action="store_true",
        help="clip rotor commands only at 0 (the reference code; the default for "
        "the paper's scenarios)",
    )
    p.add_argument(
        "--max-thrust",
        type=float,
        default=None,
        help="per-rotor thrust limit [N] (default: none for the paper's fault scenarios "
        "degradation, abrupt and combined, as the paper flies them; "
        "thrust-to-weight 2 for the others)",
    )
    p.add_argument(
        "--no-accel-feedforward",
        action="store_true",
        help="the reference's a_d = 0 in the controller",
    )
    p.add_argument("--frame", choices=("NED", "ENU"), default="NED", help="output world frame")
    p.add_argument(
        "--commands",
        choices=("f", "u"),
        default="f",
        help="write thrust commands f1..f4 [N] (default) or rotor speeds u1..u4 "
        f"[rad/s] with thrust_coefficient {DEFAULT_THRUST_COEFFICIENT:g}",
    )
    p.add_argument(
        "--effect",
        action="append",
        default=[],
        metavar="NAME=VALUES",
        help="add an unmodelled effect to the true plant, e.g. drag=0.3, "
        "wind=2,0,0, motor_lag=0.05, blade_flapping=0.05,0.002, mass=1.15 "
        "(repeatable; see docs/effects.md)",
    )
    p.add_argument(
        "--model",
        default=None,
        metavar="DIAG.json",
        help="fly a diagnosis' fitted model: its nominal vehicle (what the controller "
        "and the recording's sidecar know) plus its accepted effects with their "
        "fitted parameters (the recording's truth); --effect adds more",
    )
    p.add_argument(
        "--no-truth",
        action="store_true",
        help="omit the true efficiency eta1..eta4 and effect truth",
    )


def run(args) -> int:
    import numpy as np

    from quadfault.io.recording import write_recording
    from quadfault.model.controller import ControllerConfig, GeometricGains
    from quadfault.model.scenarios import PAPER_SCENARIOS, named_scenario
    from quadfault.model.sensor_presets import as_sensor_noise
    from quadfault.model.vehicle import Vehicle
    from quadfault.sim.simulator import SimConfig, simulate

    out = Path(args.out)
    if out.suffix != ".csv":
        raise ConfigError(f"--out must end in .csv, got {args.out!r}")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ConfigError(f"--duration must be positive [s], got {args.duration}")
    if not (math.isfinite(args.dt) and 0 < args.dt <= 0.1):
        raise ConfigError(f"--dt must be in (0, 0.1] s, got {args.dt}")
    if args.control_rate is not None and not (
        math.isfinite(args.control_rate) and args.control_rate > 0
    ):
        raise ConfigError(f"--control-rate must be positive [Hz], got {args.control_rate}")
    if args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    if args.thrust_noise is not None and not (0 <= args.thrust_noise < 2):
        raise ConfigError(f"--thrust-noise must be in [0, 2), got {args.thrust_noise}")
    from quadfault.fileio import check_writable
    from quadfault.io.recording import sidecar_path

    check_writable([out, sidecar_path(out)], force=args.force)
    if args.scenario is None:
        args.scenario = "nominal" if args.effect else "combined"
        if args.effect and not args.quiet:
            print(
                "note: --effect without --scenario flies the nominal scenario (no motor "
                "faults); give --scenario combined for the paper's faults under the effect",
                file=sys.stderr,
            )
    scenario = named_scenario(args.scenario, args.duration, args.dt)
    if args.trajectory is not None:
        from quadfault.model.trajectory import Circle, Hover, Lissajous

        traj = {"circle": Circle, "lissajous": Lissajous, "hover": Hover}[args.trajectory]()
        scenario = scenario.replace(trajectory=traj)
    noise = as_sensor_noise(args.sensor_noise or None, "--sensor-noise")
    model = None
    if args.model is not None:
        from quadfault.model.effects import from_diagnosis

        model = from_diagnosis(args.model)
    vehicle = Vehicle() if model is None else model.vehicle
    if args.max_thrust is not None:
        vehicle = vehicle.replace(max_thrust=args.max_thrust)
    # the paper's scenarios fly as the paper (and `reproduce`) fly them: no upper thrust limit
    saturate = not (
        args.no_saturation or (args.scenario in PAPER_SCENARIOS and args.max_thrust is None)
    )
    if args.integrator == "reference":
        cfg = SimConfig.reference(dt=args.dt, sensor_noise=noise)
    else:
        # a model's vehicle flies the paper's gains carried over to its mass and inertia
        gains = GeometricGains() if model is None else GeometricGains().scaled(vehicle)
        ctrl = ControllerConfig(
            gains=gains,
            acceleration_feedforward=not args.no_accel_feedforward,
            yaw_release=args.mixer == "yaw-release",
        )
        period = None if args.control_rate is None else 1.0 / args.control_rate
        cfg = SimConfig(
            dt=args.dt,
            control_period=period,
            saturate=saturate,
            sensor_noise=noise,
            controller=ctrl,
        )
    effects, scenario = _effects(args, model, scenario)
    # an absurd parameter (wind=1e308) overflows inside numpy; the simulator's own
    # non-finite-state check turns that into the one-line error, so numpy's warnings are noise
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        rec = simulate(
            scenario,
            vehicle=vehicle,
            config=cfg,
            seed=args.seed,
            effects=effects,
            thrust_noise=args.thrust_noise,
            progress=not args.quiet,
            stop_at_loss=True,
        )
    if model is not None:
        rec.meta["truth"] = {"model": model.source}
    _warn_if_ended(rec, saturate and args.integrator != "reference")
    if args.commands == "u":
        from quadfault.model.effects import curve_command, curve_thrust

        curve = (0.0, 0.0, DEFAULT_THRUST_COEFFICIENT)
        if model is not None and model.thrust_curve is not None:
            curve = model.thrust_curve
        u = curve_command(curve, rec.thrust_cmd)
        rec = dataclasses.replace(
            rec, commands_u=u, thrust_curve=tuple(curve), thrust_cmd=curve_thrust(curve, u)
        )
    if args.no_truth:
        rec = rec.without_truth()
    write_recording(rec, out, frame=args.frame, force=args.force)
    if not args.quiet:
        print(
            f"wrote {out} ({len(rec)} rows, {rec.duration:.3f} s, scenario {args.scenario}, "
            f"seed {args.seed})"
        )
    return 0


def _effects(args, model, scenario):
    """The plant's effects (the model's, then ``--effect``'s; canonical order) and the scenario,
    which records a ``battery_thrust`` effect's voltage as ``vbat``."""
    from quadfault.model.effects import BatteryThrust, canonical_order, parse_effect
    from quadfault.model.scenarios import LinearVoltage

    effects = list(model.effects) if model is not None else []
    for spec in args.effect:
        e = parse_effect(spec)
        if isinstance(e, BatteryThrust) and "duration=" not in spec:
            e = dataclasses.replace(e, duration=scenario.duration)  # discharge over the flight
        effects.append(e)
    names = [e.name for e in effects]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ConfigError(f"effect {twice[0]} given twice (in --model and --effect, or twice)")
    battery = [e for e in effects if isinstance(e, BatteryThrust)]
    if battery:
        if scenario.voltage is not None:
            raise ConfigError(
                f"scenario {scenario.name!r} has its own battery voltage profile; "
                "battery_thrust needs one without (e.g. nominal, abrupt, hover)"
            )
        b = battery[0]
        scenario = scenario.replace(voltage=LinearVoltage(b.v_start, b.v_end, b.duration))
    return canonical_order(effects), scenario


def _warn_if_ended(rec, saturated: bool) -> None:
    """A warning on stderr when the flight ended early because it lost the vehicle or went
    below the ground (``simulate(..., stop_at_loss=True)``: the recording stops at that row and
    its sidecar's ``end`` says why)."""
    import sys

    from quadfault.model.effects.motor_lag import MotorLag
    from quadfault.model.effects.rotor_inertia import RotorInertia
    from quadfault.sim.simulator import LOST_CONTROL_ERROR

    end = rec.meta.get("end")
    if end is None:
        return
    hint = ""
    names = {e["name"] for e in rec.meta.get("effects", ())}
    if RotorInertia.name in names and MotorLag.name not in names:
        hint = (
            " rotor_inertia without motor_lag makes every thrust step a yaw kick; a rotor "
            "with inertia has a lag: add --effect motor_lag=TAU (docs/effects.md)."
        )
    elif saturated:
        hint = (
            " With a rotor thrust limit the rotors may not carry the vehicle: fly without "
            "one (--no-saturation), raise --max-thrust, or use the estimate-aware controller "
            "(agents)."
        )
    what = {
        "lost_control": f"the controller lost the vehicle (tracking error > "
        f"{LOST_CONTROL_ERROR:g} m)",
        "below_ground": "the controller lost the vehicle below the ground",
    }[end["reason"]]
    print(
        f"warning: {what} at t = {end['t']:.3f} s; the recording ends there ({len(rec)} rows "
        f'of a planned {end["planned_duration"]:g} s; the sidecar\'s "end" says why).{hint}',
        file=sys.stderr,
    )
