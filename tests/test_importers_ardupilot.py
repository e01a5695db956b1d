"""ArduPilot DataFlash importer on small logs written by the tests (binary from FMT messages,
and the same flight as a text log): motors on remapped servo channels, a second IMU and EKF
core, ESC telemetry, invalid-velocity spans, land events, the thrust-curve parameters, and
one-line errors on bad input."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from quadfault.errors import QuadfaultError
from tests.support.field_logs import HOVER, OMEGA_PER_U, T_LAND, T_TAKEOFF, G, dataflash_flight

pytest.importorskip("pymavlink")


def _import(path, **kw):
    from quadfault.io.importers.ardupilot import import_ardupilot

    return import_ardupilot(path, **kw)


@pytest.mark.parametrize("text", [False, True], ids=["bin", "log"])
def test_dataflash_flight(tmp_path, text):
    path = tmp_path / ("flight.log" if text else "flight.bin")
    dataflash_flight(path, text=text)
    from quadfault.io.importers import detect_format

    assert detect_format(path) == "ardupilot"
    rec = _import(path, mass=1.5)
    # land events: free flight only, take-off and landing cut
    assert rec.t[0] >= T_TAKEOFF + 0.5 + 1.0 - 1e-6 and rec.t[-1] <= T_LAND - 0.5 - 1.0 + 1e-6
    assert rec.meta["import"]["flight_span_from"] == "land detector"
    # motors on SERVO5..8 (Motor1..4), not channels 1-4; IMU and EKF instance 0 only
    np.testing.assert_allclose(np.median(rec.commands_u, axis=0), HOVER, atol=0.02)
    np.testing.assert_allclose(rec.accel, np.tile([0, 0, -G], (len(rec), 1)), atol=1e-5)
    assert np.all(np.abs(rec.position[:, 2] + 1.0) < 1e-6)
    np.testing.assert_allclose(rec.rotor_speed / rec.commands_u, OMEGA_PER_U, rtol=0.02)
    # invalid velocity (XKF4 SS bit 1 cleared on 8-9 s) is never written
    assert not np.any((rec.t > 8.0) & (rec.t < 9.0))
    assert np.all(np.abs(rec.velocity) < 0.1)
    # ATT yaw 30 deg
    from quadfault.model.rotation import quat_to_rot

    R = quat_to_rot(rec.quaternion)
    np.testing.assert_allclose(np.degrees(np.arctan2(R[:, 1, 0], R[:, 0, 0])), 30.0, atol=1e-3)
    # the thrust-curve parameters shape the curve, the scale is calibrated on free flight
    cal = rec.meta["calibration"]
    assert "MOT_THST_EXPO = 0.5" in cal["thrust_model"]
    a, b, c = rec.thrust_curve
    s0, s1 = 0.1, 0.95
    x = (0.6 - s0) / (s1 - s0)
    ref = (a + b * 0.6 + c * 0.36) / (a + b * s1 + c * s1**2)
    assert ref == pytest.approx(0.5 * x + 0.5 * x * x, rel=1e-4)
    assert a + b * s0 + c * s0**2 == pytest.approx(0.0, abs=1e-5)
    sel = (rec.t >= cal["segment"][0]) & (rec.t <= cal["segment"][1])
    assert rec.thrust_cmd[sel].sum(1).mean() == pytest.approx(1.5 * G, rel=1e-6)
    assert rec.meta["log_parameters"]["MOT_SPIN_MIN"] == pytest.approx(0.1)
    assert "geometry" in rec.meta["assumed"]  # ArduPilot logs no arm length
    assert rec.vbat is not None


def test_low_rate_outputs_and_no_land_events(tmp_path):
    path = tmp_path / "slow.bin"
    dataflash_flight(path, rcou_rate=10.0, invalid_vxy=None, params={"FRAME_TYPE": 12})
    rec = _import(path)
    assert rec.meta["import"]["stream_rates_hz"]["u"] == pytest.approx(10.0, rel=1e-3)
    # Betaflight X order: rotor 1 rear-right, reacting clockwise (-z)
    A = rec.vehicle.allocation
    assert A[2, 0] < 0 and A[1, 0] < 0 and A[3, 0] < 0


def test_a_land_detector_that_never_reports_flight_falls_back_to_the_threshold(tmp_path):
    from quadfault.io.importers.ardupilot import read_ardupilot
    from quadfault.io.importers.field_log import build_recording

    path = tmp_path / "flight.bin"
    dataflash_flight(path)
    log = read_ardupilot(path)
    ts, _ = log.landed
    log.landed = (ts, np.ones(len(ts), dtype=bool))
    rec = build_recording(log)
    assert "never reports a flight" in rec.meta["import"]["flight_span_from"]
    assert rec.t[0] > T_TAKEOFF and np.all(rec.commands_u > 0.3)


def test_threshold_span_without_land_events(tmp_path):
    from quadfault.io.importers.ardupilot import read_ardupilot
    from quadfault.io.importers.field_log import build_recording

    path = tmp_path / "flight.bin"
    dataflash_flight(path)
    log = read_ardupilot(path)
    log.landed = None
    rec = build_recording(log)
    assert rec.meta["import"]["flight_span_from"].startswith("mean command above")
    assert rec.t[0] > T_TAKEOFF and rec.t[-1] < T_LAND
    assert np.all(rec.commands_u > 0.3)  # no armed idle


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "quadfault.cli", "import", *map(str, args)],
        capture_output=True,
        text=True,
    )


@pytest.mark.parametrize("case", ["truncated", "wrong_format", "no_motors", "no_imu", "not_a_quad"])
def test_bad_input_gives_one_line(tmp_path, case):
    path = tmp_path / "flight.bin"
    dataflash_flight(path)
    args = []
    if case == "truncated":
        path.write_bytes(path.read_bytes()[:1500])
    elif case == "wrong_format":
        path.write_bytes(b"\x00\x01garbage" * 50)
        args = ["--format", "ardupilot"]
    elif case == "no_motors":
        data = path.read_bytes().replace(b"RCOU", b"RCOX")
        path.write_bytes(data)
    elif case == "no_imu":
        path.write_bytes(path.read_bytes().replace(b"GyrX", b"Gyr1"))  # no gyro, any name
    else:
        dataflash_flight(path, params={"FRAME_CLASS": 2})
    res = _cli(path, "--out", tmp_path / "o.csv", *args)
    assert res.returncode != 0
    assert res.stderr.count("\n") == 1 and "Traceback" not in res.stderr, res.stderr
    assert "flight.bin" in res.stderr or "FRAME_CLASS" in res.stderr


def test_motors_never_running_is_an_error(tmp_path):
    from quadfault.io.importers.ardupilot import read_ardupilot
    from quadfault.io.importers.field_log import build_recording

    path = tmp_path / "flight.bin"
    dataflash_flight(path)
    log = read_ardupilot(path)
    ts, u, kind = log.streams["u"]
    log.streams["u"] = (ts, 0.0 * u, kind)
    with pytest.raises(QuadfaultError, match="motors never run"):
        build_recording(log)


# ------------------------------------------------------------------ old text logs (3.x)
@pytest.mark.parametrize("gps", ["board", "tow"])
def test_old_text_log_timed_by_gps_with_position_from_gps(tmp_path, gps):
    """No time stamp in IMU/ATT/MOT: they are timed by their place between the GPS fixes
    (board clock T, else GPS time of week); position and velocity come from the GPS."""
    from tests.support.field_logs import BOARD_T0, old_text_log

    path = tmp_path / "old.log"
    old_text_log(path, gps=gps)
    rec = _import(path)
    t = rec.t - (BOARD_T0 if gps == "board" else 0.0)  # the time of week starts at 0
    dt = np.diff(t)
    assert np.median(dt) == pytest.approx(0.02, rel=0.02)  # the 50 Hz loop
    assert np.max(dt[dt < 0.1]) < 0.03  # evenly timed between fixes
    # the threshold span: hover only, take-off and landing cut
    assert t[0] > T_TAKEOFF and t[-1] < T_LAND and np.all(rec.commands_u > 0.3)
    expected = 0.1 * np.sin(0.3 * t)  # north [m] of the synthetic flight
    np.testing.assert_allclose(rec.position[:, 0], expected, atol=0.03)
    np.testing.assert_allclose(rec.position[:, 2], -1.0, atol=0.02)
    np.testing.assert_allclose(rec.velocity[:, 0], 0.03 * np.cos(0.3 * t), atol=0.01)
    np.testing.assert_allclose(rec.velocity[:, 2], 0.0, atol=0.02)
    np.testing.assert_allclose(rec.accel[:, 2], -G, atol=1e-3)
    assert rec.vbat is not None and 14.0 < np.median(rec.vbat) < 16.0  # centivolts
    warnings = " ".join(rec.meta["import"]["warnings"])
    assert "position and velocity from GPS" in warnings


def test_old_text_log_with_a_second_imu_only(tmp_path):
    from tests.support.field_logs import old_text_log

    path = tmp_path / "old.log"
    old_text_log(path, imu="IMU2")
    rec = _import(path)
    np.testing.assert_allclose(rec.accel[:, 2], -G, atol=1e-3)
    assert "body rates from IMU2" in " ".join(rec.meta["import"]["warnings"])


@pytest.mark.parametrize("case", ["no_gyro", "no_clock"])
def test_old_text_log_says_what_is_missing(tmp_path, case):
    from tests.support.field_logs import old_text_log

    path = tmp_path / "old.log"
    old_text_log(
        path, imu=None if case == "no_gyro" else "IMU", gps="board" if case == "no_gyro" else None
    )
    res = _cli(path, "--out", tmp_path / "o.csv")
    assert res.returncode != 0
    assert res.stderr.count("\n") == 1 and "Traceback" not in res.stderr, res.stderr
    assert "old.log" in res.stderr
    if case == "no_gyro":  # names what is missing and what the log has instead
        assert "no body rates" in res.stderr and "ATT, CURR, GPS, MOT" in res.stderr
    else:
        assert "no time stamps" in res.stderr


# ------------------------------------------------------------------ every era's names
_OLD = {
    "rcou_chan": {"RCOU": ("RCOU", {f"C{k}": f"Chan{k}" for k in range(1, 9)})},
    "rcou_ch": {"RCOU": ("RCOU", {f"C{k}": f"Ch{k}" for k in range(1, 9)})},
    "imu_no_instance": {"IMU": ("IMU", {"I": None})},
    "imu2_only": {"IMU": ("IMU2", {"I": None})},
    "ahr2_attitude": {"ATT": ("AHR2", {})},
    "nkf": {"XKF1": ("NKF1", {"C": None}), "XKF4": ("NKF4", {"C": None})},
    "ekf_3_2": {"XKF1": ("EKF1", {"C": None}), "XKF4": ("EKF4", {"C": None})},
}


@pytest.mark.parametrize("family", list(_OLD))
@pytest.mark.parametrize("text", [False, True], ids=["bin", "log"])
def test_every_era_names_import_alike(tmp_path, family, text):
    """Each rename family of the messages the importer reads, as older firmware wrote it,
    imports to the same recording as the current names."""
    ref_path, path = tmp_path / "new.bin", tmp_path / ("old.log" if text else "old.bin")
    dataflash_flight(ref_path)
    dataflash_flight(path, text=text, renames=_OLD[family])
    ref, rec = _import(ref_path, mass=1.5), _import(path, mass=1.5)
    assert len(rec) == len(ref)
    np.testing.assert_allclose(rec.commands_u, ref.commands_u, atol=1e-6)
    np.testing.assert_allclose(rec.accel, ref.accel, atol=1e-5)
    np.testing.assert_allclose(rec.position, ref.position, atol=1e-5)
    np.testing.assert_allclose(rec.quaternion, ref.quaternion, atol=1e-5)
    assert not np.any((rec.t > 8.0) & (rec.t < 9.0))  # the EKF status still flags velocity


def test_rcou_without_the_motor_channels_names_what_it_has(tmp_path):
    path = tmp_path / "flight.bin"
    dataflash_flight(path, renames={"RCOU": ("RCOU", {"C5": "Ch5"})})  # C1..C4, Ch5, C6..
    with pytest.raises(QuadfaultError, match=r"lacks the motor channels \['C5'.*it has C1"):
        _import(path)


# ------------------------------------------------------------------ frames, damage, messages
@pytest.mark.parametrize(
    "params, says",
    [
        ({"FRAME_CLASS": 3}, "FRAME_CLASS is 3 (octa)"),
        ({"FRAME_CLASS": 7}, "FRAME_CLASS is 7 (tri)"),
        ({"SERVO9_FUNCTION": 37}, "SERVO9_FUNCTION is 37 (Motor 5)"),
        ({"FRAME_CLASS": None, "Q_ENABLE": 1, "Q_FRAME_CLASS": 2}, "Q_FRAME_CLASS is 2 (hexa)"),
    ],
    ids=["octa", "tri", "fifth_motor", "quadplane_hexa"],
)
def test_frames_the_model_does_not_fly_are_refused(tmp_path, params, says):
    from quadfault.io.importers.ardupilot import frame_check

    given = {"FRAME_CLASS": 1, **params}
    with pytest.raises(QuadfaultError, match=says.replace("(", r"\(").replace(")", r"\)")):
        frame_check({k: v for k, v in given.items() if v is not None})
    with pytest.raises(QuadfaultError, match="Frame: HEXA"):
        frame_check({}, ["APM:Copter V3.3", "Frame: HEXA"])
    assert frame_check({}, ["Frame: QUAD"]) is None
    assert "QuadPlane" in frame_check({"Q_ENABLE": 1, "Q_FRAME_CLASS": 1})


def test_a_cut_or_corrupt_binary_log_says_what_was_skipped(tmp_path):
    path = tmp_path / "flight.bin"
    dataflash_flight(path)
    data = bytearray(path.read_bytes())
    n = len(data)
    data[n // 2 : n // 2 + 40] = b"\x00" * 40  # corrupt frames in the middle
    path.write_bytes(bytes(data[: int(n * 0.9) + 7]))  # and cut mid-message
    res = _cli(path, "--out", tmp_path / "o.csv", "--mass", "1.5")
    assert res.returncode == 0, res.stderr
    assert res.stderr.count("\n") == 1 and "bytes skipped" in res.stderr, res.stderr
    import json

    skipped = json.loads((tmp_path / "o.json").read_text())["import"]["skipped"]
    assert skipped["truncated"] and skipped["corrupt"] >= 1 and skipped["bytes"] >= 40
    assert len(skipped["spans"]) >= 1 and skipped["after_t"] > 10.0


def test_never_armed_is_said_as_such(tmp_path):
    path = tmp_path / "bench.bin"
    dataflash_flight(path, armed=False)
    res = _cli(path, "--out", tmp_path / "o.csv")
    assert res.returncode == 2 and "never armed" in res.stderr, res.stderr


def test_battery_cells_from_the_parameters(tmp_path):
    path = tmp_path / "flight.bin"
    dataflash_flight(path, params={"MOT_BAT_VOLT_MAX": 25.2})  # 6S, the log says 16 V
    bat = _import(path, mass=1.5).meta["import"]["battery"]
    assert bat["cells"] == 6 and not bat["plausible"]


def test_a_quadplane_imports_its_lift_motors(tmp_path):
    path = tmp_path / "quadplane.bin"
    plane = {"FRAME_CLASS": None, "FRAME_TYPE": None, "Q_ENABLE": 1, "Q_FRAME_CLASS": 1}
    dataflash_flight(path, params={**plane, "Q_FRAME_TYPE": 1, "SERVO3_FUNCTION": 70})
    rec = _import(path, mass=1.5)
    assert any("QuadPlane" in w for w in rec.meta["import"]["warnings"])
    assert "RCOU C[5, 6, 7, 8]" in rec.meta["import"]["commands"]  # Motor 1-4, not throttle
    np.testing.assert_allclose(np.median(rec.commands_u, axis=0), HOVER, atol=0.02)


def test_ground_spool_up_the_land_detector_calls_flight_is_left_out(tmp_path):
    """A land detector that says "not landed" while the vehicle still sits on the ground
    (here from 0.5 s after arming, 1.5 s before lift-off) does not put that ground time into
    the flight: the span starts where the vehicle's own height leaves its resting value."""
    from quadfault.io.importers.ardupilot import read_ardupilot
    from quadfault.io.importers.field_log import TRANSITION_S, build_recording

    path = tmp_path / "flight.bin"
    dataflash_flight(path)
    log = read_ardupilot(path)
    log.landed = (np.array([1.0, 2.5, T_LAND - 0.5]), np.array([True, False, True]))
    rec = build_recording(log)
    lift = T_TAKEOFF + 0.5  # where the synthetic vehicle's height leaves the ground
    assert rec.t[0] == pytest.approx(lift + TRANSITION_S, abs=0.02)
    assert "on the ground left out" in rec.meta["import"]["flight_span_from"]
    log.landed = (np.array([1.0, 2.5, T_LAND - 0.5]), np.array([True, False, True]))
    log.streams = {k: v for k, v in log.streams.items() if k not in ("pos", "vel")}
    log.invalid = {}
    without_height = build_recording(log)  # no height: the land detector alone decides
    assert without_height.t[0] == pytest.approx(2.5 + TRANSITION_S, abs=0.02)
