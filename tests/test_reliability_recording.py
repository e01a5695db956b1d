"""Reliability of the recording reader: fuzzed files end in a one-line error naming the file
and the column / key / row, or in a correct result; never a traceback, a hang or wrong numbers.
"""

from __future__ import annotations

import gzip
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.fuzzing import (
    BASE_COLUMNS,
    MUTATIONS,
    bad_case,
    csv_bytes,
    error_is_clean,
    json_bytes,
    time_limit,
    valid_recording,
    write_case,
)

from quadfault.errors import QuadfaultError, RecordingError
from quadfault.io.recording import read_recording

FAST = settings(
    max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)


def _write(folder, header, rows, side, stem="flight"):
    csv_path = Path(folder) / f"{stem}.csv"
    csv_path.write_bytes(csv_bytes(header, rows))
    (Path(folder) / f"{stem}.json").write_bytes(json_bytes(side))
    return csv_path


def _read_or_error(path):
    """``(Recording, None)`` or ``(None, RecordingError)``; anything else propagates."""
    with time_limit(20):
        try:
            return read_recording(path), None
        except QuadfaultError as exc:
            return None, exc


def test_the_base_recording_is_valid(tmp_path):
    header, rows, side = valid_recording()
    rec = read_recording(_write(tmp_path, header, rows, side))
    assert len(rec) == len(rows)
    np.testing.assert_allclose(rec.thrust_cmd, 9.8 / 4)


@pytest.mark.parametrize("index", range(len(MUTATIONS)), ids=[m.__name__ for m in MUTATIONS])
def test_each_mutation_is_a_clean_error(index, tmp_path):
    case = bad_case(np.random.default_rng(index), index)
    csv_path, side_path = write_case(case, tmp_path)
    rec, err = _read_or_error(csv_path)
    assert err is not None, f"{case.name}: a broken recording was accepted"
    assert error_is_clean(str(err), case, csv_path, side_path) is None, str(err)


@FAST
@given(index=st.integers(0, len(MUTATIONS) - 1), seed=st.integers(0, 2**32 - 1))
def test_fuzzed_recordings_are_clean_errors(index, seed):
    case = bad_case(np.random.default_rng(seed), index)
    with tempfile.TemporaryDirectory() as folder:
        csv_path, side_path = write_case(case, folder)
        rec, err = _read_or_error(csv_path)
        assert err is not None, f"{case.name} (seed {seed}) was accepted"
        why = error_is_clean(str(err), case, csv_path, side_path)
        assert why is None, f"{case.name} (seed {seed}): {why}: {err}"


@FAST
@given(data=st.binary(max_size=3000))
def test_arbitrary_bytes_never_crash(data):
    _, _, side = valid_recording()
    with tempfile.TemporaryDirectory() as folder:
        csv_path = Path(folder) / "flight.csv"
        csv_path.write_bytes(data)
        (Path(folder) / "flight.json").write_bytes(json_bytes(side))
        rec, err = _read_or_error(csv_path)
        assert err is not None  # random bytes never carry the required columns
        assert "flight.csv" in str(err) and "\n" not in str(err)


@FAST
@given(cell=st.text(max_size=12), column=st.sampled_from(BASE_COLUMNS), row=st.integers(0, 39))
def test_any_cell_text_is_a_correct_value_or_an_error_naming_it(cell, column, row):
    header, rows, side = valid_recording()
    j = header.index(column)
    rows[row][j] = '"' + cell.replace('"', '""') + '"'
    with tempfile.TemporaryDirectory() as folder:
        rec, err = _read_or_error(_write(folder, header, rows, side))
    try:
        value = float(cell)
    except ValueError:
        value = None
    if rec is not None:
        # accepted: then the cell was a finite number and it is what the recording holds
        assert value is not None and np.isfinite(value)
        if column == "t":
            assert rec.t[row] == value
        elif column.startswith("f"):
            assert rec.thrust_cmd[row, int(column[1]) - 1] == value
    else:
        assert "flight.csv" in str(err) and "\n" not in str(err)
        if value is None or not np.isfinite(value):
            if "\x00" not in cell and "\r" not in cell and "\n" not in cell:
                assert f"column '{column}'" in str(err) and f"row {row + 1}" in str(err), str(err)


