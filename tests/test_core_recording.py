"""The quadfault-recording/1 format: round trips, frames, and every validation error path."""

import dataclasses
import json
import shutil

import numpy as np
import pytest

from quadfault.errors import QuadfaultError, RecordingError
from quadfault.io.recording import read_recording, sidecar_path, write_recording
from quadfault.model.scenarios import named_scenario
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate


@pytest.fixture(scope="module")
def rec():
    cfg = SimConfig(sensor_noise=SensorNoise(0.01, 0.01, 0.002, 0.01, 0.05))
    return simulate(named_scenario("combined", duration=0.6), config=cfg, seed=1)


@pytest.fixture
def written(rec, tmp_path):
    path = tmp_path / "flight.csv"
    write_recording(rec, path)
    return path


def _fields(r):
    return {
        k: getattr(r, k)
        for k in (
            "t",
            "position",
            "velocity",
            "quaternion",
            "omega",
            "accel",
            "thrust_cmd",
            "vbat",
            "eta_true",
        )
    }


def test_round_trip_is_exact(rec, written):
    back = read_recording(written)
    for name, value in _fields(rec).items():
        np.testing.assert_array_equal(getattr(back, name), value, err_msg=name)
    assert back.vehicle == rec.vehicle
    assert back.meta["scenario"] == "combined"


def test_enu_round_trip_and_conversion(rec, tmp_path):
    path = tmp_path / "enu.csv"
    write_recording(rec, path, frame="ENU")
    side = json.loads(sidecar_path(path).read_text())
    assert side["frame"] == "ENU"
    back = read_recording(path)
    for name, value in _fields(rec).items():
        np.testing.assert_allclose(getattr(back, name), value, atol=1e-14, err_msg=name)
    np.testing.assert_allclose(back.vehicle.allocation, rec.vehicle.allocation, atol=1e-15)
    np.testing.assert_allclose(back.vehicle.inertia, rec.vehicle.inertia, atol=1e-15)
    # in the ENU file the altitude is +z and the accelerometer reads about +g along body z
    import csv

    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    assert float(rows[0]["pz"]) == pytest.approx(1.0, abs=0.05)
    assert float(rows[10]["az"]) > 5.0


def test_u_commands_with_thrust_coefficient(rec, tmp_path):
    k = 1e-5
    u = np.sqrt(np.maximum(rec.thrust_cmd, 0) / k)
    r = dataclasses.replace(rec, commands_u=u, thrust_curve=(0.0, 0.0, k), thrust_cmd=k * u * u)
    path = tmp_path / "u.csv"
    write_recording(r, path)
    header = path.read_text().splitlines()[0].split(",")
    assert "u1" in header and "f1" not in header
    back = read_recording(path)
    np.testing.assert_allclose(
        back.thrust_cmd, np.maximum(rec.thrust_cmd, 0), rtol=1e-12, atol=1e-12
    )


def test_arm_and_torque_coefficient_sidecar(written):
    side = json.loads(sidecar_path(written).read_text())
    del side["vehicle"]["allocation"]
    side["vehicle"].update(arm=0.225, torque_coefficient=0.009012)
    sidecar_path(written).write_text(json.dumps(side))
    back = read_recording(written)
    d, c = 0.225, 0.009012
    np.testing.assert_allclose(back.vehicle.allocation[1], [-d, d, d, -d])
    np.testing.assert_allclose(back.vehicle.allocation[3], [-c, c, -c, c])


def test_refuses_to_overwrite(rec, written):
    with pytest.raises(QuadfaultError, match="already exists"):
        write_recording(rec, written)
    write_recording(rec, written, force=True)


def _edit_csv(path, fn):
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    rows = [ln.split(",") for ln in lines[1:]]
    header, rows = fn(header, rows)
    path.write_text("\n".join([",".join(header)] + [",".join(r) for r in rows]) + "\n")


def _set(col, row, value):
    def fn(header, rows):
        rows[row - 1][header.index(col)] = value
        return header, rows

    return fn


def _drop(col):
    def fn(header, rows):
        j = header.index(col)
        return header[:j] + header[j + 1 :], [r[:j] + r[j + 1 :] for r in rows]

    return fn


