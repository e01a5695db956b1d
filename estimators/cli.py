"""``quadfault estimate``: run a motor-efficiency estimator over a recording.

    quadfault estimate FILE.csv --estimator irls|ekf|rls|ukf --out EST.csv [--force]
                       [--improved] [--median N] [--q-eta Q] [--forgetting L]
                       [--prefilter TAU] [--accelerometer off|auto|on]

Writes ``EST.csv`` (``t, eta1..eta4, sd1..sd4, status``) and its sidecar ``EST.json``
(:mod:`estimators.series_io`). Estimators are looked up in the registry
(:mod:`estimators.registry`) and imported only when chosen. :func:`estimate_series` is the one path from options to a series (the CLI
and ``quadfault reproduce`` both use it; :func:`cli_args` writes the options back as
arguments).
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings

from estimators.accelerometer import MODES, AccelerometerMissing
from estimators.registry import ESTIMATORS, estimator_names, estimator_spec, make_estimator
from quadfault.errors import ConfigError


def _choices() -> tuple[str, ...]:
    """The estimators ``quadfault estimate`` offers: the registry's real estimators."""
    return estimator_names(role="estimator")


def check_options(
    name: str,
    improved: bool,
    median,
    q_eta,
    forgetting=None,
    prefilter=None,
    accelerometer=None,
):
    """One-line errors for options that do not fit together or are out of range (which
    estimator takes which option: the registry's ``options``)."""
    options = estimator_spec(name).options
    for key, given in (
        ("improved", improved),
        ("q_eta", q_eta),
        ("forgetting", forgetting),
        ("prefilter", prefilter),
        ("accelerometer", accelerometer),
    ):
        if given is not None and given is not False and key not in options:
            takers = [s.name for s in ESTIMATORS.values() if key in s.options]
            raise ConfigError(
                f"--{key.replace('_', '-')} applies to the "
                f"{', '.join(takers)} estimator, not {name!r}"
            )
    if q_eta is not None and (
        isinstance(q_eta, bool)
        or not isinstance(q_eta, (int, float))
        or not (math.isfinite(q_eta) and q_eta > 0)
    ):
        raise ConfigError(f"--q-eta must be a positive number, got {q_eta!r}")
    if forgetting is not None and (
        isinstance(forgetting, bool)
        or not isinstance(forgetting, (int, float))
        or not 0 < forgetting <= 1
    ):
        raise ConfigError(f"--forgetting must be in (0, 1], got {forgetting!r}")
    if prefilter is not None and (
        isinstance(prefilter, bool)
        or not isinstance(prefilter, (int, float))
        or not (math.isfinite(prefilter) and prefilter >= 0)
    ):
        raise ConfigError(f"--prefilter must be a time constant >= 0 [s], got {prefilter!r}")
    if accelerometer is not None and accelerometer not in MODES:
        raise ConfigError(
            f"--accelerometer must be one of {', '.join(MODES)}, got {accelerometer!r}"
        )
    if median is not None and (
        isinstance(median, bool) or not isinstance(median, int) or median < 1
    ):
        raise ConfigError(f"--median must be an integer >= 1 samples, got {median!r}")


def estimate_series(
    recording,
    name: str,
    *,
    improved: bool = False,
    median: int | None = None,
    q_eta: float | None = None,
    forgetting: float | None = None,
    prefilter: float | None = None,
    accelerometer: str | None = None,
    progress: bool = False,
):
    """Run estimator ``name`` over ``recording`` (never its truth) with the options of
    ``quadfault estimate``; the series' ``postprocess`` says which median it got."""
    from estimators.median import median_series

    check_options(name, improved, median, q_eta, forgetting, prefilter, accelerometer)
    online_median = "median" in estimator_spec(name).options
    est = make_estimator(
        name,
        recording.vehicle,
        improved=improved,
        q_eta=q_eta,
        forgetting=forgetting,
        prefilter=prefilter,
        accelerometer=accelerometer,
        median=median if online_median else None,
    )
    series = est.run(recording.without_truth(), progress=progress)
    if median is not None and not online_median:
        series = median_series(series, median)
    return series


