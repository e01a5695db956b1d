"""Cost of the estimate-aware allocation per control step, next to the nominal inverse.

    python benchmarks/bench_allocation.py

Prints microseconds per call for each allocation mode and the ratio to ``A^-1 w`` measured
in the same run (a 1 kHz loop has 1000 us per step).
"""

from __future__ import annotations

import time

import numpy as np

from quadfault.model.allocation import EstimateAwareAllocator
from quadfault.model.vehicle import Vehicle


def per_call(fn, n=2000) -> float:
    fn()
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - t0) / n * 1e6


def main() -> int:
    veh = Vehicle()
    alloc = EstimateAwareAllocator(veh)
    hover = np.array([veh.weight, 0.0, 0.0, 0.0])
    cases = {
        "exact (eta = 0.7 on motor 1)": (hover, np.array([0.7, 1, 1, 1.0])),
        "yaw released (eta = 0.3)": (hover, np.array([0.3, 1, 1, 1.0])),
        "weighted lsq (two motors at 0.2, 18 N)": (
            np.array([18.0, 0, 0, 0]),
            np.array([0.2, 0.2, 1, 1.0]),
        ),
    }
    base = per_call(lambda: veh.rotor_thrust(hover))
    print(f"{'nominal inverse A^-1 w':42s} {base:8.1f} us   1.0x")
    for name, (w, eta) in cases.items():
        mode = alloc.allocate(w, eta).mode
        us = per_call(lambda w=w, eta=eta: alloc.allocate(w, eta))
        print(f"{name:42s} {us:8.1f} us {us / base:6.1f}x  [{mode}]")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
