"""PX4 ULog importer on small ULogs written by the tests (tests/support/field_logs.py):
multi-instance UAVCAN outputs, measured rotor speed, the land detector's flight span,
invalid-velocity spans, the log's rotor geometry, and one-line errors on bad input."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from quadfault.errors import QuadfaultError
from quadfault.io.importers.resample import (
    interp_linear,
    interp_quaternion,
    merge_topics,
    zero_order_hold,
)
from quadfault.model.rotation import quat_to_rot
from tests.support.field_logs import HOVER, OMEGA_PER_U, T_LAND, T_TAKEOFF, px4_flight

pyulog = pytest.importorskip("pyulog")


# ----------------------------------------------------------------------------------------
# resampling
def test_zero_order_hold_holds_the_last_command():
    ts = np.array([0.0, 1.0, 2.0])
    x = np.array([[1.0], [2.0], [3.0]])
    out = zero_order_hold(ts, x, np.array([-0.5, 0.0, 0.99, 1.0, 1.5, 5.0]))
    assert np.isnan(out[0, 0])
    np.testing.assert_array_equal(out[1:, 0], [1.0, 1.0, 2.0, 2.0, 3.0])


def test_interp_linear_is_nan_outside_and_exact_inside():
    ts = np.array([0.0, 1.0])
    x = np.array([[0.0, 10.0], [1.0, 20.0]])
    out = interp_linear(ts, x, np.array([-1.0, 0.25, 2.0]))
    assert np.all(np.isnan(out[[0, 2]]))
    np.testing.assert_allclose(out[1], [0.25, 12.5])


def test_interp_quaternion_handles_sign_flips():
    ang = np.array([0.0, 0.2, 0.4])
    q = np.stack([np.cos(ang / 2), np.zeros(3), np.zeros(3), np.sin(ang / 2)], axis=1)
    q[1] *= -1.0
    out = interp_quaternion(np.array([0.0, 1.0, 2.0]), q, np.array([0.5, 1.5]))
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0)
    yaw = np.arctan2(quat_to_rot(out)[:, 1, 0], quat_to_rot(out)[:, 0, 0])
    np.testing.assert_allclose(yaw, [0.1, 0.3], atol=1e-3)


def test_merge_topics_sorts_and_drops_duplicate_source_stamps():
    t = np.array([0.5, 1.5])
    res = merge_topics(
        t,
        {
            "a": (np.array([1.0, 0.0, 1.0, 2.0]), np.array([[1.0], [0.0], [9.0], [2.0]]), "linear"),
            "u": (np.array([0.0, 1.0]), np.array([[3.0], [4.0]]), "hold"),
        },
    )
    np.testing.assert_allclose(res["a"][:, 0], [0.5, 1.5])
    np.testing.assert_allclose(res["u"][:, 0], [3.0, 4.0])
    with pytest.raises(ValueError):
        merge_topics(t, {"x": (np.array([0.0, 1.0]), np.zeros(2), "cubic")})


# ----------------------------------------------------------------------------------------
def _import(path, **kw):
    from quadfault.io.importers.px4_ulog import import_px4_ulog

    return import_px4_ulog(path, **kw)


def test_uavcan_outputs_on_instance_1_rotor_speed_and_flight_span(tmp_path):
    path = tmp_path / "uavcan.ulg"
    px4_flight(path)
    rec = _import(path, mass=1.5)
    # flight span: land detector minus the take-off and landing transitions, never idle
    assert rec.t[0] >= T_TAKEOFF + 0.5 + 1.0 - 1e-6 and rec.t[-1] <= T_LAND - 0.5 - 1.0 + 1e-6
    assert np.all(rec.commands_u > 0.3)
    # instance 1 normalised with UAVCAN's 0-8191, not instance 0's zeros
    assert "instance 1" in rec.meta["import"]["commands"]
    np.testing.assert_allclose(np.median(rec.commands_u), HOVER, atol=0.02)
    # measured rotor speed from esc_status rpm, in rad/s
    np.testing.assert_allclose(rec.rotor_speed / rec.commands_u, OMEGA_PER_U, rtol=0.02)
    # invalid horizontal velocity (8-9 s) is never written: those rows are a gap
    assert not np.any((rec.t > 8.0) & (rec.t < 9.0))
    assert np.all(np.abs(rec.velocity[:, 0]) < 0.1)
    # geometry and spin directions from CA_ROTOR*, thrust calibrated on free flight only
    A = rec.vehicle.allocation
    np.testing.assert_allclose(A[1], [-0.12, 0.12, 0.12, -0.12])
    np.testing.assert_allclose(A[3], [0.02, 0.02, -0.02, -0.02])
    seg = rec.meta["calibration"]["segment"]
    spans = rec.meta["import"]["flight_spans"]
    assert spans[0][0] <= seg[0] < seg[1] <= spans[0][1]
    sel = (rec.t >= seg[0]) & (rec.t <= seg[1])
    assert rec.thrust_cmd[sel].sum(1).mean() == pytest.approx(1.5 * 9.81, rel=1e-6)
    assert rec.meta["assumed"] == ["inertia"]
    assert rec.vbat is not None and rec.extra["current"].mean() == pytest.approx(10.0)
    assert rec.meta["import"]["stream_rates_hz"]["u"] == pytest.approx(100.0, rel=1e-3)


def test_esc_actuator_function_maps_esc_to_motor(tmp_path):
    path = tmp_path / "esc.ulg"
    px4_flight(path, outputs="motors", esc_motors=(2, 0, 3, 1))
    rec = _import(path)
    np.testing.assert_allclose(rec.rotor_speed / rec.commands_u, OMEGA_PER_U, rtol=0.01)


def test_keep_all_keeps_the_ground(tmp_path):
    path = tmp_path / "uavcan.ulg"
    px4_flight(path, invalid_vxy=None)
    rec = _import(path, keep_all=True, mass=1.5)
    assert rec.t[0] < T_TAKEOFF and rec.t[-1] > T_LAND
    seg = rec.meta["calibration"]["segment"]
    assert seg[0] > T_TAKEOFF + 0.5  # still calibrated on free flight only


def test_a_tiny_command_is_not_running_and_low_rate_outputs(tmp_path):
    path = tmp_path / "motors.ulg"
    px4_flight(path, outputs="motors", disarmed_value=7e-10, motor_rate=10.0)
    rec = _import(path)
    assert rec.t[0] > T_TAKEOFF
    assert rec.meta["import"]["stream_rates_hz"]["u"] == pytest.approx(10.0, rel=1e-3)
    assert set(rec.meta["assumed"]) == {"mass", "inertia"}


def test_mostly_invalid_velocity_gives_an_imu_only_recording(tmp_path):
    path = tmp_path / "novel.ulg"
    px4_flight(path, invalid_vxy=(0.0, 30.0))
    rec = _import(path)
    assert rec.position is None and rec.accel is not None
    assert any("invalid" in m for m in rec.meta["import"]["missing"])


def test_placeholder_geometry_is_flagged(tmp_path):
    path = tmp_path / "generic.ulg"
    params = {}
    for i, (x, y) in enumerate(((1.0, 1.0), (-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0))):
        params.update({f"CA_ROTOR{i}_PX": x, f"CA_ROTOR{i}_PY": y})
    px4_flight(path, params=params)
    rec = _import(path)
    assert "geometry" in rec.meta["assumed"]
    assert any("placeholder" in w for w in rec.meta["import"]["warnings"])
    rec = _import(path, arm=0.2)
    assert "geometry" not in rec.meta["assumed"]
    np.testing.assert_allclose(np.abs(rec.vehicle.allocation[1:3]), 0.2)


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "quadfault.cli", "import", *map(str, args)],
        capture_output=True,
        text=True,
    )


@pytest.mark.slow
def test_cli_detects_the_format_and_warns_on_one_line(tmp_path):
    path = tmp_path / "flight.ulg"
    px4_flight(path)
    res = _cli(path, "--out", tmp_path / "o.csv")
    assert res.returncode == 0, res.stderr
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("warning:")
    assert "assumed mass, inertia" in res.stderr
    res = _cli(
        "px4", path, "--out", tmp_path / "o2.csv", "--mass", "1.5", "--inertia", "0.01,0.01,0.02"
    )
    assert res.returncode == 0, res.stderr
    from quadfault.io.recording import read_recording

    rec = read_recording(tmp_path / "o2.csv")
    assert rec.vehicle.mass == 1.5 and rec.rotor_speed is not None


@pytest.mark.slow
@pytest.mark.parametrize("case", ["truncated", "wrong_format", "forced_format", "no_motors"])
def test_bad_input_gives_one_line(tmp_path, case):
    path = tmp_path / "flight.ulg"
    px4_flight(path)
    extra = []
    if case == "truncated":
        path.write_bytes(path.read_bytes()[:3000])
    elif case == "wrong_format":
        path.write_text("time,a,b\n0,1,2\n")
    elif case == "forced_format":
        path.write_text("time,a,b\n0,1,2\n")
        extra = ["--format", "px4"]
    else:
        px4_flight(path, outputs="none")
    res = _cli(path, "--out", tmp_path / "o.csv", *extra)
    assert res.returncode != 0
    assert res.stderr.count("\n") == 1 and "Traceback" not in res.stderr, res.stderr
    assert "flight.ulg" in res.stderr


def test_commands_of_7e_10_never_run(tmp_path):
    from quadfault.io.importers.field_log import build_recording
    from quadfault.io.importers.px4_ulog import read_px4

    path = tmp_path / "flight.ulg"
    px4_flight(path, outputs="motors")
    log = read_px4(path)
    ts, u, kind = log.streams["u"]
    log.streams["u"] = (ts, 0.0 * u + 7e-10, kind)
    with pytest.raises(QuadfaultError, match="motors never run"):
        build_recording(log)


@pytest.mark.slow
def test_vehicle_flags_only_where_they_apply(tmp_path):
    from tests.support.field_logs import blackbox_log

    path = tmp_path / "flight.ulg"
    px4_flight(path)
    res = _cli(path, "--out", tmp_path / "o.csv", "--log", "2")
    assert res.returncode == 2 and "--log" in res.stderr
    bbl = tmp_path / "f.bbl"
    bbl.write_bytes(blackbox_log(19.0))
    res = _cli(bbl, "--out", tmp_path / "o.csv", "--time-base", "imu")
    assert res.returncode == 2 and "--time-base" in res.stderr
    from pathlib import Path

    fixture = Path(__file__).parent / "fixtures" / "eschmann_log.csv"
    res = _cli("eschmann", fixture, "--out", tmp_path / "o.csv", "--arm", "0.1")
    assert res.returncode == 2 and "--arm" in res.stderr and res.stderr.count("\n") == 1


# ----------------------------------------------------------------------------------------
# frames: the lift rotors by the autopilot's own parameters, or a one-line refusal
def _vtol_params(**extra):
    """A standard VTOL: rotor 0 the pusher (axis +x), rotors 1-4 lift at quad X positions."""
    p = {"CA_AIRFRAME": 2, "CA_ROTOR_COUNT": 5, "MAV_TYPE": 22}
    p.update({"CA_ROTOR0_PX": -0.3, "CA_ROTOR0_PY": 0.0, "CA_ROTOR0_AX": 1.0})
    p.update({"CA_ROTOR0_AZ": 0.0, "CA_ROTOR0_KM": 0.05})
    for i, ((x, y), km) in enumerate(
        zip(((0.2, 0.2), (-0.2, -0.2), (0.2, -0.2), (-0.2, 0.2)), (0.02, 0.02, -0.02, -0.02)),
        start=1,
    ):
        p.update({f"CA_ROTOR{i}_PX": x, f"CA_ROTOR{i}_PY": y, f"CA_ROTOR{i}_KM": km})
    p.update(extra)
    return p


def test_standard_vtol_imports_its_lift_rotors_from_their_assigned_outputs(tmp_path):
    path = tmp_path / "vtol.ulg"
    funcs = {"UAVCAN_EC_FUNC1": 101}  # the pusher (Motor 1) on output 1, surfaces on 2-4
    funcs.update({f"UAVCAN_EC_FUNC{k}": 97 + k for k in range(5, 9)})  # Motor 2..5 on 5-8
    px4_flight(path, motor_channels=(5, 6, 7, 8), params=_vtol_params(**funcs))
    rec = _import(path, mass=1.5)
    assert "outputs [5, 6, 7, 8]" in rec.meta["import"]["commands"]
    np.testing.assert_allclose(np.median(rec.commands_u, axis=0), HOVER, atol=0.02)
    assert any("standard VTOL" in w for w in rec.meta["import"]["warnings"])
    np.testing.assert_allclose(rec.vehicle.allocation[1], [-0.2, 0.2, 0.2, -0.2])


@pytest.mark.parametrize(
    "params, says",
    [
        (_vtol_params(), "lift motors [2, 3, 4, 5]"),  # no output assigned to them
        ({"CA_ROTOR_COUNT": 6, "CA_AIRFRAME": 0}, "CA_ROTOR_COUNT 6"),
        ({"CA_AIRFRAME": 3, "MAV_TYPE": 21}, "tiltrotor VTOL"),
        ({"CA_ROTOR_COUNT": 0, "MAV_TYPE": 13}, "CA_ROTOR_COUNT 0"),
    ],
    ids=["vtol_unassigned", "hexa", "tiltrotor", "no_rotors"],
)
def test_frames_the_model_does_not_fly_are_refused_in_one_line(tmp_path, params, says):
    path = tmp_path / "frame.ulg"
    px4_flight(path, motor_channels=(5, 6, 7, 8), params=params)
    res = _cli(path, "--out", tmp_path / "o.csv")
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert says in res.stderr and "quadrotors" in res.stderr, res.stderr


def test_frames_before_control_allocation(tmp_path):
    """PX4 before CA_ROTOR*: MAV_TYPE names the frame; a standard VTOL's VT_MOT_ID names its
    multicopter outputs."""
    from quadfault.io.importers.px4_ulog import lift_rotors

    assert lift_rotors({"MAV_TYPE": 2})[0] == (0, 1, 2, 3)
    with pytest.raises(QuadfaultError, match="hexarotor.*MAV_TYPE 13"):
        lift_rotors({"MAV_TYPE": 13})
    with pytest.raises(QuadfaultError, match="VTOL.*SYS_AUTOSTART 13000"):
        lift_rotors({"SYS_AUTOSTART": 13000})
    path = tmp_path / "old_vtol.ulg"
    no_ca = {k: None for k in ("CA_ROTOR_COUNT",) + tuple(f"CA_ROTOR{i}_PX" for i in range(4))}
    px4_flight(
        path, motor_channels=(5, 6, 7, 8), params={"MAV_TYPE": 22, "VT_MOT_ID": 5678, **no_ca}
    )
    rec = _import(path, mass=1.5)
    assert "outputs [5, 6, 7, 8]" in rec.meta["import"]["commands"]
    np.testing.assert_allclose(np.median(rec.commands_u, axis=0), HOVER, atol=0.02)
    assert any("VT_MOT_ID 5678" in w for w in rec.meta["import"]["warnings"])


# ----------------------------------------------------------------------------------------
# cut and corrupt logs, messages
def test_a_cut_log_imports_what_precedes_the_cut_and_says_so(tmp_path):
    path = tmp_path / "flight.ulg"
    px4_flight(path, outputs="motors")
    data = path.read_bytes()
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(data[: int(len(data) * 0.8) + 5])
    res = _cli(cut, "--out", tmp_path / "o.csv", "--mass", "1.5")
    assert res.returncode == 0, res.stderr
    assert res.stderr.count("\n") == 1 and "cut" in res.stderr and "bytes skipped" in res.stderr
    import json

    side = json.loads((tmp_path / "o.json").read_text())
    skipped = side["import"]["skipped"]
    assert skipped["truncated"] and 0 < skipped["bytes"] < 1000
    assert skipped["after_t"] == pytest.approx(0.8 * 19.0, abs=1.0)
    whole = _import(path, mass=1.5)
    assert skipped["after_t"] > 0 and whole.meta["import"].get("skipped") is None


def test_nothing_valid_is_one_line_listing_what_the_file_has(tmp_path):
    path = tmp_path / "flight.ulg"
    px4_flight(path)
    data = path.read_bytes().replace(b"vehicle_attitude", b"vehicle_attitudX")
    path.write_bytes(data)
    res = _cli(path, "--out", tmp_path / "o.csv")
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert "no vehicle_attitude topic" in res.stderr
    assert "the log has" in res.stderr and "vehicle_attitudX" in res.stderr


def test_never_armed_is_said_as_such(tmp_path):
    path = tmp_path / "bench.ulg"
    px4_flight(path, armed=False)
    res = _cli(path, "--out", tmp_path / "o.csv")
    assert res.returncode == 2 and "never armed" in res.stderr, res.stderr


def test_implausible_battery_voltage_is_flagged(tmp_path):
    path = tmp_path / "flight.ulg"
    px4_flight(path, params={"BAT1_N_CELLS": 6})  # 16 V on 6 cells: 2.7 V per cell
    rec = _import(path, mass=1.5)
    bat = rec.meta["import"]["battery"]
    assert bat["cells"] == 6 and bat["cells_from"] == "BAT1_N_CELLS"
    assert bat["plausible"] is False and "battery_thrust" in bat["why"]
    assert any("implausible battery voltage" in w for w in rec.meta["import"]["warnings"])
    path2 = tmp_path / "flight4.ulg"
    px4_flight(path2)  # 16 V: 4 cells inferred, 3.9-4.0 V per cell
    bat = _import(path2, mass=1.5).meta["import"]["battery"]
    assert bat["plausible"] is True and bat["cells"] == 4