@FAST
@given(
    scale=st.one_of(st.floats(0.0, 3.0), st.floats(0.998, 1.002)),
    direction=st.lists(st.floats(-1, 1), min_size=4, max_size=4),
    row=st.integers(0, 39),
)
def test_quaternion_norm_is_renormalised_within_tolerance_else_rejected(scale, direction, row):
    q = np.asarray(direction)
    if np.linalg.norm(q) < 1e-3:
        q = np.array([1.0, 0.0, 0.0, 0.0])
    q = scale * q / np.linalg.norm(q)
    header, rows, side = valid_recording()
    for i, c in enumerate(("qw", "qx", "qy", "qz")):
        rows[row][header.index(c)] = repr(float(q[i]))
    with tempfile.TemporaryDirectory() as folder:
        rec, err = _read_or_error(_write(folder, header, rows, side))
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) <= 1e-3 * (1 - 1e-9):
        assert rec is not None, str(err)
        assert np.linalg.norm(rec.quaternion[row]) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(rec.quaternion[row], q / norm, atol=1e-12)
    elif abs(norm - 1.0) > 1e-3 * (1 + 1e-9):
        assert rec is None and "column 'qw'" in str(err) and f"row {row + 1}" in str(err)


@FAST
@given(
    mass=st.one_of(
        st.floats(allow_nan=True, allow_infinity=True),
        st.text(max_size=5),
        st.booleans(),
        st.none(),
        st.integers(-5, 5),
    )
)
def test_vehicle_mass_accepted_iff_positive_finite_number(mass):
    header, rows, side = valid_recording()
    side["vehicle"]["mass"] = mass
    with tempfile.TemporaryDirectory() as folder:
        rec, err = _read_or_error(_write(folder, header, rows, side))
    good = (
        isinstance(mass, (int, float))
        and not isinstance(mass, bool)
        and np.isfinite(mass)
        and mass > 0
    )
    if good:
        assert rec is not None and rec.vehicle.mass == float(mass)
    else:
        assert rec is None and "flight.json" in str(err) and "vehicle.mass" in str(err)


@FAST
@given(rank=st.integers(1, 4), seed=st.integers(0, 2**31))
def test_allocation_accepted_iff_full_rank(rank, seed):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((4, rank)) @ rng.standard_normal((rank, 4))
    header, rows, side = valid_recording()
    side["vehicle"]["allocation"] = A.tolist()
    with tempfile.TemporaryDirectory() as folder:
        rec, err = _read_or_error(_write(folder, header, rows, side))
    if np.linalg.matrix_rank(A) == 4:
        assert rec is not None
    else:
        assert rec is None and "flight.json" in str(err) and "singular" in str(err)


@FAST
@given(t=st.lists(st.floats(-1e6, 1e6), min_size=2, max_size=30))
def test_time_accepted_iff_strictly_increasing_else_first_bad_row_named(t):
    header, rows, side = valid_recording(len(t))
    for r, tk in zip(rows, t):
        r[0] = repr(tk)
    with tempfile.TemporaryDirectory() as folder:
        rec, err = _read_or_error(_write(folder, header, rows, side))
    dt = np.diff(t)
    if np.all(dt > 0):
        assert rec is not None and np.array_equal(rec.t, t)
    else:
        first = int(np.flatnonzero(dt <= 0)[0]) + 2
        assert rec is None and "column 't'" in str(err) and f"row {first}" in str(err)


def test_byte_order_mark_is_accepted(tmp_path):
    header, rows, side = valid_recording()
    path = _write(tmp_path, header, rows, side)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    assert len(read_recording(path)) == len(rows)


