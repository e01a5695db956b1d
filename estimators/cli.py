"""``quadfault estimate``: run a motor-efficiency estimator over a recording.

    quadfault estimate FILE.csv --estimator irls|ekf --out EST.csv [--force] [--improved]
                       [--median N] [--q-eta Q]

Writes ``EST.csv`` (``t, eta1..eta4, sd1..sd4, status``) and its sidecar ``EST.json``
(:mod:`estimators.series_io`). Estimators are looked up in :data:`ESTIMATORS` and imported
only when chosen. :func:`estimate_series` is the one path from options to a series (the CLI
and ``quadfault reproduce`` both use it; :func:`cli_args` writes the options back as
arguments).
"""

from __future__ import annotations

import argparse
import importlib
import math
import sys
from dataclasses import replace

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


#: estimators whose configuration has an online output median (``output_median``); the
#: others get the same median on their output series (:func:`estimators.median.median_series`)
ONLINE_MEDIAN = ("irls",)


def make_estimator(name: str, vehicle, improved: bool = False, median: int | None = None,
                   q_eta: float | None = None):
    """Build an estimator with its default configuration; ``improved``: the IRLS with the
    options beyond the paper (``IRLSConfig.improved()``); ``median``: the IRLS's online output
    median [samples] (other estimators get it as post-processing, :func:`estimate_series`);
    ``q_eta``: the EKF's efficiency random walk per 1 ms step."""
    cls = estimator_class(name)
    check_options(name, improved, median, q_eta)
    if name == "irls":
        from estimators.irls import IRLSConfig

        cfg = IRLSConfig.improved() if improved else IRLSConfig()
        if median is not None:
            cfg = replace(cfg, output_median=int(median))
        return cls(vehicle, cfg)
    if name == "ekf" and q_eta is not None:
        from estimators.ekf import EKFConfig

        return cls(vehicle, EKFConfig(q_eta=float(q_eta)))
    return cls(vehicle)


def check_options(name: str, improved: bool, median, q_eta) -> None:
    """One-line errors for options that do not fit together or are out of range."""
    if improved and name != "irls":
        raise ConfigError(f"--improved applies to the irls estimator, not {name!r}")
    if q_eta is not None and name != "ekf":
        raise ConfigError(f"--q-eta applies to the ekf estimator, not {name!r}")
    if q_eta is not None and (isinstance(q_eta, bool) or not isinstance(q_eta, (int, float))
                              or not (math.isfinite(q_eta) and q_eta > 0)):
        raise ConfigError(f"--q-eta must be a positive number, got {q_eta!r}")
    if median is not None and (isinstance(median, bool) or not isinstance(median, int)
                               or median < 1):
        raise ConfigError(f"--median must be an integer >= 1 samples, got {median!r}")


def estimate_series(recording, name: str, *, improved: bool = False, median: int | None = None,
                    q_eta: float | None = None, progress: bool = False):
    """Run estimator ``name`` over ``recording`` (never its truth) with the options of
    ``quadfault estimate``; the series' ``postprocess`` says which median it got."""
    from estimators.median import median_series

    est = make_estimator(name, recording.vehicle, improved=improved, median=median, q_eta=q_eta)
    series = est.run(recording.without_truth(), progress=progress)
    if median is not None and name not in ONLINE_MEDIAN:
        series = median_series(series, median)
    return series


def cli_args(name: str, *, improved: bool = False, median: int | None = None,
             q_eta: float | None = None) -> list[str]:
    """The ``quadfault estimate`` arguments of :func:`estimate_series`'s options (``q_eta``
    written with ``repr``, so the arguments reproduce the series exactly)."""
    args = ["--estimator", name]
    if improved:
        args.append("--improved")
    if q_eta is not None:
        args += ["--q-eta", repr(float(q_eta))]
    if median is not None:
        args += ["--median", str(int(median))]
    return args


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", metavar="FILE.csv", help="input recording (+ FILE.json)")
    p.add_argument("--estimator", choices=tuple(ESTIMATORS), default="irls",
                   help="irls (the paper's sliding-window IRLS, default) or ekf (baseline)")
    p.add_argument("--out", required=True, help="output EST.csv (+ EST.json)")
    p.add_argument("--force", action="store_true", help="overwrite existing files")
    p.add_argument("--improved", action="store_true",
                   help="IRLS with the options beyond the paper: change completion and a "
                        "21-sample causal output median (docs/irls.md)")
    p.add_argument("--median", type=int, default=None, metavar="N",
                   help="post-processing of any estimator: causal running median of the last N "
                        "estimates (the IRLS's output_median; 1 = none; overrides --improved's "
                        "21)")
    p.add_argument("--q-eta", type=float, default=None, metavar="Q",
                   help="EKF: random-walk variance of each efficiency per 1 ms step "
                        "(default 0.5, the reference code's)")


def run(args) -> int:
    from estimators.series_io import estimate_paths, write_estimate_series
    from quadfault.fileio import check_writable
    from quadfault.progress import enabled
    from quadfault.recording import read_recording

    check_options(args.estimator, args.improved, args.median, args.q_eta)
    out, side = estimate_paths(args.out)
    check_writable([out, side], force=args.force)
    rec = read_recording(args.recording)
    if not rec.has_pose:
        raise ConfigError(f"{args.recording}: 'estimate' needs position, velocity and attitude "
                          "columns (px..pz, vx..vz, qw..qz); this recording is IMU-only")
    series = estimate_series(rec, args.estimator, improved=args.improved, median=args.median,
                             q_eta=args.q_eta, progress=enabled())
    write_estimate_series(series, out, input_path=args.recording, force=args.force)
    if not args.quiet:
        print(f"{series.estimator}: {len(series.t)} estimates in {series.seconds:.2f} s -> {out}",
              file=sys.stdout)
    return 0
