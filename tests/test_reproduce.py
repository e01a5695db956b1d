"""``quadfault reproduce``: calibration logic, the contract shape of metrics.json, outputs,
overwrite refusal."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from estimators.paper.calibration import match_larger_root
from quadfault.errors import ConfigError


def _u_curve(q):
    """U-shaped in log q: minimum 0.02 at q = 1e-2, rising 0.01 per decade squared."""
    return 0.02 + 0.01 * (math.log10(q) + 2.0) ** 2


def test_calibration_picks_the_larger_root():
    grid = np.logspace(-6, 2, 9)
    res = match_larger_root(_u_curve, 0.035, grid, bisection_steps=30, rtol=1e-6)
    assert res.matched
    # roots at log10 q = -2 -+ sqrt(1.5): the larger one
    assert res.q_eta == pytest.approx(10 ** (-2 + math.sqrt(1.5)), rel=1e-4)
    assert res.rmse == pytest.approx(0.035, rel=1e-5)
    assert list(res.curve_q) == sorted(res.curve_q) and len(res.curve_q) > len(grid)
    assert "larger root" in res.message


def test_calibration_uses_the_minimum_when_the_target_is_unreachable():
    grid = np.logspace(-6, 2, 17)
    res = match_larger_root(_u_curve, 0.01, grid)
    assert not res.matched and res.q_eta == pytest.approx(1e-2)
    assert res.rmse == pytest.approx(0.02) and "minimum" in res.message


def test_calibration_rejects_a_bad_grid():
    with pytest.raises(ConfigError, match="grid"):
        match_larger_root(_u_curve, 0.03, [1.0, 0.1])
    with pytest.raises(ConfigError, match="target"):
        match_larger_root(_u_curve, -1.0, [0.1, 1.0])


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "quadfault.cli", "reproduce", *args],
        capture_output=True,
        text=True,
        timeout=900,
    )


def _check_contract(doc):
    assert set(doc["scenarios"]) == {"degradation", "abrupt", "combined", "clipping"}
    for name, per in doc["scenarios"].items():
        for est in ("irls", "ekf"):
            s = per[est]
            for key in ("rmse", "std"):
                assert len(s[key]) == 4 and all(isinstance(v, float) and v >= 0 for v in s[key])
            assert isinstance(s["seconds"], float) and s["seconds"] > 0
            if name == "degradation":
                assert s["spike"] is None
            else:
                assert len(s["spike"]) == 4 and all(isinstance(v, float) for v in s["spike"])
            # sanity of the numbers: both estimators track the efficiency
            assert max(s["rmse"]) < 0.15
            # std^2 = N/(N-1) (rmse^2 - mean^2) <= N/(N-1) rmse^2, N >= 10^4 here
            assert all(sd <= rm * 1.001 for sd, rm in zip(s["std"], s["rmse"]))


@pytest.mark.slow
def test_existing_outputs_are_refused_before_any_work(tmp_path):
    (tmp_path / "metrics.json").write_text("{}")
    r = _cli("--quick", "--out", str(tmp_path))
    assert r.returncode == 2
    assert "already exists" in r.stderr and "--force" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert (tmp_path / "metrics.json").read_text() == "{}"


@pytest.mark.slow
def test_bad_flags_are_one_line_errors(tmp_path):
    r = _cli("--quick", "--out", str(tmp_path / "x"), "--workers", "0")
    assert r.returncode == 2 and "--workers" in r.stderr and "Traceback" not in r.stderr
    (tmp_path / "file").write_text("")
    r = _cli("--quick", "--out", str(tmp_path / "file"))
    assert r.returncode == 2 and "not a folder" in r.stderr
    r = _cli("--quick", "--out", str(tmp_path / "y"), "--sensor-noise", "pixhawk")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "--sensor-noise: unknown sensor noise preset 'pixhawk'; presets: none" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "y").exists()


@pytest.mark.slow
def test_quick_reproduce_writes_the_contract_outputs(tmp_path):
    out = tmp_path / "repro"
    r = _cli("--quick", "--out", str(out), "--quiet")
    assert r.returncode == 0, r.stderr
    assert "| combined | irls |" in r.stdout and "| combined | ekf |" in r.stdout
    doc = json.loads((out / "metrics.json").read_text())
    _check_contract(doc)
    assert set(doc["reference_mode"]["scenarios"]) == {"degradation", "abrupt", "combined"}
    assert doc["config"]["ekf_q_eta"] > 0 and doc["config"]["seed"] == 0
    assert not any(f["diverged"] for f in doc["flights"].values())
    assert not any(f["diverged"] for f in doc["reference_mode_flights"].values())
    assert doc["config"]["calibration"]["rk4"]["curve_q"]
    report = (out / "report.md").read_text()
    assert "paper" in report and "![estimates_combined.png](estimates_combined.png)" in report
    for name in (
        "estimates_abrupt.png",
        "errors_combined.png",
        "rmse_std_bars.png",
        "spikes_per_motor.png",
        "calibration_curve.png",
        "irls_convergence.png",
        "kkt_convergence.png",
    ):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    # the IRLS detector finds every abrupt fault on the right motor
    assert doc["fdi"]["abrupt"]["irls"]["detected"] == 4
    assert doc["fdi"]["abrupt"]["irls"]["false_alarms"] == 0
    # every IRLS variant beside its partners (EKF, RLS, UKF), with the identical post-processing
    per = doc["scenarios"]["combined"]
    assert set(per) == {
        f"{e}{v}" for e in ("irls", "ekf", "rls", "ukf") for v in ("", "_median", "_improved")
    }
    for key, entry in per.items():
        partner = per[entry["partner"]]
        assert partner["postprocess"] == entry["postprocess"]
        if key.startswith("irls"):
            assert partner["partner"] == key and entry["partner"].startswith("ekf")
        else:
            assert entry["partner"].startswith("irls")
        assert entry["cli"][:2] == ["--estimator", key.split("_")[0]]
        assert ("q_eta" in entry) == key.startswith(("ekf", "ukf"))
        assert ("forgetting" in entry) == key.startswith("rls")
    assert set(doc["baseline_ratios"]) == {"ekf", "rls", "ukf"}
    assert doc["baseline_ratios"]["ekf"] == doc["ratios"]
    assert 0 < per["rls"]["forgetting"] < 1
    assert per["ekf"]["postprocess"] == "none" and per["ekf_improved"]["postprocess"] == "median:21"
    assert per["ekf_improved"]["cli"][-2:] == ["--median", "21"]
    assert doc["config"]["ekf_q_eta_improved"] > 0
    assert set(doc["spike_ratio"]["abrupt"]) == {"paper", "median", "improved"}
    assert set(doc["ratios"]["abrupt"]["paper"]) == {
        "spike",
        "excess_spike",
        "rmse",
        "excess_spike_difference",
    }
    cal = doc["config"]["calibration"]["rk4_improved"]
    q_min = cal["curve_q"][int(np.argmin(cal["curve_rmse"]))]
    feasible = [
        e
        for q, r, e in zip(cal["curve_q"], cal["curve_rmse"], cal["curve_excess"])
        if r <= cal["target_rmse"] and q >= q_min
    ]
    assert cal["matched"] and cal["excess_spike"] == min(feasible)
    assert doc["fdi"]["abrupt"]["irls_improved"]["detected"] == 4
    assert "| combined | irls_improved |" in r.stdout and "excess" in r.stdout
    # a second run refuses to overwrite
    r2 = _cli("--quick", "--out", str(out), "--quiet")
    assert r2.returncode == 2 and "already exists" in r2.stderr
