"""Every real-flight number of docs/diagnosis.md ("Real flights") and docs/importers.md.

Reads the real data sets from ``../shared/data/real`` (never copied into the repository) and
skips with one line when they are absent:

* Eschmann et al. (IMU-only, 1 kHz): ``quadfault diagnose`` on every log -> ``motor_lag`` tau
  with uncertainty, held-out improvement, spread over the logs.
* Nano-drone (100 Hz, pose + rotor speeds): the diagnosis with its full library on every
  flight, and with the library minus ``inertia`` (``--effects``), because the nominal rotational
  model lacks the rotor-drag moment (see :func:`quadfault.importers.flight_analysis.
  rotational_check`, also run here) and ``inertia`` is the only library effect that can shrink
  the modelled angular response. Drag and motor lag with uncertainty, held-out improvement.
* CrazyPAD (100 Hz): per flight and rotor the efficiency from the diagnosis'
  ``motor_efficiency`` effect (airborne blocks, held-out score) and from the IRLS estimator;
  per condition mean and sd over flights, and the difference to the nominal flights in units
  of the nominal flight-to-flight sd. The condition label is read (for the table only) after
  the estimate, which sees the recording without truth.

    python benchmarks/real_flights.py [--data DIR] [--only eschmann,nanodrone,crazypad]
                                      [--json OUT.json] [--force] [--quiet]
    python benchmarks/real_flights.py --from-json OUT.json   # re-print the tables
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
DATASETS = ("eschmann", "nanodrone", "crazypad")
NO_INERTIA = ("motor_efficiency", "thrust_scale", "drag", "wind", "motor_lag", "delay",
              "ground_effect", "com_offset")


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return x


def _effects(res) -> list:
    return [{"name": e.name, "params": e.params, "uncertainty": e.uncertainty,
             "improvement": e.improvement, "explanation": e.explanation} for e in res.effects]


def _diagnose(rec, effects=None) -> dict:
    """The diagnosis on the rows outside the importer's calibration segment (fit and score)."""
    from quadfault.diagnosis import Diagnosis, DiagnosisConfig
    from quadfault.importers.flight_analysis import without_calibration

    res = Diagnosis(DiagnosisConfig(effects=effects)).fit(without_calibration(rec).without_truth())
    return _jsonable({"verdict": res.verdict, "effects": _effects(res),
                      "model_improvement": res.model_improvement,
                      "untestable": list(res.untestable), "seconds": res.seconds,
                      "prediction": res.prediction})


def jobs(data: Path, only) -> list:
    out = []
    if "eschmann" in only:
        out += [("eschmann", p) for p in sorted((data / "eschmann-cf21-sysid").glob("*.csv.gz"))]
    if "nanodrone" in only:
        out += [("nanodrone", p) for p in sorted((data / "nanodrone-cf21bl").glob("*.csv.gz"))]
    if "crazypad" in only:
        out += [("crazypad", p) for p in sorted((data / "crazypad-cf21-faults").rglob("*.csv.gz"))]
    return out


def run_one(kind: str, path: Path) -> dict:
    from quadfault.importers import get_importer

    rec = get_importer(kind)(path)
    row = {"kind": kind, "file": str(path.relative_to(path.parents[2] if kind == "crazypad"
                                                      else path.parent))}
    if kind == "eschmann":
        row["diagnosis"] = _diagnose(rec)
        row["diagnosis_timing"] = _diagnose(rec, ("motor_lag",))
    elif kind == "nanodrone":
        from quadfault.importers.crazyflie import BRUSHLESS_KF
        from quadfault.importers.flight_analysis import (
            effect_fit,
            rotational_check,
            without_calibration,
        )

        speed = np.linalg.norm(rec.velocity, axis=1)
        row["speed_p95"], row["speed_max"] = float(np.percentile(speed, 95)), float(speed.max())
        row["rotational_check"] = _jsonable(rotational_check(rec, BRUSHLESS_KF).__dict__)
        row["effect_fit"] = _jsonable(effect_fit(without_calibration(rec), ("drag", "motor_lag"),
                                                 min_height=None).__dict__)
        row["diagnosis"] = _diagnose(rec)
        row["diagnosis_no_inertia"] = _diagnose(rec, NO_INERTIA)
    else:
        from estimators.flight_efficiency import irls_efficiency
        from quadfault.importers.flight_analysis import efficiency_fit

        fit = efficiency_fit(rec)
        eta_irls, n_irls = irls_efficiency(rec)
        row.update(kind_of_log=rec.meta["log_kind"], efficiency=_jsonable(fit.__dict__),
                   eta_irls=list(eta_irls), irls_samples=n_irls,
                   thrust_scale=rec.meta["calibration"]["fitted"]["thrust_scale"],
                   condition=rec.meta["truth"]["condition"],  # label: only for the table
                   airframe=path.name.split("_")[0])
    return row


