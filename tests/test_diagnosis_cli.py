"""Diagnosis JSON format (docs/formats.md), CLI, malformed input, IMU-only logs, gaps."""

import dataclasses
import json

import numpy as np
import pytest

from quadfault.cli import main
from quadfault.diagnosis import Diagnosis, DiagnosisConfig
from quadfault.errors import ConfigError, QuadfaultError, RecordingError
from quadfault.io.recording import write_recording
from quadfault.model import effects as fx
from quadfault.model.scenarios import named_scenario
from quadfault.model.trajectory import Lissajous
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate

CHANNELS = {"acc_x", "acc_y", "acc_z", "sf_x", "sf_y", "sf_z", "alpha_x", "alpha_y", "alpha_z"}


@pytest.fixture(scope="module")
def com_recording():
    sc = named_scenario("nominal", 5.0, 4e-3).replace(
        trajectory=Lissajous(amplitude=(1.5, 1.0, 0.2), frequency=0.2)
    )
    cfg = SimConfig(dt=4e-3, sensor_noise=SensorNoise(0.002, 0.005, 0.001, 0.001))
    return simulate(
        sc, config=cfg, seed=3, effects=(fx.ComOffset((0.015, 0.0)),), thrust_noise=0.02
    )


def _number(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def validate_contract(doc: dict) -> None:
    """A small validator of the diagnose output schema (docs/formats.md)."""
    assert set(doc) >= {"verdict", "baseline", "untestable", "where", "effects", "model"}
    assert doc["verdict"] in ("mismatch", "consistent")
    rm = doc["baseline"]["rmse"]
    assert isinstance(rm, dict) and rm and all(_number(v) and v >= 0 for v in rm.values())
    assert isinstance(doc["untestable"], list) and all(
        isinstance(s, str) for s in doc["untestable"]
    )
    for w in doc["where"]:
        assert set(w) == {"channel", "t0", "t1", "note"}
        assert isinstance(w["channel"], str) and isinstance(w["note"], str)
        assert _number(w["t0"]) and _number(w["t1"]) and w["t0"] <= w["t1"]
    imps = []
    for e in doc["effects"]:
        assert set(e) >= {
            "name",
            "params",
            "uncertainty",
            "improvement",
            "explanation",
            "bounds",
            "folds",
        }
        assert isinstance(e["name"], str) and e["name"] == e["name"].lower()
        assert isinstance(e["params"], dict) and isinstance(e["uncertainty"], dict)
        assert _number(e["improvement"]) and e["improvement"] <= 1.0
        assert isinstance(e["explanation"], str) and e["explanation"]
        imps.append(e["improvement"])
    assert imps == sorted(imps, reverse=True)  # most important first
    if doc["verdict"] == "consistent":
        assert doc["effects"] == []
    assert set(doc["model"]) >= {"rmse", "improvement"}
    assert _number(doc["model"]["improvement"]) and doc["model"]["improvement"] <= 1.0
    assert set(doc["model"]["rmse"]) == set(rm)


@pytest.mark.slow
def test_json_validates_and_cli_writes_report(com_recording, tmp_path):
    csv = tmp_path / "flight.csv"
    write_recording(com_recording, csv)
    out = tmp_path / "diag.json"
    rep = tmp_path / "rep"
    assert main(["diagnose", str(csv), "--json", str(out), "--report", str(rep), "--quiet"]) == 0
    doc = json.loads(out.read_text())
    validate_contract(doc)
    assert doc["verdict"] == "mismatch" and doc["effects"][0]["name"] == "com_offset"
    assert set(doc["baseline"]["rmse"]) == CHANNELS
    assert doc["effects"][0]["params"]["offset_m"][0] == pytest.approx(0.015, abs=0.002)
    for f in ("report.md", "residuals.png", "regimes.png", "prediction.png"):
        assert (rep / f).stat().st_size > 100
    assert "com_offset" in (rep / "report.md").read_text()
    # no silent overwrite; --force allows it
    assert main(["diagnose", str(csv), "--json", str(out), "--quiet"]) == 2
    assert (
        main(
            [
                "diagnose",
                str(csv),
                "--json",
                str(out),
                "--quiet",
                "--force",
                "--effects",
                "drag,wind",
            ]
        )
        == 0
    )
    validate_contract(json.loads(out.read_text()))


def test_cli_errors_are_one_line(tmp_path, capsys, com_recording):
    assert main(["diagnose", str(tmp_path / "none.csv"), "--json", str(tmp_path / "o.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "not found" in err
    bad = tmp_path / "bad.csv"
    bad.write_text("t,wx\n0,1\n")
    assert main(["diagnose", str(bad), "--json", str(tmp_path / "o.json")]) == 2
    assert "sidecar" in capsys.readouterr().err
    csv = tmp_path / "flight.csv"
    write_recording(com_recording, csv)
    side = (tmp_path / "flight.json").read_text()
    # the recording's own sidecar is never the output, not even with --force
    assert main(["diagnose", str(csv), "--json", str(tmp_path / "flight.json"), "--force"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "sidecar" in err
    assert (tmp_path / "flight.json").read_text() == side
    assert (
        main(["diagnose", str(csv), "--json", str(tmp_path / "o.json"), "--effects", "vortex"]) == 2
    )
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "vortex" in err


def test_no_mask_flag_and_json_additions(com_recording, tmp_path):
    csv = tmp_path / "flight.csv"
    write_recording(com_recording, csv, frame="ENU")
    out = tmp_path / "d.json"
    assert main(["diagnose", str(csv), "--json", str(out), "--quiet", "--no-mask"]) == 0
    doc = json.loads(out.read_text())
    assert doc["format"] == "quadfault-diagnosis/2" and doc["frame"] == "ENU"
    assert doc["vehicle"] == json.loads((tmp_path / "flight.json").read_text())["vehicle"]
    assert doc["scoring"]["excluded"] == [] and doc["scoring"]["excluded_fraction"] == 0.0
    assert set(doc["model"]["channels"]) == set(doc["baseline"]["rmse"])
    for key in ("suspect", "rejected"):
        assert isinstance(doc[key], list)
    for e in doc["effects"] + doc["suspect"] + doc["rejected"]:
        assert set(e["bounds"]) and set(e["folds"])


def test_malformed_recordings_give_clear_errors(com_recording):
    short = com_recording.slice(0, 12)
    with pytest.raises(RecordingError, match="too short"):
        Diagnosis().fit(short)
    omega = com_recording.omega.copy()
    omega[40, 1] = np.nan
    with pytest.raises(RecordingError, match="row 41"):
        Diagnosis().fit(dataclasses.replace(com_recording, omega=omega))
    from quadfault.model.vehicle import Vehicle

    six = Vehicle.from_rotors(
        [(1, 0), (0.5, 0.8), (-0.5, 0.8), (-1, 0), (-0.5, -0.8), (0.5, -0.8)],
        [1, -1, 1, -1, 1, -1],
        0.01,
    )
    with pytest.raises(RecordingError, match="rotor"):
        Diagnosis().fit(com_recording, vehicle=six)
    with pytest.raises(ConfigError, match="folds"):
        DiagnosisConfig(folds=1)
    with pytest.raises(ConfigError, match="unknown effect"):
        DiagnosisConfig(effects=("vortex",))
    with pytest.raises(QuadfaultError):
        Diagnosis().fit("not a recording")


def test_imu_only_log_lists_untestable_effects(com_recording):
    imu = dataclasses.replace(com_recording, position=None, velocity=None, quaternion=None)
    res = Diagnosis().fit(imu)
    assert set(res.untestable) == {
        "drag",
        "wind",
        "ground_effect",
        "blade_flapping",
        "battery_thrust",
    }
    assert set(res.baseline_rmse) == {"sf_x", "sf_y", "sf_z", "alpha_x", "alpha_y", "alpha_z"}
    assert res.effect_names[0] == "com_offset"
    # no pose to start from: the prediction is of the body rate and the attitude change
    p = res.prediction
    assert "position_rmse_m" not in p and set(p["rate_rmse_rad_per_s"]) == {
        "nominal",
        "model",
        "constant_velocity",
        "constant_acceleration",
    }


def test_gaps_and_jitter_are_handled(com_recording):
    rec = com_recording
    keep = np.ones(len(rec), bool)
    keep[300:340] = False  # a 0.16 s dropout
    keep[::7] = False  # irregular sampling
    idx = np.flatnonzero(keep)
    cut = dataclasses.replace(
        rec,
        t=rec.t[idx],
        omega=rec.omega[idx],
        thrust_cmd=rec.thrust_cmd[idx],
        position=rec.position[idx],
        velocity=rec.velocity[idx],
        quaternion=rec.quaternion[idx],
        accel=rec.accel[idx],
        eta_true=None,
    )
    res = Diagnosis().fit(cut)
    assert res.effect_names[0] == "com_offset"
    assert res.effects[0].params["offset_m"][0] == pytest.approx(0.015, abs=0.003)
