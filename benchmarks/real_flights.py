"""Every real-flight number of the docs, through the user's path, over every log in a folder.

For each log this runs exactly what a user runs, through the console script's own entry
point (``quadfault.cli.main``): ``quadfault import LOG --out NAME.csv`` (the format read from
the file; for the Crazyflie research data sets ``quadfault import DATASET LOG``) and
``quadfault diagnose NAME.csv --json NAME.json`` with the defaults -- and, for the CrazyPAD
propeller-fault flights, with ``--effects motor_efficiency``, alone and against the healthy
flights of the same airframe (``--baseline HEALTHY.json ...``, every healthy flight but the
one diagnosed). One flight alone reports a per-rotor pattern it cannot tell from the
vehicle's own imbalance as that (``vehicle imbalance`` in the rejection); the tables give
those patterns beside the accepted ones. The tables are built
from the JSON files it wrote. Per log it prints the accepted effects with their figures, what
was not identifiable and why, and a loud ``!! ABSURD`` line for any absurd accepted answer:

* a parameter at a bound;
* an inertia scale outside 0.5-2;
* a rotor efficiency below 0.5, or all four below 0.85 (that is a common factor);
* a steady external force above 20 % of the weight;
* a lag or delay from commands logged slower than 2 samples per time constant.

An import that fails prints its one-line error (``!! IMPORT FAILED``). Two references are
computed here, independently of the diagnosis: the nano-drone drag (a least-squares fit of the
body-frame accelerometer against the body-frame velocity, ``m a_b = -k v_b`` per horizontal
axis, on the blocks the diagnosis scored), and, on every log with measured rotor speeds, the
motor lag from command to speed (a first-order lag from the commanded thrust to ``omega^2``,
per rotor with its own gain and offset, one time constant for all four, on the scored span).

    python benchmarks/real_flights.py [--data DIR] [--out DIR] [--only NAME,...]
                                      [--crazypad-all] [--json OUT.json] [--force] [--quiet]
    python benchmarks/real_flights.py --from-json OUT.json     # re-print the tables

``--data`` defaults to ``../shared/data/real`` next to the repository (never copied into
it); without it the script prints one line and exits 0. ``--only`` keeps the folders whose
name contains one of the words.
"""

from __future__ import annotations

import argparse
import io
import json
import shutil
import sys
import tempfile
import time
from contextlib import redirect_stderr
from pathlib import Path

import numpy as np

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
#: Crazyflie research data sets: folder -> ``quadfault import DATASET`` name, and the files
DATASETS = {
    "eschmann-cf21-sysid": ("eschmann", "*.csv.gz"),
    "nanodrone-cf21bl": ("nanodrone", "*.csv.gz"),
    "crazypad-cf21-faults": ("crazypad", "motor_data/*/*.csv.gz"),
}
#: CrazyPAD conditions of the default run (healthy, and graded propeller damage)
TARGET_CONDITIONS = (
    "normal_flight",
    "cut_propeller_M3_1mm",
    "cut_propeller_M3_2mm",
    "cut_propeller_M3_3mm",
)
LOG_SUFFIXES = (".ulg", ".bin", ".log", ".bbl", ".bfl", ".bfl.csv", ".bbl.csv")
MAX_INERTIA, MIN_INERTIA, MIN_ETA, HEALTHY_ETA, MAX_FORCE, TIMING_SAMPLES = (
    2.0,
    0.5,
    0.5,
    0.85,
    0.2,
    2.0,
)


def jobs(data: Path, only, crazypad_all: bool) -> list:
    """``(folder, dataset or None, path, name, condition)`` of every log under ``data``."""
    out = []
    for folder in sorted(p for p in data.iterdir() if p.is_dir()):
        if only and not any(w in folder.name for w in only):
            continue
        if folder.name in DATASETS:
            kind, pattern = DATASETS[folder.name]
            for p in sorted(folder.glob(pattern)):
                cond = p.parent.name if kind == "crazypad" else None
                if cond is None or crazypad_all or cond in TARGET_CONDITIONS:
                    name = p.name.split(".")[0]
                    out.append((folder.name, kind, p, f"{cond}_{name}" if cond else name, cond))
            continue
        for p in sorted(folder.rglob("*")):
            if p.is_file() and p.name.lower().endswith(LOG_SUFFIXES):
                out.append((folder.name, None, p, p.name.split(".")[0], None))
    return out


