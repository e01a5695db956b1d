"""``quadfault estimate``: run a motor-efficiency estimator over a recording.

    quadfault estimate FILE.csv --estimator irls|ekf --out EST.csv [--force] [--improved]

Writes ``EST.csv`` (``t, eta1..eta4, sd1..sd4, status``) and its sidecar ``EST.json``
(:mod:`estimators.series_io`). Estimators are looked up in :data:`ESTIMATORS` and imported
only when chosen.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from quadfault.errors import ConfigError

#: name -> "module:Class"; each class takes ``(vehicle, config=None)`` and implements
#: :class:`estimators.base.OnlineEstimator`.
ESTIMATORS: dict[str, str] = {
    "irls": "estimators.irls:SlidingWindowIRLS",
    "ekf": "estimators.ekf:MotorEfficiencyEKF",
}


def estimator_class(name: str):
    """The estimator class registered under ``name`` (clean error if unknown or missing)."""
    if name not in ESTIMATORS:
        raise ConfigError(f"unknown estimator {name!r}; choose from {', '.join(ESTIMATORS)}")
    module_name, class_name = ESTIMATORS[name].split(":")
    try:
        module = importlib.import_module(module_name)
        return getattr(module, class_name)
    except (ImportError, AttributeError) as exc:
        raise ConfigError(f"estimator {name!r} is not available ({module_name}.{class_name}: "
                          f"{exc})") from None


def make_estimator(name: str, vehicle, backend: str | None = None, improved: bool = False):
    """Build an estimator with its default configuration; ``improved``: the IRLS with the
    options beyond the paper (``IRLSConfig.improved()``). ``backend`` is deprecated and
    ignored (there is one implementation)."""
    cls = estimator_class(name)
    if backend is not None:
        from estimators.irls_config import deprecated_backend

        deprecated_backend("make_estimator", backend)
    if improved:
        if name != "irls":
            raise ConfigError(f"--improved applies to the irls estimator, not {name!r}")
        from estimators.irls import IRLSConfig

        return cls(vehicle, IRLSConfig.improved())
    return cls(vehicle)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", metavar="FILE.csv", help="input recording (+ FILE.json)")
    p.add_argument("--estimator", choices=tuple(ESTIMATORS), default="irls",
                   help="irls (the paper's sliding-window IRLS, default) or ekf (baseline)")
    p.add_argument("--out", required=True, help="output EST.csv (+ EST.json)")
    p.add_argument("--force", action="store_true", help="overwrite existing files")
    p.add_argument("--backend", choices=("auto", "numpy", "numba"), default=None,
                   help="deprecated, does nothing (one compiled implementation); removed in "
                        "the next release")
    p.add_argument("--improved", action="store_true",
                   help="IRLS with the options beyond the paper: change completion and a "
                        "21-sample causal output median (docs/irls.md)")


def run(args) -> int:
    from estimators.series_io import estimate_paths, write_estimate_series
    from quadfault.fileio import check_writable
    from quadfault.progress import enabled
    from quadfault.recording import read_recording

    out, side = estimate_paths(args.out)
    check_writable([out, side], force=args.force)
    rec = read_recording(args.recording)
    if not rec.has_pose:
        raise ConfigError(f"{args.recording}: 'estimate' needs position, velocity and attitude "
                          "columns (px..pz, vx..vz, qw..qz); this recording is IMU-only")
    if args.backend is not None:
        print("quadfault estimate: --backend is deprecated and does nothing (one compiled "
              "implementation); it goes in the next release", file=sys.stderr)
    est = make_estimator(args.estimator, rec.vehicle, improved=args.improved)
    series = est.run(rec.without_truth(), progress=enabled())
    write_estimate_series(series, out, input_path=args.recording, force=args.force)
    if not args.quiet:
        print(f"{series.estimator}: {len(series.t)} estimates in {series.seconds:.2f} s -> {out}",
              file=sys.stdout)
    return 0
