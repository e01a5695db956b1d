"""Every real-flight number of the README and docs/diagnosis.md, through the user's path.

For each log this runs exactly what a user runs -- ``quadfault import KIND LOG --out
DIR/NAME.csv`` and ``quadfault diagnose DIR/NAME.csv --json DIR/NAME.json`` with the defaults
(and, for CrazyPAD, once more with ``--effects motor_efficiency``) -- through the console
script's own entry point (``quadfault.cli.main``), prints each command, and builds the tables
from the JSON files it wrote and nothing else. The only other computation is the reference of
the nano-drone drag target: a least-squares fit of the body-frame accelerometer against the
body-frame velocity, ``m a_b = -k v_b`` per horizontal axis, on the blocks the diagnosis scored
(compared with ``drag``'s ``k`` or, when the diagnosis explains the same force as rotor drag
proportional to thrust, ``blade_flapping``'s ``k_force m g``).

Flights (the 30 of the targets): Eschmann et al. log10, log15, log16; the 9 nano-drone
flights; CrazyPAD motor_data ``normal_flight`` (12) and ``cut_propeller_M3_3mm`` (6).
``--crazypad-all`` adds the other CrazyPAD motor_data conditions. The CrazyPAD condition is
read from the folder name, for the table only.

    python benchmarks/real_flights.py [--data DIR] [--out DIR] [--only eschmann,nanodrone,crazypad]
                                      [--crazypad-all] [--json OUT.json] [--force] [--quiet]
    python benchmarks/real_flights.py --from-json OUT.json     # re-print the tables

Reads ``../shared/data/real`` (never copied into the repository) and prints one line and
exits 0 when it is absent.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
DATASETS = ("eschmann", "nanodrone", "crazypad")
TARGET_CONDITIONS = ("normal_flight", "cut_propeller_M3_3mm")


def jobs(data: Path, only, crazypad_all: bool) -> list:
    out = []
    if "eschmann" in only:
        out += [("eschmann", p, p.name.split(".")[0], None)
                for p in sorted((data / "eschmann-cf21-sysid").glob("*.csv.gz"))]
    if "nanodrone" in only:
        out += [("nanodrone", p, p.name.split(".")[0], None)
                for p in sorted((data / "nanodrone-cf21bl").glob("*.csv.gz"))]
    if "crazypad" in only:
        for p in sorted((data / "crazypad-cf21-faults" / "motor_data").glob("*/*.csv.gz")):
            cond = p.parent.name
            if crazypad_all or cond in TARGET_CONDITIONS:
                out.append(("crazypad", p, f"{cond}_{p.name.split('.')[0]}", cond))
    return out


def quadfault(args: list, quiet: bool) -> None:
    """Run one ``quadfault`` command through the console script's entry point."""
    from quadfault.cli import main

    if not quiet:
        print("$ quadfault " + " ".join(str(a) for a in args), flush=True)
    code = main([str(a) for a in args] + ["--quiet"])
    if code != 0:
        raise SystemExit(f"real_flights: quadfault {args[0]} failed on {args[1]}")


def drag_reference(csv: Path, doc: dict) -> list:
    """k [N s/m] per horizontal body axis from ``m sf_b = -k v_b`` on the scored span."""
    from quadfault.recording import read_recording

    rec = read_recording(csv)
    keep = np.ones(len(rec), dtype=bool)
    for e in doc["scoring"]["excluded"]:
        keep &= ~((rec.t >= e["t0"]) & (rec.t <= e["t1"]))
    vb = np.einsum("nji,nj->ni", rec.rotation, rec.velocity)[keep]
    sf = rec.accel[keep]
    m = rec.vehicle.mass
    return [float(-m * np.sum(sf[:, i] * vb[:, i]) / np.sum(vb[:, i] ** 2)) for i in (0, 1)]


def run_one(kind, path, name, cond, out: Path, quiet: bool) -> dict:
    csv = out / f"{kind}_{name}.csv"
    quadfault(["import", kind, path, "--out", csv, "--force"], quiet)
    js = out / f"{kind}_{name}.diagnosis.json"
    quadfault(["diagnose", csv, "--json", js, "--force"], quiet)
    row = {"kind": kind, "name": name, "condition": cond, "diagnosis": json.loads(js.read_text())}
    if kind == "crazypad":
        js2 = out / f"{kind}_{name}.efficiency.json"
        quadfault(["diagnose", csv, "--json", js2, "--force", "--effects", "motor_efficiency"],
                  quiet)
        row["efficiency"] = json.loads(js2.read_text())
    if kind == "nanodrone":
        row["drag_reference"] = drag_reference(csv, row["diagnosis"])
    return row


