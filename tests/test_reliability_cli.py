"""Every ``quadfault`` subcommand: bad input -> one line on stderr and exit 2 (in-process and as
subprocesses); nothing overwritten without ``--force``; no half-written file on interrupt."""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.fuzzing import (
    MUTATIONS,
    bad_case,
    csv_bytes,
    error_is_clean,
    json_bytes,
    time_limit,
    valid_recording,
    write_case,
)

from quadfault.cli import SUBCOMMANDS, main

FIXTURES = Path(__file__).parent / "fixtures"
FUZZ = settings(
    max_examples=25,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


def run_cli(argv, timeout: float = 600.0):
    """``(exit code, stdout, stderr)`` of ``quadfault.cli.main(argv)`` run in-process; a run
    longer than ``timeout`` [s] (generous: a first call may JIT-compile kernels on a loaded
    machine) fails as a hang (:class:`support.fuzzing.Hang`)."""
    out, err = io.StringIO(), io.StringIO()
    with time_limit(timeout), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse usage errors and --help
            code = exc.code
    return code, out.getvalue(), err.getvalue()


def assert_one_line_error(code, err, command):
    assert code == 2, f"exit {code}, stderr {err!r}"
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"quadfault {command}: error: "), err
    assert "Traceback" not in err
    return lines[0]


@pytest.fixture
def hover(tmp_path):
    """A valid 40-row hover recording."""
    header, rows, side = valid_recording()
    path = tmp_path / "hover.csv"
    path.write_bytes(csv_bytes(header, rows))
    (tmp_path / "hover.json").write_bytes(json_bytes(side))
    return path


def _files(folder) -> set:
    return {p.name for p in Path(folder).iterdir()}


# -- fuzzed recordings through estimate and diagnose --------------------------------------------
@FUZZ
@given(
    index=st.integers(0, len(MUTATIONS) - 1),
    seed=st.integers(0, 2**32 - 1),
    command=st.sampled_from(["estimate", "diagnose"]),
)
def test_fuzzed_recordings_through_the_cli(index, seed, command):
    case = bad_case(np.random.default_rng(seed), index)
    with tempfile.TemporaryDirectory() as folder:
        csv_path, side_path = write_case(case, folder)
        before = _files(folder)
        out = Path(folder) / ("est.csv" if command == "estimate" else "diag.json")
        flag = "--out" if command == "estimate" else "--json"
        code, _, err = run_cli([command, csv_path, flag, out, "--quiet"])
        line = assert_one_line_error(code, err, command)
        why = error_is_clean(line, case, csv_path, side_path)
        assert why is None, f"{case.name}: {why}: {line}"
        assert _files(folder) == before, "a failed run left files behind"


def _strict_json(path):
    def no_constant(name):
        raise ValueError(f"{path.name} holds {name} (not valid JSON)")

    return json.loads(path.read_text(), parse_constant=no_constant)


@settings(
    max_examples=3, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(20, 80), log_scale=st.floats(-3, 3))