@pytest.mark.parametrize(
    "edit, pattern",
    [
        (_drop("wy"), r"column 'wy'.*missing"),
        (_drop("f3"), r"column 'f3'.*missing"),
        (_set("px", 5, "nan"), r"column 'px', row 5: NaN or inf"),
        (_set("f2", 7, "inf"), r"column 'f2', row 7: NaN or inf"),
        (_set("vx", 3, "abc"), r"column 'vx', row 3: not a number"),
        (_set("t", 4, "0.0"), r"column 't', row 4: time must be strictly increasing"),
        (_set("qw", 6, "0.9"), r"column 'qw', row 6: quaternion norm"),
    ],
)
def test_csv_validation_errors_name_file_column_and_row(written, edit, pattern):
    _edit_csv(written, edit)
    with pytest.raises(RecordingError, match=pattern) as info:
        read_recording(written)
    assert str(written) in str(info.value)


def _scale_quaternion(row, factor):
    def fn(header, rows):
        for c in ("qw", "qx", "qy", "qz"):
            j = header.index(c)
            rows[row - 1][j] = repr(float(rows[row - 1][j]) * factor)
        return header, rows

    return fn


def test_quaternion_close_to_unit_is_renormalised(written):
    _edit_csv(written, _scale_quaternion(2, 1.0005))
    back = read_recording(written)
    np.testing.assert_allclose(np.linalg.norm(back.quaternion, axis=1), 1.0, atol=1e-15)


@pytest.mark.parametrize(
    "mutate, pattern",
    [
        (lambda s: s.update(format="quadfault-recording/2"), r"key 'format'"),
        (lambda s: s.update(frame="XYZ"), r"key 'frame'"),
        (lambda s: s.pop("vehicle"), r"key 'vehicle'"),
        (lambda s: s["vehicle"].update(mass=-1), r"key 'vehicle.mass'"),
        (lambda s: s["vehicle"].update(mass="heavy"), r"key 'vehicle.mass'"),
        (lambda s: s["vehicle"].pop("inertia"), r"key 'vehicle.inertia'"),
        (lambda s: s["vehicle"].update(allocation=[[1, 1, 1, 1]] * 4), r"singular"),
        (lambda s: s["vehicle"].update(allocation=[[1, 2], [3, 4]]), r"key 'vehicle.allocation'"),
        (lambda s: s["vehicle"].pop("allocation"), r"needs 'allocation'"),
    ],
)
def test_sidecar_validation_errors(written, mutate, pattern):
    side = json.loads(sidecar_path(written).read_text())
    mutate(side)
    sidecar_path(written).write_text(json.dumps(side))
    with pytest.raises(RecordingError, match=pattern):
        read_recording(written)


def test_missing_sidecar_empty_file_and_bad_json(written, tmp_path):
    other = tmp_path / "copy.csv"
    shutil.copy(written, other)
    with pytest.raises(RecordingError, match="sidecar JSON not found"):
        read_recording(other)
    sidecar_path(written).write_text("{not json")
    with pytest.raises(RecordingError, match="invalid JSON"):
        read_recording(written)
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    sidecar_path(empty).write_text(
        json.dumps(
            {
                "format": "quadfault-recording/1",
                "frame": "NED",
                "vehicle": {"mass": 1, "inertia": [1, 1, 1]},
            }
        )
    )
    with pytest.raises(RecordingError, match="empty"):
        read_recording(empty)
    with pytest.raises(RecordingError, match="file not found"):
        read_recording(tmp_path / "nope.csv")


def test_imu_only_recording_loads(rec, tmp_path):
    r = dataclasses.replace(rec, position=None, velocity=None, quaternion=None)
    path = tmp_path / "imu.csv"
    write_recording(r, path)
    back = read_recording(path)
    assert not back.has_pose
    np.testing.assert_array_equal(back.accel, rec.accel)


def test_without_truth_strips_truth(rec):
    clean = rec.without_truth()
    assert clean.eta_true is None and "scenario" not in clean.meta


def test_unknown_text_columns_are_kept_and_ignored(written):
    _edit_csv(written, lambda header, rows: (header + ["note"], [r + ["hello"] for r in rows]))
    back = read_recording(written)
    assert "note" in back.extra and np.all(np.isnan(back.extra["note"]))
