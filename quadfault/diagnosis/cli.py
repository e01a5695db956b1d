"""``quadfault diagnose FILE.csv --json OUT.json [--report DIR] [--force]``: the arguments
and the run; the command's module (:mod:`estimators.diagnose_cli`, above the estimators)
hands it the online estimator for the weak-rotor cross-check."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from quadfault.diagnosis.diagnose import Diagnosis, DiagnosisConfig
from quadfault.diagnosis.report import FILES, write_report
from quadfault.errors import ConfigError, RecordingError
from quadfault.fileio import atomic_write_text, check_writable
from quadfault.io.recording import read_recording, sidecar_path
from quadfault.model.effects.motor_efficiency import MotorEfficiency
from quadfault.progress import progress_bar


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", metavar="FILE.csv", help="recording (quadfault-recording/1)")
    p.add_argument(
        "--json",
        required=True,
        metavar="OUT.json",
        help="diagnosis result (format: docs/formats.md)",
    )
    p.add_argument(
        "--report", metavar="DIR", default=None, help="also write DIR/report.md and PNG plots"
    )
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.add_argument(
        "--effects",
        default=None,
        metavar="NAME,...",
        help="restrict the candidate library (default: all effects)",
    )
    p.add_argument(
        "--block", type=float, default=0.02, help="smoothing block length [s] (default 0.02)"
    )
    p.add_argument("--max-effects", type=int, default=3, help="most effects accepted (default 3)")
    p.add_argument(
        "--baseline",
        metavar="HEALTHY.json",
        nargs="+",
        default=None,
        help="the diagnosis JSON of one or more flights of the healthy vehicle, "
        "each with a motor_efficiency fit: eta is then relative to them (one "
        "flight alone cannot tell a weak rotor from the vehicle's own "
        "imbalance; several also give the flight-to-flight spread)",
    )
    p.add_argument(
        "--no-mask",
        action="store_true",
        help="fit and score every block: do not exclude what is not free flight "
        "(motors off, ground or pad contact, impacts; see docs/diagnosis.md)",
    )


def baseline_eta(path) -> tuple:
    """The healthy flight's relative rotor efficiencies from its diagnosis JSON (its
    ``motor_efficiency`` fit: accepted, suspect or rejected; its own ``eta_flight`` when it
    had a baseline itself)."""

    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except OSError as exc:
        raise RecordingError(path, f"cannot read: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise RecordingError(path, f"not valid JSON: {exc}") from None
    fits = (
        [
            e
            for key in ("effects", "suspect", "rejected")
            for e in (doc.get(key) or [])
            if isinstance(e, dict) and e.get("name") == MotorEfficiency.name
        ]
        if isinstance(doc, dict)
        else []
    )
    if not fits:
        raise RecordingError(
            path,
            "no motor_efficiency fit in this diagnosis (run quadfault "
            "diagnose --effects motor_efficiency on the healthy flight)",
            key="effects",
        )
    params = fits[0].get("params") or {}
    eta = params.get("eta_flight", params.get("eta"))
    try:
        eta = tuple(float(v) for v in eta)
    except (TypeError, ValueError):
        eta = ()
    if len(eta) != 4 or not all(v > 0 for v in eta):
        raise RecordingError(
            path,
            f"motor_efficiency eta must be 4 positive numbers, got {params.get('eta')!r}",
            key="effects",
        )
    return eta


def run(args, efficiency_estimate=None) -> int:
    """Run the diagnosis; ``efficiency_estimate`` (the command module above the estimators
    passes it) gives the online estimator's efficiencies beside a weak-rotor hypothesis."""

    out = Path(args.json)
    if out.suffix != ".json":
        raise ConfigError(f"--json must end in .json, got {args.json!r}")
    if out.resolve() == sidecar_path(Path(args.recording)).resolve():
        raise ConfigError(
            f"--json {args.json} is the recording's own sidecar; choose another "
            "name (it would be overwritten)"
        )
    check_writable([out], force=args.force)
    if args.report is not None:
        rdir = Path(args.report)
        if rdir.exists():
            check_writable([rdir / f for f in FILES], force=args.force)
    effects = None
    if args.effects:
        effects = tuple(e.strip() for e in args.effects.split(",") if e.strip())
    cfg = DiagnosisConfig(
        block_seconds=args.block,
        max_effects=args.max_effects,
        effects=effects,
        mask=not args.no_mask,
        baseline_eta=None
        if args.baseline is None
        else tuple(baseline_eta(b) for b in args.baseline),
    )
    rec = read_recording(args.recording).without_truth()
    bar = progress_bar(
        total=None, desc="diagnose", unit="fit", disable=None if not args.quiet else True
    )
    try:
        res = Diagnosis(cfg, efficiency_estimate).fit(rec, progress=lambda: bar.update(1))
    finally:
        bar.close()
    atomic_write_text(out, res.to_json(), force=args.force)
    if args.report is not None:
        write_report(res, args.report, source=Path(args.recording).name, force=args.force)
    if not args.quiet:
        print(f"{res.summary()}; wrote {out}")
    return 0