def test_random_valid_recordings_give_finite_results(seed, rows, log_scale):
    """Valid but meaningless data (random states, unit quaternions, irregular time steps,
    magnitudes 1e-3..1e3): estimates are finite numbers, the diagnosis is strict JSON."""
    from estimators.series_io import read_estimate_csv

    rng = np.random.default_rng(seed)
    header, _, side = valid_recording(rows)
    scale = 10.0**log_scale
    q = rng.standard_normal((rows, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    data = np.column_stack(
        [
            np.cumsum(rng.uniform(1e-4, 0.05, rows)),
            scale * rng.standard_normal((rows, 6)),
            q,
            scale * rng.standard_normal((rows, 3)),
            np.abs(scale * rng.standard_normal((rows, 4))),
        ]
    )
    with tempfile.TemporaryDirectory() as folder:
        src = Path(folder) / "r.csv"
        src.write_bytes(csv_bytes(header, [[repr(float(x)) for x in r] for r in data]))
        (Path(folder) / "r.json").write_bytes(json_bytes(side))
        for est in ("irls", "ekf"):
            out = Path(folder) / f"{est}.csv"
            code, _, err = run_cli(["estimate", src, "--estimator", est, "--out", out, "--quiet"])
            assert code == 0, err
            assert np.all(np.isfinite(read_estimate_csv(out)["eta"]))
            _strict_json(out.with_suffix(".json"))
        out = Path(folder) / "diag.json"
        code, _, err = run_cli(["diagnose", src, "--json", out, "--quiet"])
        assert code == 0, err
        assert _strict_json(out)["verdict"] in ("consistent", "mismatch")


# -- bad arguments of every subcommand ------------------------------------------------------------
BAD_ARGUMENTS = [
    ("simulate", ["--duration", "-1", "--out", "a.csv"], "--duration"),
    ("simulate", ["--duration", "nan", "--out", "a.csv"], "--duration"),
    ("simulate", ["--dt", "0", "--out", "a.csv"], "--dt"),
    ("simulate", ["--out", "a.txt"], ".csv"),
    ("simulate", ["--sensor-noise", "a,b", "--out", "a.csv"], "--sensor-noise"),
    ("simulate", ["--thrust-noise", "5", "--out", "a.csv"], "--thrust-noise"),
    ("simulate", ["--effect", "bogus=1", "--out", "a.csv"], "bogus"),
    ("simulate", ["--max-thrust", "-1", "--out", "a.csv", "--duration", "0.05"], "max_thrust"),
    ("simulate", ["--scenario", "nope", "--out", "a.csv"], "--scenario"),
    ("simulate", ["--seed", "x", "--out", "a.csv"], "--seed"),
    ("simulate", ["--out", "nodir/a.csv", "--duration", "0.05"], "nodir"),
    ("simulate", ["--control-rate", "0", "--out", "a.csv", "--duration", "0.05"], "--control-rate"),
    ("simulate", ["--seed", "-1", "--out", "a.csv", "--duration", "0.05"], "--seed"),
    ("simulate", ["--dt", "1e-12", "--duration", "1", "--out", "a.csv"], "memory"),
    (
        "simulate",
        ["--effect", "wind=1e308,0,0", "--duration", "0.05", "--out", "a.csv"],
        "diverged",
    ),
    ("estimate", ["missing.csv", "--out", "e.csv"], "missing.csv"),
    ("estimate", [".", "--out", "e.csv"], "directory"),
    ("estimate", ["{hover}", "--out", "e.txt"], ".csv"),
    ("estimate", ["{hover}", "--estimator", "kalman", "--out", "e.csv"], "--estimator"),
    ("estimate", ["{hover}"], "--out"),
    ("diagnose", ["{hover}", "--json", "o.txt"], ".json"),
    ("diagnose", ["{hover}", "--json", "o.json", "--block", "-1"], "block"),
    ("diagnose", ["{hover}", "--json", "o.json", "--block", "nan"], "block"),
    ("diagnose", ["{hover}", "--json", "o.json", "--max-effects", "-1"], "max_effects"),
    ("diagnose", ["{hover}", "--json", "o.json", "--effects", "bogus"], "bogus"),
    ("import", ["eschmann", "missing.csv", "--out", "i.csv"], "missing.csv"),
    ("import", ["eschmann", "{hover}", "--out", "i.csv"], "hover.csv"),
    ("import", ["nanodrone", "{hover}", "--out", "i.csv"], "hover.csv"),
    ("import", ["crazypad", "{hover}", "--out", "i.csv"], "hover.csv"),
    ("import", ["px4", "{hover}", "--out", "i.csv"], "hover.csv"),
    ("import", ["{hover}", "--out", "i.csv"], "unknown log format"),
    ("import", ["px4", "{hover}", "--out", "i.csv", "--vehicle", "{hover}"], "hover.csv"),
    ("import", ["eschmann", "{hover}", "--out", "i.csv", "--calibration", "a"], "--calibration"),
    ("import", ["eschmann", "{hover}", "--out", "i.csv", "--mass", "-1"], "--mass"),
    ("import", ["nosuchformat", "{hover}", "--out", "i.csv"], "nosuchformat"),
    ("reproduce", ["--workers", "0", "--out", "rep"], "--workers"),
    ("reproduce", ["--out", "{hover}"], "not a folder"),
    ("train", ["--timesteps", "-5", "--out", "tr"], "timesteps"),
    ("train", ["--env-kwargs", "{{bad", "--out", "tr"], "--env-kwargs"),
    ("train", ["--config", "missing.json", "--out", "tr"], "missing.json"),
    ("train", ["--seeds", "-1", "--out", "tr"], "seeds"),
    ("evaluate", ["--agents", "bogus", "--out", "ev"], "bogus"),
    ("evaluate", ["--duration", "-1", "--out", "ev"], "--duration"),
    ("evaluate", ["--seeds", "--out", "ev"], "--seeds"),
    ("evaluate", ["--seeds", "-1", "--duration", "0.05", "--no-plots", "--out", "ev"], "seeds"),
]


def _values(case):
    return case.values if hasattr(case, "values") else case


def test_every_subcommand_has_bad_argument_cases():
    assert {_values(c)[0] for c in BAD_ARGUMENTS} == set(SUBCOMMANDS)


@pytest.mark.parametrize(
    "command,args,mentions",
    BAD_ARGUMENTS,
    ids=[f"{_values(c)[0]}-{'_'.join(_values(c)[1])[:40]}" for c in BAD_ARGUMENTS],
)
def test_bad_arguments_give_one_line_error(command, args, mentions, hover, monkeypatch):
    if command == "train":
        pytest.importorskip("stable_baselines3")
    if command == "import" and args[0] == "px4":  # the ulog extra reads the file
        pytest.importorskip("pyulog")
    monkeypatch.chdir(hover.parent)
    argv = [command] + [a.format(hover=hover) for a in args] + ["--quiet"]
    before = _files(hover.parent)
    code, _, err = run_cli(argv)
    line = assert_one_line_error(code, err, command)
    assert mentions in line, line
    assert _files(hover.parent) == before, "a failed run left files behind"


def test_deeply_nested_vehicle_file_is_one_line(tmp_path):
    deep = tmp_path / "vehicle.json"
    deep.write_text("[" * 100_000)
    code, _, err = run_cli(
        [
            "import",
            "eschmann",
            FIXTURES / "eschmann_log.csv",
            "--vehicle",
            deep,
            "--out",
            tmp_path / "o.csv",
            "--quiet",
        ]
    )
    assert "vehicle.json" in assert_one_line_error(code, err, "import")


def test_unknown_subcommand_is_one_line():
    code, _, err = run_cli(["fly"])
    assert code == 2 and len(err.strip().splitlines()) == 1 and "invalid choice" in err


# -- fuzzed raw logs through quadfault import -----------------------------------------------------
IMPORT_FIXTURES = {
    "eschmann": "eschmann_log.csv",
    "nanodrone": "nanodrone_flight.csv",
    "crazypad": "crazypad_motor_log.csv",
}
JUNK = ("abc", "", "nan", "inf", "-inf", "1e999", "-1", "0", "1e300")


@FUZZ
@given(
    kind=st.sampled_from(sorted(IMPORT_FIXTURES)),
    how=st.integers(0, 3),
    seed=st.integers(0, 2**32 - 1),
)
def test_fuzzed_raw_logs_through_import(kind, how, seed):
    """A raw log with a junk cell, cut anywhere, missing a column or with time going back:
    a valid recording comes out, or one line and exit 2."""
    from quadfault.io.recording import read_recording

    rng = np.random.default_rng(seed)
    lines = (FIXTURES / IMPORT_FIXTURES[kind]).read_text().splitlines()
    k = int(rng.integers(2, len(lines)))
    if how == 0:
        cells = lines[k].split(",")
        cells[int(rng.integers(len(cells)))] = JUNK[int(rng.integers(len(JUNK)))]
        lines[k] = ",".join(cells)
    elif how == 1:
        text = "\n".join(lines)
        lines = text[: int(rng.integers(len(text)))].split("\n")
    elif how == 2:
        j = int(rng.integers(len(lines[0].split(","))))
        lines = [",".join(c for i, c in enumerate(ln.split(",")) if i != j) for ln in lines]
    else:
        cells, prev = lines[k].split(","), lines[k - 1].split(",")
        cells[0] = prev[0] if rng.uniform() < 0.5 else str(float(prev[0]) - 5)
        lines[k] = ",".join(cells)
    with tempfile.TemporaryDirectory() as folder:
        src, out = Path(folder) / "log.csv", Path(folder) / "rec.csv"
        src.write_text("\n".join(lines) + "\n")
        code, _, err = run_cli(["import", kind, src, "--out", out, "--quiet"])
        if code == 0:
            rec = read_recording(out)  # what import writes must read back
            assert np.all(np.isfinite(rec.t)) and np.all(np.diff(rec.t) > 0)
        else:
            assert_one_line_error(code, err, "import")
            assert not out.exists()


# -- no overwrite without --force -----------------------------------------------------------------
SENTINEL = "user data, must survive\n"


def _plant(paths):
    for p in paths:
        Path(p).parent.mkdir(parents=True, exist_ok=True)
        Path(p).write_text(SENTINEL)


def _untouched(paths):
    return all(Path(p).read_text() == SENTINEL for p in paths)


def test_simulate_refuses_to_overwrite_then_force_replaces(tmp_path):
    out = tmp_path / "sim.csv"
    targets = [out, tmp_path / "sim.json"]
    for existing in (targets[:1], targets[1:]):  # either file of the pair blocks the write
        _plant(existing)
        code, _, err = run_cli(["simulate", "--duration", "0.05", "--out", out, "--quiet"])
        assert "--force" in assert_one_line_error(code, err, "simulate")
        assert _untouched(existing)
        for p in existing:
            p.unlink()
    _plant(targets)
    code, _, err = run_cli(["simulate", "--duration", "0.05", "--out", out, "--quiet", "--force"])
    assert code == 0, err
    assert "qw" in out.read_text().splitlines()[0]
    assert json.loads((tmp_path / "sim.json").read_text())["format"] == "quadfault-recording/1"


@pytest.mark.parametrize("estimator", ["irls", "ekf"])
def test_estimate_refuses_to_overwrite_then_force_replaces(hover, estimator):
    out = hover.parent / "est.csv"
    targets = [out, hover.parent / "est.json"]
    _plant(targets)
    argv = ["estimate", hover, "--estimator", estimator, "--out", out, "--quiet"]
    code, _, err = run_cli(argv)
    assert "--force" in assert_one_line_error(code, err, "estimate")
    assert _untouched(targets)
    code, _, err = run_cli(argv + ["--force"])
    assert code == 0, err
    assert out.read_text().startswith("t,eta1")
    assert json.loads(targets[1].read_text())["estimator"] == estimator


def test_diagnose_refuses_to_overwrite_json_and_report(hover):
    folder = hover.parent
    out = folder / "diag.json"
    _plant([out])
    code, _, err = run_cli(["diagnose", hover, "--json", out, "--quiet"])
    assert "--force" in assert_one_line_error(code, err, "diagnose")
    assert _untouched([out])
    report = folder / "report"
    _plant([report / "report.md"])
    code, _, err = run_cli(
        ["diagnose", hover, "--json", folder / "d2.json", "--report", report, "--quiet"]
    )
    assert "--force" in assert_one_line_error(code, err, "diagnose")
    assert _untouched([report / "report.md"]) and not (folder / "d2.json").exists()
    code, _, err = run_cli(
        ["diagnose", hover, "--json", out, "--report", report, "--quiet", "--force"]
    )
    assert code == 0, err
    assert json.loads(out.read_text())["verdict"] in ("consistent", "mismatch")
    assert (report / "report.md").read_text() != SENTINEL


def test_import_refuses_to_overwrite(tmp_path):
    out = tmp_path / "imp.csv"
    _plant([tmp_path / "imp.json"])
    code, _, err = run_cli(
        ["import", "eschmann", FIXTURES / "eschmann_log.csv", "--out", out, "--quiet"]
    )
    assert "--force" in assert_one_line_error(code, err, "import")
    assert _untouched([tmp_path / "imp.json"]) and not out.exists()


def test_reproduce_refuses_to_overwrite_before_running(tmp_path):
    from estimators.paper.reproduce import planned_files

    for victim in planned_files(tmp_path)[:2]:
        _plant([victim])
        code, _, err = run_cli(["reproduce", "--quick", "--out", tmp_path, "--quiet"], timeout=30)
        assert "--force" in assert_one_line_error(code, err, "reproduce")
        assert _untouched([victim])
        victim.unlink()


def test_evaluate_refuses_to_overwrite_before_running(tmp_path):
    _plant([tmp_path / "results.json"])
    code, _, err = run_cli(["evaluate", "--out", tmp_path, "--quiet"], timeout=30)
    assert "--force" in assert_one_line_error(code, err, "evaluate")
    assert _untouched([tmp_path / "results.json"])


def test_train_refuses_to_overwrite_before_running(tmp_path):
    pytest.importorskip("stable_baselines3")
    model = tmp_path / "seed_0" / "model.zip"
    _plant([model])
    code, _, err = run_cli(["train", "--timesteps", "64", "--out", tmp_path, "--quiet"], timeout=60)
    assert "--force" in assert_one_line_error(code, err, "train")
    assert _untouched([model])


# -- interrupted writes ---------------------------------------------------------------------------
def _recording(tmp_path, shift=0.0, source="first"):
    import dataclasses

    from quadfault.io.recording import read_recording

    header, rows, side = valid_recording(20)
    src = tmp_path / "src.csv"
    src.write_bytes(csv_bytes(header, rows))
    (tmp_path / "src.json").write_bytes(json_bytes(side))
    rec = read_recording(src)
    return dataclasses.replace(rec, t=rec.t + shift, source=source)


@pytest.mark.parametrize("n_before", [0, 1, 2, 3])
def test_keyboard_interrupt_inside_the_writer_leaves_no_partial_file(
    tmp_path, monkeypatch, n_before
):
    """Ctrl-C during the n-th fsync (while a temporary file is being written): no new file,
    no temporary file, the old pair intact."""
    from quadfault.io.recording import read_recording, write_recording

    old = _recording(tmp_path)
    path = tmp_path / "f.csv"
    write_recording(old, path)
    calls = []
    real = os.fsync

    def fsync(fd):
        calls.append(fd)
        if len(calls) > n_before:
            raise KeyboardInterrupt
        real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    new = _recording(tmp_path, shift=5.0, source="second")
    for target in (path, tmp_path / "fresh.csv"):
        calls.clear()
        try:
            write_recording(new, target, force=True)
        except KeyboardInterrupt:
            pass
    monkeypatch.setattr(os, "fsync", real)
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    back = read_recording(path)
    fresh = {p.name for p in tmp_path.iterdir()} & {"fresh.csv", "fresh.json"}
    if n_before < 2:  # interrupted before both temporary files were complete
        assert back.source == "first" and back.t[0] == 0.0
        assert not fresh
    else:
        assert back.source == "second" and back.t[0] == 5.0
        assert fresh == {"fresh.csv", "fresh.json"}


@pytest.mark.parametrize("at_rename", [1, 2])
def test_sigint_between_the_renames_keeps_the_pair_consistent(tmp_path, monkeypatch, at_rename):
    """A real SIGINT arriving while the CSV and its sidecar are renamed into place: the pair is
    either all old or all new (never a new sidecar beside the old CSV)."""
    from quadfault.io.recording import read_recording, write_recording

    path = tmp_path / "f.csv"
    write_recording(_recording(tmp_path), path)
    real = os.replace
    calls = []

    def replace(a, b):
        calls.append(b)
        if len(calls) == at_rename:
            os.kill(os.getpid(), signal.SIGINT)
        real(a, b)

    monkeypatch.setattr(os, "replace", replace)
    # Ctrl-C as at a terminal, whatever this process inherited (a job started in the
    # background of a script starts with SIGINT ignored, and Python then raises nothing)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            write_recording(_recording(tmp_path, 5.0, "second"), path, force=True)
    finally:
        signal.signal(signal.SIGINT, previous)
    monkeypatch.setattr(os, "replace", real)
    back = read_recording(path)
    assert (back.source, back.t[0]) in (("first", 0.0), ("second", 5.0))
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_keyboard_interrupt_in_a_subcommand_exits_130_without_files(tmp_path, monkeypatch):
    import quadfault.sim.simulator as simulator

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(simulator, "simulate", interrupted)
    code, _, err = run_cli(["simulate", "--duration", "5", "--out", tmp_path / "s.csv", "--quiet"])
    assert code == 130 and err.strip() == "quadfault simulate: error: interrupted"
    assert not list(tmp_path.iterdir())


# -- real subprocesses ----------------------------------------------------------------------------
def _quadfault():
    exe = shutil.which("quadfault")
    return [exe] if exe else [sys.executable, "-m", "quadfault.cli"]


def test_subprocess_bad_recording_exits_2_with_one_line(tmp_path):
    case = bad_case(np.random.default_rng(3), 6)  # NaN / inf in a required column
    csv_path, side_path = write_case(case, tmp_path)
    proc = subprocess.run(
        _quadfault() + ["estimate", str(csv_path), "--out", str(tmp_path / "e.csv")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert error_is_clean(proc.stderr.strip(), case, csv_path, side_path) is None, proc.stderr
    assert not (tmp_path / "e.csv").exists()


def test_subprocess_usage_error_exits_2_with_one_line(tmp_path):
    proc = subprocess.run(
        _quadfault() + ["diagnose", "--json"], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_sigint_to_a_long_simulation_leaves_no_file(tmp_path):
    """Ctrl-C to ``quadfault simulate`` of a long flight: exit 130, one line, no output, no
    temporary file."""
    # a short flight first compiles the kernels (on an empty numba cache a SIGINT that lands
    # in one of llvmlite's finalizers during compilation is swallowed by Python, and the
    # flight then runs to its end): the signal is meant for the flight itself
    # the child takes Ctrl-C as at a terminal, whatever this process inherited
    code = (
        "import signal\nsignal.signal(signal.SIGINT, signal.default_int_handler)\n"
        "import sys, tempfile, quadfault.cli, quadfault.sim.simulator, quadfault.sim.cli, "
        "quadfault.model.controller, quadfault.io.recording\n"
        "with tempfile.TemporaryDirectory() as warm:\n"
        "    quadfault.cli.main(['simulate', '--duration', '0.05', '--quiet', '--out', "
        "warm + '/warm.csv'])\n"
        "print('ready', flush=True)\n"
        "sys.exit(quadfault.cli.main(sys.argv[1:]))\n"
    )
    out = tmp_path / "long.csv"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            code,
            "simulate",
            "--duration",
            "1200",
            "--out",
            str(out),
            "--quiet",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline().strip() == "ready"
        import time

        time.sleep(1.0)  # well inside the flight (1200 s of simulated time, compiled)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert err.strip() == "quadfault simulate: error: interrupted"
    assert list(tmp_path.iterdir()) == []