def cli_args(
    name: str,
    *,
    improved: bool = False,
    median: int | None = None,
    q_eta: float | None = None,
    forgetting: float | None = None,
    prefilter: float | None = None,
    accelerometer: str | None = None,
) -> list[str]:
    """The ``quadfault estimate`` arguments of :func:`estimate_series`'s options (``q_eta``
    written with ``repr``, so the arguments reproduce the series exactly)."""
    args = ["--estimator", name]
    if improved:
        args.append("--improved")
    if q_eta is not None:
        args += ["--q-eta", repr(float(q_eta))]
    if forgetting is not None:
        args += ["--forgetting", repr(float(forgetting))]
    if prefilter is not None:
        args += ["--prefilter", repr(float(prefilter))]
    if accelerometer is not None:
        args += ["--accelerometer", str(accelerometer)]
    if median is not None:
        args += ["--median", str(int(median))]
    return args


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", metavar="FILE.csv", help="input recording (+ FILE.json)")
    p.add_argument(
        "--estimator",
        choices=_choices(),
        default="irls",
        help="; ".join(
            f"{s.name}: {s.summary}" for s in ESTIMATORS.values() if s.name in _choices()
        ),
    )
    p.add_argument("--out", required=True, help="output EST.csv (+ EST.json)")
    p.add_argument("--force", action="store_true", help="overwrite existing files")
    p.add_argument(
        "--improved",
        action="store_true",
        help="IRLS with the options beyond the paper: change completion and a "
        "21-sample causal output median (docs/irls.md)",
    )
    p.add_argument(
        "--median",
        type=int,
        default=None,
        metavar="N",
        help="post-processing of any estimator: causal running median of the last N "
        "estimates (the IRLS's output_median; 1 = none; overrides --improved's "
        "21)",
    )
    p.add_argument(
        "--q-eta",
        type=float,
        default=None,
        metavar="Q",
        help="EKF, UKF: random-walk variance of each efficiency per 1 ms step "
        "(default 0.5, the reference code's)",
    )
    p.add_argument(
        "--forgetting",
        type=float,
        default=None,
        metavar="L",
        help="RLS: forgetting factor per 1 ms step, in (0, 1] (default 0.99)",
    )
    p.add_argument(
        "--prefilter",
        type=float,
        default=None,
        metavar="TAU",
        help="IRLS, RLS: time constant [s] of the low-pass filter on both sides of the "
        "regression, against sensor noise (0 = off; default: IRLS 0, --improved and RLS "
        "0.01)",
    )
    p.add_argument(
        "--accelerometer",
        choices=MODES,
        default=None,
        help="IRLS, RLS: the thrust rows from the accelerometer's specific force (ax, ay, "
        "az) instead of the differenced velocity; EKF, UKF: the specific force as one more "
        "measurement: on (a recording without it falls back to the velocity, and says so), "
        "auto (the same, silently), off (the velocity only; default: off, --improved auto)",
    )


def run(args) -> int:
    from estimators.series_io import estimate_paths, write_estimate_series
    from quadfault.fileio import check_writable
    from quadfault.io.recording import read_recording
    from quadfault.progress import enabled

    check_options(
        args.estimator,
        args.improved,
        args.median,
        args.q_eta,
        args.forgetting,
        args.prefilter,
        args.accelerometer,
    )
    out, side = estimate_paths(args.out)
    check_writable([out, side], force=args.force)
    rec = read_recording(args.recording)
    if "pose" in estimator_spec(args.estimator).needs and not rec.has_pose:
        raise ConfigError(
            f"{args.recording}: 'estimate' needs position, velocity and attitude "
            "columns (px..pz, vx..vz, qw..qz); this recording is IMU-only"
        )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", AccelerometerMissing)
        series = estimate_series(
            rec,
            args.estimator,
            improved=args.improved,
            median=args.median,
            q_eta=args.q_eta,
            forgetting=args.forgetting,
            prefilter=args.prefilter,
            accelerometer=args.accelerometer,
            progress=enabled(),
        )
    for w in caught:  # the fallback said on one line; any other warning as Python says it
        if issubclass(w.category, AccelerometerMissing):
            print(f"quadfault estimate: note: {w.message}", file=sys.stderr)
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    write_estimate_series(series, out, input_path=args.recording, force=args.force)
    if not args.quiet:
        print(
            f"{series.estimator}: {len(series.t)} estimates in {series.seconds:.2f} s -> {out}",
            file=sys.stdout,
        )
    return 0
