"""``quadfault estimate`` end to end (subprocess) and its error exits."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from estimators.series_io import read_estimate_csv
from quadfault.io.recording import Recording, read_recording, write_recording


def _quadfault(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "quadfault.cli", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.fixture(scope="module")
def flight_csv(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    out = d / "flight.csv"
    r = _quadfault(
        "simulate",
        "--scenario",
        "degradation",
        "--duration",
        "0.4",
        "--seed",
        "3",
        "--out",
        out,
        "--quiet",
        cwd=d,
    )
    assert r.returncode == 0, r.stderr
    return out


@pytest.mark.slow
def test_simulate_then_estimate_round_trip(flight_csv, tmp_path):
    est = tmp_path / "est.csv"
    r = _quadfault(
        "estimate", flight_csv, "--estimator", "irls", "--out", est, "--quiet", cwd=tmp_path
    )
    assert r.returncode == 0, r.stderr
    rec = read_recording(flight_csv)
    header = est.read_text().splitlines()[0].split(",")
    assert header == ["t", "eta1", "eta2", "eta3", "eta4", "sd1", "sd2", "sd3", "sd4", "status"]
    data = read_estimate_csv(est)
    np.testing.assert_array_equal(data["t"], rec.t)
    assert np.all(np.isfinite(data["eta"]))
    assert set(data["status"]) <= {"warmup", "ok", "ill_conditioned", "max_iter", "rejected"}
    assert np.all(data["status"][:9] == "warmup") and np.mean(data["status"] == "ok") > 0.8
    err = data["eta"][100:] - rec.eta_true[100:]
    assert np.sqrt(np.mean(err**2)) < 0.05
    side = json.loads((tmp_path / "est.json").read_text())
    assert side["estimator"] == "irls" and side["config"]["window"] == 10
    assert side["input"] == str(flight_csv) and "backend_used" not in side
    # no overwrite without --force; with --force it succeeds
    again = _quadfault("estimate", flight_csv, "--out", est, "--quiet", cwd=tmp_path)
    assert again.returncode == 2 and "--force" in again.stderr
    assert len(again.stderr.strip().splitlines()) == 1
    forced = _quadfault("estimate", flight_csv, "--out", est, "--force", "--quiet", cwd=tmp_path)
    assert forced.returncode == 0, forced.stderr


def test_removed_backend_option_is_a_one_line_error(flight_csv, tmp_path):
    r = _quadfault(
        "estimate", flight_csv, "--out", tmp_path / "a.csv", "--backend", "numpy", cwd=tmp_path
    )
    assert r.returncode == 2 and "--backend" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "a.csv").exists()


@pytest.mark.slow
def test_estimate_improved_irls_records_its_options(flight_csv, tmp_path):
    est = tmp_path / "imp.csv"
    r = _quadfault("estimate", flight_csv, "--improved", "--out", est, "--quiet", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    config = json.loads((tmp_path / "imp.json").read_text())["config"]
    assert config["change_completion"] is True and config["output_median"] == 21
    rec, data = read_recording(flight_csv), read_estimate_csv(est)
    assert np.sqrt(np.mean((data["eta"][100:] - rec.eta_true[100:]) ** 2)) < 0.05
    bad = _quadfault(
        "estimate",
        flight_csv,
        "--estimator",
        "ekf",
        "--improved",
        "--out",
        tmp_path / "x.csv",
        "--quiet",
        cwd=tmp_path,
    )
    assert bad.returncode == 2 and "--improved" in bad.stderr and not (tmp_path / "x.csv").exists()


@pytest.mark.slow
def test_estimate_ekf_through_the_registry(flight_csv, tmp_path):
    pytest.importorskip("estimators.ekf")
    est = tmp_path / "ekf.csv"
    r = _quadfault(
        "estimate", flight_csv, "--estimator", "ekf", "--out", est, "--quiet", cwd=tmp_path
    )
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "ekf.json").read_text())["estimator"] == "ekf"
    assert len(read_estimate_csv(est)["t"]) == len(read_recording(flight_csv))


@pytest.mark.slow
def test_estimate_error_exits(flight_csv, tmp_path):
    rec = read_recording(flight_csv)
    imu = Recording(
        t=rec.t, omega=rec.omega, thrust_cmd=rec.thrust_cmd, vehicle=rec.vehicle, accel=rec.accel
    )
    write_recording(imu, tmp_path / "imu.csv")
    cases = [
        (("estimate", tmp_path / "imu.csv", "--out", tmp_path / "a.csv"), "IMU-only"),
        (("estimate", tmp_path / "missing.csv", "--out", tmp_path / "b.csv"), "not found"),
        (("estimate", flight_csv, "--out", tmp_path / "c.txt"), ".csv"),
        (("estimate", flight_csv, "--out", tmp_path / "nodir" / "d.csv"), "does not exist"),
    ]
    for args, words in cases:
        r = _quadfault(*args, "--quiet", cwd=tmp_path)
        assert r.returncode == 2, (args, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and words in lines[0] and "Traceback" not in r.stderr
    r = _quadfault(
        "estimate", flight_csv, "--estimator", "kalman", "--out", tmp_path / "e.csv", cwd=tmp_path
    )
    assert r.returncode == 2 and "invalid choice" in r.stderr
    assert not (tmp_path / "a.csv").exists() and not (tmp_path / "a.json").exists()


def test_unknown_or_missing_estimator_is_a_clean_error(monkeypatch):
    from estimators import registry
    from quadfault.errors import ConfigError

    monkeypatch.setitem(
        registry.ESTIMATORS,
        "ghost",
        registry.EstimatorSpec("ghost", "estimators.not_there:Ghost", "missing"),
    )
    with pytest.raises(ConfigError, match="not available"):
        registry.estimator_class("ghost")
    with pytest.raises(ConfigError, match="unknown estimator"):
        registry.estimator_class("nope")
