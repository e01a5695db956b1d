"""Render a short fault episode of QuadFaultEnv to a GIF.

The paper's circle with a 30 % loss of motor 2 at 1 s. The IRLS estimate (orange bars,
one-sigma error bars) follows the true efficiency (grey bars) and the geometric controller
divides its commands by it (``compensate=True``; ``--no-compensate`` flies the nominal
allocation). Frames come from ``render_mode="rgb_array"``; the GIF is written with
imageio when it is installed, else with matplotlib's PillowWriter, atomically and never over
an existing file unless ``--force``.

    python examples/render_fault_episode.py --out fault_episode.gif --seconds 4
"""

from __future__ import annotations

import argparse
import io
import os
import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import quad_fault_env  # noqa: E402,F401  (registers the ids)
from quadfault.errors import QuadfaultError  # noqa: E402
from quadfault.fileio import atomic_write_bytes, check_writable  # noqa: E402
from quadfault.scenarios import (AbruptFault, ConstantEfficiency,  # noqa: E402
                                 EfficiencySchedule, Scenario)
from quadfault.trajectory import Circle  # noqa: E402


def fault_scenario(seconds: float) -> Scenario:
    """The paper's circle; motor 2 drops to 70 % at 1 s (or a quarter in, if shorter)."""
    onset = min(1.0, 0.25 * seconds)
    schedule = EfficiencySchedule(ConstantEfficiency(), (AbruptFault(2, onset, level=0.7),))
    return Scenario("motor2_fault", seconds, schedule, Circle(), thrust_noise=0.07)


def collect_frames(seconds: float, fps: float, estimator: str, seed: int,
                   compensate: bool = True) -> list[np.ndarray]:
    env = gym.make("QuadFault-v0", estimator=estimator, scenario=fault_scenario(seconds),
                   compensate=compensate, render_mode="rgb_array")
    every = max(1, round(1.0 / (fps * env.unwrapped.control_period)))
    env.reset(seed=seed)
    frames = [env.render()]
    k, done = 0, False
    while not done:
        _, _, terminated, truncated, info = env.step(np.zeros(4, dtype=np.float32))
        done = terminated or truncated
        k += 1
        if k % every == 0 or done:
            frames.append(env.render())
    env.close()
    if info["termination_reason"]:
        print(f"episode ended early: {info['termination_reason']} at t = {info['t']:.2f} s")
    return frames


def gif_bytes(frames: list[np.ndarray], fps: float) -> bytes:
    try:
        import imageio.v2 as imageio
    except ImportError:
        imageio = None
    if imageio is not None:
        buf = io.BytesIO()
        imageio.mimwrite(buf, frames, format="GIF", duration=1.0 / fps, loop=0)
        return buf.getvalue()
    from matplotlib.animation import PillowWriter
    from matplotlib.figure import Figure

    h, w = frames[0].shape[:2]
    dpi = 100
    fig = Figure(figsize=(w / dpi, h / dpi), dpi=dpi)
    ax = fig.add_axes([0, 0, 1, 1])
    ax.axis("off")
    image = ax.imshow(frames[0])
    fd, tmp = tempfile.mkstemp(suffix=".gif")
    os.close(fd)
    try:
        writer = PillowWriter(fps=fps)
        with writer.saving(fig, tmp, dpi):
            for frame in frames:
                image.set_data(frame)
                writer.grab_frame()
        return Path(tmp).read_bytes()
    finally:
        os.unlink(tmp)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="fault_episode.gif", help="GIF to write")
    p.add_argument("--seconds", type=float, default=3.0, help="episode length [s]")
    p.add_argument("--fps", type=float, default=10.0, help="frames per second of the GIF")
    p.add_argument("--no-compensate", action="store_true",
                   help="fly the nominal allocation (the estimate is only observed)")
    p.add_argument("--estimator", default="irls", choices=["irls", "ekf", "truth", "none"])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--force", action="store_true", help="overwrite --out")
    args = p.parse_args(argv)
    try:
        if not (args.seconds > 0 and args.fps > 0):
            raise QuadfaultError("--seconds and --fps must be positive")
        check_writable([args.out], force=args.force)
        frames = collect_frames(args.seconds, args.fps, args.estimator, args.seed,
                                not args.no_compensate)
        atomic_write_bytes(args.out, gif_bytes(frames, args.fps), force=args.force)
    except QuadfaultError as exc:
        print(f"render_fault_episode: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.out} ({len(frames)} frames)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