# ----------------------------------------------------------------------------- tables
def _short(v) -> str:
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_short(x) for x in v) + "]"
    return f"{v:.3g}" if isinstance(v, (int, float)) else str(v)


def _effects(entries, skip=("inertia_diag_kg_m2", "ground_z_m")) -> str:
    parts = []
    for e in entries:
        p = ", ".join(f"{k}={_short(v)}" for k, v in e["params"].items() if k not in skip)
        parts.append(f"{e['name']}({p}; {100 * e['improvement']:.0f}%)")
    return "; ".join(parts) or "none"


def _vertical(doc):
    ch = doc["model"]["channels"]
    key = "sf_z" if "sf_z" in ch else "acc_z"
    return key, ch[key]


def _prediction(doc) -> str:
    p = doc.get("prediction") or {}
    key = "position_rmse_m" if "position_rmse_m" in p else "attitude_rmse_deg"
    if key not in p:
        return "-"
    e = {k: v[-1] for k, v in p[key].items()}
    return (f"{e['nominal']:.3g} / {e['model']:.3g} / {e['constant_velocity']:.3g} / "
            f"{e['constant_acceleration']:.3g}")


def print_flights(rows) -> None:
    print("\n## Every flight (quadfault diagnose, defaults)\n")
    print("| flight | verdict | effects (params; held-out improvement alone) | suspect (at a "
          "bound) | model improvement [95% CI] | vertical channel improvement [95% CI] | "
          "excluded (not free flight) | open-loop error at the last horizon: nominal / model "
          "/ const. velocity / const. acceleration |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        d = r["diagnosis"]
        key, v = _vertical(d)
        ci = d["model"]["ci95"]
        print(f"| {r['kind']} {r['name']} | {d['verdict']} | {_effects(d['effects'])} | "
              f"{', '.join(e['name'] for e in d['suspect']) or '-'} | "
              f"{100 * d['model']['improvement']:.1f}% [{100 * ci[0]:.0f}, {100 * ci[1]:.0f}] | "
              f"{key} {100 * v['improvement']:.0f}% [{100 * v['ci95'][0]:.0f}, "
              f"{100 * v['ci95'][1]:.0f}] | {100 * d['scoring']['masked_fraction']:.1f}% | "
              f"{_prediction(d)} |")


def print_crazypad(rows) -> None:
    sub = [r for r in rows if r["kind"] == "crazypad"]
    nom = np.array([r["efficiency"]["effects"][0]["params"]["eta"] if r["efficiency"]["effects"]
                    else [np.nan] * 4 for r in sub if r["condition"] == "normal_flight"])
    if len(nom) < 2:
        return
    mu, sd = np.nanmean(nom, axis=0), np.nanstd(nom, axis=0, ddof=1)
    print(f"\n## CrazyPAD, `--effects motor_efficiency` ({len(nom)} nominal flights; d = "
          "(eta - nominal mean) / nominal sd)\n")
    print("| condition | n | eta1 | eta2 | eta3 | eta4 | d(eta3) |")
    print("|---|---|---|---|---|---|---|")
    for cond in sorted({r["condition"] for r in sub}, key=lambda c: (c != "normal_flight", c)):
        e = np.array([r["efficiency"]["effects"][0]["params"]["eta"]
                      if r["efficiency"]["effects"] else [np.nan] * 4
                      for r in sub if r["condition"] == cond])
        m = np.nanmean(e, axis=0)
        s = np.nanstd(e, axis=0, ddof=1) if len(e) > 1 else np.zeros(4)
        cells = " | ".join(f"{m[i]:.3f} +- {s[i]:.3f}" for i in range(4))
        print(f"| {cond} | {len(e)} | {cells} | {(m[2] - mu[2]) / sd[2]:+.1f} |")


def horizontal_drag(effects):
    """``(name, k)``: the accepted horizontal drag coefficient [N s/m] -- ``drag``'s mean x/y
    ``k``, or ``blade_flapping``'s rotor drag at hover thrust (``drag_at_hover_N_s_per_m``,
    its force ``-k_force T v`` with ``T = m g``) -- or None."""
    for e in effects:
        if e["name"] == "drag":
            return "drag", float(np.mean(e["params"]["k_N_s_per_m"][:2]))
        if e["name"] == "blade_flapping":
            return "blade_flapping", float(e["params"]["drag_at_hover_N_s_per_m"])
    return None


def _params(e) -> list:
    out = []
    for v in e["params"].values():
        out += list(np.ravel(v))
    return out


def targets(rows) -> list:
    """``(target, measured, met)`` of the issue's real-flight targets present in ``rows``."""
    out = []
    accepted = [(r, e) for r in rows for e in r["diagnosis"]["effects"]]
    at_bound = [f"{r['name']}:{e['name']}" for r, e in accepted if e.get("at_bound")]
    out.append(("no accepted parameter at a bound", f"{len(at_bound)} ({', '.join(at_bound)})",
                not at_bound))
    inert = [(r["name"], e["params"]["scale"]) for r, e in accepted if e["name"] == "inertia"]
    bad = [f"{n}: {_short(s)}" for n, s in inert if min(s) < 0.5 or max(s) > 2.0]
    out.append(("no inertia scale outside 0.5-2", "; ".join(bad) or "none", not bad))
    eff = [(r, e) for r, e in accepted if e["name"] == "motor_efficiency"
           and r["condition"] in (None, "normal_flight")]
    bad = [f"{r['name']}: {_short(e['params']['eta'])}" for r, e in eff
           if min(e["params"]["eta"]) < 0.5]
    out.append(("no efficiency below 0.5 without a known fault", "; ".join(bad) or "none",
                not bad))
    bad = []
    for r, e in accepted:
        if e["name"] == "wind":
            m = r["diagnosis"]["vehicle"]["mass"]
            frac = np.linalg.norm(e["params"]["force_N"]) / (m * r["diagnosis"]["gravity"])
            if frac > 0.2:
                bad.append(f"{r['name']}: {100 * frac:.0f}% of the weight")
    out.append(("no steady external force above 20% of the weight", "; ".join(bad) or "none",
                not bad))
    esch = [r for r in rows if r["kind"] == "eschmann"]
    if esch:
        cells, ok = [], True
        for r in esch:
            d = r["diagnosis"]
            lag = [e for e in d["effects"] if e["name"] == "motor_lag"]
            key, v = _vertical(d)
            tau = lag[0]["params"]["tau_s"] if lag else None
            good = (tau is not None and 0.05 <= tau <= 0.11 and v["improvement"] >= 0.3
                    and v["ci95"][0] > 0)
            ok &= good
            cells.append(f"{r['name']}: tau {'-' if tau is None else f'{tau:.3f} s'}, {key} "
                         f"{100 * v['improvement']:.0f}% [{100 * v['ci95'][0]:.0f}, "
                         f"{100 * v['ci95'][1]:.0f}]")
        out.append(("Eschmann: motor_lag tau 0.05-0.11 s, vertical >= 30% with CI above 0",
                    "; ".join(cells), ok))
    fitted = [(r, e) for r in rows for key in ("effects", "suspect", "rejected")
              for e in r["diagnosis"][key]]
    lags = [e.get("folds_agree") for r, e in fitted
            if r["kind"] == "eschmann" and e["name"] == "motor_lag"]
    inert = [e.get("folds_agree") for r, e in fitted
             if r["kind"] == "crazypad" and e["name"] == "inertia"]
    if lags or inert:
        out.append(("fold agreement accepts the Eschmann lag, rejects the CrazyPAD inertia",
                    f"lag folds agree on {sum(bool(a) for a in lags)} of {len(lags)} logs; "
                    f"inertia folds agree on {sum(bool(a) for a in inert)} of {len(inert)} "
                    "CrazyPAD flights", all(lags) and not any(inert)))
    nano = [r for r in rows if r["kind"] == "nanodrone"]
    if nano:
        n_ok, cells, taus = 0, [], []
        for r in nano:
            d = r["diagnosis"]
            k = horizontal_drag(d["effects"])
            ref = np.mean(r["drag_reference"])
            if k is not None:
                n_ok += abs(k[1] - ref) <= 0.3 * ref
                cells.append(f"{r['name']} {k[0]} {k[1]:.4f} (ref {ref:.4f})")
            else:
                cells.append(f"{r['name']} - (ref {ref:.4f})")
            taus += [e["params"]["tau_s"] for e in d["effects"] if e["name"] == "motor_lag"]
        out.append(("nano-drone: horizontal drag (drag, or blade_flapping's rotor drag at hover "
                    "thrust) within 30% of the accelerometer fit on >= 7 of 9",
                    f"{n_ok} of {len(nano)}: " + "; ".join(cells), n_ok >= 7))
        out.append(("nano-drone: motor lag 0.02-0.06 s where found",
                    f"{len(taus)} flights: " + ", ".join(f"{t:.3f}" for t in taus),
                    all(0.02 <= t <= 0.06 for t in taus)))
    pad = [r for r in rows if r["kind"] == "crazypad" and r["efficiency"]["effects"]]
    nom = [r["efficiency"]["effects"][0]["params"]["eta"][2] for r in pad
           if r["condition"] == "normal_flight"]
    cut = [r["efficiency"]["effects"][0]["params"]["eta"][2] for r in pad
           if r["condition"] == "cut_propeller_M3_3mm"]
    if len(nom) > 1 and cut:
        d = (np.mean(cut) - np.mean(nom)) / np.std(nom, ddof=1)
        out.append(("CrazyPAD --effects motor_efficiency: cut M3 below nominal by > 2 sd",
                    f"eta3 {np.mean(cut):.3f} ({len(cut)} cut) vs {np.mean(nom):.3f} +- "
                    f"{np.std(nom, ddof=1):.3f} ({len(nom)} nominal): d = {d:+.1f}", d < -2))
    return out


def print_targets(rows) -> None:
    print("\n## Targets\n")
    print("| target | measured | met |")
    print("|---|---|---|")
    for name, measured, met in targets(rows):
        print(f"| {name} | {measured} | {'yes' if met else '**no**'} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the real data folder")
    ap.add_argument("--out", type=Path, default=None,
                    help="keep the imported recordings and diagnosis JSON here (default: a "
                         "temporary folder)")
    ap.add_argument("--only", default=",".join(DATASETS), help="comma-separated data sets")
    ap.add_argument("--crazypad-all", action="store_true",
                    help="every CrazyPAD motor_data condition, not only nominal and 3 mm cut")
    ap.add_argument("--json", type=Path, default=None, help="also write all results here")
    ap.add_argument("--force", action="store_true", help="overwrite --json")
    ap.add_argument("--quiet", action="store_true", help="do not print the commands")
    ap.add_argument("--from-json", type=Path, default=None,
                    help="print the tables of an earlier run's --json instead of computing")
    args = ap.parse_args(argv)
    only = tuple(s.strip() for s in args.only.split(",") if s.strip())
    bad = [s for s in only if s not in DATASETS]
    if bad:
        print(f"error: unknown data set {bad[0]!r}; choose from {', '.join(DATASETS)}",
              file=sys.stderr)
        return 2
    if args.from_json is None and not args.data.is_dir():
        print(f"skipped: real data not available ({args.data} is absent)")
        return 0
    from quadfault.fileio import atomic_write_text, check_writable

    t0 = time.perf_counter()
    if args.from_json is not None:
        rows = [r for r in json.loads(args.from_json.read_text()) if r["kind"] in only]
    else:
        if args.json is not None:
            check_writable([args.json], force=args.force)
        out = args.out or Path(tempfile.mkdtemp(prefix="real_flights_"))
        out.mkdir(parents=True, exist_ok=True)
        try:
            rows = [run_one(*job, out, args.quiet)
                    for job in jobs(args.data, only, args.crazypad_all)]
        finally:
            if args.out is None:
                shutil.rmtree(out, ignore_errors=True)
        if args.json is not None:
            atomic_write_text(args.json, json.dumps(rows, indent=1), force=args.force)
    print_flights(rows)
    print_crazypad(rows)
    print_targets(rows)
    print(f"\n{len(rows)} flights in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
