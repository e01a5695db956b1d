"""Writing an :class:`~estimators.base.EstimateSeries` as ``EST.csv`` + ``EST.json``.

``EST.csv`` (docs/formats.md): columns ``t, eta1..etaN, sd1..sdN, status``, one row per
update; ``t`` is the time of the newest sample the estimate used. An unknown uncertainty (before
the first solved window) is written as ``nan``. The JSON sidecar (same stem) names the
estimator, its configuration and the input recording.
"""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np

from estimators.base import EstimateSeries
from quadfault.errors import ConfigError
from quadfault.fileio import atomic_write_files, check_writable

FORMAT = "quadfault-estimate/1"


def estimate_paths(csv_path) -> tuple[Path, Path]:
    """``(EST.csv, EST.json)`` for an output path that must end in ``.csv``."""
    path = Path(csv_path)
    if path.suffix != ".csv":
        raise ConfigError(f"--out must end in .csv, got {str(csv_path)!r}")
    return path, path.with_suffix(".json")


def estimate_columns(n_rotors: int) -> list[str]:
    return (
        ["t"]
        + [f"eta{i + 1}" for i in range(n_rotors)]
        + [f"sd{i + 1}" for i in range(n_rotors)]
        + ["status"]
    )


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, tuple):
        return list(value)
    return str(value)


def _clean(value):
    """NaN/inf -> None so the sidecar is strict JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    return value


def format_series(series: EstimateSeries) -> str:
    """The CSV text of ``series``."""
    n = series.eta.shape[1]
    sd = series.sd if series.sd is not None else np.full_like(series.eta, np.nan)
    buf = io.StringIO()
    buf.write(",".join(estimate_columns(n)) + "\n")
    numbers = np.column_stack((series.t, series.eta, sd)).tolist()
    for row, status in zip(numbers, series.status):
        buf.write(",".join(map(repr, row)))
        buf.write(f",{status}\n")
    return buf.getvalue()


def write_estimate_series(
    series: EstimateSeries,
    csv_path,
    *,
    input_path=None,
    force: bool = False,
    extra: dict | None = None,
) -> Path:
    """Write ``EST.csv`` and ``EST.json`` atomically; refuse to overwrite unless ``force``."""
    path, side = estimate_paths(csv_path)
    check_writable([path, side], force=force)
    statuses, counts = np.unique(np.asarray(series.status, dtype=str), return_counts=True)
    meta = {
        "format": FORMAT,
        "estimator": series.estimator,
        "config": series.config,
        "postprocess": series.postprocess,
        "input": None if input_path is None else str(input_path),
        "rows": len(series.t),
        "columns": estimate_columns(series.eta.shape[1]),
        "status_counts": {str(s): int(c) for s, c in zip(statuses, counts)},
        "seconds": series.seconds,
    }
    if extra:
        meta.update(extra)
    text = json.dumps(_clean(json.loads(json.dumps(meta, default=_json_default))), indent=2)
    atomic_write_files({side: text + "\n", path: format_series(series)}, force=True)
    return path


def read_estimate_csv(csv_path) -> dict:
    """Read an ``EST.csv`` back: ``{"t": (N,), "eta": (N, n), "sd": (N, n), "status": (N,)}``."""
    path = Path(csv_path)
    with open(path, encoding="utf-8") as fh:
        header = fh.readline().strip().split(",")
        rows = [line.rstrip("\n").split(",") for line in fh if line.strip()]
    n = sum(1 for h in header if h.startswith("eta"))
    data = np.array([[float(x) for x in r[:-1]] for r in rows]).reshape(-1, 1 + 2 * n)
    return {
        "t": data[:, 0],
        "eta": data[:, 1 : 1 + n],
        "sd": data[:, 1 + n :],
        "status": np.array([r[-1] for r in rows]),
    }
