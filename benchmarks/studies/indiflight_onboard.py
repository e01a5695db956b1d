"""Our four estimators against INDIflight's own onboard effectiveness estimates, per motor.

INDIflight (a Betaflight fork) learns its actuator model onboard with recursive least squares
and logs the estimates; its thrust row ``fx_z_rls_x[0..3]`` is each motor's effectiveness on
the specific force along z. For each INDIflight blackbox log this runs what a user runs --
``quadfault import LOG --vehicle VEHICLE.json --out DIR/NAME.csv`` (the vehicle: the
authors' published mass, inertia, rotor positions and yaw moment, written by this script) and
``quadfault estimate DIR/NAME.csv --estimator E --out DIR/NAME.E.csv`` for IRLS, EKF, RLS and
the UKF with their defaults -- through the console script's entry point, and reads the onboard
estimates from the same log with quadfault's blackbox decoder.

Both sides carry an unknown common scale (the firmware's units; our imported thrust curve), so
each is compared normalised by its mean over the four motors: the onboard ``e_j = x_j /
mean(x)`` from the end of its learning phase, ours ``eta_j(t) / mean_k eta_k(t)``. Agreement
per flight and estimator: the RMS and the largest difference over the motors between the
onboard ``e_j`` and the median of ours over the ``ok`` rows (those whose mean over the motors
exceeds 0.3), and their correlation across the motors (undefined when ours are all equal, e.g.
all at the upper bound). The figure (``--plot``) shows ours over time against the onboard levels.

What the logs can tell: the onboard learner runs for about half a second after the motors spin
up and then holds its estimate; the imported recording starts after that (its take-off cut),
so over the recording the onboard estimates are constant and the comparison is of levels, not
of tracking over time.

    python benchmarks/studies/indiflight_onboard.py [--data DIR] [--out DIR] [--plot FIG.png]
                                            [--json OUT.json] [--quiet]

Reads ``../shared/data/real/indiflight-throws-early`` (never copied into the repository) and
prints one line and exits 0 when it is absent.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

DEFAULT_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real"
FOLDER = "indiflight-throws-early"
ESTIMATORS = ("irls", "ekf", "rls", "ukf")
#: the authors' published vehicle (the dataset's README): mass [kg], inertia [kg m^2], rotor
#: positions (FRD, Betaflight order 0 rear-right, 1 front-right, 2 rear-left, 3 front-left)
#: [m], yaw moment per newton [m], rotors 0 and 3 clockwise seen from above
MASS = 0.428
INERTIA = (7.2e-4, 7.8e-4, 8.9e-4)
ROTOR_X = (-0.0455, 0.0455, -0.0455, 0.0455)
ROTOR_Y = (0.0635, 0.0635, -0.0635, -0.0635)
YAW = (-0.01, 0.01, 0.01, -0.01)


def vehicle() -> dict:
    """The sidecar ``vehicle`` object: wrench = allocation @ f with rows [T; Mx; My; Mz] (FRD:
    thrust along -z, so Mx = -y f, My = x f)."""
    return {
        "mass": MASS,
        "inertia": list(INERTIA),
        "allocation": [[1.0] * 4, [-y for y in ROTOR_Y], list(ROTOR_X), list(YAW)],
    }


def quadfault(args: list, quiet: bool) -> None:
    from quadfault.cli import main

    if not quiet:
        print("$ quadfault " + " ".join(str(a) for a in args), flush=True)
    code = main([str(a) for a in args] + ["--quiet"])
    if code != 0:
        raise SystemExit(f"indiflight_onboard: quadfault {args[0]} failed on {args[1]}")


def onboard(log: Path) -> dict:
    """The onboard thrust-row estimates of the longest log in the file: their final values
    and the times their learning started and ended [s]."""
    from quadfault.io.importers.blackbox_format import decode_log, split_logs

    data = log.read_bytes()
    lg = max((decode_log(data, a, b) for a, b in split_logs(data)), key=lambda g: len(g.main))
    t = lg.field("time") / 1e6
    x = np.stack([lg.field(f"fx_z_rls_x[{j}]") for j in range(4)], axis=1)
    moved = np.flatnonzero(np.any(np.diff(x, axis=0) != 0, axis=1))
    if moved.size == 0:
        return {"x": None}
    return {"x": x[-1].tolist(), "learning": [float(t[moved[0]]), float(t[moved[-1] + 1])]}


def relative(x) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return x / np.mean(x, axis=-1, keepdims=True)


def run(data: Path, out: Path, quiet: bool) -> list:
    from estimators.series_io import read_estimate_csv
    from quadfault.fileio import atomic_write_text

    vpath = out / "indiflight_vehicle.json"
    atomic_write_text(vpath, json.dumps(vehicle(), indent=2) + "\n", force=True)
    rows = []
    for log in sorted((data / FOLDER).glob("*.BFL")):
        name = log.stem
        csv = out / f"{name}.csv"
        quadfault(["import", log, "--vehicle", vpath, "--out", csv, "--force"], quiet)
        ob = onboard(log)
        row = {"flight": name, "onboard": ob, "estimators": {}}
        e_ob = None if ob["x"] is None else relative(ob["x"])
        for est in ESTIMATORS:
            path = out / f"{name}.{est}.csv"
            quadfault(["estimate", csv, "--estimator", est, "--out", path, "--force"], quiet)
            s = read_estimate_csv(path)
            # ok rows whose motors' mean is not near zero (the normalisation's denominator)
            ok = (s["status"] == "ok") & (np.mean(s["eta"], axis=1) > 0.3)
            rel = relative(s["eta"][ok])
            med = np.median(rel, axis=0)
            entry = {"t": s["t"][ok].tolist(), "relative": rel.tolist(), "median": med.tolist()}
            if e_ob is not None:
                d = med - e_ob
                entry.update(
                    rms=float(np.sqrt(np.mean(d**2))),
                    worst=float(np.max(np.abs(d))),
                    corr=float(np.corrcoef(med, e_ob)[0, 1]),
                )
            row["estimators"][est] = entry
        rows.append(row)
    return rows


def print_table(rows: list) -> None:
    print(
        "\nper motor, normalised by the four motors' mean: onboard (end of its learning) and "
        "the median of ours over the ok rows; agreement RMS / worst / correlation"
    )
    print(
        f"{'flight':9s} {'source':8s} {'m1':>6s} {'m2':>6s} {'m3':>6s} {'m4':>6s} "
        f"{'RMS':>6s} {'worst':>6s} {'corr':>6s}"
    )
    for r in rows:
        ob = r["onboard"]
        if ob["x"] is not None:
            print(
                f"{r['flight']:9s} {'onboard':8s} "
                + " ".join(f"{v:6.3f}" for v in relative(ob["x"]))
                + f"   (learned {ob['learning'][0]:.2f}-{ob['learning'][1]:.2f} s)"
            )
        for est, e in r["estimators"].items():
            tail = f" {e['rms']:6.3f} {e['worst']:6.3f} {e['corr']:+6.2f}" if "rms" in e else ""
            print(f"{r['flight']:9s} {est:8s} " + " ".join(f"{v:6.3f}" for v in e["median"]) + tail)


def plot(rows: list, path: Path) -> None:
    import matplotlib

    from quadfault.fileio import atomic_savefig

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colors = {"irls": "tab:blue", "ekf": "tab:orange", "rls": "tab:green", "ukf": "tab:purple"}
    fig, axes = plt.subplots(
        len(rows), 4, figsize=(14, 2.6 * len(rows)), squeeze=False, sharey=True
    )
    for i, r in enumerate(rows):
        e_ob = None if r["onboard"]["x"] is None else relative(r["onboard"]["x"])
        for j in range(4):
            ax = axes[i][j]
            for est, e in r["estimators"].items():
                rel = np.asarray(e["relative"])
                ax.plot(e["t"], rel[:, j], lw=0.6, color=colors[est], label=est)
            if e_ob is not None:
                ax.axhline(e_ob[j], color="k", lw=1.5, ls="--", label="INDIflight onboard")
            ax.set_title(f"{r['flight']} motor {j + 1}", fontsize=9)
            ax.set_ylim(0.5, 1.6)
            ax.grid(alpha=0.3)
            if j == 0:
                ax.set_ylabel("eta / mean over motors")
    axes[-1][0].set_xlabel("t [s]")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=5, fontsize=8)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    atomic_savefig(fig, path, force=True, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=DEFAULT_DATA)
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="folder for the recordings and estimates (default: a temporary one)",
    )
    p.add_argument("--plot", type=Path, default=None, help="write the figure (PNG)")
    p.add_argument("--json", type=Path, default=None, help="also write the summary as JSON")
    p.add_argument("--quiet", action="store_true", help="do not print the commands")
    args = p.parse_args(argv)
    if not (args.data / FOLDER).is_dir():
        print(f"indiflight_onboard: no {FOLDER} under {args.data}; nothing to do")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        rows = run(args.data, out, args.quiet)
    print_table(rows)
    if args.plot:
        plot(rows, args.plot)
        print(f"wrote {args.plot}")
    if args.json:
        from quadfault.fileio import atomic_write_text

        slim = [
            {
                **r,
                "estimators": {
                    k: {m: v for m, v in e.items() if m not in ("t", "relative")}
                    for k, e in r["estimators"].items()
                },
            }
            for r in rows
        ]
        atomic_write_text(args.json, json.dumps(slim, indent=2) + "\n", force=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
