"""PX4 ULog importer: the resampling functions on synthetic arrays, and a whole import of a
tiny ULog written by a minimal ULog writer (pyulog can read ULogs but not build them)."""

from __future__ import annotations

import struct
import subprocess
import sys

import numpy as np
import pytest

from quadfault.errors import ConfigError, QuadfaultError
from quadfault.importers.px4_ulog import (interp_linear, interp_quaternion, merge_topics,
                                          zero_order_hold)
from quadfault.rotation import quat_to_rot


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
    # the same rotation stored as q and -q must not interpolate through zero
    ang = np.array([0.0, 0.2, 0.4])
    q = np.stack([np.cos(ang / 2), np.zeros(3), np.zeros(3), np.sin(ang / 2)], axis=1)
    q[1] *= -1.0
    out = interp_quaternion(np.array([0.0, 1.0, 2.0]), q, np.array([0.5, 1.5]))
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0)
    yaw = np.arctan2(quat_to_rot(out)[:, 1, 0], quat_to_rot(out)[:, 0, 0])
    np.testing.assert_allclose(yaw, [0.1, 0.3], atol=1e-3)


def test_merge_topics_sorts_and_drops_duplicate_source_stamps():
    t = np.array([0.5, 1.5])
    res = merge_topics(t, {"a": (np.array([1.0, 0.0, 1.0, 2.0]),
                                 np.array([[1.0], [0.0], [9.0], [2.0]]), "linear"),
                           "u": (np.array([0.0, 1.0]), np.array([[3.0], [4.0]]), "hold")})
    np.testing.assert_allclose(res["a"][:, 0], [0.5, 1.5])
    np.testing.assert_allclose(res["u"][:, 0], [3.0, 4.0])
    with pytest.raises(ValueError):
        merge_topics(t, {"x": (np.array([0.0, 1.0]), np.zeros(2), "cubic")})


# ----------------------------------------------------------------------------------------
# a minimal ULog writer (file format: docs.px4.io "ULog File Format")
_TYPES = {"uint64_t": "Q", "float": "f", "uint8_t": "B", "int32_t": "i"}


def _msg(kind: str, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), ord(kind)) + payload


def write_ulog(path, topics: dict, params: dict | None = None) -> None:
    """``topics``: name -> (fields [(type, name, array_len)], rows [tuple of values])."""
    out = bytearray(b"ULog\x01\x12\x35" + bytes([1]) + struct.pack("<Q", 0))
    out += _msg("B", bytes(16) + struct.pack("<QQQ", 0, 0, 0))
    for name, (fields, _) in topics.items():
        spec = "".join(f"{t}[{n}] {f};" if n else f"{t} {f};" for t, f, n in fields)
        out += _msg("F", f"{name}:{spec}".encode())
    for key, value in (params or {}).items():
        k = f"float {key}".encode()
        out += _msg("P", bytes([len(k)]) + k + struct.pack("<f", value))
    for msg_id, name in enumerate(topics):
        out += _msg("A", struct.pack("<BH", 0, msg_id) + name.encode())
    events = []
    for msg_id, (name, (fields, rows)) in enumerate(topics.items()):
        fmt = "<" + "".join(_TYPES[t] * (n or 1) for t, _, n in fields)
        for row in rows:
            flat = []
            for v in row:
                flat.extend(v if isinstance(v, (list, tuple, np.ndarray)) else [v])
            events.append((row[0], _msg("D", struct.pack("<H", msg_id) + struct.pack(fmt, *flat))))
    for _, blob in sorted(events, key=lambda e: e[0]):
        out += blob
    path.write_bytes(bytes(out))


