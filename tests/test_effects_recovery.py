"""The new effects recovered by ``quadfault diagnose`` from seeded simulated recordings; the
fitted model as a simulator (simulate -> diagnose -> simulate --model -> diagnose finds the same
parameters); a calibrated simulator predicts a held-out stretch better than the nominal one.

Flights: the paper's F450 on a Lissajous curve, 250 Hz, sensor noise and 2 % thrust noise.
"""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from quadfault.cli import main
from quadfault.diagnosis.replay import replay_errors
from quadfault.io.recording import read_recording, write_recording
from quadfault.model import effects as fx
from quadfault.model.scenarios import LinearVoltage, named_scenario
from quadfault.model.trajectory import Lissajous
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate

DT = 4e-3
TRAJ = Lissajous(amplitude=(2.0, 1.5, 0.3), frequency=0.15)
U_CURVE = (0.0, 0.0, 1e-5)  # u commands [rad/s] with f = k u^2
REAL = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real"


def fly(effects, seed=1, duration=8.0, voltage=None, u_curve=None, vehicle=None):
    sc = named_scenario("nominal", duration, DT).replace(trajectory=TRAJ, voltage=voltage)
    cfg = SimConfig(dt=DT, sensor_noise=SensorNoise(0.002, 0.005, 0.001, 0.001))
    rec = simulate(
        sc, vehicle=vehicle, config=cfg, seed=seed, effects=tuple(effects), thrust_noise=0.02
    )
    if u_curve is not None:
        u = fx.curve_command(u_curve, rec.thrust_cmd)
        rec = dataclasses.replace(
            rec, commands_u=u, thrust_curve=u_curve, thrust_cmd=fx.curve_thrust(u_curve, u)
        )
    return rec


def diagnose(rec, tmp_path, *extra, name="flight") -> dict:
    """``quadfault diagnose`` as a user runs it; the JSON plus the sidecar's frame and vehicle
    (``quadfault diagnose`` writes them; ``setdefault`` for a JSON that lacks them)."""
    csv = tmp_path / f"{name}.csv"
    write_recording(rec.without_truth(), csv, force=True)
    out = tmp_path / f"{name}.diag.json"
    assert main(["diagnose", str(csv), "--json", str(out), "--quiet", "--force", *extra]) == 0
    doc = json.loads(out.read_text())
    side = json.loads(csv.with_suffix(".json").read_text())
    for key in ("frame", "gravity", "vehicle"):
        doc.setdefault(key, side[key])
    doc.setdefault("format", "quadfault-diagnosis/2")
    return doc


def found(doc, name) -> dict:
    """The fitted parameters of ``name``: an accepted effect, or one side of an
    ``indistinguishable`` pair of rival explanations (the honest answer when the flight
    cannot tell the two apart, e.g. mass and a common thrust factor)."""
    names = [e["name"] for e in doc["effects"]]
    if name in names:
        return doc["effects"][names.index(name)]["params"]
    rivals = [
        e for s in doc.get("indistinguishable", []) for side in s.get("sets", ()) for e in side
    ]
    named = [e["name"] for e in rivals]
    assert name in named, (names, named)
    return rivals[named.index(name)]["params"]


def curve_error(params, truth: fx.ThrustCurve, hover: float) -> float:
    """Relative RMS error of the thrust change over commands of 0.6-1.4 times hover."""
    f = np.linspace(0.6, 1.4, 41) * hover
    want = fx.recurve(f, truth.nominal, truth.curve) - f
    got = fx.recurve(f, params["nominal_curve"], params["curve"]) - f
    return float(np.sqrt(np.mean((got - want) ** 2) / np.mean(want**2)))


HOVER = Vehicle().hover_thrust
U_TRUTH = fx.ThrustCurve(tuple(fx.curve_from_changes(U_CURVE, HOVER, (0.05, -0.25, 0.2))), U_CURVE)
F_TRUTH = fx.ThrustCurve(tuple(fx.curve_from_changes((0, 1, 0), HOVER, (0.05, -0.25, 0.2))))

