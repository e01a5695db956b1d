"""Speed (and, optionally, accuracy) of the sliding-window IRLS estimator.

Measures, side by side in one run on the same recording:

* window updates per second of the numpy path and of the compiled numba path (``run``,
  one window per sample), and their ratio; compile/cache-load time is reported apart;
* the compiled EKF against the compiled IRLS on the same recording (updates/s, alternating
  repeats, median), and their ratio (target: EKF at least as fast);
* the single compiled estimator's online ``update()`` (one sample per call, what the
  environment runs at every physics substep) against its offline ``run()``, with the reference
  and the improved settings (``IRLSConfig.improved()``), alternating;
* the batched IRLS (``estimators.batched.BatchedIRLS``, N vehicles per call, target 100,000
  window updates/s at N = 4096) with the reference and the improved settings side by side,
  against the single compiled estimator's online ``update``;
* with ``--accuracy``: RMSE / std / spike per scenario (degradation, abrupt, combined, 80 s,
  sigma_f = 0.07) with the numba path, scored by :mod:`estimators.metrics`.

Simulated recordings are cached in ``--cache`` (default /tmp/quadfault-bench), since an 80 s
flight takes a while on the numpy simulator.

    python benchmarks/bench_irls.py                     # speed on 80 s combined
    python benchmarks/bench_irls.py --duration 20 --batch 4096   # shorter, batch size
    python benchmarks/bench_irls.py --accuracy          # + accuracy table
    python benchmarks/bench_irls.py --integrator reference --accuracy
    python benchmarks/bench_irls.py --only online --only batched   # online and batched parts
    python benchmarks/bench_irls.py --only online --baseline ec394f0  # vs an older update()
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
    import estimators

    print(f"estimators from {os.path.dirname(estimators.__file__)}")
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


def _median_rate(fn, count: int, repeat: int):
    """Median over ``repeat`` calls of ``(count / wall s, count / CPU s)``."""
    rates = []
    for _ in range(repeat):
        _, wall, cpu = _timed(fn)
        rates.append((count / wall, count / max(cpu, 1e-9)))
    walls, cpus = zip(*rates)
    return float(np.median(walls)), float(np.median(cpus))


def ekf_vs_irls(rec, repeat: int) -> None:
    """Compiled EKF and compiled IRLS on the same recording, alternating, median rates."""
    from estimators.ekf import EKFConfig, MotorEfficiencyEKF

    if not numba_available():
        print("ekf vs irls: numba not installed")
        return
    rec = rec.without_truth()
    ekf = MotorEfficiencyEKF(rec.vehicle, EKFConfig(backend="numba"))
    irls = SlidingWindowIRLS(rec.vehicle, IRLSConfig(backend="numba"))
    ekf.run(rec.slice(0, 30))  # compile / load the cache
    irls.run(rec.slice(0, 30))
    res = {"ekf": [], "irls": []}
    for _ in range(repeat):  # alternate, so both see the same machine load
        for name, est in (("ekf", ekf), ("irls", irls)):
            res[name].append(_median_rate(lambda e=est: e.run(rec), len(rec), 1))
    print(f"\ncompiled EKF vs compiled IRLS, run() on {len(rec)} samples, median of {repeat} "
          f"alternating runs (load average {os.getloadavg()[0]:.1f})")
    med = {k: (np.median([r[0] for r in v]), np.median([r[1] for r in v])) for k, v in res.items()}
    for name in ("ekf", "irls"):
        print(f"{name:5s}: {med[name][0]:10.0f} updates/s wall, {med[name][1]:10.0f} per CPU-s")
    print(f"ratio EKF / IRLS: {med['ekf'][0] / med['irls'][0]:.2f} (wall), "
          f"{med['ekf'][1] / med['irls'][1]:.2f} (CPU)")


def baseline_estimator(rev: str):
    """``SlidingWindowIRLS`` of ``estimators/irls.py`` at git revision ``rev`` (run against
    today's other modules and compiled kernels), to time an older online path side by side."""
    import subprocess
    import sys
    import types

    repo = Path(__file__).resolve().parent.parent
    src = subprocess.run(["git", "-C", str(repo), "show", f"{rev}:estimators/irls.py"],
                         capture_output=True, text=True, check=True).stdout
    mod = types.ModuleType("_irls_baseline")
    sys.modules[mod.__name__] = mod
    code = compile(src, f"{rev}:estimators/irls.py", "exec")
    exec(code, mod.__dict__)  # noqa: S102 -- this repository's own history
    return mod


def online(rec, updates: int, repeat: int, baseline: str | None = None) -> None:
    """The single estimator's online ``update()`` (one sample per call, as the environment at
    every physics substep) against its offline ``run()``, numba path, reference and improved
    settings, alternating; median rates. With ``baseline`` (a git revision), the online
    update of that revision's ``estimators/irls.py`` (reference settings) in the same loop."""
    from estimators.base import samples

    if not numba_available():
        print("online: numba not installed")
        return
    rec = rec.without_truth()
    sub = rec.slice(0, updates + 9)
    rows = list(samples(sub))
    variants = (("reference", IRLSConfig(backend="numba")),
                ("improved", IRLSConfig.improved(backend="numba")))
    ests = {name: SlidingWindowIRLS(rec.vehicle, cfg) for name, cfg in variants}
    if baseline:
        old = baseline_estimator(baseline)
        ests[f"@{baseline}"] = old.SlidingWindowIRLS(rec.vehicle, old.IRLSConfig(backend="numba"))
        variants = variants + ((f"@{baseline}", None),)
    for est in ests.values():  # compile / load the cache outside the timing
        for s in rows[:30]:
            est.update(s)
        est.run(rec.slice(0, 30))

    def run_online(est):
        est.reset()
        for s in rows:
            est.update(s)

    res = {}
    for _ in range(repeat):  # alternate, so all see the same machine load
        for name, est in ests.items():
            res.setdefault((name, "update"), []).append(
                _median_rate(lambda e=est: run_online(e), len(rows), 1))
            res.setdefault((name, "run"), []).append(
                _median_rate(lambda e=est: e.run(sub), len(rows), 1))
    if baseline:
        etas = []
        for name in ("reference", f"@{baseline}"):
            ests[name].reset()
            etas.append(np.array([ests[name].update(s).eta for s in rows]))
        print(f"max |update() - update()@{baseline}| (reference settings): "
              f"{np.max(np.abs(etas[0] - etas[1])):.1e}")
    print(f"\nsingle IRLS online update() vs offline run(), {len(rows)} samples, median of "
          f"{repeat} alternating runs (load average {os.getloadavg()[0]:.1f})")
    med = {k: (np.median([r[0] for r in v]), np.median([r[1] for r in v]))
           for k, v in res.items()}
    for name, _cfg in variants:
        up, off = med[(name, "update")], med[(name, "run")]
        print(f"{name:9s} update(): {up[0]:8.0f} updates/s wall, {up[1]:8.0f} per CPU-s; "
              f"run(): {off[0]:8.0f} /s wall, {off[1]:8.0f} per CPU-s; "
              f"update / run {up[1] / off[1]:.2f} (CPU)")
    if baseline:
        new, old = med[("reference", "update")], med[(f"@{baseline}", "update")]
        print(f"ratio update() now / @{baseline}: {new[0] / old[0]:.1f}x wall, "
              f"{new[1] / old[1]:.1f}x per CPU-s")


def batched(rec, N: int, updates: int, repeat: int, start: float = 0.0) -> None:
    """BatchedIRLS at N vehicles, reference and improved settings (alternating, median), vs
    the single compiled estimator's online update, same samples. All rows fly the same
    flight from ``start`` [s] (a fault edge in range makes every row's change completion
    start at once: the improved variant's worst case)."""
    from estimators.base import samples
    from estimators.batched import CODE, BatchedIRLS

    if not numba_available():
        print("batched: numba not installed")
        return
    import numba

    rec = rec.without_truth()
    k0 = int(np.searchsorted(rec.t, rec.t[0] + start))
    warm = 22  # untimed: 12 samples fill the windows, 10 solve (compile / load the cache)
    rows = list(samples(rec.slice(k0, k0 + warm + repeat * updates)))
    rng = np.random.default_rng(0)

    def tile(x):
        return np.broadcast_to(np.asarray(x, float), (N,) + np.shape(x))

    batches = [(np.full(N, s.t), tile(s.p) + 1e-4 * rng.standard_normal((N, 3)), tile(s.v),
                tile(s.R), tile(s.w), tile(s.f)) for s in rows]
    variants = (("reference", IRLSConfig(backend="numba")),
                ("improved", IRLSConfig.improved(backend="numba")))
    ests = {name: BatchedIRLS(rec.vehicle, N, cfg) for name, cfg in variants}
    solved = {name: [0, 0] for name in ests}
    slowest = {name: 0.0 for name in ests}

    def run_batch(name, chunk):
        for b in chunk:
            w0 = time.perf_counter()
            out = ests[name].update(*b)
            slowest[name] = max(slowest[name], time.perf_counter() - w0)
            solved[name][0] += int(np.sum((out.status == CODE['ok'])
                                          | (out.status == CODE['max_iter'])))
            solved[name][1] += N

    for name in ests:  # fill the windows and compile / load the cache outside the timing
        run_batch(name, batches[:warm])
        solved[name], slowest[name] = [0, 0], 0.0
    res = {name: [] for name in ests}
    for r in range(repeat):  # each repeat continues the flights with the next samples
        chunk = batches[warm + r * updates:warm + (r + 1) * updates]
        for name in ests:
            res[name].append(_median_rate(lambda n=name, c=chunk: run_batch(n, c), N * updates,
                                          1))
    single = SlidingWindowIRLS(rec.vehicle, IRLSConfig(backend="numba"))

    def run_single():
        single.reset()
        for s in rows:
            single.update(s)

    run_single()
    sw, sc = _median_rate(run_single, len(rows), repeat)
    events = ests["improved"]._completion.events
    print(f"\nbatched IRLS, N = {N}, timed from {rows[warm].t:.3f} s, {updates} updates per run, "
          f"change completions started: {int(events.sum())} in {int(np.sum(events > 0))} rows; "
          f"median of {repeat} "
          f"alternating runs, {numba.get_num_threads()} numba threads "
          f"(load average {os.getloadavg()[0]:.1f})")
    med = {k: (np.median([r[0] for r in v]), np.median([r[1] for r in v]))
           for k, v in res.items()}
    for name in ests:
        ok = solved[name][0] / max(solved[name][1], 1)
        print(f"batched {name:9s}: {med[name][0]:10.0f} window updates/s wall, "
              f"{med[name][1]:10.0f} per CPU-s ({ok:.0%} solved ok; slowest update "
              f"{1e3 * slowest[name]:.0f} ms wall)")
    print(f"single update()  : {sw:10.0f} window updates/s wall, {sc:10.0f} per CPU-s (online)")
    r, i = med["reference"], med["improved"]
    print(f"ratio batched improved / reference: {i[0] / r[0]:.2f} wall, {i[1] / r[1]:.2f} per "
          f"CPU-s; batched reference / single online: {r[0] / sw:.1f}x wall, {r[1] / sc:.1f}x "
          "per CPU-s")


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
    p.add_argument("--batch", type=int, default=4096, help="vehicles of the batched IRLS "
                   "(0: skip)")
    p.add_argument("--batch-updates", type=int, default=30)
    p.add_argument("--batch-start", type=float, default=0.0, help="time [s] the batched rows "
                   "start at (1.64 on the 20 s 'combined' flight: every row starts a change "
                   "completion at 1.672 s, inside the first timed run)")
    p.add_argument("--repeat", type=int, default=3, help="alternating runs of the side-by-side "
                   "comparisons (EKF/IRLS, online/offline, batched variants)")
    p.add_argument("--online-updates", type=int, default=5000,
                   help="samples of the online update() timing")
    p.add_argument("--baseline", metavar="REV", help="also time the online update of "
                   "estimators/irls.py at this git revision (e.g. ec394f0), side by side")
    p.add_argument("--only", choices=("speed", "ekf", "online", "batched"), action="append",
                   help="run only these parts (repeatable; default all)")
    args = p.parse_args()
    only = set(args.only or ("speed", "ekf", "online", "batched"))
    rec = cached_flight(args.scenario, args.duration, args.integrator, args.cache, args.seed)
    if "speed" in only:
        speed(rec, args.numpy_windows)
    if "ekf" in only:
        ekf_vs_irls(rec, args.repeat)
    if "online" in only:
        online(rec, args.online_updates, args.repeat, args.baseline)
    if args.batch > 0 and "batched" in only:
        batched(rec, args.batch, args.batch_updates, args.repeat, args.batch_start)
    if args.accuracy:
        accuracy(args)


if __name__ == "__main__":
    main()