def _hover_log(path, *, n=200, with_battery=True):
    """Hover at 2 m, yawed 0.5 rad, 250 Hz attitude, 500 Hz IMU, 100 Hz motors and position;
    motors idle (NaN) for the first 0.1 s."""
    yaw = 0.5
    q = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
    att = [(int(4000 * k), q) for k in range(n)]
    imu = [(int(2000 * k), [0.01, -0.02, 0.0], [0.0, 0.0, -9.81]) for k in range(2 * n)]
    pos = [(int(10000 * k), 1.0, 2.0, -2.0, 0.1, 0.0, 0.0) for k in range(n // 2 + 1)]
    motors = [(int(10000 * k), [np.nan] * 4 if k < 10 else [0.5 + 0.01 * k, 0.5, 0.5, 0.5])
              for k in range(n // 2 + 1)]
    topics = {
        "vehicle_attitude": ([("uint64_t", "timestamp", 0), ("float", "q", 4)], att),
        "sensor_combined": ([("uint64_t", "timestamp", 0), ("float", "gyro_rad", 3),
                             ("float", "accelerometer_m_s2", 3)], imu),
        "vehicle_local_position": ([("uint64_t", "timestamp", 0), ("float", "x", 0),
                                    ("float", "y", 0), ("float", "z", 0), ("float", "vx", 0),
                                    ("float", "vy", 0), ("float", "vz", 0)], pos),
        "actuator_motors": ([("uint64_t", "timestamp", 0), ("float", "control", 4)], motors),
    }
    if with_battery:
        topics["battery_status"] = ([("uint64_t", "timestamp", 0), ("float", "voltage_v", 0)],
                                    [(int(50000 * k), 12.0 - 0.01 * k) for k in range(n // 10)])
    write_ulog(path, topics, {"THR_MDL_FAC": 0.3})


def _vehicle():
    from quadfault.importers.px4_ulog import px4_quad_x_vehicle

    return px4_quad_x_vehicle(1.5, [0.03, 0.03, 0.05], 0.17, 0.016)


def test_px4_quad_x_allocation_signs():
    A = _vehicle().allocation  # motor order FR, RL, FL, RR
    e = np.eye(4)
    assert (A @ (e[2] + e[1]))[1] > 0  # left rotors up: +roll (FRD)
    assert (A @ (e[0] + e[2]))[2] > 0  # front rotors up: +pitch (nose up)
    assert (A @ (e[0] + e[1]))[3] > 0  # CCW rotors 1, 2 react clockwise: +yaw (FRD)
    np.testing.assert_allclose(A @ np.ones(4), [4, 0, 0, 0], atol=1e-15)


def test_px4_import_of_a_written_ulog(tmp_path):
    pytest.importorskip("pyulog")
    from quadfault.importers.px4_ulog import import_px4_ulog
    from quadfault.recording import read_recording, write_recording

    path = tmp_path / "hover.ulg"
    _hover_log(path)
    rec = import_px4_ulog(path, vehicle=_vehicle())
    # trimmed to the motors-running span (motors idle before t = 0.1 s)
    assert rec.t[0] >= 0.1 - 1e-9
    assert np.all(np.diff(rec.t) > 0)
    np.testing.assert_allclose(rec.t[1] - rec.t[0], 0.004, rtol=1e-6)  # attitude time base
    np.testing.assert_allclose(rec.position[:, :2], np.tile([1.0, 2.0], (len(rec), 1)), atol=1e-6)
    np.testing.assert_allclose(rec.accel, np.tile([0.0, 0.0, -9.81], (len(rec), 1)), atol=1e-5)
    R = quat_to_rot(rec.quaternion)
    np.testing.assert_allclose(np.arctan2(R[:, 1, 0], R[:, 0, 0]), 0.5, atol=1e-6)
    # commands are held, not interpolated: u1 only takes the logged values
    logged = {round(0.5 + 0.01 * k, 6) for k in range(10, 101)}
    assert {round(float(v), 6) for v in rec.commands_u[:, 0]} <= logged
    # PX4 thrust model scaled so that hover thrust = m g on the calibration segment
    cal = rec.meta["calibration"]
    assert cal["fitted"]["THR_MDL_FAC"] == pytest.approx(0.3)
    sel = (rec.t >= cal["segment"][0]) & (rec.t <= cal["segment"][1])
    assert rec.thrust_cmd[sel].sum(1).mean() == pytest.approx(1.5 * 9.81, rel=1e-6)
    assert rec.vbat is not None and np.all(rec.vbat < 12.0 + 1e-6)
    out = write_recording(rec, tmp_path / "hover.csv")
    back = read_recording(out)
    np.testing.assert_allclose(back.thrust_cmd, rec.thrust_cmd, rtol=1e-12)


def test_px4_import_reports_missing_battery(tmp_path):
    pytest.importorskip("pyulog")
    from quadfault.importers.px4_ulog import import_px4_ulog

    path = tmp_path / "nobat.ulg"
    _hover_log(path, with_battery=False)
    rec = import_px4_ulog(path, vehicle=_vehicle(), thrust_curve=(0.0, 0.0, 10.0))
    assert any("battery" in m for m in rec.meta["import"]["missing"])
    assert rec.thrust_curve == (0.0, 0.0, 10.0)
    np.testing.assert_allclose(rec.thrust_cmd, 10.0 * rec.commands_u ** 2)
    imu = import_px4_ulog(path, vehicle=_vehicle(), thrust_curve=(0.0, 0.0, 10.0),
                          time_base="imu")
    np.testing.assert_allclose(np.median(np.diff(imu.t)), 0.002, rtol=1e-6)
    assert len(imu) == pytest.approx(2 * len(rec), abs=2)
    with pytest.raises(ConfigError, match="time_base"):
        import_px4_ulog(path, vehicle=_vehicle(), time_base="gps")


def test_px4_import_errors(tmp_path):
    pytest.importorskip("pyulog")
    from quadfault.importers.px4_ulog import import_px4_ulog

    with pytest.raises(ConfigError, match="vehicle file"):
        import_px4_ulog(tmp_path / "x.ulg")
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(b"not a ulog at all")
    with pytest.raises(QuadfaultError, match="bad.ulg"):
        import_px4_ulog(bad, vehicle=_vehicle())
    with pytest.raises(QuadfaultError, match="not found"):
        import_px4_ulog(tmp_path / "missing.ulg", vehicle=_vehicle())


def test_px4_cli_with_vehicle_file(tmp_path):
    pytest.importorskip("pyulog")
    import json

    path = tmp_path / "hover.ulg"
    _hover_log(path)
    v = _vehicle()
    (tmp_path / "veh.json").write_text(json.dumps({"mass": v.mass, "inertia": [0.03, 0.03, 0.05],
                                                   "allocation": v.allocation.tolist()}))
    cmd = [sys.executable, "-m", "quadfault.cli", "import", "px4", str(path), "--out",
           str(tmp_path / "o.csv"), "--vehicle", str(tmp_path / "veh.json")]
    res = subprocess.run(cmd, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "rows" in res.stdout and "Hz" in res.stdout
    res = subprocess.run(cmd[:-2], capture_output=True, text=True)  # no --vehicle
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and "vehicle" in res.stderr
    flags = ["--mass", "1.5", "--arm", "0.17", "--torque-coefficient", "0.016",
             "--inertia", "0.03,0.03,0.05"]
    res = subprocess.run(cmd[:-2] + ["--force"] + flags, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    from quadfault.recording import read_recording

    np.testing.assert_allclose(read_recording(tmp_path / "o.csv").vehicle.allocation,
                               v.allocation)
    res = subprocess.run(cmd[:-2] + ["--force"] + flags[:-2], capture_output=True, text=True)
    assert res.returncode == 2 and "--inertia" in res.stderr