CASES = {  # name: (effects, fly keywords, diagnose flags, check of the found params)
    "blade_flapping": (
        [fx.BladeFlapping(0.05, 0.005)],
        {},
        (),
        lambda d: (
            abs(found(d, "blade_flapping")["k_force_s_per_m"] - 0.05) < 0.0025
            and abs(found(d, "blade_flapping")["k_moment_s"] - 0.005) < 0.0005
        ),
    ),
    "rotor_inertia": (
        [fx.RotorInertia(0.005)],
        {},
        (),
        lambda d: abs(found(d, "rotor_inertia")["kappa_m_s"] - 0.005) < 0.00025,
    ),
    "battery_thrust": (
        [fx.BatteryThrust(2.0, 12.0, 11.0, 8.0)],
        {"voltage": LinearVoltage(12.0, 11.0, 8.0)},
        (),
        lambda d: abs(found(d, "battery_thrust")["exponent"] - 2.0) < 0.2,
    ),
    "rate_damping": (
        [fx.RateDamping((0.07, 0.07, 0.14))],
        {},
        (),
        lambda d: np.allclose(
            found(d, "rate_damping")["linear_N_m_s_per_rad"], [0.07, 0.07, 0.14], rtol=0.15
        ),
    ),
    # u commands: the curve is in the default library
    "thrust_curve": (
        [U_TRUTH],
        {"u_curve": U_CURVE},
        (),
        lambda d: curve_error(found(d, "thrust_curve"), U_TRUTH, HOVER) < 0.2,
    ),
    # a lag fitted jointly with the curve
    "thrust_curve+motor_lag": (
        [U_TRUTH, fx.MotorLag(0.05)],
        {"u_curve": U_CURVE},
        (),
        lambda d: (
            abs(found(d, "motor_lag")["tau_s"] - 0.05) < 0.005
            and curve_error(found(d, "thrust_curve"), U_TRUTH, HOVER) < 0.3
        ),
    ),
    # thrust commands: in closed loop a curve's slope is what an inertia does, so it is asked for
    "thrust_curve_f": (
        [F_TRUTH],
        {},
        ("--effects", "thrust_curve"),
        lambda d: curve_error(found(d, "thrust_curve"), F_TRUTH, HOVER) < 0.2,
    ),
    # a payload: the default library reports the same translation as a thrust scale (one class)
    "mass": (
        [fx.Mass(1.15)],
        {},
        ("--effects", "mass"),
        lambda d: abs(found(d, "mass")["scale"] - 1.15) < 0.01,
    ),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_new_effect_recovered_by_quadfault_diagnose(name, tmp_path):
    effects, kw, flags, check = CASES[name]
    doc = diagnose(fly(effects, **kw), tmp_path, *flags)
    assert doc["verdict"] == "mismatch"
    assert check(doc), doc["effects"]


@pytest.mark.slow
def test_payload_in_the_default_library_is_the_thrust_class(tmp_path):
    doc = diagnose(fly([fx.Mass(1.15)]), tmp_path)
    names = [e["name"] for e in doc["effects"]] + [
        n for s in doc.get("indistinguishable", []) for n in s["names"]
    ]
    assert set(names) & {"thrust_scale", "mass"}, doc["effects"]
    for name in sorted(set(names) & {"thrust_scale", "mass"}):  # either, or both as rivals
        scale = found(doc, name)["scale"]
        assert scale == pytest.approx(1.15 if name == "mass" else 1 / 1.15, abs=0.01)


def _within(a: dict, b: dict, z: float = 3.0) -> list:
    """Parameters of ``b`` farther than ``z`` combined sigmas from ``a`` (effect, key)."""
    out = []
    for key, sa in a["uncertainty"].items():
        pa, pb = np.asarray(a["params"][key]), np.asarray(b["params"][key])
        s = np.hypot(np.asarray(sa), np.asarray(b["uncertainty"][key]))
        if np.any(np.abs(pb - pa) > z * s + 1e-12):
            out.append((a["name"], key, pa.tolist(), pb.tolist(), s.tolist()))
    return out


@pytest.mark.slow
def test_simulate_model_round_trip_finds_the_same_parameters(tmp_path):
    """simulate (known effects) -> diagnose -> simulate --model (another seed) -> diagnose:
    the same effects, every parameter within 3 combined one-sigma uncertainties."""
    common = [
        "--scenario",
        "nominal",
        "--trajectory",
        "lissajous",
        "--duration",
        "12",
        "--dt",
        "0.004",
        "--sensor-noise",
        "0.002,0.005,0.001,0.001",
        "--thrust-noise",
        "0.02",
        "--quiet",
    ]
    first = tmp_path / "first.csv"
    assert (
        main(
            [
                "simulate",
                *common,
                "--seed",
                "1",
                "--out",
                str(first),
                "--effect",
                "motor_efficiency=1,0.75,1,1",
                "--effect",
                "blade_flapping=0.04,0.006",
                "--effect",
                "rate_damping=0.1",
            ]
        )
        == 0
    )
    d1 = diagnose(read_recording(first), tmp_path, name="d1")
    assert {e["name"] for e in d1["effects"]} == {
        "motor_efficiency",
        "blade_flapping",
        "rate_damping",
    }
    model_json = tmp_path / "model.json"
    model_json.write_text(json.dumps(d1))
    second = tmp_path / "second.csv"
    assert (
        main(["simulate", *common, "--seed", "2", "--out", str(second), "--model", str(model_json)])
        == 0
    )
    d2 = diagnose(read_recording(second), tmp_path, name="d2")
    again = {e["name"]: e for e in d2["effects"]}
    assert set(again) == {e["name"] for e in d1["effects"]}
    far = [x for e in d1["effects"] for x in _within(e, again[e["name"]])]
    assert not far, far


@pytest.mark.slow
def test_calibrated_simulator_predicts_a_held_out_stretch_better(tmp_path):
    truth = [fx.Drag(0.3), fx.MotorLag(0.05), fx.BladeFlapping(0.03, 0.004)]
    rec = fly(truth, duration=20.0)
    cut = int(0.6 * len(rec))
    model = fx.from_diagnosis(diagnose(rec.slice(0, cut), tmp_path))
    assert len(model.effects) >= 2
    span = (rec.t[cut], rec.t[-1])
    nominal = replay_errors(rec, model.vehicle, (), span=span, starts=20)
    calibrated = replay_errors(rec, model.vehicle, model.effects, span=span, starts=20)
    for key in ("position_rmse_m", "velocity_rmse_m_per_s", "attitude_rmse_deg"):
        assert calibrated[key][-1] < 0.3 * nominal[key][-1], key  # 0.5 s


@pytest.mark.slow
@pytest.mark.skipif(not (REAL / "nanodrone-cf21bl").is_dir(), reason="real data not present")
def test_calibrated_simulator_beats_nominal_on_a_real_flight(tmp_path):
    raw = REAL / "nanodrone-cf21bl" / "random2_20251017_run2.csv.gz"
    csv = tmp_path / "real.csv"
    assert main(["import", "nanodrone", str(raw), "--out", str(csv), "--quiet"]) == 0
    rec = read_recording(csv)
    cut = int(0.6 * len(rec))
    model = fx.from_diagnosis(diagnose(rec.slice(0, cut), tmp_path, name="real_fit"))
    span = (rec.t[cut], rec.t[-1])
    nominal = replay_errors(rec, model.vehicle, (), span=span, starts=20)
    calibrated = replay_errors(rec, model.vehicle, model.effects, span=span, starts=20)
    for key in ("position_rmse_m", "velocity_rmse_m_per_s", "attitude_rmse_deg"):
        assert all(c < n for c, n in zip(calibrated[key][1:], nominal[key][1:])), key


def test_replay_needs_a_pose(tmp_path):
    rec = fly([], duration=1.0)
    imu = dataclasses.replace(rec, position=None, velocity=None, quaternion=None)
    with pytest.raises(Exception, match="needs a recording with pose"):
        replay_errors(imu, Vehicle())
    with pytest.raises(Exception, match="no stretch"):
        replay_errors(rec, Vehicle(), horizons=(5.0,))
