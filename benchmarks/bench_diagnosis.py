"""Speed of the model-mismatch diagnosis: 60 s recordings at 1 kHz (target <= 10 s).

Flies the paper vehicle (Lissajous, sensor noise, thrust noise 0.02) for each case -- ``none``,
``drag`` (0.3 N s/m), ``motor_lag`` (0.04 s), ``drag+motor_lag``, ``weak_rotor`` (rotor 3 at
0.7) and ``com_offset`` (10, -8 mm; the last two are the cases that fit the rival sets of a
weak rotor and an imbalance in each other's place) -- and times
``Diagnosis().fit`` on it (CPU and wall, after the imports): the first call, what one
``quadfault diagnose`` pays, and the best of ``--rounds`` warm calls after it. With ``--reference REV`` the
diagnosis package as it was at git revision ``REV`` (e.g. the commit before the speed work)
is loaded side by side from ``git show`` and timed on the same recordings in the same run, so
the ratio is meaningful on a loaded machine.

    python benchmarks/bench_diagnosis.py --reference 721f9a5 [--cache DIR] [--cases none,drag]

Simulating 60 s at 1 kHz with effects runs on the numpy path (1-4 ms per step); ``--cache DIR``
keeps the recordings (``DIR/<case>.csv``) for later runs.
"""

from __future__ import annotations

import argparse
import importlib
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from quadfault.io.recording import read_recording, write_recording
from quadfault.model import effects as fx
from quadfault.model.scenarios import named_scenario
from quadfault.model.trajectory import Lissajous
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate

CASES = {
    "none": (),
    "drag": (fx.Drag(0.3),),
    "motor_lag": (fx.MotorLag(0.04),),
    "drag+motor_lag": (fx.Drag(0.3), fx.MotorLag(0.04)),
    # rival sets fitted in each other's place: a weak rotor against an imbalance
    "weak_rotor": (fx.MotorEfficiency((1.0, 1.0, 0.7, 1.0)),),
    "com_offset": (fx.ComOffset((0.01, -0.008)),),
}
REPO = Path(__file__).resolve().parent.parent


def recording(case, duration, rate, cache):
    path = None if cache is None else Path(cache) / f"{case}.csv"
    if path is not None and path.exists():
        return read_recording(path)
    dt = 1.0 / rate
    sc = named_scenario("nominal", duration, dt).replace(
        trajectory=Lissajous(amplitude=(2.0, 1.5, 0.3), frequency=0.15)
    )
    cfg = SimConfig(dt=dt, sensor_noise=SensorNoise(0.002, 0.005, 0.001, 0.001))
    rec = simulate(sc, config=cfg, seed=1, effects=CASES[case], thrust_noise=0.02).without_truth()
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_recording(rec, path)
        rec = read_recording(path)
    return rec


