"""Single-vehicle closed-loop simulation speed at 1 kHz, controller included: numpy vs numba.

Both backends of :func:`quadfault.simulator.simulate` fly the same scenario in one run; the
table gives steps per second, microseconds per step, the ratio to real time and the ratio
between the two paths. The numba JIT cost (compile, or load from numba's on-disk cache) is
measured separately on a 10 ms flight and is not part of the timed runs. ``--cold`` points
numba at an empty cache directory so the first call really compiles.

    python benchmarks/bench_simulator.py                      # 80 s numba, 5 s numpy flight
    python benchmarks/bench_simulator.py --cold --numpy-duration 10
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from dataclasses import replace


def _parse(argv):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="combined", help="named scenario (default: combined)")
    p.add_argument("--duration", type=float, default=80.0,
                   help="flight time of the numba run [s] (default 80, the paper's flight)")
    p.add_argument("--numpy-duration", type=float, default=5.0,
                   help="flight time of the numpy run [s] (default 5; ~0.5-1 ms per step)")
    p.add_argument("--repeat", type=int, default=3, help="numba runs, best kept (default 3)")
    p.add_argument("--sensor-noise", action="store_true", help="add white sensor noise")
    p.add_argument("--integrator", choices=("rk4", "reference"), default="rk4")
    p.add_argument("--cold", action="store_true",
                   help="use an empty numba cache so the JIT compile time is measured")
    return p.parse_args(argv)


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def main(argv=None) -> int:
    args = _parse(argv)
    if args.cold:  # must be set before numba is imported
        os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="quadfault-numba-")
    import numpy as np

    from quadfault import _sim_numba
    from quadfault.scenarios import named_scenario
    from quadfault.simulator import SensorNoise, SimConfig, simulate

    if not _sim_numba.AVAILABLE:
        print("numba is not installed: pip install 'quadfault[fast]'", file=sys.stderr)
        return 1
    base = SimConfig.reference() if args.integrator == "reference" else SimConfig()
    if args.sensor_noise:
        base = replace(base, sensor_noise=SensorNoise(0.01, 0.02, 0.003, 0.01, 0.05))
    cfg_np, cfg_nb = replace(base, backend="numpy"), replace(base, backend="numba")
    dt = base.dt

    _, jit = _timed(lambda: simulate(named_scenario(args.scenario, 0.01), config=cfg_nb))

    sc_np = named_scenario(args.scenario, args.numpy_duration)
    rec_np, t_np = _timed(lambda: simulate(sc_np, config=cfg_np, seed=0))
    # cross-check on the same flight: the two paths must agree
    rec_chk = simulate(sc_np, config=cfg_nb, seed=0)
    diff = max(float(np.max(np.abs(getattr(rec_np, k) - getattr(rec_chk, k))))
               for k in ("position", "velocity", "quaternion", "omega", "thrust_cmd"))

    sc_nb = named_scenario(args.scenario, args.duration)
    t_nb = min(_timed(lambda: simulate(sc_nb, config=cfg_nb, seed=0))[1]
               for _ in range(max(1, args.repeat)))

    rows = []
    for name, duration, wall in (("numpy", args.numpy_duration, t_np),
                                 ("numba", args.duration, t_nb)):
        steps = round(duration / dt)
        rows.append((name, duration, steps, wall, steps / wall, 1e6 * wall / steps,
                     duration / wall))
    print(f"closed-loop simulate(), scenario {args.scenario}, {args.integrator}, "
          f"dt = {dt * 1e3:g} ms, sensor noise {'on' if args.sensor_noise else 'off'}, "
          f"cpus {os.cpu_count()}")
    print(f"{'backend':8} {'flight [s]':>10} {'steps':>7} {'wall [s]':>9} {'steps/s':>10} "
          f"{'us/step':>8} {'x real time':>11}")
    for name, duration, steps, wall, sps, us, rt in rows:
        print(f"{name:8} {duration:10.1f} {steps:7d} {wall:9.3f} {sps:10.0f} {us:8.1f} {rt:11.1f}")
    print(f"numba / numpy speed-up: {rows[1][4] / rows[0][4]:.0f}x (steps/s ratio)")
    print(f"numba first call (10 ms flight, {'cold cache: JIT compile' if args.cold else 'JIT compile or cache load'}): "
          f"{jit:.2f} s (not in the timings above)")
    print(f"max |numba - numpy| over the {args.numpy_duration:g} s flight: {diff:.1e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
