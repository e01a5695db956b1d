"""Speed (and, optionally, accuracy) of the sliding-window IRLS estimator.

Measures, side by side in one run on the same recording:

* window updates per second of the numpy path and of the compiled numba path (``run``,
  one window per sample), and their ratio; compile/cache-load time is reported apart;
* with ``--accuracy``: RMSE / std / spike per scenario (degradation, abrupt, combined, 80 s,
  sigma_f = 0.07) with the numba path, scored by :mod:`estimators.metrics`.

Simulated recordings are cached in ``--cache`` (default /tmp/quadfault-bench), since an 80 s
flight takes a while on the numpy simulator.

    python benchmarks/bench_irls.py                     # speed on 80 s combined
    python benchmarks/bench_irls.py --accuracy          # + accuracy table
    python benchmarks/bench_irls.py --integrator reference --accuracy
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from estimators.irls import IRLSConfig, SlidingWindowIRLS, numba_available
from quadfault.recording import read_recording, write_recording
from quadfault.scenarios import named_scenario
from quadfault.simulator import SimConfig, simulate


def cached_flight(scenario: str, duration: float, integrator: str, cache: Path, seed: int = 0):
    cache.mkdir(parents=True, exist_ok=True)
    path = cache / f"{scenario}_{duration:g}s_{integrator}_seed{seed}.csv"
    if not path.exists():
        cfg = SimConfig.reference() if integrator == "reference" else SimConfig()
        rec = simulate(named_scenario(scenario, duration), config=cfg, seed=seed)
        write_recording(rec, path)
    return read_recording(path)


def _timed(fn):
    """``(result, wall seconds, CPU seconds of this process)``."""
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w0, time.process_time() - c0


def speed(rec, numpy_windows: int) -> None:
    print(f"recording: {len(rec)} samples ({rec.duration:.1f} s); load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs (CPU-time rates are less "
          "affected by a busy machine)")
    sub = rec.slice(0, numpy_windows + 9)
    est = SlidingWindowIRLS(rec.vehicle, IRLSConfig(backend="numpy"))
    _, wall, cpu = _timed(lambda: est.run(sub))
    numpy_rate = numpy_windows / wall
    print(f"numpy : {numpy_rate:10.0f} window updates/s wall, {numpy_windows / cpu:10.0f} per "
          f"CPU-s  ({numpy_windows} windows)")
    if not numba_available():
        print("numba : not installed (pip install -e '.[fast]')")
        return
    est = SlidingWindowIRLS(rec.vehicle, IRLSConfig(backend="numba"))
    _, wall, _ = _timed(lambda: est.run(rec.slice(0, 30)))
    print(f"numba : compile / cache load {wall:.2f} s")
    series, wall, cpu = _timed(lambda: est.run(rec))
    n_win = len(rec) - 9
    rate = n_win / wall
    print(f"numba : {rate:10.0f} window updates/s wall, {n_win / cpu:10.0f} per CPU-s  "
          f"({n_win} windows in {wall:.2f} s, including residual set-up)")
    print(f"ratio numba / numpy: {rate / numpy_rate:.0f}x")
    same = SlidingWindowIRLS(rec.vehicle, IRLSConfig(backend="numpy")).run(sub)
    diff = np.max(np.abs(same.eta - series.eta[:len(sub)]))
    print(f"max |numba - numpy| over the first {numpy_windows} windows: {diff:.2e}")


def accuracy(args) -> None:
    from estimators.metrics import score

    print(f"\naccuracy (80 s, sigma_f = 0.07, integrator {args.integrator}, seed {args.seed}, "
          f"align=end; mean over motors)")
    print(f"{'scenario':12s} {'rmse':>7s} {'std':>7s} {'spike':>7s} {'ok %':>6s} {'s':>6s}")
    for name in ("degradation", "abrupt", "combined"):
        rec = cached_flight(name, 80.0, args.integrator, args.cache, args.seed)
        series = SlidingWindowIRLS(rec.vehicle).run(rec.without_truth())
        sc = score(rec, series)
        spikes = [s for s in (sc.spike or ()) if s is not None]
        spike = f"{np.mean(spikes):.4f}" if spikes else "-"
        ok = 100 * np.mean(series.status == "ok")
        print(f"{name:12s} {np.mean(sc.rmse):7.4f} {np.mean(sc.std):7.4f} {spike:>7s} "
              f"{ok:6.1f} {series.seconds:6.2f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="combined")
    p.add_argument("--duration", type=float, default=80.0)
    p.add_argument("--integrator", choices=("rk4", "reference"), default="rk4")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--numpy-windows", type=int, default=2000)
    p.add_argument("--cache", type=Path, default=Path("/tmp/quadfault-bench"))
    p.add_argument("--accuracy", action="store_true")
    args = p.parse_args()
    rec = cached_flight(args.scenario, args.duration, args.integrator, args.cache, args.seed)
    speed(rec, args.numpy_windows)
    if args.accuracy:
        accuracy(args)


if __name__ == "__main__":
    main()
