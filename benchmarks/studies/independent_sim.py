"""Held-out check of ``quadfault diagnose`` on recordings from an independent simulator (RotorPy).

RotorPy (github.com/spencerfolk/rotorpy) has its own rigid-body dynamics, rotor aerodynamics
(rotor drag ``H_i = -omega_i K_d v_local`` per rotor, parasitic drag ``-|v| C_D v``,
translational lift), first-order motor *speed* dynamics (``tau_m``), its own SE(3)
controller, z-up world and FLU body. Each case flies one of its bundled vehicles
(``crazyflie_params``, ``hummingbird_params``) on a circle or a Lissajous curve with its
effects on or off, and exports the flight to our recording format (docs/formats.md)
with this script's own writer -- ENU/FLU, quaternion scalar first, commanded rotor speeds
``u1..u4`` [rad/s] with RotorPy's ``k_eta`` as ``thrust_coefficient``, the allocation taken
from RotorPy's ``f_to_TM`` (its rotor geometry and yaw ratio ``k_m / k_eta``) and the
ground-truth state (no sensor noise). RotorPy's parameters go to the sidecar's ``truth``
(hidden from the diagnosis). Then ``quadfault diagnose`` runs on each file.

RotorPy's effects in the diagnosis' terms (``blade_flapping`` when the diagnosis reports the
rotor drag as proportional to thrust): rotor drag is linear in velocity with a coefficient
``K_d sum(omega_i)`` that follows the rotor speeds; parasitic drag is quadratic (its best
linear equivalent over the flight is reported); ``tau_m`` acts on the rotor speed, so for small
changes the thrust follows with the same time constant.

Nothing in the diagnosis was tuned on these recordings: this is a held-out check. ``PYTHON``
is any interpreter where ``rotorpy`` and ``quadfault`` are importable (RotorPy installed in
its own environment).

    PYTHON benchmarks/studies/independent_sim.py [--out DIR] [--duration 15]
        [--rate 200] [--settle S] [--cases NAME,...] [--reuse] [--force] [--quiet]

Skips with a one-line message when RotorPy is not importable.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path

import numpy as np

CASES = {  # name: (vehicle, trajectory, aero, tau_m [s] or None for the vehicle's own)
    "cf_circle_aero_lag": ("crazyflie", "circle", True, None),
    "cf_circle_none": ("crazyflie", "circle", False, 0.001),
    "cf_lissajous_aero": ("crazyflie", "lissajous", True, 0.001),
    "cf_lissajous_lag": ("crazyflie", "lissajous", False, None),
    "hb_circle_aero": ("hummingbird", "circle", True, None),
    "hb_lissajous_none": ("hummingbird", "lissajous", False, 0.001),
    "hb_lissajous_aero_lag": ("hummingbird", "lissajous", True, 0.05),
}


def vehicle_params(name: str) -> dict:
    if name == "crazyflie":
        from rotorpy.vehicles.crazyflie_params import quad_params
    else:
        from rotorpy.vehicles.hummingbird_params import quad_params
    return copy.deepcopy(quad_params)


def trajectory(kind: str, vehicle: str):
    scale = 1.0 if vehicle == "crazyflie" else 1.5
    if kind == "circle":
        from rotorpy.trajectories.circular_traj import ThreeDCircularTraj

        return ThreeDCircularTraj(
            center=np.array([0.0, 0.0, 1.0]),
            radius=scale * np.array([1.0, 1.0, 0.3]),
            freq=np.array([0.3, 0.3, 0.15]),
        )
    from rotorpy.trajectories.lissajous_traj import TwoDLissajous

    return TwoDLissajous(A=scale, B=scale, a=1.6, b=2.4, delta=0.5, height=1.0)


def fly(case: str, duration: float, rate: float, settle: float = 0.0) -> dict:
    """Simulate one case with RotorPy for ``settle + duration`` [s] and keep the last
    ``duration`` (the first ``settle`` seconds hold the start-up transient from a level hover
    into the trajectory); returns the raw arrays and parameters."""
    from rotorpy.controllers.quadrotor_control import SE3Control
    from rotorpy.estimators.nullestimator import NullEstimator
    from rotorpy.sensors.external_mocap import MotionCapture
    from rotorpy.sensors.imu import Imu
    from rotorpy.simulate import simulate
    from rotorpy.vehicles.multirotor import Multirotor
    from rotorpy.wind.default_winds import NoWind
    from rotorpy.world import World

    vname, tkind, aero, tau = CASES[case]
    params = vehicle_params(vname)
    if tau is not None:
        params["tau_m"] = tau
    traj = trajectory(tkind, vname)
    flat0 = traj.update(0.0)
    hover = np.sqrt(params["mass"] * 9.81 / (4 * params["k_eta"]))
    x0 = {
        "x": np.asarray(flat0["x"], float),
        "v": np.asarray(flat0["x_dot"], float),
        "q": np.array([0.0, 0.0, 0.0, 1.0]),
        "w": np.zeros(3),
        "wind": np.zeros(3),
        "rotor_speeds": np.full(4, hover),
    }
    veh = Multirotor(params, initial_state=x0, aero=aero)
    out = simulate(
        World.empty((-50, 50, -50, 50, -50, 50)),
        x0,
        veh,
        SE3Control(params),
        traj,
        NoWind(),
        Imu(sampling_rate=rate),
        MotionCapture(sampling_rate=rate, with_artifacts=False),
        NullEstimator(),
        settle + duration,
        1.0 / rate,
        0.0,
        False,
        terminate=False,
    )
    t, state, control = out[0], out[1], out[2]
    keep = t >= settle - 1e-9
    state = {k: np.asarray(v)[keep] for k, v in state.items()}
    # RotorPy clips the commanded speed to its rotor limits (and f = k u^2 needs u >= 0)
    u = np.clip(
        np.asarray(control["cmd_motor_speeds"])[keep],
        params["rotor_speed_min"],
        params["rotor_speed_max"],
    )
    return {
        "t": t[keep] - t[keep][0],
        "state": state,
        "u": u,
        "params": params,
        "vehicle": vname,
        "trajectory": tkind,
        "aero": aero,
        "f_to_TM": veh.f_to_TM,
        "settle": settle,
    }


def expected(run: dict) -> dict:
    """RotorPy's own effects expressed as the diagnosis' parameters."""
    p, st = run["params"], run["state"]
    out = {"motor_lag_tau_s": float(p["tau_m"])}
    if not run["aero"]:
        out["drag_k_N_s_per_m"] = [0.0, 0.0, 0.0]
        return out
    from scipy.spatial.transform import Rotation

    rs = np.sum(st["rotor_speeds"], axis=1)
    rotor = np.array([p["k_d"], p["k_d"], p["k_z"]]) * float(np.mean(rs))
    R = Rotation.from_quat(st["q"]).as_matrix()
    vb = np.einsum("nji,nj->ni", R, st["v"])  # body airspeed (no wind)
    speed = np.linalg.norm(vb, axis=1)
    cd = np.array([p.get("c_Dx", 0.0), p.get("c_Dy", 0.0), p.get("c_Dz", 0.0)])
    # best linear k for the quadratic -|v| C_D v in the least-squares sense, per body axis
    parasitic = (
        cd * np.sum(speed[:, None] * vb * vb, axis=0) / np.maximum(np.sum(vb * vb, axis=0), 1e-12)
    )
    out["drag_k_N_s_per_m"] = (rotor + parasitic).tolist()
    out["drag_rotor_part"] = rotor.tolist()
    # the same rotor drag in blade_flapping's terms (force proportional to thrust; RotorPy's
    # rotors sit in the CoM plane, so no flapping moment): k_force = k_rotor / (m g) at hover
    out["blade_flapping_k_force_s_per_m"] = float(rotor[0] / (p["mass"] * 9.81))
    out["translational_lift_k_h"] = float(p.get("k_h", 0.0))
    return out


def write_recording(run: dict, csv_path: Path, force: bool) -> None:
    """Our recording format, written independently of quadfault.io.recording (ENU / FLU)."""
    from quadfault.fileio import atomic_write_files

    st, p = run["state"], run["params"]
    q = st["q"]  # RotorPy: [x, y, z, w], body -> world
    cols = {
        "t": run["t"],
        "px": st["x"][:, 0],
        "py": st["x"][:, 1],
        "pz": st["x"][:, 2],
        "vx": st["v"][:, 0],
        "vy": st["v"][:, 1],
        "vz": st["v"][:, 2],
        "qw": q[:, 3],
        "qx": q[:, 0],
        "qy": q[:, 1],
        "qz": q[:, 2],
        "wx": st["w"][:, 0],
        "wy": st["w"][:, 1],
        "wz": st["w"][:, 2],
    }
    for i in range(4):
        cols[f"u{i + 1}"] = run["u"][:, i]
    for i in range(4):
        cols[f"omega{i + 1}"] = st["rotor_speeds"][:, i]
    data = np.column_stack(list(cols.values()))
    lines = [",".join(cols)] + [",".join(f"{x:.9g}" for x in row) for row in data]
    sidecar = {
        "format": "quadfault-recording/1",
        "frame": "ENU",
        "gravity": 9.81,
        "vehicle": {
            "mass": p["mass"],
            "inertia": [
                [p["Ixx"], p["Ixy"], p["Ixz"]],
                [p["Ixy"], p["Iyy"], p["Iyz"]],
                [p["Ixz"], p["Iyz"], p["Izz"]],
            ],
            "allocation": np.asarray(run["f_to_TM"]).tolist(),
            "thrust_coefficient": p["k_eta"],
            "max_thrust": p["k_eta"] * p["rotor_speed_max"] ** 2,
        },
        "source": f"RotorPy {run['vehicle']} ({run['trajectory']}, aero={run['aero']}, "
        f"tau_m={p['tau_m']} s, first {run['settle']} s dropped), exported by "
        "benchmarks/studies/independent_sim.py",
        "truth": {
            "rotorpy_params": {
                k: (v.tolist() if isinstance(v, np.ndarray) else v)
                for k, v in p.items()
                if k != "rotor_pos"
            },
            "expected": expected(run),
        },
    }
    atomic_write_files(
        {
            csv_path: "\n".join(lines) + "\n",
            csv_path.with_suffix(".json"): json.dumps(sidecar, indent=1),
        },
        force=force,
    )


def reused(csv_path: Path) -> tuple:
    """``(expected, speed p95)`` of a recording written earlier by this script."""
    truth = json.loads(csv_path.with_suffix(".json").read_text())["truth"]["expected"]
    data = np.genfromtxt(csv_path, delimiter=",", names=True)
    speed = np.sqrt(data["vx"] ** 2 + data["vy"] ** 2 + data["vz"] ** 2)
    return truth, float(np.percentile(speed, 95))


def diagnose(csv_path: Path, force: bool) -> dict:
    from quadfault import cli

    out = csv_path.with_name(csv_path.stem + "_diag.json")
    code = cli.main(
        ["diagnose", str(csv_path), "--json", str(out), "--quiet"] + (["--force"] if force else [])
    )
    if code != 0:
        raise SystemExit(f"quadfault diagnose failed on {csv_path} (exit {code})")
    return json.loads(out.read_text())


def _found(diag: dict, name: str, key: str):
    for e in diag["effects"]:
        if e["name"] == name:
            return e["params"][key], e["uncertainty"].get(key), e["improvement"]
    return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path("independent_sim_out"))
    ap.add_argument("--duration", type=float, default=15.0, help="flight length [s]")
    ap.add_argument("--rate", type=float, default=200.0, help="simulation/recording rate [Hz]")
    ap.add_argument(
        "--settle",
        type=float,
        default=0.0,
        help="simulate this long first and drop it (start-up transient) [s]",
    )
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated case names")
    ap.add_argument("--force", action="store_true", help="overwrite existing outputs")
    ap.add_argument(
        "--reuse",
        action="store_true",
        help="diagnose the recordings already in --out instead of flying again",
    )
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    args = ap.parse_args(argv)
    try:
        import rotorpy  # noqa: F401
    except ImportError:
        print(
            "skipped: RotorPy is not importable (pip install rotorpy, or run with the "
            "interpreter that has it)"
        )
        return 0
    from quadfault.progress import progress_bar

    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    bad = [c for c in cases if c not in CASES]
    if bad:
        print(f"error: unknown case {bad[0]!r}; choose from {', '.join(CASES)}")
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    with progress_bar(
        total=len(cases),
        desc="independent sim",
        unit="flight",
        disable=True if args.quiet else None,
    ) as bar:
        for case in cases:
            t0 = time.perf_counter()
            csv_path = args.out / f"{case}.csv"
            if args.reuse and csv_path.exists():
                exp, v95 = reused(csv_path)
            else:
                run = fly(case, args.duration, args.rate, args.settle)
                write_recording(run, csv_path, args.force)
                exp = expected(run)
                v95 = float(np.percentile(np.linalg.norm(run["state"]["v"], axis=1), 95))
            t1 = time.perf_counter()
            diag = diagnose(csv_path, args.force or args.reuse)
            rows.append((case, exp, diag, t1 - t0, time.perf_counter() - t1, v95))
            bar.update(1)
    print(
        "| case | RotorPy: drag k (x,y,z) [N s/m], tau_m [s] (as blade_flapping k_force "
        "[s/m]) | speed p95 [m/s] | verdict | "
        "diagnosis: effects (params +- sd; held-out improvement) | model improvement |"
    )
    print("|---|---|---|---|---|---|")
    for case, exp, diag, _t_sim, _t_diag, v95 in rows:
        eff = (
            "; ".join(
                f"{e['name']}("
                + ", ".join(
                    f"{k}={_fmt(v)} +- {_fmt(e['uncertainty'].get(k))}"
                    for k, v in e["params"].items()
                )
                + f"; {100 * e['improvement']:.0f}%)"
                for e in diag["effects"]
            )
            or "none"
        )
        flap = exp.get("blade_flapping_k_force_s_per_m")
        flap = "" if flap is None else f" ({flap:.3g})"
        print(
            f"| {case} | {_fmt(exp['drag_k_N_s_per_m'])}, {exp['motor_lag_tau_s']:g}{flap} | "
            f"{v95:.2f} | {diag['verdict']} | {eff} | "
            f"{100 * diag['model']['improvement']:.1f}% |"
        )
    print(
        f"\n(simulation + export {sum(r[3] for r in rows):.0f} s, diagnosis "
        f"{sum(r[4] for r in rows):.0f} s; files in {args.out})"
    )
    return 0


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(f"{x:.3g}" for x in v) + "]"
    return f"{v:.3g}"


if __name__ == "__main__":
    sys.exit(main())