def quadfault(args: list, quiet: bool) -> tuple[int, str]:
    """Run one ``quadfault`` command through the console script's entry point; returns the
    exit code and the last line it wrote to stderr (its one-line error)."""
    from quadfault.cli import main

    if not quiet:
        print("$ quadfault " + " ".join(str(a) for a in args), flush=True)
    err = io.StringIO()
    with redirect_stderr(err):
        code = main([str(a) for a in args] + ["--quiet"])
    lines = [s for s in err.getvalue().splitlines() if s.strip()]
    return code, (lines[-1] if lines else "")


def drag_reference(csv: Path, doc: dict) -> list:
    """k [N s/m] per horizontal body axis from ``m sf_b = -k v_b`` on the scored span."""
    from quadfault.io.recording import read_recording

    rec = read_recording(csv)
    keep = _scored_rows(rec.t, doc)
    vb = np.einsum("nji,nj->ni", rec.rotation, rec.velocity)[keep]
    sf = rec.accel[keep]
    m = rec.vehicle.mass
    return [float(-m * np.sum(sf[:, i] * vb[:, i]) / np.sum(vb[:, i] ** 2)) for i in (0, 1)]


def _scored_rows(t, doc) -> np.ndarray:
    keep = np.ones(len(t), dtype=bool)
    for e in doc["scoring"]["excluded"]:
        keep &= ~((t >= e["t0"]) & (t <= e["t1"]))
    return keep


def rotor_lag_reference(csv: Path, doc: dict) -> float | None:
    """The motor time constant [s] from command to measured rotor speed, or None without
    rotor speeds: ``omega_i^2 ~ a_i y_i + b_i`` with ``y`` the commanded thrust through a
    first-order lag (the effects' own ``lag_series``), one ``tau`` for all rotors, least
    squares on the rows the diagnosis scored."""
    from scipy.optimize import minimize_scalar

    from quadfault.io.recording import read_recording
    from quadfault.model.effects import lag_series

    rec = read_recording(csv)
    if rec.rotor_speed is None:
        return None
    W2 = np.asarray(rec.rotor_speed, dtype=float) ** 2
    ok = np.all(np.isfinite(W2), axis=1)
    if ok.sum() < 100:
        return None
    f, dt = rec.thrust_cmd[:-1], np.diff(rec.t)
    use = (_scored_rows(rec.t, doc) & ok)[1:] & (dt <= 2.5 * np.median(dt))
    target = W2[1:][use]

    def sse(log_tau):
        y = lag_series(f, dt, float(np.exp(log_tau)))[use]
        total = 0.0
        for i in range(y.shape[1]):
            X = np.column_stack((y[:, i], np.ones(len(y))))
            coef, *_ = np.linalg.lstsq(X, target[:, i], rcond=None)
            r = target[:, i] - X @ coef
            total += float(r @ r) / max(float(np.var(target[:, i])), 1e-300)
        return total

    grid = np.log(np.geomspace(0.003, 0.3, 25))
    best = grid[int(np.argmin([sse(g) for g in grid]))]
    res = minimize_scalar(sse, bounds=(best - 0.2, best + 0.2), method="bounded")
    return float(np.exp(res.x))


