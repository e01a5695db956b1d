"""``quadfault estimate --median N / --q-eta Q`` for every estimator, and command clipping that
follows the recording's ``saturated`` flag (end to end through the CLI)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from estimators.median import causal_median
from estimators.metrics import score
from estimators.series_io import read_estimate_csv
from quadfault.io.recording import read_recording


def _quadfault(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "quadfault.cli", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )


def _estimate(flight, out, *args):
    r = _quadfault("estimate", flight, "--out", out, "--quiet", *args, cwd=out.parent)
    assert r.returncode == 0, r.stderr
    return read_estimate_csv(out), json.loads(out.with_suffix(".json").read_text())


@pytest.fixture(scope="module")
def abrupt(tmp_path_factory):
    """A short abrupt-fault flight without an upper thrust limit whose weak rotor is
    commanded beyond the sidecar's max_thrust (3.5 N) in its fault windows."""
    d = tmp_path_factory.mktemp("post")
    out = d / "abrupt.csv"
    r = _quadfault(
        "simulate",
        "--scenario",
        "abrupt",
        "--duration",
        "12",
        "--seed",
        "1",
        "--no-saturation",
        "--max-thrust",
        "3.5",
        "--out",
        out,
        "--quiet",
        cwd=d,
    )
    assert r.returncode == 0, r.stderr
    return out


@pytest.mark.slow
def test_median_is_the_same_post_processing_for_irls_and_ekf(abrupt, tmp_path):
    for name, extra in (("irls", []), ("ekf", ["--q-eta", "1.778"])):
        plain, side0 = _estimate(abrupt, tmp_path / f"{name}.csv", "--estimator", name, *extra)
        med, side = _estimate(
            abrupt, tmp_path / f"{name}_m.csv", "--estimator", name, *extra, "--median", "21"
        )
        np.testing.assert_array_equal(med["eta"], causal_median(plain["eta"], 21))
        np.testing.assert_array_equal(med["sd"], plain["sd"])
        assert side0["postprocess"] == "none" and side["postprocess"] == "median:21"
        assert not np.array_equal(med["eta"], plain["eta"])
    assert side["config"]["q_eta"] == 1.778  # the EKF's sidecar records its Q_eta


@pytest.mark.slow
def test_q_eta_changes_the_ekf_and_median_overrides_improved(abrupt, tmp_path):
    a, _ = _estimate(abrupt, tmp_path / "a.csv", "--estimator", "ekf")
    b, side = _estimate(abrupt, tmp_path / "b.csv", "--estimator", "ekf", "--q-eta", "0.01")
    assert side["config"]["q_eta"] == 0.01 and not np.allclose(a["eta"], b["eta"])
    _, side = _estimate(
        abrupt, tmp_path / "i.csv", "--estimator", "irls", "--improved", "--median", "5"
    )
    assert side["config"]["output_median"] == 5 and side["config"]["change_completion"]
    assert side["postprocess"] == "median:5"


@pytest.mark.parametrize(
    "args, words",
    [
        (["--median", "0"], "--median must be an integer >= 1"),
        (["--estimator", "ekf", "--q-eta", "-1"], "--q-eta must be a positive number"),
        (["--estimator", "irls", "--q-eta", "0.3"], "--q-eta applies to the ekf"),
        (["--estimator", "ekf", "--improved"], "--improved applies to the irls"),
    ],
)
def test_bad_post_processing_options_are_one_line_errors(abrupt, tmp_path, args, words):
    r = _quadfault("estimate", abrupt, "--out", tmp_path / "x.csv", *args, cwd=tmp_path)
    assert r.returncode == 2 and words in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.csv").exists()


def _with_sidecar(src, dst, change):
    """A copy of recording ``src`` at ``dst`` whose sidecar is ``change``d (a dict edit)."""
    dst.write_text(src.read_text())
    side = json.loads(src.with_suffix(".json").read_text())
    change(side)
    dst.with_suffix(".json").write_text(json.dumps(side))
    return dst


@pytest.mark.slow
def test_clipping_follows_the_recording(abrupt, tmp_path):
    rec = read_recording(abrupt)
    assert rec.meta["saturated"] is False and rec.vehicle.rotor_max_thrust == 3.5
    assert np.mean(rec.thrust_cmd > 3.5) > 0.005  # the weak rotor is commanded beyond it
    old = _with_sidecar(abrupt, tmp_path / "old.csv", lambda s: s.pop("saturated"))
    sat = _with_sidecar(abrupt, tmp_path / "sat.csv", lambda s: s.update(saturated=True))
    for name in ("irls", "ekf"):
        follows, _ = _estimate(abrupt, tmp_path / f"{name}_f.csv", "--estimator", name)
        legacy, _ = _estimate(old, tmp_path / f"{name}_o.csv", "--estimator", name)
        clipped, _ = _estimate(sat, tmp_path / f"{name}_s.csv", "--estimator", name)
        # a sidecar without the key is clipped at max_thrust, as before the key existed
        np.testing.assert_array_equal(legacy["eta"], clipped["eta"])
        # the unsaturated flight is not clipped, and that is the more accurate model
        assert _rmse(rec, follows, name) < 0.95 * _rmse(rec, clipped, name), name


def _rmse(rec, d, name):
    from estimators.base import EstimateSeries

    s = EstimateSeries(d["t"], d["eta"], d["sd"], d["status"], name)
    return float(np.mean(score(rec, s).rmse))


def test_simulate_records_saturation_and_bad_flags_are_errors(abrupt, tmp_path):
    d = tmp_path
    r = _quadfault(
        "simulate",
        "--scenario",
        "hover",
        "--duration",
        "0.3",
        "--seed",
        "0",
        "--out",
        d / "h.csv",
        "--quiet",
        cwd=d,
    )
    assert r.returncode == 0, r.stderr
    assert json.loads((d / "h.json").read_text())["saturated"] is True
    bad = _with_sidecar(abrupt, d / "bad.csv", lambda s: s.update(saturated="yes"))
    r = _quadfault("estimate", bad, "--out", d / "e.csv", cwd=d)
    assert r.returncode == 2 and "'saturated' must be true or false" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
