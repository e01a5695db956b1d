"""The agents examples run as subprocesses."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(args, tmp_path, timeout=600):
    return subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)


def test_evaluate_controllers_example(tmp_path):
    out = tmp_path / "eval"
    res = _run(["examples/evaluate_controllers.py", "--suite", "smoke", "--seeds", "0",
                "--duration", "0.2", "--agents", "geometric", "estimate-aware:none",
                "--out", str(out)], tmp_path)
    assert res.returncode == 0, res.stderr
    assert "| abrupt_4s | estimate-aware:none |" in (out / "results.md").read_text()


@pytest.mark.slow
def test_train_ppo_residual_example(tmp_path):
    pytest.importorskip("torch")
    pytest.importorskip("stable_baselines3")
    out = tmp_path / "ppo"
    res = _run(["examples/train_ppo_residual.py", "--out", str(out), "--timesteps", "512",
                "--n-envs", "1", "--duration", "0.5", "--estimator", "none"], tmp_path)
    assert res.returncode == 0, res.stderr
    assert (out / "learning_curve.png").stat().st_size > 1000
    assert (out / "seed_0" / "model.zip").exists()
