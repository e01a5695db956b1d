"""Render a short fault episode of QuadFaultEnv to a GIF that plays in real time.

The paper's circle with a 30 % loss of motor 2 at 1 s. The IRLS estimate (orange bars,
one-sigma error bars) follows the true efficiency (grey bars) and the geometric controller
divides its commands by it (``compensate=True``; ``--no-compensate`` flies the nominal
allocation). Frames come from ``render_mode="rgb_array"``.

Timing: the environment steps at 100 Hz; the GIF takes every k-th control step, k =
round(100 / ``--fps``), and shows each frame for k x 10 ms, so one second of the GIF is one
second of flight (``--fps`` from 2 to 50: GIF delays come in 10 ms units and browsers slow
down delays under 20 ms). When 100 / fps is not a whole number the rate actually used is
printed. The last frame is held for one more second, so a crash banner stays readable.
Written with Pillow (a matplotlib dependency), atomically and never over an existing file
unless ``--force``.

    python examples/render_fault_episode.py --out fault_episode.gif --seconds 4
"""

from __future__ import annotations

import argparse
import io
import sys

import matplotlib

matplotlib.use("Agg")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import quad_fault_env  # noqa: E402,F401  (registers the ids)
from quadfault.errors import QuadfaultError  # noqa: E402
from quadfault.fileio import atomic_write_bytes, check_writable  # noqa: E402
from quadfault.model.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario  # noqa: E402
from quadfault.model.trajectory import Circle  # noqa: E402


def fault_scenario(seconds: float) -> Scenario:
    """The paper's circle; motor 2 drops to 70 % at 1 s (or a quarter in, if shorter)."""
    onset = min(1.0, 0.25 * seconds)
    schedule = EfficiencySchedule(ConstantEfficiency(), (AbruptFault(2, onset, level=0.7),))
    return Scenario("motor2_fault", seconds, schedule, Circle(), thrust_noise=0.07)


def frame_stride(fps: float, control_period: float) -> int:
    """Control steps per GIF frame for ``fps`` frames per second of flight (at least 2:
    a GIF frame lasts a whole number of 10 ms and browsers slow down anything under 20 ms)."""
    return max(2, round(1.0 / (fps * control_period)))


def collect_frames(
    seconds: float, fps: float, estimator: str, seed: int, compensate: bool = True
) -> tuple[list[np.ndarray], int]:
    """``(frames, frame_ms)``: frames at reset and after every k-th control step (and the
    last step), k from :func:`frame_stride`; each covers ``frame_ms`` of flight."""
    env = gym.make(
        "QuadFault-v1",
        estimator=estimator,
        scenario=fault_scenario(seconds),
        compensate=compensate,
        render_mode="rgb_array",
    )
    period = env.unwrapped.control_period
    every = frame_stride(fps, period)
    frame_ms = round(every * period * 1000)
    if abs(1000 / frame_ms - fps) > 1e-9:
        print(
            f"--fps {fps:g}: using {1000 / frame_ms:g} fps (every {every} control steps of "
            f"{period * 1000:g} ms), so the GIF plays in real time"
        )
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
        print(
            f"episode ended early: {info['termination_reason']} at t = {env.unwrapped.time:.2f} s"
        )
    return frames, frame_ms


def gif_bytes(frames: list[np.ndarray], frame_ms: int, hold_ms: int = 1000) -> bytes:
    """A looping GIF: every frame shown for ``frame_ms`` [ms] (a multiple of 10), the last
    one for ``hold_ms`` more."""
    from PIL import Image

    images = [Image.fromarray(f) for f in frames]
    durations = [frame_ms] * (len(images) - 1) + [frame_ms + hold_ms]
    buf = io.BytesIO()
    images[0].save(
        buf, format="GIF", save_all=True, append_images=images[1:], duration=durations, loop=0
    )
    return buf.getvalue()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="fault_episode.gif", help="GIF to write")
    p.add_argument("--seconds", type=float, default=3.0, help="episode length [s]")
    p.add_argument(
        "--fps",
        type=float,
        default=20.0,
        help="frames per second of the GIF, 2-50 (default 20); plays in real time",
    )
    p.add_argument(
        "--no-compensate",
        action="store_true",
        help="fly the nominal allocation (the estimate is only observed)",
    )
    p.add_argument("--estimator", default="irls", choices=["irls", "ekf", "truth", "none"])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--force", action="store_true", help="overwrite --out")
    args = p.parse_args(argv)
    try:
        if not args.seconds > 0:
            raise QuadfaultError(f"--seconds must be positive, got {args.seconds}")
        if not 2 <= args.fps <= 50:
            raise QuadfaultError(f"--fps must be between 2 and 50, got {args.fps}")
        check_writable([args.out], force=args.force)
        frames, frame_ms = collect_frames(
            args.seconds, args.fps, args.estimator, args.seed, not args.no_compensate
        )
        atomic_write_bytes(args.out, gif_bytes(frames, frame_ms), force=args.force)
    except QuadfaultError as exc:
        print(f"render_fault_episode: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.out} ({len(frames)} frames, {frame_ms} ms each)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