def run_one(folder, kind, path, name, cond, out: Path, quiet: bool) -> dict:
    stem = f"{folder}_{name}"
    csv = out / f"{stem}.csv"
    args = ["import"] + ([kind] if kind else []) + [path, "--out", csv, "--force"]
    row = {"folder": folder, "kind": kind or "", "name": name, "condition": cond}
    code, err = quadfault(args, quiet)
    if code != 0:
        row["import_error"] = err or f"exit status {code}"
        return row
    js = out / f"{stem}.diagnosis.json"
    code, err = quadfault(["diagnose", csv, "--json", js, "--force"], quiet)
    if code != 0:
        row["diagnose_error"] = err or f"exit status {code}"
        return row
    row["diagnosis"] = json.loads(js.read_text())
    if kind == "crazypad":
        js2 = out / f"{stem}.efficiency.json"
        code, err = quadfault(
            ["diagnose", csv, "--json", js2, "--force", "--effects", "motor_efficiency"], quiet
        )
        row["efficiency"] = json.loads(js2.read_text()) if code == 0 else None
        row["files"] = {"csv": str(csv), "efficiency": str(js2)}
    if kind == "nanodrone":
        row["drag_reference"] = drag_reference(csv, row["diagnosis"])
    row["rotor_lag_reference"] = rotor_lag_reference(csv, row["diagnosis"])
    return row


def vehicle_of(row) -> str:
    """The CrazyPAD airframe of a flight (its file name's prefix, ``E8``, ``E9``)."""
    return row["name"].split("_")[-2]


def against_baseline(rows, quiet: bool) -> None:
    """CrazyPAD, ``--effects motor_efficiency --baseline HEALTHY.json ...``: each flight
    against every other healthy flight of the same airframe."""
    pad = [r for r in rows if r["kind"] == "crazypad" and r.get("efficiency") is not None]
    for r in pad:
        healthy = [
            h
            for h in pad
            if h["condition"] == "normal_flight" and vehicle_of(h) == vehicle_of(r) and h is not r
        ]
        if not healthy:
            continue
        js = Path(r["files"]["efficiency"]).with_suffix(".baseline.json")
        code, err = quadfault(
            [
                "diagnose",
                r["files"]["csv"],
                "--json",
                js,
                "--force",
                "--effects",
                "motor_efficiency",
                "--baseline",
                *[h["files"]["efficiency"] for h in healthy],
            ],
            quiet,
        )
        r["baseline_flight"] = f"{len(healthy)} healthy flights"
        r["vs_baseline"] = json.loads(js.read_text()) if code == 0 else None


# ----------------------------------------------------------------------------- per log
def _short(v) -> str:
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_short(x) for x in v) + "]"
    return f"{v:.3g}" if isinstance(v, (int, float)) else str(v)


SKIP_KEYS = (
    "inertia_diag_kg_m2",
    "ground_z_m",
    "nominal_curve",
    "v_ref_V",
    "v_start_V",
    "v_end_V",
    "duration_s",
)


def _effects(entries) -> str:
    parts = []
    for e in entries:
        p = ", ".join(f"{k}={_short(v)}" for k, v in e["params"].items() if k not in SKIP_KEYS)
        parts.append(f"{e['name']}({p}; {100 * e['improvement']:.0f}%)")
    return "; ".join(parts) or "none"


def absurd(doc: dict) -> list:
    """The absurd accepted answers of one diagnosis (module docstring), one line each."""
    out = []
    weight = doc["vehicle"]["mass"] * doc["gravity"]
    rate = (doc.get("evidence") or {}).get("command_rate_hz")
    for e in doc["effects"]:
        n, p = e["name"], e["params"]
        if e.get("at_bound"):
            out.append(f"{n}: a parameter at its bound ({_short(p)})")
        if n == "inertia" and (min(p["scale"]) < MIN_INERTIA or max(p["scale"]) > MAX_INERTIA):
            out.append(f"inertia scale {_short(p['scale'])} outside {MIN_INERTIA}-{MAX_INERTIA}")
        if n == "motor_efficiency":
            for key in ("eta", "eta_absolute"):
                eta = p.get(key)
                if eta and min(eta) < MIN_ETA:
                    out.append(f"motor_efficiency {key} {_short(eta)}: a rotor below {MIN_ETA}")
                if eta and max(eta) < HEALTHY_ETA:
                    out.append(
                        f"motor_efficiency {key} {_short(eta)}: all four below "
                        f"{HEALTHY_ETA} (a common factor)"
                    )
        if n == "wind" and np.linalg.norm(p["force_N"]) > MAX_FORCE * weight:
            out.append(
                f"wind {_short(p['force_N'])} N: "
                f"{100 * np.linalg.norm(p['force_N']) / weight:.0f}% of the weight"
            )
        for key in ("tau_s", "delay_s"):
            if key in p and rate and p[key] * rate < TIMING_SAMPLES:
                out.append(
                    f"{n} {p[key]:.3g} s from commands at {rate:.3g} Hz: "
                    f"{p[key] * rate:.2g} samples per time constant"
                )
    return out


