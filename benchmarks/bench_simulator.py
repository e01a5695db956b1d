"""Single-vehicle closed-loop simulation speed at 1 kHz, and the compile time of its kernels.

Times :func:`quadfault.sim.simulator.simulate` (the paper's 80 s ``combined`` flight by default,
the geometric controller in the loop; best of ``--repeat``), a flight with effects (drag and
motor lag, compiled into the loop's effect chain; after a warm-up flight with the same
effects, best of ``--repeat``) and the cold start: the
first 10 ms flight in a fresh process with an empty numba cache (CPU seconds: the compile,
which a busy machine does not inflate as much as the wall time).

With ``--baseline PATH`` (another checkout of the project, e.g. ``git worktree add
../qf-base <commit>``) every number is measured in both, rounds alternated, and the table
gives the ratio (baseline / this checkout: above 1 = this checkout is faster).

    python benchmarks/bench_simulator.py
    python benchmarks/bench_simulator.py --baseline ../qf-base --rounds 3
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time


def flights(
    duration: float = 80.0,
    effects_duration: float = 4.0,
    repeat: int = 3,
    scenario: str = "combined",
) -> dict:
    """Wall seconds of the timed flights (each after a warm-up flight that compiles or loads
    its kernels)."""
    from quadfault.model.effects import parse_effect
    from quadfault.model.scenarios import named_scenario
    from quadfault.sim.simulator import simulate

    simulate(named_scenario(scenario, 0.01))  # compile or load the cache
    sc = named_scenario(scenario, duration)
    best = float("inf")
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        simulate(sc, seed=0)
        best = min(best, time.perf_counter() - t0)
    fx = (parse_effect("drag=0.3"), parse_effect("motor_lag=0.04"))
    sc_fx = named_scenario("lissajous", effects_duration)
    simulate(named_scenario("lissajous", 0.01), seed=4, effects=fx)  # its chain compiled
    best_fx = float("inf")
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        simulate(sc_fx, seed=4, effects=fx)
        best_fx = min(best_fx, time.perf_counter() - t0)
    return {
        "flight_s": best,
        "steps": round(duration / 1e-3),
        "effects_flight_s": best_fx,
        "effects_steps": round(effects_duration / 1e-3),
    }


def cold_start(scenario: str = "combined") -> dict:
    """CPU seconds of the first 10 ms flight with an empty numba cache (set by the caller's
    environment: ``NUMBA_CACHE_DIR``)."""
    from quadfault.model.scenarios import named_scenario
    from quadfault.sim.simulator import simulate

    c0, w0 = time.process_time(), time.perf_counter()
    simulate(named_scenario(scenario, 0.01))
    return {"cold_cpu_s": time.process_time() - c0, "cold_wall_s": time.perf_counter() - w0}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="combined", help="named scenario (default combined)")
    p.add_argument("--duration", type=float, default=80.0, help="flight time [s] (80)")
    p.add_argument("--repeat", type=int, default=3, help="timed flights per round (3)")
    p.add_argument("--baseline", default=None, help="another checkout, measured side by side")
    p.add_argument("--rounds", type=int, default=3, help="alternated rounds with --baseline")
    args = p.parse_args(argv)
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import side_by_side as sbs

    kw = dict(duration=args.duration, repeat=args.repeat, scenario=args.scenario)
    if args.baseline:
        now, base = sbs.compare(args.baseline, "bench_simulator", "flights", args.rounds, **kw)
        cold = [
            sbs.compare(
                args.baseline,
                "bench_simulator",
                "cold_start",
                1,
                env={"NUMBA_CACHE_DIR": tempfile.mkdtemp(prefix="qf-cold-")},
                scenario=args.scenario,
            )
            for _ in range(args.rounds)
        ]
        now.update({k: min(c[0][k] for c in cold) for k in cold[0][0]})
        base.update({k: min(c[1][k] for c in cold) for k in cold[0][1]})
    else:
        now, base = sbs.measure(sbs.ROOT, "bench_simulator", "flights", **kw), None
        now.update(
            sbs.measure(
                sbs.ROOT,
                "bench_simulator",
                "cold_start",
                env={"NUMBA_CACHE_DIR": tempfile.mkdtemp(prefix="qf-cold-")},
                scenario=args.scenario,
            )
        )
    print(
        f"# simulate(), scenario {args.scenario}, dt = 1 ms; {sbs.load()} on {os.cpu_count()} cpus"
    )
    rows = [
        ("flight", f"{args.duration:g} s flight [s]", now["flight_s"], base and base["flight_s"]),
        (
            "us/step",
            "microseconds per step",
            1e6 * now["flight_s"] / now["steps"],
            base and 1e6 * base["flight_s"] / base["steps"],
        ),
        (
            "effects",
            f"lissajous {now['effects_steps'] / 1e3:g} s with drag + motor lag [s]",
            now["effects_flight_s"],
            base and base["effects_flight_s"],
        ),
        (
            "cold",
            "first flight, empty numba cache [CPU s]",
            now["cold_cpu_s"],
            base and base["cold_cpu_s"],
        ),
    ]
    if base:
        print("| measure | baseline | this checkout | baseline / this |\n|---|---|---|---|")
        for _, label, x, y in rows:
            print(f"| {label} | {y:.4g} | {x:.4g} | {y / x:.2f}x |")
    else:
        print("| measure | value |\n|---|---|")
        for _, label, x, _ in rows:
            print(f"| {label} | {x:.4g} |")
    print(f"real-time factor: {args.duration / now['flight_s']:.0f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
