"""What domain randomisation costs: the closed loop and the vector env with and without it.

Measured in one run, rounds interleaved (the ratios are what to compare; the machine may be
shared), at N vehicles (default 1024), with numba's default thread count (what a user gets):

1. ``quadfault.model.closed_loop.fly_batch`` with the geometric controller at every step, hovering
   vehicles with thrust noise: the nominal plant (no effects: the chain is compiled out)
   against every vehicle flying its own draw of mass, inertia, drag, motor lag and wind with
   gusts (``Plant.assign``: one row of the compiled effect chain per vehicle);
2. ``QuadFaultVectorEnv`` steps (no estimator, zero residual action) without and with the
   env keyword ``effects`` (the same ranges, drawn per sub-env at every reset).

The total against the nominal vehicles includes the physics of drag, lag and wind, which the
nominal vehicles do not fly. So each effect is also measured alone, (a) with the same
parameters for every vehicle (each range's midpoint) and (b) randomised per vehicle: (a)
against nominal is the cost of that physics, (b) against (a) the cost of randomising it.

Prints vehicle-steps per wall second and per CPU second of this process, the costs
(1 - variant / nominal) and the load average::

    python benchmarks/randomisation_cost.py            # N = 1024
    python benchmarks/randomisation_cost.py --n 256 --rounds 5
    python benchmarks/randomisation_cost.py --skip-env --ranges thrust_scale=1   # a no-op effect
    python benchmarks/randomisation_cost.py --total-only   # only the randomised set, no breakdown
    python benchmarks/randomisation_cost.py --baseline ../other-checkout --rounds 3

With ``--baseline`` (another checkout) the nominal and randomised rates are measured in both
checkouts, in fresh processes, alternated round by round (``benchmarks/side_by_side.py``),
and printed with their ratios this / baseline (above 1: this checkout is faster).
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "passive")  # as benchmarks/throughput.py

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

#: the randomised physics: ``quadfault simulate --effect`` specs with ``a:b`` ranges
RANGES = (
    "mass=0.8:1.2",
    "inertia=0.8:1.2,0.8:1.2,0.8:1.2",
    "drag=0.1:0.5",
    "motor_lag=0.01:0.05",
    "wind=-2:2,-2:2,0,gust=0.5",
)
RATE = 1000.0  # physics rate [Hz]
_RANGE = re.compile(r"(-?[0-9.]+(?:[eE][-+]?[0-9]+)?):(-?[0-9.]+(?:[eE][-+]?[0-9]+)?)")


def fixed(spec: str) -> str:
    """``spec`` with every range ``a:b`` replaced by its midpoint (every vehicle the same)."""
    return _RANGE.sub(lambda m: repr((float(m.group(1)) + float(m.group(2))) / 2), spec)


def _timed(fn, work: int, min_time: float) -> tuple[float, float]:
    """``work`` units per wall second and per CPU second of ``fn()`` repeated >= min_time."""
    calls, t0, c0 = 0, time.perf_counter(), time.process_time()
    while True:
        fn()
        calls += 1
        wall = time.perf_counter() - t0
        if wall >= min_time:
            break
    return work * calls / wall, work * calls / max(time.process_time() - c0, 1e-9)


def loop_batch(N: int, horizon: int, randomise: bool, ranges=RANGES):
    """``fn`` advancing N hovering vehicles by ``horizon`` physics steps with the controller in
    the loop (one ``fly_batch`` call); with ``randomise`` each vehicle flies its own draw of
    ``ranges`` (default :data:`RANGES`; a spec without ranges: every vehicle the same)."""
    from quadfault.model import closed_loop
    from quadfault.model.controller import GeometricController
    from quadfault.model.effects import parse_effect
    from quadfault.model.motors import MotorModel
    from quadfault.model.plant import Plant
    from quadfault.model.sensors import SensorNoise
    from quadfault.model.trajectory import Hover
    from quadfault.model.vehicle import Vehicle

    veh = Vehicle()
    plant = Plant(veh, MotorModel(0.07), dt=1.0 / RATE, n_vehicles=N)
    if randomise:
        rng = np.random.default_rng(1)
        for i in range(N):
            plant.assign(i, [parse_effect(s, rng) for s in ranges])
    V = plant.vehicles
    ctrl = GeometricController(veh, Hover(position=(0.0, 0.0, -1.0)))
    refs = np.zeros((N, horizon, 6, 3))
    refs[:, :, 0, 2], refs[:, :, 3, 0] = -1.0, 1.0  # hover at 1 m, heading north
    tables = closed_loop.Tables(np.zeros(N, np.int64), np.ones((N, horizon, 4)), refs)
    consts = closed_loop.constants(plant, SensorNoise(), 1)
    gens = closed_loop.generators([np.random.default_rng(i) for i in range(N)])
    active, k0 = np.ones(N, dtype=bool), np.zeros(N, dtype=np.int64)
    none = closed_loop.Records.none(N, 4)
    start = [x.copy() for x in V]

    def fn():
        for x, x0 in zip(V, start):  # every call flies the same `horizon` steps from hover
            x[...] = x0
        closed_loop.fly_batch(
            gens, active, k0, horizon, True, consts, V, tables, none, ctrl.constants, plant.hook
        )

    fn()  # compile (or load numba's cache)
    return fn


def env_batch(N: int, steps: int, randomise: bool, ranges=RANGES):
    """``fn`` stepping a reset ``QuadFaultVectorEnv`` (no estimator) ``steps`` times."""
    from quad_fault_env.vector import QuadFaultVectorEnv

    kw = {"effects": list(ranges)} if randomise else {}
    env = QuadFaultVectorEnv(N, "none", scenario="hover", duration=600.0, **kw)
    env.reset(seed=0)
    a = np.zeros((N, 4), dtype=np.float32)
    env.step(a)

    def fn():
        for _ in range(steps):
            env.step(a)

    return fn, env.substeps


def _best(variants: dict, work: dict, rounds: int, min_time: float) -> dict:
    """name -> best (wall, CPU) rate of each ``fn`` of ``variants``, rounds interleaved (load
    changes hit every variant alike)."""
    best = {key: (0.0, 0.0) for key in variants}
    for _ in range(rounds):
        for key, fn in variants.items():
            r = _timed(fn, work[key], min_time)
            best[key] = tuple(max(a, b) for a, b in zip(best[key], r))
    return best


def _cost(rate: float, base: float) -> str:
    return f"{100 * (1 - rate / base):5.1f} %"


def _report(name: str, best: dict, specs) -> None:
    """The total (the randomised set against nominal) and, per spec, the effect flown the
    same by every vehicle and randomised per vehicle (CPU rates)."""
    (w0, c0), (w1, c1) = best["nominal"], best["randomised"]
    print(f"{name}")
    print(f"  nominal     {w0:12.4g} vehicle-steps/s (wall)  {c0:12.4g} (CPU)")
    print(f"  randomised  {w1:12.4g} vehicle-steps/s (wall)  {c1:12.4g} (CPU)")
    print(f"  cost of randomisation: {_cost(w1, w0)} (wall)  {_cost(c1, c0)} (CPU)")
    if not specs:
        return
    print(
        "  per effect, vehicle-steps per CPU-s (cost against nominal, CPU ns added per "
        "vehicle-step; randomising: randomised against the same)"
    )
    print(f"    {'effect':34s} {'same for all':>28s} {'randomised':>28s} {'randomising':>11s}")
    for spec in (*specs, "all"):
        (_, a) = best[("same", spec)]
        (_, b) = best.get(("randomised", spec), (w1, c1) if spec == "all" else (0.0, a))
        cells = [f"{x:9.4g} ({_cost(x, c0)}, {1e9 / x - 1e9 / c0:+4.0f} ns)" for x in (a, b)]
        print(f"    {spec:34s} {cells[0]:>28s} {cells[1]:>28s} {_cost(b, a):>11s}")


def totals(n: int, horizon: int, steps: int, min_time: float, skip_env: bool) -> dict:
    """Vehicle-steps per wall and CPU second, nominal and randomised (:data:`RANGES`), of the
    closed loop and (unless ``skip_env``) the vector env: what ``--baseline`` compares."""
    out = {}
    for randomise in (False, True):
        kind = "randomised" if randomise else "nominal"
        fns = {"loop": (loop_batch(n, horizon, randomise), n * horizon)}
        if not skip_env:
            fn, substeps = env_batch(n, steps, randomise)
            fns["env"] = (fn, n * steps * substeps)
        for name, (fn, work) in fns.items():
            out[f"{name}_{kind}_wall"], out[f"{name}_{kind}_cpu"] = _timed(fn, work, min_time)
    return out


def _side_by_side(args) -> int:
    """``--baseline``: :func:`totals` in this checkout and the baseline, alternated."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import side_by_side as sbs

    kw = dict(n=args.n, horizon=args.horizon, steps=args.steps, min_time=args.min_time)
    now, base = sbs.compare(
        args.baseline,
        "randomisation_cost",
        "totals",
        args.rounds,
        better=max,
        skip_env=args.skip_env,
        **kw,
    )
    print(f"N = {args.n}, {args.rounds} alternated rounds (best of each); {sbs.load()}")
    print("| vehicle-steps per second | baseline | this checkout | this / baseline |")
    print("|---|---|---|---|")
    for key in now:
        print(f"| {key} | {base[key]:.4g} | {now[key]:.4g} | {now[key] / base[key]:.3f} |")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1024, help="vehicles (default 1024)")
    ap.add_argument("--horizon", type=int, default=100, help="physics steps per loop call")
    ap.add_argument("--steps", type=int, default=5, help="env steps per timing call")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds (best kept)")
    ap.add_argument("--min-time", type=float, default=0.5, help="seconds per timing")
    ap.add_argument("--skip-env", action="store_true", help="only the closed loop")
    ap.add_argument(
        "--total-only",
        action="store_true",
        help="only the randomised set against nominal (no per-effect breakdown)",
    )
    ap.add_argument(
        "--ranges",
        nargs="+",
        default=list(RANGES),
        metavar="SPEC",
        help="the randomised effects (--effect syntax with a:b ranges)",
    )
    ap.add_argument("--baseline", default=None, help="another checkout, measured side by side")
    args = ap.parse_args(argv)
    if args.baseline:
        return _side_by_side(args)

    import numba

    N, ranges = args.n, list(args.ranges)
    specs = [] if args.total_only or len(ranges) < 2 else ranges

    def variants(make):
        out = {"nominal": make(False, ranges), "randomised": make(True, ranges)}
        for spec in specs:
            out[("same", spec)] = make(True, [fixed(spec)])
            if fixed(spec) != spec:  # (a spec without ranges: the same, timed once)
                out[("randomised", spec)] = make(True, [spec])
        if specs:
            out[("same", "all")] = make(True, [fixed(s) for s in ranges])
        return out

    loops = variants(lambda r, x: loop_batch(N, args.horizon, r, x))
    print(
        f"N = {N}, physics {RATE:g} Hz, numba {numba.__version__}, "
        f"{numba.get_num_threads()} threads ({numba.threading_layer()}), "
        f"OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY')}, {os.cpu_count()} cpus"
    )
    print(f"randomised: {', '.join(ranges)}")
    if specs:
        print(f"the same for all: {', '.join(fixed(s) for s in ranges)}")
    print(f"load average before: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    _report(
        "closed loop + controller (fly_batch)",
        _best(loops, dict.fromkeys(loops, N * args.horizon), args.rounds, args.min_time),
        specs,
    )
    if not args.skip_env:
        envs = variants(lambda r, x: env_batch(N, args.steps, r, x))
        work = {key: N * args.steps * S for key, (_, S) in envs.items()}
        _report(
            "QuadFaultVectorEnv step (no estimator), effects= vs none",
            _best({key: fn for key, (fn, _) in envs.items()}, work, args.rounds, args.min_time),
            specs,
        )
    print(f"load average after: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