def print_log(r) -> None:
    head = f"\n### {r['folder']} {r['name']}"
    if "import_error" in r:
        print(f"{head}\n!! IMPORT FAILED: {r['import_error']}")
        return
    if "diagnose_error" in r:
        print(f"{head}\n!! DIAGNOSE FAILED: {r['diagnose_error']}")
        return
    d = r["diagnosis"]
    ev = d.get("evidence") or {}
    rates = ", ".join(
        f"{k.replace('_rate_hz', '')} {v:.3g} Hz"
        for k, v in ev.items()
        if k.endswith("_rate_hz") and v
    )
    print(f"{head} ({rates}; {100 * d['scoring']['masked_fraction']:.0f}% not free flight)")
    print(
        f"{d['verdict']}: {_effects(d['effects'])}; held-out improvement "
        f"{100 * d['model']['improvement']:.1f}%"
    )
    if d["suspect"]:
        print("suspect (at a bound): " + ", ".join(e["name"] for e in d["suspect"]))
    for n in d.get("indistinguishable", []):
        print(f"indistinguishable: {' or '.join(n['names'])}: {n['reason']}")
    for n in d.get("not_identifiable", []):
        print(f"not identifiable: {n['name']}: {n['reason']}")
    if d.get("assumptions"):
        print(f"assumed: {', '.join(d['assumptions']['assumed'])}")
    if r.get("efficiency") is not None:
        imb = _eta(r["efficiency"], imbalance=True)
        print(
            f"--effects motor_efficiency: {_effects(r['efficiency']['effects'])}"
            + (f"; vehicle imbalance, eta {_short(imb)}" if np.all(np.isfinite(imb)) else "")
        )
    if r.get("vs_baseline") is not None:
        print(f"--baseline {r['baseline_flight']}: {_effects(r['vs_baseline']['effects'])}")
    if r.get("rotor_lag_reference") is not None:
        print(f"lag from command to measured rotor speed: {r['rotor_lag_reference']:.3f} s")
    for line in absurd(d):
        print(f"!! ABSURD: {line}")


# ----------------------------------------------------------------------------- tables
def print_flights(rows) -> None:
    print("\n## Every log (quadfault import, quadfault diagnose with defaults)\n")
    print(
        "| log | verdict | accepted effects (params; held-out improvement alone) | "
        "not identifiable | model improvement [95% CI] | excluded (not free flight) | "
        "absurd |"
    )
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        if "diagnosis" not in r:
            err = r.get("import_error") or r.get("diagnose_error")
            print(f"| {r['folder']} {r['name']} | failed: {err} | - | - | - | - | - |")
            continue
        d = r["diagnosis"]
        ci = d["model"]["ci95"]
        skipped = ", ".join(n["name"] for n in d.get("not_identifiable", [])) or "-"
        print(
            f"| {r['folder']} {r['name']} | {d['verdict']} | {_effects(d['effects'])} | "
            f"{skipped} | {100 * d['model']['improvement']:.1f}% [{100 * ci[0]:.0f}, "
            f"{100 * ci[1]:.0f}] | {100 * d['scoring']['masked_fraction']:.1f}% | "
            f"{len(absurd(d)) or '-'} |"
        )