# ----------------------------------------------------------------------------- tables
def _fmt_effects(effects) -> str:
    parts = []
    for e in effects:
        p = ", ".join(f"{k}={_short(v)}" for k, v in e["params"].items())
        u = ", ".join(f"{_short(v)}" for v in e["uncertainty"].values())
        parts.append(f"{e['name']}({p} +- {u}; {100 * e['improvement']:.0f}%)")
    return "; ".join(parts) or "none"


def _short(v) -> str:
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(f"{x:.3g}" for x in v) + "]"
    return f"{v:.3g}"


def _deg(v) -> str:
    return "-" if v is None else "[" + ", ".join(f"{x:.0f}" for x in v) + "]"


def print_eschmann(rows) -> None:
    print("\n## Eschmann (quadfault diagnose)")
    for key, title in (("diagnosis", "full library"),
                       ("diagnosis_timing", "library restricted to motor_lag")):
        print(f"\n### {title}\n")
        print("| log | verdict | effects (params +- sd; held-out improvement alone) | "
              "model improvement |")
        print("|---|---|---|---|")
        taus = []
        for r in rows:
            d = r[key]
            print(f"| {r['file']} | {d['verdict']} | {_fmt_effects(d['effects'])} | "
                  f"{100 * d['model_improvement']:.1f}% |")
            taus += [e["params"]["tau_s"] for e in d["effects"] if e["name"] == "motor_lag"]
        if taus:
            sd = np.std(taus, ddof=1) if len(taus) > 1 else 0.0
            print(f"\nmotor_lag tau over {len(taus)} of {len(rows)} logs: mean "
                  f"{np.mean(taus):.3f} s, sd {sd:.3f} s, range {min(taus):.3f}-{max(taus):.3f} s")