def reference_package(rev: str):
    """``quadfault.diagnosis`` as of git revision ``rev``, imported as ``_diagnosis_ref``,
    with the effects module of the same revision (``quadfault/model/effects.py`` or the package
    ``quadfault/model/effects/``) inside it as ``_diagnosis_ref._effects``."""
    tmp = Path(tempfile.mkdtemp(prefix="diag_ref_")) / "_diagnosis_ref"
    tmp.mkdir()

    def files(path):
        return subprocess.run(
            ["git", "-C", str(REPO), "ls-tree", "-r", "--name-only", rev, path],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.split()

    def rewrite(text):
        return (
            text.replace(
                "from quadfault.model import effects as", "from _diagnosis_ref import _effects as"
            )
            .replace("quadfault.model.effects", "_diagnosis_ref._effects")
            .replace("quadfault.diagnosis", "_diagnosis_ref")
        )

    copies = [(name, tmp / Path(name).name) for name in files("quadfault/diagnosis/")]
    copies += [
        (name, tmp / "_effects" / Path(name).relative_to("quadfault/model/effects"))
        for name in files("quadfault/model/effects/")
    ]
    copies += [(name, tmp / "_effects.py") for name in files("quadfault/model/effects.py")]
    for name, dest in copies:
        if not name.endswith(".py"):
            continue
        text = subprocess.run(
            ["git", "-C", str(REPO), "show", f"{rev}:{name}"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_text(rewrite(text))
    sys.path.insert(0, str(tmp.parent))
    pkg = importlib.import_module("_diagnosis_ref")
    importlib.import_module("_diagnosis_ref.locate")
    importlib.import_module("_diagnosis_ref.prediction")
    return pkg


def timed(pkg, rec, rounds=1):
    """CPU and wall seconds of ``Diagnosis().fit``: the first call (what one ``quadfault
    diagnose`` pays: it loads compiled kernels from the cache), then the best of ``rounds``
    warm calls (0: none, reported as NaN); and the first call's result."""
    c0, w0 = time.process_time(), time.perf_counter()
    res = pkg.Diagnosis().fit(rec)
    first = (time.process_time() - c0, time.perf_counter() - w0)
    calls = []
    for _ in range(rounds):
        c0, w0 = time.process_time(), time.perf_counter()
        pkg.Diagnosis().fit(rec)
        calls.append((time.process_time() - c0, time.perf_counter() - w0))
    warm = tuple(min(x) for x in zip(*calls)) if calls else (float("nan"), float("nan"))
    return first, warm, res


def describe(res):
    out = []
    for e in res.effects:
        p = {
            k: (
                np.round(v, 4).tolist()
                if isinstance(v, (list, tuple, np.ndarray))
                else round(float(v), 4)
            )
            for k, v in e.params.items()
            if k in ("tau_s", "k_N_s_per_m", "delay_s", "eta", "scale", "force_N")
        }
        out.append(f"{e.name} {p}")
    return "; ".join(out) or "none"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--cases", default=",".join(CASES), help="comma-separated subset of " + ", ".join(CASES)
    )
    ap.add_argument("--duration", type=float, default=60.0, help="[s] (default 60)")
    ap.add_argument("--rate", type=float, default=1000.0, help="[Hz] (default 1000)")
    ap.add_argument(
        "--reference",
        default=None,
        metavar="REV",
        help="also time the diagnosis package of this git revision",
    )
    ap.add_argument("--cache", default=None, metavar="DIR", help="keep/reuse recordings here")
    ap.add_argument(
        "--rounds", type=int, default=2, help="warm calls timed after the first (default 2)"
    )
    args = ap.parse_args(argv)
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    bad = [c for c in cases if c not in CASES]
    if bad:
        print(f"bench_diagnosis: unknown case {bad[0]!r}", file=sys.stderr)
        return 2
    import quadfault.diagnosis as new
    import quadfault.diagnosis.locate  # imports are not timed
    import quadfault.diagnosis.prediction  # noqa: F401

    ref = reference_package(args.reference) if args.reference else None
    print(f"load: {os.getloadavg()[0]:.1f} (1 min), {os.cpu_count()} CPUs")
    for case in cases:
        t0 = time.perf_counter()
        rec = recording(case, args.duration, args.rate, args.cache)
        print(
            f"{case}: {len(rec)} rows ({time.perf_counter() - t0:.0f} s to simulate/load)",
            flush=True,
        )
        first, warm, res = timed(new, rec, args.rounds)
        print(
            f"  new: first {first[0]:6.1f} s CPU {first[1]:6.1f} s wall; warm {warm[0]:6.1f} s "
            f"CPU {warm[1]:6.1f} s wall  improvement {res.model_improvement:.3f}  "
            f"{describe(res)}",
            flush=True,
        )
        if ref is not None:
            first0, warm0, res0 = timed(ref, rec, args.rounds)
            print(
                f"  ref: first {first0[0]:6.1f} s CPU {first0[1]:6.1f} s wall; warm "
                f"{warm0[0]:6.1f} s CPU {warm0[1]:6.1f} s wall  improvement "
                f"{res0.model_improvement:.3f}  {describe(res0)}"
            )
            print(
                f"  new / ref (CPU): first x{first[0] / max(first0[0], 1e-9):.2f}, warm "
                f"x{warm[0] / max(warm0[0], 1e-9):.2f}; (wall) first "
                f"x{first[1] / max(first0[1], 1e-9):.2f}, warm x{warm[1] / max(warm0[1], 1e-9):.2f}"
                f"; load {os.getloadavg()[0]:.1f}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
