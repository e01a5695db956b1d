"""The fitted model as a simulator: ``from_diagnosis`` and ``quadfault simulate --model``."""

import json

import numpy as np
import pytest

from quadfault.cli import main
from quadfault.errors import ConfigError
from quadfault.io.recording import Recording, read_recording, recording_sidecar, write_recording
from quadfault.model import effects as fx
from quadfault.model.vehicle import Vehicle

VEHICLE = Vehicle.from_arm(
    0.1, 0.01, mass=0.5, inertia=(0.003, 0.004, 0.006), gravity=9.81, max_thrust=3.0
)


def _sidecar(vehicle=VEHICLE, frame="NED", curve=None):
    rec = Recording(
        t=np.arange(3.0),
        omega=np.zeros((3, 3)),
        thrust_cmd=np.ones((3, 4)),
        vehicle=vehicle,
        position=np.zeros((3, 3)),
        velocity=np.zeros((3, 3)),
        quaternion=np.tile([1.0, 0, 0, 0], (3, 1)),
        commands_u=None if curve is None else np.ones((3, 4)),
        thrust_curve=curve,
    )
    return recording_sidecar(rec, frame)


def _doc(effects, frame="NED", curve=None, **extra):
    side = _sidecar(frame=frame, curve=curve)
    doc = {
        "format": "quadfault-diagnosis/2",
        "verdict": "mismatch",
        "frame": frame,
        "gravity": side["gravity"],
        "vehicle": side["vehicle"],
        "effects": effects,
    }
    doc.update(extra)
    return doc


EFFECTS = [
    {
        "name": "drag",
        "params": {"k_N_s_per_m": [0.2, 0.25, 0.1]},
        "uncertainty": {"k_N_s_per_m": [0.01, 0.01, 0.02]},
        "bounds": {"k_N_s_per_m": [[0, 0, 0], [1.5, 1.5, 2.5]]},
    },
    {
        "name": "motor_lag",
        "params": {"tau_s": 0.04},
        "uncertainty": {"tau_s": 0.002},
        "bounds": {"tau_s": [1e-4, 0.3]},
    },
    {"name": "mass", "params": {"scale": 1.1, "mass_kg": 0.55}, "uncertainty": {"scale": 0.01}},
]


def test_from_diagnosis_gives_the_nominal_vehicle_and_the_effects_in_canonical_order(tmp_path):
    path = tmp_path / "d.json"
    path.write_text(json.dumps(_doc(EFFECTS)))
    model = fx.from_diagnosis(path)
    assert model.vehicle == VEHICLE and model.thrust_curve is None
    assert [e.name for e in model.effects] == ["motor_lag", "drag", "mass"]  # thrust, wrench, body
    assert model.effects[0] == fx.MotorLag(0.04)
    assert model.effects[1].k == (0.2, 0.25, 0.1)
    assert model.fitted[1].uncertainty == {"k_N_s_per_m": [0.01, 0.01, 0.02]}
    assert fx.from_diagnosis(_doc(EFFECTS)).effects == model.effects  # a dict works too


def test_enu_diagnosis_converts_directions_and_the_vehicle():
    effects = [
        {"name": "wind", "params": {"force_N": [1.0, 2.0, 0.5]}},
        {
            "name": "com_offset",
            "params": {"offset_m": [0.01, 0.02]},
            "uncertainty": {"offset_m": [0.001, 0.002]},
        },
    ]
    model = fx.from_diagnosis(_doc(effects, frame="ENU"))
    assert model.vehicle == VEHICLE  # the sidecar's FLU vehicle back in FRD
    np.testing.assert_allclose(model.effects[0].steady_force(), [2.0, 1.0, -0.5])
    assert model.effects[1].offset == (0.01, -0.02)
    assert model.fitted[1].uncertainty["offset_m"] == [0.001, 0.002]


def test_u_command_model_keeps_its_curve_and_a_refit_curve_is_relative_to_it():
    curve = (0.0, 0.0, 2e-6)
    refit = [{"name": "thrust_curve", "params": {"curve": [0.01, 1e-4, 2.2e-6]}}]
    model = fx.from_diagnosis(_doc(refit, curve=curve))
    assert model.thrust_curve == curve
    assert model.effects[0].nominal == curve


def test_wind_with_drag_keeps_the_air_velocity():
    effects = [
        {
            "name": "wind",
            "params": {"force_N": [0.6, -0.3, 0.0], "air_velocity_m_per_s": [2.0, -1.0, 0.0]},
        }
    ]
    wind = fx.from_diagnosis(_doc(effects)).effects[0]
    assert wind.k == pytest.approx((0.3,) * 3)
    np.testing.assert_allclose(wind.steady_force(), [0.6, -0.3, 0.0])


def test_sample_draws_within_bounds_and_is_seeded():
    model = fx.from_diagnosis(_doc(EFFECTS))
    a = model.sample(np.random.default_rng(1))
    b = model.sample(np.random.default_rng(1))
    assert a == b and a != model.effects
    draws = [model.sample(np.random.default_rng(k))[0].tau for k in range(200)]
    assert 0.035 < np.mean(draws) < 0.045 and 0.0015 < np.std(draws) < 0.0025
    wide = _doc([dict(EFFECTS[1], uncertainty={"tau_s": 1.0})])
    taus = [fx.from_diagnosis(wide).sample(np.random.default_rng(k))[0].tau for k in range(50)]
    assert min(taus) >= 1e-4 and max(taus) <= 0.3  # clipped to the reported bounds


