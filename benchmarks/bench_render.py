"""Rendering speed: the time of one ``env.render()`` frame (``render_mode="rgb_array"``).

Part 1 (the user's path): ``gym.make("QuadFault-v0", render_mode="rgb_array")`` (the paper's
circle, IRLS in the loop) flies ``--steps`` control steps with the zero residual action and
renders after every step; prints the wall time per frame (median and 90th percentile), the
CPU time per frame of this process, the first frame (figure set-up and the first full draw)
and whether the median meets the 20 ms target.

Part 2 (side by side, on the same recorded frames): the renderer as it runs (static parts
drawn once, moving artists blitted over them) against a full redraw of the same figure for
every frame, in interleaved rounds (best round kept); prints both and their ratio.

Every timing line carries the 1-minute load average: on a shared machine read the ratio and
the CPU times.

    python benchmarks/bench_render.py                 # 300 frames
    python benchmarks/bench_render.py --steps 60      # a quick run
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

TARGET_MS = 20.0


def _load() -> str:
    return f"load {os.getloadavg()[0]:.2f}"


def user_path(steps: int) -> list:
    """Render after every step through ``env.render()``; returns the recorded frame states."""
    import gymnasium as gym

    import quad_fault_env  # noqa: F401  (registers the ids)
    from quad_fault_env.rendering import frame_state

    env = gym.make("QuadFault-v0", render_mode="rgb_array")
    env.reset(seed=0)
    t0 = time.perf_counter()
    env.render()
    first = time.perf_counter() - t0
    wall, cpu, states = [], [], []
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(np.zeros(4, dtype=np.float32))
        w, c = time.perf_counter(), time.process_time()
        frame = env.render()
        wall.append(time.perf_counter() - w)
        cpu.append(time.process_time() - c)
        states.append(frame_state(env.unwrapped))
        if terminated or truncated:
            break
    env.close()
    med, p90 = np.median(wall) * 1e3, np.percentile(wall, 90) * 1e3
    print(f"env.render(), {len(wall)} frames of {frame.shape[1]}x{frame.shape[0]} px: "
          f"median {med:.1f} ms, 90th percentile {p90:.1f} ms wall, "
          f"{np.median(cpu) * 1e3:.1f} ms CPU per frame; first frame {first * 1e3:.0f} ms "
          f"({_load()})")
    print(f"target <= {TARGET_MS:.0f} ms per frame: {'met' if med <= TARGET_MS else 'NOT met'}")
    return states


def _blitted(renderer, states) -> float:
    w = time.perf_counter()
    for s in states:
        renderer.draw_state(s)
    return (time.perf_counter() - w) / len(states)


def _full_redraw(renderer, states) -> float:
    """The same figure with every artist drawn in each frame (no kept background)."""
    for artist in renderer._animated:
        artist.set_animated(False)
    canvas = renderer.fig.canvas
    w = time.perf_counter()
    for s in states:
        renderer._update(s)
        canvas.draw()
        np.asarray(canvas.buffer_rgba())[..., :3].copy()
    elapsed = (time.perf_counter() - w) / len(states)
    for artist in renderer._animated:
        artist.set_animated(True)
    return elapsed


def side_by_side(states, rounds: int) -> None:
    from quad_fault_env.rendering import FlightRenderer
    from quadfault.vehicle import Vehicle

    renderer = FlightRenderer(Vehicle())
    renderer.draw_state(states[-1])  # limits of the whole flight: no redraw while timing
    blit, full = [], []
    for _ in range(rounds):
        blit.append(_blitted(renderer, states))
        renderer._background = None
        full.append(_full_redraw(renderer, states))
        renderer.draw_state(states[-1])
    b, f = min(blit) * 1e3, min(full) * 1e3
    print(f"same {len(states)} frames, best of {rounds} interleaved rounds: blitted "
          f"{b:.1f} ms, full redraw {f:.1f} ms per frame; full / blitted = {f / b:.1f}x "
          f"({_load()})")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=300, help="frames (control steps, default 300)")
    p.add_argument("--rounds", type=int, default=3, help="interleaved rounds of part 2")
    args = p.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    states = user_path(args.steps)
    side_by_side(states, args.rounds)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