def _eta(doc, imbalance: bool = False):
    """Relative eta of the accepted motor_efficiency (with ``imbalance``: of the one rejected
    as the vehicle's own imbalance), or NaN x 4."""
    doc = doc or {}
    if imbalance:
        eff = [
            e
            for e in doc.get("rejected", [])
            if e["name"] == "motor_efficiency"
            and e.get("reason", "").startswith("vehicle imbalance")
        ]
    else:
        eff = [e for e in doc.get("effects", []) if e["name"] == "motor_efficiency"]
    return eff[0]["params"]["eta"] if eff else [np.nan] * 4


#: the CrazyPAD tables: (result key, reported as imbalance, what)
PAD_TABLES = (
    ("efficiency", False, "one flight, accepted: eta relative to the median rotor"),
    (
        "efficiency",
        True,
        "one flight, reported as the vehicle's own imbalance (not "
        "accepted): eta relative to the median rotor",
    ),
    (
        "vs_baseline",
        False,
        "`--baseline` the other healthy flights of the same "
        "airframe, accepted: eta relative to them",
    ),
)


def print_crazypad(rows) -> None:
    for key, imbalance, what in PAD_TABLES:
        sub = [r for r in rows if r["kind"] == "crazypad" and r.get(key) is not None]
        if sub:
            _crazypad_table(sub, key, imbalance, what)


def _crazypad_table(sub, key, imbalance, what) -> None:
    print(
        f"\n## CrazyPAD, `--effects motor_efficiency`, {what} (mean +- sd over the flights "
        "where it is so)\n"
    )
    print(
        f"| condition | {'as imbalance' if imbalance else 'accepted'} | eta1 | eta2 | eta3 | eta4 |"
    )
    print("|---|---|---|---|---|---|")
    for cond in sorted({r["condition"] for r in sub}, key=lambda c: (c != "normal_flight", c)):
        e = np.array([_eta(r[key], imbalance) for r in sub if r["condition"] == cond])
        n_ok = int(np.sum(np.all(np.isfinite(e), axis=1)))
        if n_ok == 0:
            print(f"| {cond} | 0 of {len(e)} | - | - | - | - |")
            continue
        m = np.nanmean(e, axis=0)
        s = np.nanstd(e, axis=0, ddof=1) if n_ok > 1 else np.zeros(4)
        cells = " | ".join(f"{m[i]:.3f} +- {s[i]:.3f}" for i in range(4))
        print(f"| {cond} | {n_ok} of {len(e)} | {cells} |")


def lag_rows(rows) -> list:
    """``(row, tau from commands or None, tau from rotor speeds)`` of logs with rotor speeds
    on which a lag is identifiable (fast enough outputs)."""
    out = []
    for r in rows:
        ref = r.get("rotor_lag_reference")
        if "diagnosis" not in r or ref is None:
            continue
        if "motor_lag" in {n["name"] for n in r["diagnosis"].get("not_identifiable", [])}:
            continue
        lag = [e for e in r["diagnosis"]["effects"] if e["name"] == "motor_lag"]
        out.append((r, lag[0]["params"]["tau_s"] if lag else None, ref))
    return out


def print_lags(rows) -> None:
    lags = lag_rows(rows)
    if not lags:
        return
    print("\n## Motor lag on logs with measured rotor speeds\n")
    print("| log | motor_lag accepted (tau_s) | from command to rotor speed (tau_s) | within 20% |")
    print("|---|---|---|---|")
    for r, tau, ref in lags:
        ok = tau is not None and abs(tau - ref) <= 0.2 * ref
        print(
            f"| {r['folder']} {r['name']} | {'-' if tau is None else f'{tau:.3f}'} | "
            f"{ref:.3f} | {'yes' if ok else 'no'} |"
        )


