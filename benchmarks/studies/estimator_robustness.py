"""Estimator robustness: degenerate windows and recovery after a burst of corrupted samples.

    python benchmarks/studies/estimator_robustness.py [--duration 3] [--burst 0.05] [--seed 0]

Both estimators (sliding-window IRLS and the EKF) are fed one measurement row at a time
(``update``), as the environment does, from a simulated circle flight with motor 2 at 70 %.

Degenerate windows (each reports the statuses seen, whether the previous estimate was kept
exactly, and whether any estimate was NaN):

* ``hover``: a steady noise-free hover with the commands that hold it at the true eta (no
  manoeuvre; eta is still observable through the allocation, so this must *not* be flagged
  and must converge);
* ``idle``: the same hover, then motors off (zero commanded thrust) at the same pose, as on
  the ground: no information on eta;
* ``rotor_off``: rotor 1 commanded 0 N (lower saturation) during the flight: its efficiency
  is unobservable;
* ``nan_rows``: dropped samples delivered as NaN rows;
* ``repeated_time``: a sample delivered twice (same time stamp);
* ``saturated`` (a separate flight): rotors limited to 3.2 N, so the weak motor's command
  stays far above its limit (the estimators clip commands to the limit; eta stays observable).

Recovery: a burst of ``--burst`` seconds at mid-flight is corrupted (``spikes``: position
+-0.5 m, velocity N(0, 2 m/s), rate N(0, 5 rad/s); ``nan``: NaN rows; ``frozen``: the sensors
repeat the last sample; ``gap``: the rows are missing). The recovery time is the time from the
end of the burst until the estimate stays within ``--tol`` (max over rotors) of the same
estimator's estimate on the clean flight.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from estimators.base import Sample, samples
from estimators.ekf import MotorEfficiencyEKF
from estimators.irls import SlidingWindowIRLS
from quadfault.errors import QuadfaultError
from quadfault.model.scenarios import ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Circle
from quadfault.sim.simulator import simulate

ESTIMATORS = {"irls": SlidingWindowIRLS, "ekf": MotorEfficiencyEKF}
ETA_TRUE = (1.0, 0.7, 1.0, 1.0)
BURSTS = ("spikes", "nan", "frozen", "gap")


def flight(duration: float = 3.0, seed: int = 0):
    """``(measurement samples, vehicle)`` of a circle flight with motor 2 at 70 %, 1 kHz."""
    sc = Scenario(
        "robustness",
        duration,
        EfficiencySchedule(ConstantEfficiency(ETA_TRUE)),
        Circle(),
        thrust_noise=0.02,
    )
    rec = simulate(sc, seed=seed).without_truth()
    return list(samples(rec)), rec.vehicle


def saturated_flight(duration: float = 3.0, seed: int = 0, max_thrust: float = 3.2):
    """The same flight on a vehicle whose rotors saturate at ``max_thrust`` [N]: the weak
    motor cannot deliver what the controller asks (its recorded command goes far above the
    limit). Returns ``(samples, vehicle, fraction of rows with a command at or above the
    limit)``."""
    from quadfault.model.vehicle import Vehicle

    sc = Scenario(
        "saturated",
        duration,
        EfficiencySchedule(ConstantEfficiency(ETA_TRUE)),
        Circle(),
        thrust_noise=0.02,
    )
    rec = simulate(sc, vehicle=Vehicle(max_thrust=max_thrust), seed=seed).without_truth()
    at_limit = np.any(rec.thrust_cmd >= rec.vehicle.rotor_max_thrust, axis=1)
    return list(samples(rec)), rec.vehicle, float(np.mean(at_limit))


def check_saturated(name, vehicle, stream):
    """Statuses, NaN anywhere, and the final error against the truth."""
    t, eta, status, err = run_stream(name, vehicle, stream)
    return {
        "statuses": sorted(set(status)),
        "finite": bool(np.all(np.isfinite(eta))),
        "error_at_end": float(np.max(np.abs(eta[-1] - ETA_TRUE))),
        "raised": None if err is None else str(err),
    }


def run_stream(name, vehicle, stream, eta0=None):
    """Online estimates over ``stream``: ``(t, eta (N, n), statuses, error or None)``; an
    exception raised by ``update`` stops the stream and is returned as the error."""
    est = ESTIMATORS[name](vehicle)
    est.reset(eta0)
    t, eta, status = [], [], []
    for s in stream:
        try:
            e = est.update(s)
        except QuadfaultError as exc:
            return np.array(t), np.array(eta), status, exc
        t.append(e.t)
        eta.append(np.asarray(e.eta, dtype=float))
        status.append(e.status)
    return np.array(t), np.array(eta), status, None


# -- degenerate windows ---------------------------------------------------------------------------
#: samples after the start of a degenerate span before the checks apply (the IRLS window is 10)
SETTLE = 10


def hover_commands(vehicle, eta) -> np.ndarray:
    """Rotor commands [N] that hold a hover with efficiencies ``eta`` (A diag(eta) f = m g e1)."""
    wrench = np.array([vehicle.mass * vehicle.gravity, 0.0, 0.0, 0.0])
    return np.linalg.solve(vehicle.allocation @ np.diag(eta), wrench)


def _still(n, t0, f, dt=1e-3):
    return [
        Sample(
            t0 + k * dt,
            np.array([0.0, 0.0, -1.0]),
            np.zeros(3),
            np.eye(3),
            np.zeros(3),
            np.asarray(f, dtype=float),
        )
        for k in range(n)
    ]


def degenerate_streams(base, vehicle, at: int = 1500, n: int = 200) -> dict:
    """name -> (stream, (first, last + 1) sample of the degenerate span)."""
    out = {}
    hover = _still(at, 0.0, hover_commands(vehicle, ETA_TRUE))
    out["hover"] = (hover + _still(n, at * 1e-3, hover_commands(vehicle, ETA_TRUE)), (at, at + n))
    out["idle"] = (hover + _still(n, at * 1e-3, np.zeros(vehicle.n_rotors)), (at, at + n))
    off = [s._replace(f=np.where(np.arange(len(s.f)) == 0, 0.0, s.f)) for s in base[at : at + n]]
    out["rotor_off"] = (base[:at] + off, (at, at + n))
    nan = [s._replace(p=np.full(3, np.nan), v=np.full(3, np.nan)) for s in base[at : at + n]]
    out["nan_rows"] = (base[:at] + nan + base[at + n :], (at, at + n))
    out["repeated_time"] = (base[:at] + [base[at - 1]] + base[at:], (at, at + 1))
    return out


def check_degenerate(name, vehicle, stream, span):
    """Statuses over the span (after :data:`SETTLE` samples), whether the estimate stayed
    exactly as it was, NaN anywhere, and the error against the truth just before the span and
    at its end."""
    t, eta, status, err = run_stream(name, vehicle, stream)
    lo, hi = span
    if err is not None and len(eta) <= lo:
        return {"raised": str(err)}
    a = min(lo + SETTLE, hi - 1)
    return {
        "statuses": sorted(set(status[a:hi])),
        "kept": bool(np.all(eta[a:hi] == eta[a - 1])),
        "finite": bool(np.all(np.isfinite(eta))),
        "error_before": float(np.max(np.abs(eta[lo - 1] - ETA_TRUE))),
        "error_at_end": float(np.max(np.abs(eta[hi - 1] - ETA_TRUE))),
        "raised": None if err is None else str(err),
    }


# -- recovery ---------------------------------------------------------------------------------------
def corrupt(base, kind: str, start: int, n: int, rng: np.random.Generator) -> list:
    """``base`` with samples ``start:start+n`` corrupted by ``kind``."""
    burst = base[start : start + n]
    if kind == "spikes":
        burst = [
            s._replace(
                p=s.p + rng.uniform(-0.5, 0.5, 3),
                v=s.v + rng.normal(0, 2.0, 3),
                w=s.w + rng.normal(0, 5.0, 3),
            )
            for s in burst
        ]
    elif kind == "nan":
        burst = [s._replace(p=np.full(3, np.nan), w=np.full(3, np.nan)) for s in burst]
    elif kind == "frozen":
        last = base[start - 1]
        burst = [last._replace(t=s.t, f=s.f) for s in burst]
    elif kind == "gap":
        burst = []
    else:
        raise ValueError(kind)
    return base[:start] + burst + base[start + n :]


def recovery_time(name, vehicle, base, kind, start, n, tol, seed=0, clean=None):
    """Seconds from the end of the burst until the estimate stays within ``tol`` of the clean
    run's (inf if it never does); also the largest deviation and whether all were finite."""
    if clean is None:
        clean = run_stream(name, vehicle, base)
    t_c, eta_c, _, _ = clean
    stream = corrupt(base, kind, start, n, np.random.default_rng(seed))
    t, eta, status, err = run_stream(name, vehicle, stream)
    if err is not None:
        return {"recovery_s": math.inf, "raised": str(err)}
    ref = {float(tc): e for tc, e in zip(t_c, eta_c)}
    t_end = base[start + n - 1].t
    dev = np.array([np.max(np.abs(e - ref[float(tk)])) for tk, e in zip(t, eta)])
    after = t > t_end
    bad = np.flatnonzero(after & (dev > tol))
    rec = (
        0.0
        if bad.size == 0
        else float(t[bad[-1] + 1] - t_end)
        if bad[-1] + 1 < len(t)
        else math.inf
    )
    return {
        "recovery_s": rec,
        "max_deviation": float(dev.max()),
        "finite": bool(np.all(np.isfinite(eta))),
        "raised": None,
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=3.0, help="flight [s] (default 3)")
    p.add_argument("--burst", type=float, default=0.05, help="corrupted span [s] (default 0.05)")
    p.add_argument(
        "--tol",
        type=float,
        default=0.02,
        help="recovered when within this of the clean estimate (default 0.02)",
    )
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    base, vehicle = flight(args.duration, args.seed)
    at = len(base) // 2
    print(
        f"flight: {len(base)} samples at 1 kHz, eta = {ETA_TRUE}, seed {args.seed} "
        f"({time.perf_counter() - t0:.1f} s)"
    )
    ok = True
    print(f"degenerate windows (200 samples at mid-flight; statuses after {SETTLE} samples):")
    for case, (stream, span) in degenerate_streams(base, vehicle, at).items():
        for name in ESTIMATORS:
            r = check_degenerate(name, vehicle, stream, span)
            ok &= r.get("finite", True)
            print(f"  {case:14s} {name:4s} " + ", ".join(f"{k} {v}" for k, v in r.items()))
    sat, sat_vehicle, frac = saturated_flight(args.duration, args.seed)
    print(
        f"saturated rotors (limit {sat_vehicle.rotor_max_thrust} N; {100 * frac:.1f} % of the "
        "rows command a rotor at or above it):"
    )
    for name in ESTIMATORS:
        r = check_saturated(name, sat_vehicle, sat)
        ok &= r["finite"]
        print(f"  {name:4s} " + ", ".join(f"{k} {v}" for k, v in r.items()))
    n = int(round(args.burst / 1e-3))
    print(
        f"recovery after a {args.burst * 1e3:.0f} ms burst at t = {base[at].t:.2f} s "
        f"(tolerance {args.tol} of the clean estimate):"
    )
    for name in ESTIMATORS:
        clean = run_stream(name, vehicle, base)
        for kind in BURSTS:
            r = recovery_time(name, vehicle, base, kind, at, n, args.tol, args.seed, clean)
            ok &= r.get("finite", False) and math.isfinite(r["recovery_s"])
            text = ", ".join(
                f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()
            )
            print(f"  {name:4s} {kind:7s} {text}")
    print(f"({time.perf_counter() - t0:.0f} s) " + ("PASS" if ok else "FAIL"))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
