"""Rendering of QuadFaultEnv (rgb_array only): frames, real-time ``render_fps`` (RecordVideo),
crashes marked on the frame, the vehicle kept in view, and the GIF example run as a
subprocess (real-time frame timing)."""

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
    assert first.shape == (320, 800, 3)
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


def _gif_durations(path) -> list[int]:
    from PIL import Image

    durations = []
    with Image.open(path) as im:
        for k in range(im.n_frames):
            im.seek(k)
            durations.append(im.info["duration"])
    return durations


@pytest.mark.slow
def test_example_writes_a_gif(tmp_path):
    out = tmp_path / "episode.gif"
    script = str(REPO / "examples" / "render_fault_episode.py")
    cmd = [
        sys.executable,
        script,
        "--out",
        str(out),
        "--seconds",
        "0.3",
        "--fps",
        "20",
        "--estimator",
        "truth",
    ]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert out.read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    # real time: 0.3 s at 20 fps is 6 frames of 50 ms after the first; the last is held 1 s
    assert _gif_durations(out) == [50] * 6 + [1050]
    # an fps that is not a whole number of 10 ms control steps is rounded, and said
    res = subprocess.run(
        [*cmd[:-4], "--fps", "30", "--estimator", "truth", "--force"],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert res.returncode == 0 and "using 33.3333 fps" in res.stdout, res.stderr
    assert _gif_durations(out)[:-1] == [30] * 10
    bad = subprocess.run(
        [*cmd[:-4], "--fps", "100", "--force"],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert bad.returncode == 2 and "--fps" in bad.stderr and "Traceback" not in bad.stderr
    # never overwrites without --force: one-line error, exit 2
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert again.returncode == 2 and "already exists" in again.stderr
    assert "Traceback" not in again.stderr


def _red_pixels(frame) -> int:
    """Pixels of pure red (the termination marks; no other artist is red)."""
    r, g, b = (frame[..., i].astype(int) for i in range(3))
    return int(np.sum((r > 200) & (g < 60) & (b < 60)))


def _crash_scenario():
    from quadfault.model.scenarios import (
        AbruptFault,
        ConstantEfficiency,
        EfficiencySchedule,
        Scenario,
    )
    from quadfault.model.trajectory import Circle

    faults = (AbruptFault(1, 0.3, level=0.2),)  # motor 1 at 20 %: the vehicle falls
    return Scenario("crash", 4.0, EfficiencySchedule(ConstantEfficiency(), faults), Circle())


def test_a_crash_is_marked_and_the_vehicle_stays_in_view():
    env = QuadFaultEnv("truth", _crash_scenario(), render_mode="rgb_array")
    env.reset(seed=0)
    frames, done = [], False
    while not done:
        _, _, terminated, truncated, info = env.step(np.zeros(4, dtype=np.float32))
        done = terminated or truncated
        frames.append(env.render())
    assert terminated and info["termination_reason"] == "crash"
    assert max(_red_pixels(f) for f in frames[:-1]) == 0  # nothing red while flying
    assert _red_pixels(frames[-1]) > 500  # banner and crosses on the last frame
    # the altitude panel's scale holds the flown altitudes and the ground; the top view the
    # vehicle (the axes follow a vehicle that leaves them)
    renderer = env._renderer
    low, high = renderer.ax_alt.get_ylim()
    up = -np.asarray(env.history)[:, 2]
    assert renderer.ax_alt.get_ylabel() == "altitude [m]"
    assert low <= min(up.min(), env.limits.ground_altitude) and up.max() <= high
    p = env.plant.state.p
    x0, x1 = renderer.ax_top.get_xlim()
    y0, y1 = renderer.ax_top.get_ylim()
    assert x0 <= p[1] <= x1 and y0 <= p[0] <= y1  # east, north
    env.close()


def test_render_fps_is_the_control_rate():
    import gymnasium as gym

    import quad_fault_env  # noqa: F401

    assert gym.make("QuadFault-v0").metadata["render_fps"] == 100
    env = gym.make("QuadFault-v0", control_rate=50.0)
    assert env.metadata["render_fps"] == 50
    assert env.unwrapped.control_period * env.metadata["render_fps"] == 1.0


def test_record_video_plays_in_real_time(tmp_path):
    """RecordVideo (the ``video`` extra installs moviepy) writes one frame per step at
    ``render_fps``: the video lasts as long as the flight."""
    pytest.importorskip("moviepy")
    import gymnasium as gym
    from gymnasium.wrappers import RecordVideo
    from moviepy import VideoFileClip

    import quad_fault_env  # noqa: F401

    env = RecordVideo(
        gym.make("QuadFaultHover-v0", estimator="none", duration=0.5, render_mode="rgb_array"),
        str(tmp_path / "videos"),
        name_prefix="hover",
    )
    env.reset(seed=0)
    steps, done = 0, False
    while not done:
        _, _, terminated, truncated, info = env.step(np.zeros(4, dtype=np.float32))
        done = terminated or truncated
        steps += 1
    env.close()
    (video,) = (tmp_path / "videos").glob("hover*.mp4")
    with VideoFileClip(str(video)) as clip:
        assert clip.fps == 100
        # reset + one frame per step, at 100 frames per second of video
        assert clip.duration == pytest.approx((steps + 1) / 100, abs=0.011)
    assert env.unwrapped.time == pytest.approx(steps / 100)


@pytest.mark.slow
def test_render_benchmark_runs():
    """``benchmarks/bench_render.py`` prints the frame time (no timing assertion here)."""
    res = subprocess.run(
        [
            sys.executable,
            str(REPO / "benchmarks" / "bench_render.py"),
            "--steps",
            "5",
            "--rounds",
            "1",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    assert "env.render(), 5 frames of 800x320 px: median" in res.stdout
    assert "full / blitted" in res.stdout
