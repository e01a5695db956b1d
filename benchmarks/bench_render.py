"""Rendering speed: the time of one ``env.render()`` frame (``render_mode="rgb_array"``).

Part 1 (the user's path): ``gym.make("QuadFault-v1", render_mode="rgb_array")`` (the paper's
circle, IRLS in the loop) flies ``--steps`` control steps with the zero residual action and
renders after every step; prints the wall time per frame (median and 90th percentile), the
CPU time per frame of this process, the first frame (figure set-up and the first full draw)
and whether the median meets the 20 ms target.

Part 2 (side by side, on the same recorded frames): the renderer as it runs (static parts
drawn once, moving artists blitted over them) against a full redraw of the same figure for
every frame, in interleaved rounds (best round kept); prints both and their ratio.

Part 3 (``--reference REV``): the renderer of git revision REV
(``quad_fault_env/rendering.py`` read with ``git show``) against the current one, drawing the
same environment state, in interleaved rounds (best kept, CPU time of this process).

Every timing line carries the 1-minute load average: on a shared machine read the ratios and
the CPU times.

    python benchmarks/bench_render.py                 # 300 frames
    python benchmarks/bench_render.py --steps 60      # a quick run
    python benchmarks/bench_render.py --reference 3cc5532
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

    env = gym.make("QuadFault-v1", render_mode="rgb_array")
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
    print(
        f"env.render(), {len(wall)} frames of {frame.shape[1]}x{frame.shape[0]} px: "
        f"median {med:.1f} ms, 90th percentile {p90:.1f} ms wall, "
        f"{np.median(cpu) * 1e3:.1f} ms CPU per frame; first frame {first * 1e3:.0f} ms "
        f"({_load()})"
    )
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
    from quadfault.model.vehicle import Vehicle

    renderer = FlightRenderer(Vehicle())
    renderer.draw_state(states[-1])  # limits of the whole flight: no redraw while timing
    blit, full = [], []
    for _ in range(rounds):
        blit.append(_blitted(renderer, states))
        renderer._background = None
        full.append(_full_redraw(renderer, states))
        renderer.draw_state(states[-1])
    b, f = min(blit) * 1e3, min(full) * 1e3
    print(
        f"same {len(states)} frames, best of {rounds} interleaved rounds: blitted "
        f"{b:.1f} ms, full redraw {f:.1f} ms per frame; full / blitted = {f / b:.1f}x "
        f"({_load()})"
    )


def against_revision(rev: str, rounds: int, frames: int = 40) -> None:
    import subprocess
    import sys
    import types
    from pathlib import Path

    from quad_fault_env.envs.quad_fault import QuadFaultEnv
    from quad_fault_env.rendering import FlightRenderer

    repo = Path(__file__).resolve().parents[1]
    source = subprocess.run(
        ["git", "show", f"{rev}:quad_fault_env/rendering.py"],
        cwd=repo,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    module = types.ModuleType("reference_rendering")
    sys.modules[module.__name__] = module
    exec(compile(source, f"{rev}:quad_fault_env/rendering.py", "exec"), module.__dict__)
    env = QuadFaultEnv("irls", "combined", duration=20.0)
    env.reset(seed=0)
    for _ in range(150):
        env.step(np.zeros(4, dtype=np.float32))
    renderers = {rev: module.FlightRenderer(env.vehicle), "current": FlightRenderer(env.vehicle)}
    best = {name: np.inf for name in renderers}
    for r in renderers.values():
        r.draw(env)
    for _ in range(rounds):
        for name, r in renderers.items():
            c = time.process_time()
            for _ in range(frames):
                r.draw(env)
            best[name] = min(best[name], (time.process_time() - c) / frames)
    print(
        f"renderer of {rev} {best[rev] * 1e3:.1f} ms, current {best['current'] * 1e3:.1f} ms "
        f"CPU per frame: {best[rev] / best['current']:.1f}x ({_load()})"
    )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=300, help="frames (control steps, default 300)")
    p.add_argument("--rounds", type=int, default=3, help="interleaved rounds of parts 2 and 3")
    p.add_argument(
        "--reference",
        metavar="REV",
        help="also time the renderer of git revision REV against the current one",
    )
    args = p.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    states = user_path(args.steps)
    side_by_side(states, args.rounds)
    if args.reference:
        against_revision(args.reference, args.rounds)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