def horizontal_drag(effects):
    """``(name, k)``: the accepted horizontal drag coefficient [N s/m] -- ``drag``'s mean x/y
    ``k``, or ``blade_flapping``'s rotor drag at hover thrust -- or None."""
    for e in effects:
        if e["name"] == "drag":
            return "drag", float(np.mean(e["params"]["k_N_s_per_m"][:2]))
        if e["name"] == "blade_flapping":
            return "blade_flapping", float(e["params"]["drag_at_hover_N_s_per_m"])
    return None


def targets(rows) -> list:
    """``(target, measured, met)`` of the real-flight targets present in ``rows``."""
    out = []
    done = [r for r in rows if "diagnosis" in r]
    failed = [
        f"{r['folder']} {r['name']}: {r.get('import_error') or r.get('diagnose_error')}"
        for r in rows
        if "diagnosis" not in r
    ]
    out.append(
        (
            "every log imports and diagnoses, or fails with a one-line error",
            f"{len(done)} of {len(rows)} diagnosed; failed: " + ("; ".join(failed) or "none"),
            True,
        )
    )
    bad = [f"{r['name']}: {line}" for r in done for line in absurd(r["diagnosis"])]
    out.append(("no absurd accepted answer", "; ".join(bad) or "none", not bad))
    lags = lag_rows(rows)
    if lags:
        n_ok = sum(tau is not None and abs(tau - ref) <= 0.2 * ref for _, tau, ref in lags)
        out.append(
            (
                "logs with rotor speeds and outputs fast enough for a lag: motor_lag "
                "accepted within 20% of the lag from command to rotor speed on >= 90%",
                f"{n_ok} of {len(lags)}",
                n_ok >= 0.9 * len(lags),
            )
        )
    esch = [r for r in done if r["kind"] == "eschmann"]
    if esch:
        cells, ok = [], True
        for r in esch:
            d = r["diagnosis"]
            lag = [e for e in d["effects"] if e["name"] == "motor_lag"]
            ch = d["model"]["channels"]
            v = ch.get("sf_z") or ch.get("acc_z")
            tau = lag[0]["params"]["tau_s"] if lag else None
            good = (
                tau is not None
                and 0.05 <= tau <= 0.11
                and v["improvement"] >= 0.3
                and v["ci95"][0] > 0
            )
            ok &= good
            cells.append(
                f"{r['name']}: tau {'-' if tau is None else f'{tau:.3f} s'}, vertical "
                f"{100 * v['improvement']:.0f}% [{100 * v['ci95'][0]:.0f}, "
                f"{100 * v['ci95'][1]:.0f}]"
            )
        out.append(
            (
                "Eschmann: motor_lag tau 0.05-0.11 s, vertical >= 30% with CI above 0",
                "; ".join(cells),
                ok,
            )
        )
    nano = [r for r in done if r["kind"] == "nanodrone"]
    if nano:
        n_ok, cells = 0, []
        for r in nano:
            k = horizontal_drag(r["diagnosis"]["effects"])
            ref = np.mean(r["drag_reference"])
            if k is not None:
                n_ok += abs(k[1] - ref) <= 0.3 * ref
            cells.append(
                f"{r['name']} {'-' if k is None else f'{k[0]} {k[1]:.4f}'} (ref {ref:.4f})"
            )
        out.append(
            (
                "nano-drone: horizontal drag within 30% of the accelerometer fit on >= 7 of 9",
                f"{n_ok} of {len(nano)}: " + "; ".join(cells),
                n_ok >= 7,
            )
        )
    for key, what in (
        ("efficiency", "one flight"),
        ("vs_baseline", "against the other healthy flights (--baseline)"),
    ):
        out += _crazypad_targets(
            [r for r in done if r["kind"] == "crazypad" and r.get(key) is not None], key, what
        )
    return out


def _reported(doc):
    """Relative eta of motor_efficiency, accepted or else reported as imbalance."""
    e = np.asarray(_eta(doc), dtype=float)
    return e if np.all(np.isfinite(e)) else np.asarray(_eta(doc, True), dtype=float)


