"""The agents examples run as subprocesses."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(args, tmp_path, timeout=600):
    return subprocess.run(
        [sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout
    )


def test_evaluate_controllers_example(tmp_path):
    out = tmp_path / "eval"
    res = _run(
        [
            "examples/evaluate_controllers.py",
            "--suite",
            "smoke",
            "--seeds",
            "0",
            "--duration",
            "0.2",
            "--agents",
            "geometric",
            "estimate-aware:none",
            "--out",
            str(out),
        ],
        tmp_path,
    )
    assert res.returncode == 0, res.stderr
    assert "| abrupt_4s | estimate-aware:none |" in (out / "results.md").read_text()


@pytest.mark.slow
def test_train_ppo_residual_example(tmp_path):
    pytest.importorskip("torch")
    pytest.importorskip("stable_baselines3")
    out = tmp_path / "ppo"
    res = _run(
        [
            "examples/train_ppo_residual.py",
            "--out",
            str(out),
            "--timesteps",
            "512",
            "--n-envs",
            "1",
            "--duration",
            "0.5",
            "--estimator",
            "none",
        ],
        tmp_path,
    )
    assert res.returncode == 0, res.stderr
    assert (out / "learning_curve.png").stat().st_size > 1000
    assert (out / "seed_0" / "model.zip").exists()


NANODRONE = (
    ROOT.parent / "shared" / "data" / "real" / "nanodrone-cf21bl" / "square_20251017_run3.csv.gz"
)


@pytest.mark.slow
@pytest.mark.skipif(not NANODRONE.exists(), reason="the real Crazyflie data (../shared) is absent")
def test_train_calibrated_env_example(tmp_path):
    """Real log -> import -> diagnose -> train in the calibrated env -> evaluate nominal and
    calibrated: every agent flies every evaluation episode to its end."""
    pytest.importorskip("stable_baselines3")
    out = tmp_path / "calibrated"
    res = _run(
        [
            "examples/train_calibrated_env.py",
            "--log",
            str(NANODRONE),
            "--out",
            str(out),
            "--timesteps",
            "1024",
            "--episodes",
            "1",
            "--duration",
            "2",
        ],
        tmp_path,
    )
    assert res.returncode == 0, res.stderr
    assert (out / "diag.json").exists() and (out / "seed_0" / "model.zip").exists()
    rows = [
        line.split()
        for line in res.stdout.splitlines()
        if line.startswith(("nominal ", "calibrated ")) and "model:" not in line
    ]
    assert len(rows) == 4
    for row in rows:  # a 2 s episode at 100 Hz survived earns > 200 x 0.11 (survival bonus)
        assert float(row[-2]) > 22 and float(row[-1]) < 0.2
    model_line = next(
        line for line in res.stdout.splitlines() if line.startswith("calibrated model: ")
    )
    assert "motor_lag" in model_line.removeprefix("calibrated model: ").split(", ")
