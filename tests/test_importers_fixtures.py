"""Importers on small synthetic raw logs (tests/fixtures/, made by make_importer_fixtures.py):
allocation signs, unit and frame conversions, trimming, duplicate stamps, calibration,
round trips through the recording format, and clear errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from quadfault.errors import ConfigError, RecordingError
from quadfault.io.importers.crazyflie import (
    CF21_BRUSHED,
    CRAZYFLIE_ROTOR_XY_FLU,
    CRAZYFLIE_YAW_SIGNS_FLU,
    FOERSTER_THRUST_CURVE,
    crazyflie_allocation,
)
from quadfault.io.importers.crazypad import import_crazypad, power_distribution_legacy
from quadfault.io.importers.eschmann import import_eschmann
from quadfault.io.importers.nanodrone import import_nanodrone
from quadfault.io.recording import read_recording, vehicle_flu_to_frd, write_recording
from quadfault.model.effects import curve_thrust
from quadfault.model.rotation import quat_to_rot, rot_to_euler_zyx

FIX = Path(__file__).parent / "fixtures"
G = 9.81


# ----------------------------------------------------------------------------------------
# allocation
def test_crazyflie_allocation_signs_frd():
    A = crazyflie_allocation(0.028, 0.006)
    f = np.eye(4)  # columns: M1 front-right, M2 back-right, M3 back-left, M4 front-left
    np.testing.assert_array_equal(A[0], [1, 1, 1, 1])
    # left rotors (M3, M4) pushing up raise the left side: positive roll about +x (FRD)
    assert (A @ (f[2] + f[3]))[1] > 0 and (A @ (f[0] + f[1]))[1] < 0
    # front rotors (M1, M4) pushing up raise the nose: positive pitch about +y (FRD, right)
    assert (A @ (f[0] + f[3]))[2] > 0 and (A @ (f[1] + f[2]))[2] < 0
    # M1 and M3 react with -z_FLU torque = +z_FRD (nose right, seen from above)
    assert (A @ (f[0] + f[2]))[3] > 0 and (A @ (f[1] + f[3]))[3] < 0
    # equal thrusts give a pure collective force
    np.testing.assert_allclose(A @ np.ones(4), [4, 0, 0, 0], atol=1e-15)


def test_crazyflie_allocation_matches_a_flu_construction():
    # the same layout built directly in FLU (moment of thrust f along +z_FLU at (x, y) is
    # (y f, -x f)) and converted with the recording module's FLU -> FRD map
    d, c = 0.028, 0.006
    xy = np.asarray(CRAZYFLIE_ROTOR_XY_FLU) * d
    A_flu = np.stack([np.ones(4), xy[:, 1], -xy[:, 0], c * np.asarray(CRAZYFLIE_YAW_SIGNS_FLU)])
    veh = vehicle_flu_to_frd(0.03, [1e-5, 1e-5, 2e-5], A_flu)
    np.testing.assert_allclose(veh.allocation, crazyflie_allocation(d, c), atol=1e-15)


# ----------------------------------------------------------------------------------------
# Eschmann
def test_eschmann_fixture_units_frames_trim_and_duplicates():
    rec = import_eschmann(FIX / "eschmann_log.csv")
    # motors on in rows 10..49 (40 rows), one of them repeats a time stamp
    assert len(rec) == 39
    assert rec.meta["import"]["dropped_duplicate_times"] == 1
    assert np.all(np.diff(rec.t) > 0)
    np.testing.assert_allclose(np.median(np.diff(rec.t)), 1e-3)  # ms -> s
    assert not rec.has_pose and rec.accel is not None
    # +1 g along z_FLU -> (0, 0, -g) in FRD
    np.testing.assert_allclose(rec.accel.mean(0), [0, 0, -G], atol=0.1)
    assert np.max(np.abs(rec.omega)) < np.radians(3.0)  # deg/s -> rad/s
    # thrust scale fitted on the calibration segment: mean sum f = m * mean(-a_z) there
    cal = rec.meta["calibration"]
    sel = (rec.t >= cal["segment"][0]) & (rec.t <= cal["segment"][1])
    assert sel.sum() >= 5
    np.testing.assert_allclose(
        rec.thrust_cmd[sel].sum(1).mean(), -CF21_BRUSHED.mass * rec.accel[sel, 2].mean(), rtol=1e-9
    )
    scale = cal["fitted"]["thrust_scale"]
    np.testing.assert_allclose(rec.thrust_curve, np.array(FOERSTER_THRUST_CURVE) * scale)
    np.testing.assert_allclose(rec.thrust_cmd, curve_thrust(rec.thrust_curve, rec.commands_u))


def test_eschmann_keep_all_and_explicit_calibration():
    rec = import_eschmann(FIX / "eschmann_log.csv", keep_all=True, calibration=(30.02, 30.04))
    assert len(rec) == 54
    assert rec.meta["calibration"]["segment"] == [30.02, 30.04]
    np.testing.assert_allclose(rec.accel[:10].mean(0), [0, 0, -G], atol=0.1)  # at rest


@pytest.mark.parametrize("frame", ["NED", "ENU"])
def test_round_trip_through_the_recording_format(tmp_path, frame):
    for rec in (
        import_eschmann(FIX / "eschmann_log.csv"),
        import_nanodrone(FIX / "nanodrone_flight.csv"),
        import_crazypad(FIX / "crazypad_motor_log.csv"),
    ):
        out = write_recording(rec, tmp_path / f"{rec.meta['dataset']}_{frame}.csv", frame=frame)
        back = read_recording(out)
        np.testing.assert_allclose(back.t, rec.t)
        np.testing.assert_allclose(back.omega, rec.omega, atol=1e-12)
        np.testing.assert_allclose(back.thrust_cmd, rec.thrust_cmd, rtol=1e-12)
        np.testing.assert_allclose(back.vehicle.allocation, rec.vehicle.allocation, atol=1e-15)
        if rec.accel is not None:
            np.testing.assert_allclose(back.accel, rec.accel, atol=1e-12)
        if rec.has_pose:
            np.testing.assert_allclose(back.position, rec.position, atol=1e-12)
            np.testing.assert_allclose(
                quat_to_rot(back.quaternion), quat_to_rot(rec.quaternion), atol=1e-12
            )
        assert back.meta["dataset"] == rec.meta["dataset"]
        assert "calibration" in back.meta and "licence" in back.meta


# ----------------------------------------------------------------------------------------
# nanodrone
def test_nanodrone_fixture_frames_and_rotor_speeds():
    rec = import_nanodrone(FIX / "nanodrone_flight.csv")
    assert len(rec) == 37  # is_flying from row 3
    # ENU yaw 0.3 (from east towards north) is NED heading pi/2 - 0.3
    rpy = rot_to_euler_zyx(quat_to_rot(rec.quaternion))
    np.testing.assert_allclose(rpy[:, 2], np.pi / 2 - 0.3, atol=1e-6)
    np.testing.assert_allclose(rpy[:, :2], 0.0, atol=1e-6)
    # ENU (x east, z up) -> NED: north = y_enu, east = x_enu, down = -z
    np.testing.assert_allclose(rec.position[0], [-0.2, 0.103, -0.5], atol=1e-9)
    np.testing.assert_allclose(rec.velocity[:, 1], 0.1)
    # world specific force (0, 0, +g) rotated into the body -> (0, 0, -g) in FRD
    np.testing.assert_allclose(rec.accel.mean(0), [0, 0, -G], atol=0.05)
    # eRPM -> rad/s, dropout and telemetry spike -> NaN
    assert np.isnan(rec.rotor_speed[7 - 3, 2]) and np.isnan(rec.rotor_speed[30 - 3, 1])
    hover_w = np.sqrt(0.045 * G / 4 / 3.72e-8)
    assert abs(np.nanmedian(rec.rotor_speed) / hover_w - 1) < 0.05
    # thrust curve fitted to k_F omega^2: predicts hover thrust ~ m g
    assert rec.thrust_cmd.sum(1).mean() == pytest.approx(0.045 * G, rel=0.05)
    assert rec.vbat is not None and rec.vbat.max() <= 3.9


# ----------------------------------------------------------------------------------------
# CrazyPAD
def test_crazypad_motor_log_reconstructs_pitch_and_hides_the_label():
    rec = import_crazypad(FIX / "crazypad_motor_log.csv")
    assert rec.meta["log_kind"] == "motor_data"
    assert rec.has_pose and len(rec) == 50
    air = -rec.position[:, 2] > 0.3
    rpy = rot_to_euler_zyx(quat_to_rot(rec.quaternion))
    # the fixture leans nose-down by 2 deg: negative pitch in FRD
    np.testing.assert_allclose(np.degrees(rpy[air, 1]), -2.0, atol=0.05)
    assert rec.meta["import"]["roll_check_rms_deg"] < 0.05
    assert "truth" in rec.meta and "truth" not in rec.without_truth().meta
    np.testing.assert_allclose(rec.vbat, 3.8)
    assert set(rec.extra) == {"pwm1", "pwm2", "pwm3", "pwm4"}
    assert any("pitch" in m for m in rec.meta["import"]["missing"])


def test_crazypad_controller_log_mixer_and_gyro_sign():
    rec = import_crazypad(FIX / "crazypad_controller_log.csv")
    assert rec.meta["log_kind"] == "controller_data"
    # legacy mixer: m1 = T - r/2 + p/2 + y with (T, r, p, y) = (40000, 2000, 400, 5000)
    expected = (
        np.array(
            [
                40000 - 1000 + 200 + 5000,
                40000 - 1000 - 200 - 5000,
                40000 + 1000 - 200 + 5000,
                40000 + 1000 + 200 - 5000,
            ]
        )
        / 65536
    )
    np.testing.assert_allclose(rec.commands_u[5], expected)
    # gyro bias removed from the rest before take-off: mean rate ~ 0
    assert np.abs(rec.omega.mean(0)).max() < 2e-3
    assert "az_frd" in rec.extra and np.mean(rec.extra["az_frd"]) == pytest.approx(-G, rel=0.02)


def test_power_distribution_caps_and_stops():
    cmd = np.array([[65000.0, 0.0, 0.0, 2000.0], [0.0, 100.0, 100.0, 100.0]])
    m = power_distribution_legacy(cmd)
    assert m[0].max() == 65535 and m[0, 0] - m[0, 1] == pytest.approx(4000)
    np.testing.assert_array_equal(m[1], 0.0)


# ----------------------------------------------------------------------------------------
# errors
def test_missing_column_names_the_column(tmp_path):
    text = (FIX / "eschmann_log.csv").read_text().replace("gyro.y", "gyro_y")
    (tmp_path / "bad.csv").write_text(text)
    with pytest.raises(RecordingError, match=r"bad\.csv.*column 'gyro\.y'"):
        import_eschmann(tmp_path / "bad.csv")


def test_bad_cell_names_row_and_column(tmp_path):
    lines = (FIX / "eschmann_log.csv").read_text().splitlines()
    cells = lines[4].split(",")
    cells[3] = "oops"
    lines[4] = ",".join(cells)
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match=r"column 'acc\.z', row 4: not a number"):
        import_eschmann(tmp_path / "bad.csv")


def test_motors_never_running_and_empty_files(tmp_path):
    lines = (FIX / "eschmann_log.csv").read_text().splitlines()
    (tmp_path / "off.csv").write_text("\n".join(lines[:8]) + "\n")
    with pytest.raises(ConfigError, match="never run"):
        import_eschmann(tmp_path / "off.csv")
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(RecordingError, match="empty"):
        import_eschmann(tmp_path / "empty.csv")
    with pytest.raises(RecordingError, match="neither a motor_data"):
        import_crazypad(FIX / "nanodrone_flight.csv")


def test_trim_to_flight_drops_backward_stamps_and_keeps_the_running_span():
    from quadfault.io.importers import trim_to_flight

    t = np.arange(100) * 0.01
    t[50] = t[49]  # a repeated stamp: dropped
    u = np.zeros((100, 4))
    u[10:80, 2] = 0.4  # one motor running from row 10 to 79
    arrays = {"t": t, "u": u}
    kept, t_run, dropped = trim_to_flight("log.csv", arrays, u, keep_all=False)
    assert dropped == 1
    assert t_run == (0.10, 0.79)
    assert len(kept["t"]) == 69 and np.all(np.diff(kept["t"]) > 0)
    assert np.all(kept["u"][:, 2] == 0.4)
    whole, _, _ = trim_to_flight("log.csv", arrays, u, keep_all=True)
    assert len(whole["t"]) == 99
    with pytest.raises(ConfigError, match=r"^log.csv: only 10 rows while flying$"):
        trim_to_flight(
            "log.csv",
            arrays,
            np.where(np.arange(100)[:, None] < 10, 1.0, 0.0),
            keep_all=False,
            threshold=0.5,
            rows="while flying",
        )
    with pytest.raises(ConfigError, match="^log.csv: the motors never run$"):
        trim_to_flight("log.csv", arrays, np.zeros((100, 4)), keep_all=False)


# ----------------------------------------------------------------------------------------
# CLI
def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "quadfault.cli", "import", *map(str, args)],
        capture_output=True,
        text=True,
    )


def test_cli_writes_and_refuses_to_overwrite(tmp_path):
    out = tmp_path / "rec.csv"
    res = _cli("nanodrone", FIX / "nanodrone_flight.csv", "--out", out)
    assert res.returncode == 0, res.stderr
    assert "37 rows" in res.stdout and "100 Hz" in res.stdout
    assert read_recording(out).meta["dataset"] == "nanodrone-cf21bl"
    res = _cli("nanodrone", FIX / "nanodrone_flight.csv", "--out", out)
    assert res.returncode == 2 and "already exists" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    res = _cli("nanodrone", FIX / "nanodrone_flight.csv", "--out", out, "--force", "--quiet")
    assert res.returncode == 0 and res.stdout == ""


def test_cli_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text((FIX / "eschmann_log.csv").read_text().replace("motor.m3", "motor.mX"))
    cases = [
        (("eschmann", bad, "--out", tmp_path / "o.csv"), "column 'motor.m3'"),
        (("eschmann", tmp_path / "none.csv", "--out", tmp_path / "o.csv"), "not found"),
        (("eschmann", FIX / "eschmann_log.csv", "--out", tmp_path / "o.txt"), ".csv"),
        (
            (
                "eschmann",
                FIX / "eschmann_log.csv",
                "--out",
                tmp_path / "o.csv",
                "--calibration",
                "5",
            ),
            "--calibration",
        ),
        (
            (
                "crazypad",
                FIX / "crazypad_motor_log.csv",
                "--out",
                tmp_path / "o.csv",
                "--vehicle",
                tmp_path / "none.json",
            ),
            "not found",
        ),
    ]
    for args, needle in cases:
        res = _cli(*args)
        assert res.returncode == 2, (args, res.stderr)
        assert needle in res.stderr and "Traceback" not in res.stderr
        assert len(res.stderr.strip().splitlines()) == 1


def test_cli_vehicle_file_overrides_constants(tmp_path):
    import json

    veh = {
        "mass": 0.05,
        "inertia": [2e-5, 2e-5, 4e-5],
        "allocation": crazyflie_allocation(0.03, 0.006).tolist(),
        "thrust_curve": [0.0, 0.0, 0.2],
    }
    (tmp_path / "veh.json").write_text(json.dumps(veh))
    res = _cli(
        "crazypad",
        FIX / "crazypad_motor_log.csv",
        "--out",
        tmp_path / "o.csv",
        "--vehicle",
        tmp_path / "veh.json",
    )
    assert res.returncode == 0, res.stderr
    back = read_recording(tmp_path / "o.csv")
    assert back.vehicle.mass == 0.05 and back.thrust_curve == (0.0, 0.0, 0.2)
    np.testing.assert_allclose(back.thrust_cmd, 0.2 * back.commands_u**2)