def _crazypad_targets(pad, key, what) -> list:
    out = []
    healthy = [(r, _eta(r[key])) for r in pad if r["condition"] == "normal_flight"]
    if healthy:
        low = [
            f"{r['name']} {_short(e)}"
            for r, e in healthy
            if np.any(np.asarray(e, dtype=float) < HEALTHY_ETA)
        ]
        out.append(
            (
                f"CrazyPAD healthy, {what}: no accepted rotor below {HEALTHY_ETA} relative",
                f"{len(low)} of {len(healthy)}: " + ("; ".join(low) or "none"),
                not low,
            )
        )
    graded = {}
    for r in pad:
        c = r["condition"]
        if c.startswith("cut_propeller_M3_"):
            graded.setdefault(c, []).append(
                _reported(r[key]) if key == "efficiency" else _eta(r[key])
            )
    if graded:
        cells, ok, last = [], True, 1.0
        for c in sorted(graded, key=lambda c: float(c.rsplit("_", 1)[1].rstrip("m"))):
            e = np.array(graded[c])
            lowest = int(np.sum(np.nanargmin(np.where(np.isnan(e), np.inf, e), axis=1) == 2))
            m3 = float(np.nanmean(e[:, 2])) if np.any(np.isfinite(e[:, 2])) else np.nan
            ok &= lowest == len(e) and m3 < last
            last = m3
            cells.append(f"{c}: rotor 3 lowest on {lowest} of {len(e)}, mean eta3 {m3:.3f}")
        how = " (accepted or reported as imbalance)" if key == "efficiency" else " (accepted)"
        out.append(
            (
                f"CrazyPAD cut propeller M3 (1/2/3 mm), {what}{how}: rotor 3 lowest, "
                "falling as the damage grows",
                "; ".join(cells),
                ok,
            )
        )
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
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        help="keep the imported recordings and diagnosis JSON here (default: a temporary folder)",
    )
    ap.add_argument(
        "--only", default="", help="comma-separated words: folders whose name contains one of them"
    )
    ap.add_argument(
        "--crazypad-all",
        action="store_true",
        help="every CrazyPAD motor_data condition, not only healthy and cut",
    )
    ap.add_argument("--json", type=Path, default=None, help="also write all results here")
    ap.add_argument("--force", action="store_true", help="overwrite --json")
    ap.add_argument("--quiet", action="store_true", help="do not print the commands")
    ap.add_argument(
        "--from-json",
        type=Path,
        default=None,
        help="print the tables of an earlier run's --json instead of computing",
    )
    args = ap.parse_args(argv)
    only = tuple(s.strip() for s in args.only.split(",") if s.strip())
    if args.from_json is None and not args.data.is_dir():
        print(f"skipped: real data not available ({args.data} is absent)")
        return 0
    from quadfault.fileio import atomic_write_text, check_writable

    t0 = time.perf_counter()
    if args.from_json is not None:
        rows = [
            r
            for r in json.loads(args.from_json.read_text())
            if not only or any(w in r["folder"] for w in only)
        ]
    else:
        if args.json is not None:
            check_writable([args.json], force=args.force)
        out = args.out or Path(tempfile.mkdtemp(prefix="real_flights_"))
        out.mkdir(parents=True, exist_ok=True)
        rows = []
        try:
            for job in jobs(args.data, only, args.crazypad_all):
                rows.append(run_one(*job, out, args.quiet))
                print_log(rows[-1])
            against_baseline(rows, args.quiet)
        finally:
            if args.out is None:
                shutil.rmtree(out, ignore_errors=True)
        if args.json is not None:
            atomic_write_text(args.json, json.dumps(rows, indent=1), force=args.force)
    if args.from_json is not None:
        for r in rows:
            print_log(r)
    print_flights(rows)
    print_crazypad(rows)
    print_lags(rows)
    print_targets(rows)
    print(f"\n{len(rows)} logs in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
