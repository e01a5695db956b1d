"""Speed of the estimators, optionally side by side with another checkout of this repository.

Workloads (each on the same cached recording, 80 s of the combined scenario by default):

* ``run``: ``SlidingWindowIRLS.run()`` over the whole flight (one window per sample);
* ``online`` / ``online_improved``: the single estimator's ``update()``, one sample per call (what
  the environment runs at every physics substep), reference and ``IRLSConfig.improved()``;
* ``ekf``: ``MotorEfficiencyEKF.run()`` over the whole flight;
* ``ekf_accel`` (only when asked, ``--only ekf_accel``: a checkout without the option cannot
  run it): the same with ``EKFConfig(accelerometer="on")``, its CPU time per update then
  given relative to the EKF's;
* ``rls`` / ``ukf``: ``RecursiveLeastSquares.run()`` / ``UnscentedKalmanFilter.run()`` over
  the whole flight; the table then gives each one's CPU time per update relative to the
  EKF's, measured in the same process;
* ``batched`` / ``batched_improved``: ``BatchedIRLS.update()`` at N vehicles (default 4096);
* with ``--cold``: the time of the first call of each workload on a fresh numba cache (compile).

Each measurement runs in its own process (the fastest of ``--inner`` passes after a warm-up
pass). With ``--reference DIR`` (a checkout of another
commit, e.g. ``git worktree add ../qf-ref <commit>``) the same workloads run with that
checkout's code, alternating with this one's, ``--repeat`` times; the table gives the median
rates of both and their ratio (above 1: this checkout is faster), and the load average
before and after.

    python benchmarks/bench_irls.py                                   # this checkout
    python benchmarks/bench_irls.py --reference ../qf-ref --cold      # side by side
    python benchmarks/bench_irls.py --only run --only ekf --duration 20
    python benchmarks/bench_irls.py --accuracy --no-speed             # the accuracy table
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
WORKLOADS = ("run", "online", "online_improved", "ekf", "rls", "ukf", "batched", "batched_improved")
#: workloads run only when asked (``--only``)
ASKED = ("ekf_accel",)


def cached_flight(
    scenario: str, duration: float, integrator: str, cache: Path, seed: int = 0, paper: bool = False
) -> Path:
    """The recording's path, simulated on first use (``paper``: ``quadfault reproduce``'s
    settings, sigma_f = 0.07 and no upper thrust limit except in ``clipping``)."""
    from quadfault.io.recording import write_recording
    from quadfault.model.scenarios import named_scenario
    from quadfault.sim.simulator import SimConfig, simulate

    cache.mkdir(parents=True, exist_ok=True)
    tag = "_paper" if paper else ""
    path = cache / f"{scenario}_{duration:g}s_{integrator}{tag}_seed{seed}.csv"
    if not path.exists():
        kw = {}
        if paper:
            from estimators.paper.reproduce import sim_config

            cfg, kw = sim_config(integrator, scenario), {"thrust_noise": 0.07}
        else:
            cfg = SimConfig.reference() if integrator == "reference" else SimConfig()
        write_recording(
            simulate(named_scenario(scenario, duration), config=cfg, seed=seed, **kw), path
        )
    return path


# ------------------------------------------------------------------------------------------
# the child: one checkout's code, one set of measurements, JSON on stdout
def _timed(fn):
    w0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w0, time.process_time() - c0


def _workload(name: str, rec, args):
    """``(count, fn)``: a callable doing ``count`` updates of workload ``name``."""
    from estimators.base import samples
    from estimators.irls import IRLSConfig, SlidingWindowIRLS

    veh = rec.vehicle
    cfg = IRLSConfig.improved() if name.endswith("improved") else IRLSConfig()
    if name == "run":
        est = SlidingWindowIRLS(veh, cfg)
        return len(rec), lambda: est.run(rec)
    if name in ("ekf", "ekf_accel"):
        from estimators.ekf import EKFConfig, MotorEfficiencyEKF

        ekf = MotorEfficiencyEKF(veh, EKFConfig(accelerometer="on") if name != "ekf" else None)
        return len(rec), lambda: ekf.run(rec)
    if name in ("rls", "ukf"):
        from estimators.rls import RecursiveLeastSquares
        from estimators.ukf import UnscentedKalmanFilter

        est = {"rls": RecursiveLeastSquares, "ukf": UnscentedKalmanFilter}[name](veh)
        return len(rec), lambda: est.run(rec)
    if name.startswith("online"):
        rows = list(samples(rec.slice(0, min(len(rec), args.online_updates + 9))))
        est = SlidingWindowIRLS(veh, cfg)

        def online():
            est.reset()
            for s in rows:
                est.update(s)

        return len(rows), online
    if name.startswith("batched"):
        from estimators.batched import BatchedIRLS

        N = args.batch
        rows = list(samples(rec.slice(0, 12 + args.batch_updates)))
        rng = np.random.default_rng(0)

        def tile(x):
            return np.broadcast_to(np.asarray(x, float), (N,) + np.shape(x))

        batches = [
            (
                np.full(N, s.t),
                tile(s.p) + 1e-4 * rng.standard_normal((N, 3)),
                tile(s.v),
                tile(s.R),
                tile(s.w),
                tile(s.f),
            )
            for s in rows
        ]
        est = BatchedIRLS(veh, N, cfg)

        def batched():
            est.reset()
            for b in batches:
                est.update(*b)

        return N * len(batches), batched
    raise SystemExit(f"unknown workload {name!r}")


def child(args) -> None:
    from quadfault.io.recording import read_recording

    rec = read_recording(args.recording).without_truth()
    out = {}
    for name in args.only:
        if args.cold:  # first call on a fresh cache: compile (a short slice: little else)
            count, fn = _workload(name, rec.slice(0, 60), args)
            out[name] = _timed(fn)[0]
            continue
        count, fn = _workload(name, rec, args)
        _count, warm = _workload(name, rec.slice(0, 60), args)
        warm()  # compile / load the cache outside the timing
        fn()  # first pass: page in the data
        wall, cpu = min(_timed(fn) for _ in range(args.inner))  # the least disturbed pass
        out[name] = {"wall": count / wall, "cpu": count / max(cpu, 1e-9), "seconds": wall}
    print(json.dumps(out))


# ------------------------------------------------------------------------------------------
# the parent: alternate checkouts, print medians and ratios
def _run_child(checkout: Path, args, cold: bool, asked: bool = True) -> dict:
    """One child process on ``checkout``; ``asked``: also the workloads run only when asked
    (:data:`ASKED`; another checkout may not have them)."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    cmd = [
        sys.executable,
        str(Path(__file__).resolve()),
        "--child",
        "--recording",
        str(args.recording),
        "--batch",
        str(args.batch),
        "--batch-updates",
        str(args.batch_updates),
        "--online-updates",
        str(args.online_updates),
        "--inner",
        str(args.inner),
    ]
    for name in args.only:
        if asked or name not in ASKED:
            cmd += ["--only", name]
    with tempfile.TemporaryDirectory() as cache:
        if cold:
            cmd.append("--cold")
            env["NUMBA_CACHE_DIR"] = cache
        r = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=checkout, check=False)
    if r.returncode != 0:
        raise SystemExit(f"{checkout}: benchmark child failed:\n{r.stderr[-2000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def _load() -> str:
    return "load average " + ", ".join(f"{x:.1f}" for x in os.getloadavg())


def side_by_side(args) -> None:
    checkouts = {"this": ROOT}
    if args.reference:
        checkouts["reference"] = Path(args.reference).resolve()
    print(f"recording {args.recording}; {_load()} on {os.cpu_count()} CPUs")
    for name, path in checkouts.items():
        print(f"  {name:9s} = {path}")
    if args.cold:
        cold = {k: [] for k in checkouts}
        for _ in range(args.cold_repeat):
            for k, path in checkouts.items():
                cold[k].append(_run_child(path, args, cold=True, asked=k == "this"))
        print(
            f"\ncold compile: first call on an empty numba cache [s], median of "
            f"{args.cold_repeat} ({_load()})"
        )
        _table(cold, lambda v: v, "{:8.1f}", lower_is_better=True)
    res = {k: [] for k in checkouts}
    for _ in range(args.repeat):
        for k, path in checkouts.items():
            res[k].append(_run_child(path, args, cold=False, asked=k == "this"))
    print(
        f"\nupdates per second (wall clock), median of {args.repeat} alternating runs ({_load()})"
    )
    _table(res, lambda v: v["wall"], "{:10.0f}")
    print(f"\nupdates per CPU-second, median of {args.repeat}")
    _table(res, lambda v: v["cpu"], "{:10.0f}")
    if "ekf" in args.only:
        for k, runs in res.items():
            ratios = [
                f"{w} {np.median([r['ekf']['cpu'] / r[w]['cpu'] for r in runs]):.2f}x"
                for w in ("rls", "ukf", "ekf_accel")
                if w in args.only and w in runs[0]
            ]
            if ratios:
                print(
                    f"\nCPU time per update relative to the EKF ({k}), median of "
                    f"{args.repeat}: " + ", ".join(ratios)
                )
    if "run" in args.only:
        secs = {k: np.median([r["run"]["seconds"] for r in v]) for k, v in res.items()}
        print(
            "\nrun() of the whole flight: " + ", ".join(f"{k} {s:.2f} s" for k, s in secs.items())
        )


def _table(res: dict, value, fmt: str, lower_is_better: bool = False) -> None:
    names = list(res)
    better = "< 1: this is faster" if lower_is_better else "> 1: this is faster"
    print(
        f"{'workload':18s}"
        + "".join(f"{n:>12s}" for n in names)
        + (f"   this/reference ({better})" if len(names) > 1 else "")
    )
    total = {n: 0.0 for n in names}
    for w in res[names[0]][0]:
        have = [n for n in names if w in res[n][0]]  # (ASKED: this checkout only)
        med = {n: float(np.median([value(r[w]) for r in res[n]])) for n in have}
        for n in have:
            total[n] += med[n] if len(have) == len(names) else 0.0
        line = f"{w:18s}" + "".join(
            f"{fmt.format(med[n]) if n in med else '-':>12s}" for n in names
        )
        if len(have) > 1:
            line += f"   {med['this'] / med['reference']:.2f}"
        print(line)
    if lower_is_better:
        line = f"{'total':18s}" + "".join(f"{fmt.format(total[n]):>12s}" for n in names)
        if len(names) > 1:
            line += f"   {total['this'] / total['reference']:.2f}"
        print(line)


def accuracy(args) -> None:
    from estimators.irls import SlidingWindowIRLS
    from estimators.metrics import score
    from quadfault.io.recording import read_recording

    print(
        f"\naccuracy (80 s, quadfault reproduce's flights: sigma_f = 0.07, integrator "
        f"{args.integrator}, seed {args.seed}, align=end; mean over motors)"
    )
    print(f"{'scenario':12s} {'rmse':>7s} {'std':>7s} {'spike':>7s} {'ok %':>6s} {'s':>6s}")
    for name in ("degradation", "abrupt", "combined"):
        rec = read_recording(
            cached_flight(name, 80.0, args.integrator, args.cache, args.seed, paper=True)
        )
        series = SlidingWindowIRLS(rec.vehicle).run(rec.without_truth())
        sc = score(rec, series)
        spikes = [s for s in (sc.spike or ()) if s is not None]
        spike = f"{np.mean(spikes):.4f}" if spikes else "-"
        ok = 100 * np.mean(series.status == "ok")
        print(
            f"{name:12s} {np.mean(sc.rmse):7.4f} {np.mean(sc.std):7.4f} {spike:>7s} "
            f"{ok:6.1f} {series.seconds:6.2f}"
        )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--reference", metavar="DIR", help="another checkout to time side by side")
    p.add_argument("--scenario", default="combined")
    p.add_argument("--duration", type=float, default=80.0)
    p.add_argument("--integrator", choices=("rk4", "reference"), default="rk4")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "quadfault-bench")
    p.add_argument("--batch", type=int, default=4096, help="vehicles of the batched IRLS")
    p.add_argument("--batch-updates", type=int, default=30)
    p.add_argument("--online-updates", type=int, default=5000)
    p.add_argument("--repeat", type=int, default=3, help="alternating processes per checkout")
    p.add_argument(
        "--inner", type=int, default=3, help="timed passes per process (the fastest counts)"
    )
    p.add_argument(
        "--cold",
        action="store_true",
        help="also time the first calls on an empty numba cache (compile time)",
    )
    p.add_argument("--cold-repeat", type=int, default=1)
    p.add_argument(
        "--only",
        choices=WORKLOADS + ASKED,
        action="append",
        help="these workloads only (repeatable; default all)",
    )
    p.add_argument("--accuracy", action="store_true", help="also print the accuracy table")
    p.add_argument("--no-speed", action="store_true", help="skip the speed measurements")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--recording", type=Path, help=argparse.SUPPRESS)
    args = p.parse_args()
    args.only = list(args.only or WORKLOADS)
    if args.child:
        child(args)
        return
    args.recording = cached_flight(
        args.scenario, args.duration, args.integrator, args.cache, args.seed
    )
    if not args.no_speed:
        side_by_side(args)
    if args.accuracy:
        accuracy(args)


if __name__ == "__main__":
    main()