def test_gzip_recording_round_trip_and_truncation(tmp_path):
    header, rows, side = valid_recording()
    path = tmp_path / "flight.csv.gz"
    path.write_bytes(gzip.compress(csv_bytes(header, rows)))
    (tmp_path / "flight.json").write_bytes(json_bytes(side))
    assert len(read_recording(path)) == len(rows)
    path.write_bytes(gzip.compress(csv_bytes(header, rows))[:-20])
    with pytest.raises(RecordingError, match="flight.csv.gz"):
        read_recording(path)


def test_multi_megabyte_file_with_a_bad_last_row_fails_cleanly(tmp_path):
    header, rows, side = valid_recording(60_000)
    rows[-1][5] = "oops"  # column vy
    path = _write(tmp_path, header, rows, side)
    assert path.stat().st_size > 4e6
    with time_limit(60), pytest.raises(RecordingError) as info:
        read_recording(path)
    msg = str(info.value)
    assert "flight.csv" in msg and "column 'vy'" in msg and "row 60000" in msg and "\n" not in msg


def test_multi_megabyte_single_line_fails_cleanly(tmp_path):
    _, _, side = valid_recording()
    path = tmp_path / "flight.csv"
    path.write_bytes(b"t," + b"9" * 6_000_000)  # one field larger than any sane CSV cell
    (tmp_path / "flight.json").write_bytes(json_bytes(side))
    with time_limit(60), pytest.raises(RecordingError, match="flight.csv"):
        read_recording(path)


def test_multi_megabyte_sidecar_garbage_fails_cleanly(tmp_path):
    header, rows, _ = valid_recording()
    path = _write(tmp_path, header, rows, {})
    (tmp_path / "flight.json").write_bytes(b"[" * 3_000_000)  # deeply nested JSON
    with time_limit(60), pytest.raises(RecordingError, match="flight.json"):
        read_recording(path)


def test_sidecar_nan_in_vehicle_is_rejected(tmp_path):
    header, rows, side = valid_recording()
    side["vehicle"]["inertia"] = [float("nan"), 0.01, 0.02]
    path = _write(tmp_path, header, rows, side)
    with pytest.raises(RecordingError, match="vehicle.inertia"):
        read_recording(path)


@pytest.mark.parametrize("bad_row", [1, 7, 8, 9, 23])
def test_streaming_reader_names_the_row_across_chunks(tmp_path, monkeypatch, bad_row):
    import quadfault.io.recording as recording

    monkeypatch.setattr(recording, "_CHUNK_ROWS", 8)
    header, rows, side = valid_recording(30)
    path = _write(tmp_path, header, rows, side)
    good = read_recording(path)
    np.testing.assert_array_equal(good.t, [float(r[0]) for r in rows])
    rows[bad_row - 1][3] = "x"
    with pytest.raises(RecordingError, match=f"column 'pz', row {bad_row}:"):
        read_recording(_write(tmp_path, header, rows, side))


def test_blank_rows_only_at_the_end_are_ignored(tmp_path):
    header, rows, side = valid_recording()
    path = _write(tmp_path, header, rows, side)
    path.write_text(path.read_text() + "\n\n,,\n")
    assert len(read_recording(path)) == len(rows)
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:10] + [""] + lines[10:]) + "\n")
    with pytest.raises(RecordingError, match="row 10: has 0 fields"):
        read_recording(path)


def test_reader_memory_is_a_small_multiple_of_the_table(tmp_path):
    """The reader streams: reading a 4 MB file peaks at 3.7x the file size (the float table,
    once more while the chunks are joined, and one chunk of text); reading it as one list of
    cells peaked at 17x."""
    import tracemalloc

    header, rows, side = valid_recording(50_000)
    path = _write(tmp_path, header, rows, side)
    del rows
    size = path.stat().st_size
    tracemalloc.start()
    rec = read_recording(path)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert len(rec) == 50_000
    assert peak < 6 * size, f"peak {peak / 1e6:.1f} MB for a {size / 1e6:.1f} MB file"