def print_nanodrone(rows) -> None:
    print("\n## Nano-drone\n")
    print("Measured / modelled angular acceleration, 2-16 Hz, per axis (x, y, z): gain and "
          "phase [deg], model fed the commands or the measured rotor speeds; share of the slow "
          "(< 1 Hz) unexplained roll/pitch moment that is c T v_body, and c.\n")
    print("| flight | speed p95/max [m/s] | gain cmd | phase cmd | gain rotor | phase rotor | "
          "drag-moment share (x,y) | c [mm] (x,y) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        c = r["rotational_check"]
        print(f"| {r['file']} | {r['speed_p95']:.2f}/{r['speed_max']:.2f} | "
              f"{_short(c['gain_cmd'])} | {_deg(c['phase_cmd_deg'])} | "
              f"{_short(c['gain_rotor'])} | {_deg(c['phase_rotor_deg'])} | "
              f"{_short(c['drag_moment_fraction'])} | "
              f"{_short([1e3 * x for x in c['drag_moment_c']])} |")
    print("\n### drag and motor_lag fitted jointly on every flight (diagnosis library, "
          "outside the calibration segment; held-out improvement per channel group)\n")
    print("| flight | drag k (x, y, z) [N s/m] | sd | motor_lag tau [s] | held-out impr. "
          "translational / angular / all |")
    print("|---|---|---|---|---|")
    ks, taus = [], []
    for r in rows:
        e = r["effect_fit"]
        (k, tau), (ksd, tsd) = e["x"], e["sd"]
        imp = e["improvement"]
        ks.append(k)
        taus.append(tau[0])
        print(f"| {r['file']} | {_short(k)} | {_short(ksd)} | {tau[0]:.3f} +- {tsd[0]:.3f} | "
              f"{100 * imp['translational']:.0f}% / {100 * imp['angular']:.0f}% / "
              f"{100 * imp['all']:.0f}% |")
    ks = np.array(ks)
    print(f"\ndrag k over {len(ks)} flights: mean {_short(ks.mean(0))}, sd "
          f"{_short(ks.std(0, ddof=1))} N s/m; motor_lag tau: "
          + ", ".join(f"{t:.3f}" for t in sorted(taus)) + " s")
    for key, title in (("diagnosis", "full library"),
                       ("diagnosis_no_inertia", "library without inertia")):
        print(f"\n### diagnosis, {title}\n")
        print("| flight | verdict | effects | model improvement | open-loop 0.5 s position "
              "error nominal -> model [m] |")
        print("|---|---|---|---|---|")
        for r in rows:
            d = r[key]
            pos = (d.get("prediction") or {}).get("position_rmse_m")
            ol = f"{pos['nominal']:.2f} -> {pos['model']:.2f}" if pos else "-"
            print(f"| {r['file']} | {d['verdict']} | {_fmt_effects(d['effects'])} | "
                  f"{100 * d['model_improvement']:.1f}% | {ol} |")
    for key in ("diagnosis", "diagnosis_no_inertia"):
        for name, par in (("drag", "k_N_s_per_m"), ("motor_lag", "tau_s"), ("delay", "delay_s")):
            vals = [np.mean(e["params"][par]) for r in rows for e in r[key]["effects"]
                    if e["name"] == name]
            if vals:
                print(f"{key}: {name} found in {len(vals)}/{len(rows)} flights, {par} mean "
                      f"{np.mean(vals):.4g}, sd {np.std(vals, ddof=1) if len(vals) > 1 else 0:.2g}")


def print_crazypad(rows) -> None:
    print("\n## CrazyPAD: per-rotor efficiency per flight (mean +- sd over flights)\n")
    for kind in ("motor_data", "controller_data"):
        sub = [r for r in rows if r["kind_of_log"] == kind]
        if not sub:
            continue
        for source in ("diagnosis", "irls"):
            def eta(r, source=source):
                return np.array(r["efficiency"]["eta"] if source == "diagnosis" else r["eta_irls"])
            nom = np.array([eta(r) for r in sub if r["condition"] == "normal_flight"])
            if len(nom) < 2:
                continue
            mu, sd = nom.mean(0), nom.std(0, ddof=1)
            print(f"\n### {kind}, {source} ({len(nom)} nominal flights; d = (eta - nominal mean)"
                  " / nominal sd)\n")
            print("| condition | n | eta1 | eta2 | eta3 | eta4 | d(eta3) | "
                  "held-out impr. (angular) |")
            print("|---|---|---|---|---|---|---|---|")
            for cond in sorted({r["condition"] for r in sub},
                               key=lambda c: (c != "normal_flight", c)):
                rs = [r for r in sub if r["condition"] == cond]
                e = np.array([eta(r) for r in rs])
                m = e.mean(0)
                s = e.std(0, ddof=1) if len(e) > 1 else np.zeros(4)
                imp = np.mean([r["efficiency"]["improvement_angular"] for r in rs])
                cells = " | ".join(f"{m[i]:.3f} +- {s[i]:.3f}" for i in range(4))
                score = f"{100 * imp:.0f}%" if source == "diagnosis" else "-"
                print(f"| {cond} | {len(rs)} | {cells} | {(m[2] - mu[2]) / sd[2]:+.1f} | "
                      f"{score} |")


def print_crazypad_airframes(rows) -> None:
    """eta3 (diagnosis) per airframe (E8, E9): nominal flights vs each condition."""
    print("\n### eta3 per airframe (motor_data, diagnosis; d in units of that airframe's "
          "nominal sd)\n")
    print("| airframe | condition | n | eta3 | d(eta3) |")
    print("|---|---|---|---|---|")
    sub = [r for r in rows if r["kind_of_log"] == "motor_data"]
    for frame in sorted({r["airframe"] for r in sub}):
        mine = [r for r in sub if r["airframe"] == frame]
        nom = np.array([r["efficiency"]["eta"][2] for r in mine
                        if r["condition"] == "normal_flight"])
        if len(nom) < 2:
            continue
        for cond in sorted({r["condition"] for r in mine},
                           key=lambda c: (c != "normal_flight", c)):
            e = np.array([r["efficiency"]["eta"][2] for r in mine if r["condition"] == cond])
            sd = e.std(ddof=1) if len(e) > 1 else 0.0
            d = (e.mean() - nom.mean()) / nom.std(ddof=1)
            print(f"| {frame} | {cond} | {len(e)} | {e.mean():.3f} +- {sd:.3f} | {d:+.1f} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the real data folder")
    ap.add_argument("--only", default=",".join(DATASETS), help="comma-separated data sets")
    ap.add_argument("--json", type=Path, default=None, help="also write all results here")
    ap.add_argument("--force", action="store_true", help="overwrite --json")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    ap.add_argument("--from-json", type=Path, default=None,
                    help="print the tables of an earlier run's --json instead of computing")
    args = ap.parse_args(argv)
    only = tuple(s.strip() for s in args.only.split(",") if s.strip())
    bad = [s for s in only if s not in DATASETS]
    if bad:
        print(f"error: unknown data set {bad[0]!r}; choose from {', '.join(DATASETS)}")
        return 2
    if args.from_json is None and not args.data.is_dir():
        print(f"skipped: real data not available ({args.data} is absent)")
        return 0
    from quadfault.fileio import atomic_write_text, check_writable
    from quadfault.progress import progress_bar

    t0 = time.perf_counter()
    if args.from_json is not None:  # re-print the tables of an earlier run
        rows = [r for r in json.loads(args.from_json.read_text()) if r["kind"] in only]
    else:
        if args.json is not None:
            check_writable([args.json], force=args.force)
        todo = jobs(args.data, only)
        rows = []
        with progress_bar(total=len(todo), desc="real flights", unit="flight",
                          disable=True if args.quiet else None) as bar:
            for kind, path in todo:
                rows.append(run_one(kind, path))
                bar.update(1)
        if args.json is not None:
            atomic_write_text(args.json, json.dumps(_jsonable(rows), indent=1), force=args.force)
    by = {k: [r for r in rows if r["kind"] == k] for k in DATASETS}
    if by["eschmann"]:
        print_eschmann(by["eschmann"])
    if by["nanodrone"]:
        print_nanodrone(by["nanodrone"])
    if by["crazypad"]:
        print_crazypad(by["crazypad"])
        print_crazypad_airframes(by["crazypad"])
    print(f"\n{len(rows)} flights in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
