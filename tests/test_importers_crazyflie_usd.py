"""Crazyflie uSD-deck event logs written by the tests (tests/support/field_logs.py): several
event types at different rates aligned onto the gyro's stamps, frames, the presets, both
format versions, the CRC, cut and corrupt logs, and one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from quadfault.errors import QuadfaultError
from tests.support.field_logs import HOVER, OMEGA_PER_U, T_LAND, T_TAKEOFF, usd_log

G = 9.81


def _import(path, **kw):
    from quadfault.io.importers.crazyflie_usd import import_crazyflie_usd

    return import_crazyflie_usd(path, **kw)


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "quadfault.cli", "import", *map(str, args)],
        capture_output=True,
        text=True,
    )


@pytest.mark.parametrize("version", [2, 1])
def test_event_types_at_different_rates_make_one_recording(tmp_path, version):
    path = tmp_path / "log00"
    usd_log(path, version=version)
    from quadfault.io.importers import detect_format

    assert detect_format(path) == "crazyflie-usd"
    rec = _import(path)
    # the gyro's 500 Hz event is the time base; the flight span from the commands
    assert rec.meta["import"]["rate_hz"] == pytest.approx(500.0, rel=0.01)
    assert T_TAKEOFF < rec.t[0] and rec.t[-1] < T_LAND
    assert rec.meta["import"]["missing"] == []
    # z up (taken as ENU) / FLU -> NED / FRD: 1 m above ground is z = -1, the accelerometer
    # reads -g on z, the Crazyflie's x axis is east (the level body points there: yaw 90 deg)
    np.testing.assert_allclose(rec.position[:, 2], -1.0, atol=1e-6)
    np.testing.assert_allclose(rec.position[:, 1], 0.1 * np.sin(0.3 * rec.t), atol=1e-3)
    np.testing.assert_allclose(rec.accel[:, 2], -G, atol=1e-4)
    yaw90 = np.tile([np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)], (len(rec), 1))
    np.testing.assert_allclose(rec.quaternion, yaw90, atol=1e-9)
    np.testing.assert_allclose(np.median(rec.commands_u, axis=0), HOVER, atol=0.02)
    # the 250 Hz RPM deck aligned with the 500 Hz commands (the same profile)
    np.testing.assert_allclose(rec.rotor_speed / rec.commands_u, OMEGA_PER_U, rtol=0.03)
    assert rec.vbat is not None and rec.meta["import"]["battery"]["plausible"]
    # the brushed preset, assumed and said so; the thrust calibrated on free flight
    assert rec.vehicle.mass == pytest.approx(0.027)
    assert any("preset" in a for a in rec.meta["assumed"])
    assert any("Crazyflie 2.1 (brushed) preset" in w for w in rec.meta["import"]["warnings"])
    cal = rec.meta["calibration"]
    sel = (rec.t >= cal["segment"][0]) & (rec.t <= cal["segment"][1])
    assert rec.thrust_cmd[sel].sum(1).mean() == pytest.approx(0.027 * G, rel=1e-6)
    assert "Foerster" in cal["thrust_model"]
    rates = rec.meta["log_parameters"]["event_rates_hz"]
    assert rates == {"fixedFrequency": 500.0, "estimate": 100.0, "rpm": 250.0, "power": 10.0}


def test_brushless_preset_and_user_vehicle(tmp_path):
    path = tmp_path / "log01"
    usd_log(path)
    rec = _import(path, preset="crazyflie21-brushless")
    assert rec.vehicle.mass == pytest.approx(0.045) and rec.meta["assumed"] == []
    assert "linear in the command" in rec.meta["calibration"]["thrust_model"]
    a, b, c = rec.thrust_curve
    assert a == 0.0 and c == 0.0 and b > 0
    vfile = tmp_path / "cf.json"
    vfile.write_text(
        json.dumps(
            {
                "mass": 0.032,
                "inertia": [1.7e-5, 1.7e-5, 2.9e-5],
                "arm": 0.028,
                "torque_coefficient": 0.006,
            }
        )
    )
    res = _cli(path, "--out", tmp_path / "o.csv", "--vehicle", vfile)
    assert res.returncode == 0 and res.stderr == "", res.stderr
    side = json.loads((tmp_path / "o.json").read_text())
    assert side["vehicle"]["mass"] == pytest.approx(0.032)
    assert side["constants"]["vehicle"] == "from the user's vehicle file"


def test_motion_capture_pose_without_state_estimate(tmp_path):
    path = tmp_path / "log02"
    usd_log(path, mocap=True)
    rec = _import(path)
    np.testing.assert_allclose(rec.position[:, 2], -1.0, atol=1e-6)
    np.testing.assert_allclose(rec.velocity[:, 1], 0.03 * np.cos(0.3 * rec.t), atol=2e-3)
    assert any("locSrv" in w for w in rec.meta["import"]["warnings"])


def test_cut_and_corrupt_logs_import_what_is_valid_and_say_so(tmp_path):
    path = tmp_path / "log03"
    usd_log(path)
    data = bytearray(path.read_bytes())
    n = len(data)
    data[n // 2 : n // 2 + 60] = b"\xff" * 60  # corrupt records in the middle
    cut = tmp_path / "log04"
    cut.write_bytes(bytes(data[: int(n * 0.8) + 5]))  # no CRC, last record cut
    res = _cli(cut, "--out", tmp_path / "o.csv")
    assert res.returncode == 0, res.stderr
    assert res.stderr.count("\n") == 1 and "bytes skipped" in res.stderr, res.stderr
    assert "no CRC32" in res.stderr
    skipped = json.loads((tmp_path / "o.json").read_text())["import"]["skipped"]
    assert skipped["truncated"] and skipped["corrupt"] == 1 and skipped["bytes"] >= 60
    ((a, b),) = skipped["spans"]
    assert 0 < b - a < 0.1 and 8.0 < a < 11.0
    rec = _import(cut)
    assert rec.t[-1] < 0.8 * 19.0 + 0.5


def test_what_is_missing_is_said_in_one_line(tmp_path):
    path = tmp_path / "log05"
    usd_log(path, gyro=False)
    res = _cli(path, "--out", tmp_path / "o.csv")
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert "no body rates (gyro.x" in res.stderr and "fixedFrequency: acc.x" in res.stderr
    bad = tmp_path / "log06"
    bad.write_bytes(b"\xbc\x02\x00\x01\x00\x01\x00abc")  # cut inside its header
    res = _cli(bad, "--out", tmp_path / "o2.csv", "--format", "crazyflie-usd")
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    with pytest.raises(QuadfaultError, match="preset"):
        _import(path, preset="crazyflie3")


def test_implausible_battery_voltage_for_one_cell(tmp_path):
    path = tmp_path / "log07"
    usd_log(path, vbat=5.8)
    bat = _import(path).meta["import"]["battery"]
    assert bat["cells"] == 1 and not bat["plausible"] and "battery_thrust" in bat["why"]