@pytest.mark.parametrize(
    "change, words",
    [
        ({"format": None}, "older quadfault diagnose"),
        ({"format": "quadfault-diagnosis/1"}, "expected 'quadfault-diagnosis/2'"),
        ({"vehicle": None}, "key 'vehicle'"),
        ({"vehicle": {"mass": -1}}, "vehicle.mass"),
        ({"frame": "XYZ"}, "key 'frame'"),
        ({"effects": {"drag": 1}}, "key 'effects'"),
        ({"effects": [{"name": "vortex", "params": {}}]}, "unknown effect 'vortex'"),
        ({"effects": [{"name": "drag"}]}, "effects[0].params"),
        ({"effects": [{"name": "motor_lag", "params": {"tau": 0.1}}]}, "params need 'tau_s'"),
        ({"effects": [{"name": "motor_lag", "params": {"tau_s": "fast"}}]}, "tau"),
        ({"effects": [{"name": "motor_lag", "params": {"tau_s": -1}}]}, "tau"),
        ({"effects": [{"name": "drag", "params": {"k_N_s_per_m": [1, [2]]}}]}, "drag"),
        ({"effects": [EFFECTS[1], EFFECTS[1]]}, "appears twice"),
    ],
)
def test_malformed_diagnosis_is_a_one_line_error(change, words):
    doc = _doc(EFFECTS)
    for key, value in change.items():
        if value is None:
            doc.pop(key)
        else:
            doc[key] = value
    with pytest.raises(ConfigError) as err:
        fx.from_diagnosis(doc)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_unreadable_files(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        fx.from_diagnosis(tmp_path / "none.json")
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": ')
    with pytest.raises(ConfigError, match="invalid JSON at line 1"):
        fx.from_diagnosis(bad)
    bad.write_text("[1, 2]")
    with pytest.raises(ConfigError, match="JSON object"):
        fx.from_diagnosis(bad)


def test_simulate_model_flies_the_effects_and_keeps_the_nominal_vehicle(tmp_path, capsys):
    path = tmp_path / "d.json"
    path.write_text(json.dumps(_doc(EFFECTS)))
    out = tmp_path / "r.csv"
    assert (
        main(
            [
                "simulate",
                "--model",
                str(path),
                "--scenario",
                "nominal",
                "--trajectory",
                "lissajous",
                "--duration",
                "1",
                "--dt",
                "0.004",
                "--out",
                str(out),
                "--quiet",
                "--commands",
                "u",
            ]
        )
        == 0
    )
    rec = read_recording(out)
    assert rec.vehicle == VEHICLE  # nominal, not the heavier flown one
    side = json.loads(out.with_suffix(".json").read_text())
    assert [e["name"] for e in side["effects"]] == ["motor_lag", "drag", "mass"]
    assert side["truth"] == {"model": str(path)}
    stripped = rec.without_truth().meta
    assert "effects" not in stripped and "truth" not in stripped
    # --effect adds to the model; naming an effect twice is an error
    assert (
        main(
            [
                "simulate",
                "--model",
                str(path),
                "--duration",
                "1",
                "--dt",
                "0.004",
                "--out",
                str(tmp_path / "r2.csv"),
                "--quiet",
                "--effect",
                "motor_lag=0.1",
            ]
        )
        == 2
    )
    assert "given twice" in capsys.readouterr().err
    path.write_text("{}")
    assert (
        main(
            [
                "simulate",
                "--model",
                str(path),
                "--duration",
                "1",
                "--out",
                str(tmp_path / "r3.csv"),
                "--quiet",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "format" in err


def test_simulate_battery_thrust_records_its_voltage(tmp_path, capsys):
    out = tmp_path / "b.csv"
    assert (
        main(
            [
                "simulate",
                "--scenario",
                "nominal",
                "--duration",
                "2",
                "--dt",
                "0.004",
                "--out",
                str(out),
                "--quiet",
                "--effect",
                "battery_thrust=2,v_start=4.2,v_end=3.7",
            ]
        )
        == 0
    )
    rec = read_recording(out)
    assert rec.vbat[0] == pytest.approx(4.2) and rec.vbat[-1] == pytest.approx(3.7, abs=1e-3)
    assert (
        main(
            [
                "simulate",
                "--scenario",
                "combined",
                "--duration",
                "2",
                "--out",
                str(tmp_path / "c.csv"),
                "--quiet",
                "--effect",
                "battery_thrust=2",
            ]
        )
        == 2
    )
    assert "own battery voltage" in capsys.readouterr().err


def test_written_recording_sidecar_is_a_valid_diagnosis_vehicle(tmp_path):
    """The diagnosis copies the sidecar's vehicle: what write_recording writes loads back."""
    rec = Recording(
        t=np.arange(3.0),
        omega=np.zeros((3, 3)),
        thrust_cmd=np.ones((3, 4)),
        vehicle=VEHICLE,
        position=np.zeros((3, 3)),
        velocity=np.zeros((3, 3)),
        quaternion=np.tile([1.0, 0, 0, 0], (3, 1)),
    )
    write_recording(rec, tmp_path / "x.csv", frame="ENU")
    side = json.loads((tmp_path / "x.json").read_text())
    doc = {
        "format": "quadfault-diagnosis/2",
        "frame": side["frame"],
        "gravity": side["gravity"],
        "vehicle": side["vehicle"],
        "effects": [],
    }
    assert fx.from_diagnosis(doc).vehicle == VEHICLE


@pytest.mark.slow
def test_rotor_inertia_without_lag_losing_the_vehicle_says_why(tmp_path, capsys):
    out = tmp_path / "ri.csv"
    assert (
        main(
            [
                "simulate",
                "--scenario",
                "nominal",
                "--trajectory",
                "lissajous",
                "--duration",
                "5",
                "--dt",
                "0.004",
                "--out",
                str(out),
                "--quiet",
                "--effect",
                "rotor_inertia=0.001",
                "--mixer",
                "plain",
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    assert "lost the vehicle" in err and "add --effect motor_lag" in err
