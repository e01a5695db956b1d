"""Rendering of QuadFaultEnv (rgb_array only) and the GIF example run as a subprocess."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from quad_fault_env.envs.quad_fault import QuadFaultEnv

REPO = Path(__file__).resolve().parents[1]


def test_rgb_array_frames_change_with_the_flight():
    env = QuadFaultEnv("truth", "hover_fault", duration=1.0, render_mode="rgb_array")
    env.reset(seed=0)
    first = env.render()
    assert first.dtype == np.uint8 and first.ndim == 3 and first.shape[2] == 3
    assert first.shape[0] >= 200 and first.shape[1] >= 400
    assert first.std() > 10  # not a blank canvas
    for _ in range(40):  # past the fault at 0.3 s: the motor-1 bar drops
        env.step(np.zeros(4, dtype=np.float32))
    second = env.render()
    assert second.shape == first.shape
    assert np.mean(first != second) > 0.01
    env.close()


def test_render_without_mode_warns_and_returns_none():
    env = QuadFaultEnv("none", "hover", duration=1.0)
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


@pytest.mark.slow
def test_example_writes_a_gif(tmp_path):
    out = tmp_path / "episode.gif"
    cmd = [sys.executable, str(REPO / "examples" / "render_fault_episode.py"), "--out", str(out),
           "--seconds", "0.3", "--fps", "20", "--estimator", "truth"]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert out.read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    # never overwrites without --force: one-line error, exit 2
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert again.returncode == 2 and "already exists" in again.stderr
    assert "Traceback" not in again.stderr
