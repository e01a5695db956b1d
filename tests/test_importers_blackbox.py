"""Blackbox (Betaflight / INDIflight) importer on logs encoded by the tests
(tests/support/field_logs.py): every encoding and predictor the encoder uses round-trips
exactly, several logs in one file, corrupt frames, armed idle, eRPM -> rad/s, the decoded
CSV, and one-line errors on bad input."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from quadfault.errors import QuadfaultError
from quadfault.io.importers.blackbox_format import decode_log, split_logs
from tests.support.field_logs import (
    HOVER,
    IDLE,
    OMEGA_PER_U,
    G,
    _bb_rows,
    blackbox_csv,
    blackbox_log,
    encode_fields,
)


def test_every_encoding_round_trips():
    rng = np.random.default_rng(3)
    encodings = [0, 1, 3, 6, 6, 6, 7, 7, 7, 8, 8, 8, 8, 9, 6]
    for _ in range(200):
        scale = int(rng.choice([1, 3, 30, 3000, 30000]))
        vals = [int(v) for v in rng.integers(-scale, scale + 1, len(encodings))]
        vals[1], vals[2] = abs(vals[1]), max(-8000, min(8000, vals[2]))
        vals[9:13] = [max(-32768, min(32767, v)) for v in vals[9:13]]
        vals[13] = 0
        names = ",".join(f"f{i}" for i in range(len(encodings)))
        head = (
            f"H Product:Blackbox flight data recorder by Nicholas Sherlock\n"
            f"H Data version:2\nH Field I name:{names}\n"
            f"H Field I predictor:{','.join('0' * len(encodings))}\n"
            f"H Field I encoding:{','.join(map(str, encodings))}\n"
        ).encode()
        data = head + b"I" + encode_fields(vals, encodings)
        log = decode_log(data, 0, len(data))
        assert log.corrupt == 0 and log.main.shape == (1, len(encodings))
        assert log.main[0].tolist() == vals


def test_frames_decode_exactly_and_corrupt_frames_are_dropped():
    data = blackbox_log(19.0)
    log = decode_log(data, *split_logs(data)[0])
    np.testing.assert_array_equal(log.main, _bb_rows(19.0, 500.0))
    assert log.events[0, 1] == 0 and len(log.slow) == len(log.main) // 100
    bad = blackbox_log(19.0, corrupt_at=500)
    log = decode_log(bad, *split_logs(bad)[0])
    assert 0 < log.corrupt < 40  # the corrupt frame and the P frames until the next I frame
    rows = _bb_rows(19.0, 500.0)
    kept = {int(x) for x in log.main[:, 1]}
    assert kept < {int(x) for x in rows[:, 1]}
    times = log.main[:, 1]
    np.testing.assert_array_equal(log.main, rows[np.isin(rows[:, 1], times)])


def _import(path, **kw):
    from quadfault.io.importers.blackbox import import_blackbox

    return import_blackbox(path, **kw)


def test_several_logs_default_the_longest(tmp_path):
    path = tmp_path / "LOG001.BBL"
    path.write_bytes(blackbox_log(8.0) + blackbox_log(19.0) + blackbox_log(6.0))
    from quadfault.io.importers import detect_format

    assert detect_format(path) == "blackbox"
    rec = _import(path, mass=0.5)
    assert "log 2 of 3" in rec.meta["import"]["commands"]
    assert rec.duration > 6.0
    short = _import(path, log=3, mass=0.5)
    assert short.duration < rec.duration
    with pytest.raises(QuadfaultError, match="holds 3 log"):
        _import(path, log=4)


def test_units_frames_flight_span_and_rotor_speed(tmp_path):
    path = tmp_path / "flight.bfl"
    path.write_bytes(blackbox_log(19.0))
    rec = _import(path, mass=0.5)
    # armed idle on the ground (the first 4 s) is left out by the threshold above idle
    assert rec.meta["import"]["flight_span_from"].startswith("mean command above")
    assert np.all(rec.commands_u.mean(axis=1) > IDLE + 0.1)
    np.testing.assert_allclose(np.median(rec.commands_u), HOVER, atol=0.03)  # motorOutput
    # accSmooth +acc_1G on FLU z is -g on FRD z; gyro roll in deg/s -> rad/s
    np.testing.assert_allclose(rec.accel[:, 2], -9.80665, rtol=1e-9)
    assert np.max(np.abs(rec.omega[:, 0])) == pytest.approx(np.radians(20), rel=0.01)
    # eRPM (x100, 14 poles) -> rad/s: the flight's rotor speeds
    np.testing.assert_allclose(rec.rotor_speed / rec.commands_u, OMEGA_PER_U, rtol=0.02)
    # thrust model from omega^2, scale calibrated on free flight: sum f = m g there
    assert "omega^2" in rec.meta["calibration"]["thrust_model"]
    seg = rec.meta["calibration"]["segment"]
    sel = (rec.t >= seg[0]) & (rec.t <= seg[1])
    assert rec.thrust_cmd[sel].sum(1).mean() == pytest.approx(0.5 * 9.80665, rel=1e-6)
    # Betaflight quad X order: motor 0 rear-right (clockwise), motor 1 front-right
    A = rec.vehicle.allocation
    assert A[2, 0] < 0 < A[2, 1] and A[1, 0] < 0 and A[3, 0] < 0 < A[3, 1]
    assert rec.vbat is not None and 15.5 < np.median(rec.vbat) < 16.01


def test_decoded_csv_imports_like_the_log(tmp_path):
    log_path, csv_path = tmp_path / "f.bbl", tmp_path / "f.csv"
    log_path.write_bytes(blackbox_log(19.0))
    csv_path.write_text(blackbox_csv(19.0))
    from quadfault.io.importers import detect_format

    assert detect_format(csv_path) == "blackbox"
    a = _import(log_path, mass=0.5, arm=0.1)
    b = _import(csv_path, mass=0.5, arm=0.1)
    np.testing.assert_allclose(b.t, a.t)
    np.testing.assert_allclose(b.omega, a.omega)
    np.testing.assert_allclose(b.vbat, a.vbat)
    # without the header, the motor range and acc_1G are assumed -- and said so
    assert any("motor range assumed" in w for w in b.meta["import"]["warnings"])
    assert np.median(b.accel[:, 2]) == pytest.approx(-G, rel=0.01)


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "quadfault.cli", "import", *map(str, args)],
        capture_output=True,
        text=True,
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    "case", ["truncated", "wrong_format", "no_motors", "empty_log", "bad_log_number"]
)
def test_bad_input_gives_one_line(tmp_path, case):
    path = tmp_path / "flight.bbl"
    data = blackbox_log(19.0)
    args = []
    if case == "truncated":
        data = data[:400]
    elif case == "wrong_format":
        data = b"\x00\x01\x02 not a log" * 40
        args = ["--format", "blackbox"]
    elif case == "no_motors":
        data = data.replace(b"motor[", b"motxr[")
    elif case == "empty_log":
        data = data[: data.index(b"\nH Field I name") + 1]
    else:
        args = ["--log", "2"]
    path.write_bytes(data)
    res = _cli(path, "--out", tmp_path / "o.csv", *args)
    assert res.returncode != 0
    assert res.stderr.count("\n") == 1 and "Traceback" not in res.stderr, res.stderr
    assert "flight.bbl" in res.stderr


@pytest.mark.slow
def test_a_cut_log_says_what_was_skipped(tmp_path):
    """A log cut short (no end-of-log event) and one with a corrupt frame: each imports what
    is valid, with one warning line and the sidecar's ``import.skipped``."""
    whole = blackbox_log(19.0)
    log = decode_log(whole, *split_logs(whole)[0])
    assert log.ended and log.skipped_bytes == 0 and log.tail_bytes == 0
    cut = whole[: int(len(whole) * 0.7) + 3]
    log = decode_log(cut, *split_logs(cut)[0])
    assert not log.ended and 0 < log.tail_bytes < 40
    bad = blackbox_log(19.0, corrupt_at=500)
    log = decode_log(bad, *split_logs(bad)[0])
    assert log.ended and log.skipped_bytes > 0
    path = tmp_path / "cut.bbl"
    path.write_bytes(cut)
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "quadfault.cli",
            "import",
            str(path),
            "--out",
            str(tmp_path / "o.csv"),
        ],
        capture_output=True,
        text=True,
    )
    assert res.returncode == 0, res.stderr
    assert res.stderr.count("\n") == 1 and "cut" in res.stderr and "bytes skipped" in res.stderr
    import json

    skipped = json.loads((tmp_path / "o.json").read_text())["import"]["skipped"]
    assert skipped["truncated"] and 0.6 * 19.0 < skipped["after_t"] < 0.8 * 19.0


def test_a_cut_log_other_than_the_imported_one_is_named(tmp_path):
    path = tmp_path / "LOG002.BBL"
    second = blackbox_log(8.0)
    path.write_bytes(blackbox_log(19.0) + second[: len(second) // 2])
    rec = _import(path)
    assert rec.meta["import"].get("skipped") is None  # log 1, the longest, is whole
    assert any("log 2 of 2" in w and "cut short" in w for w in rec.meta["import"]["warnings"])
