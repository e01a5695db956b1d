"""Importers: real flight logs -> :class:`quadfault.io.recording.Recording` (NED/FRD).

One importer per source, each ``import_<name>(path, ...) -> Recording``:

- :func:`quadfault.io.importers.eschmann.import_eschmann` (Crazyflie 2.1, 1 kHz IMU + PWM)
- :func:`quadfault.io.importers.nanodrone.import_nanodrone` (Crazyflie 2.1 Brushless, full state)
- :func:`quadfault.io.importers.crazypad.import_crazypad` (Crazyflie 2.1, propeller faults)
- :func:`quadfault.io.importers.px4_ulog.import_px4_ulog` (any PX4 ULog, needs ``pyulog``)
- :func:`quadfault.io.importers.ardupilot.import_ardupilot` (ArduPilot DataFlash ``.bin`` or
  text ``.log``, needs ``pymavlink``)
- :func:`quadfault.io.importers.blackbox.import_blackbox` (Betaflight / INDIflight blackbox
  ``.bfl``/``.bbl`` or its decoded CSV; quadfault's own decoder)
- :func:`quadfault.io.importers.crazyflie_usd.import_crazyflie_usd` (Crazyflie uSD-deck
  event logs; quadfault's own reader)

The autopilot importers share :mod:`quadfault.io.importers.field_log` (flight span, validity,
vehicle assumptions, thrust calibration); :func:`detect_format` tells their logs apart by
content.

This module holds the small helpers they share: reading a raw table with errors that name
the file, column and row; dropping duplicate time stamps; finding the motors-running span;
describing gaps; and the one-line summary ``quadfault import`` prints.
"""

from __future__ import annotations

import csv
import gzip
import importlib
from pathlib import Path

import numpy as np

from quadfault.errors import ConfigError, RecordingError
from quadfault.io.importers.usd_format import is_usd_log

#: name -> (module, function) of every importer (imported lazily).
IMPORTERS: dict[str, tuple[str, str]] = {
    "eschmann": ("quadfault.io.importers.eschmann", "import_eschmann"),
    "nanodrone": ("quadfault.io.importers.nanodrone", "import_nanodrone"),
    "crazypad": ("quadfault.io.importers.crazypad", "import_crazypad"),
    "px4": ("quadfault.io.importers.px4_ulog", "import_px4_ulog"),
    "ardupilot": ("quadfault.io.importers.ardupilot", "import_ardupilot"),
    "blackbox": ("quadfault.io.importers.blackbox", "import_blackbox"),
    "crazyflie-usd": ("quadfault.io.importers.crazyflie_usd", "import_crazyflie_usd"),
}


#: leading bytes of each autopilot log format
ULOG_MAGIC = b"ULog\x01\x12\x35"
DATAFLASH_MAGIC = b"\xa3\x95"
BLACKBOX_MARK = b"H Product:Blackbox flight data recorder"


def detect_format(path) -> str:
    """``"px4"``, ``"ardupilot"``, ``"blackbox"`` or ``"crazyflie-usd"`` from the file's
    content (magic bytes or first lines), or a one-line :class:`RecordingError`."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(path, "file not found")
    if path.is_dir():
        raise RecordingError(path, "is a directory, expected a log file")
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    if head.startswith(ULOG_MAGIC):
        return "px4"
    if head.startswith(DATAFLASH_MAGIC):
        return "ardupilot"
    if BLACKBOX_MARK in head:
        return "blackbox"
    if is_usd_log(head):
        return "crazyflie-usd"
    text = head.decode("latin-1")
    lines = [ln.strip() for ln in text.splitlines()[:200]]
    if any(ln.startswith("FMT,") for ln in lines):
        return "ardupilot"
    if any(
        ln.startswith(("loopIteration", '"loopIteration"')) or ln.startswith('"Product","Blackbox')
        for ln in lines
    ):
        return "blackbox"
    raise RecordingError(
        path,
        "unknown log format (not a PX4 ULog, ArduPilot DataFlash, blackbox or "
        "Crazyflie uSD log); give --format or a data set name",
    )


def get_importer(name: str):
    """The ``import_<name>`` function registered under ``name``."""
    if name not in IMPORTERS:
        raise RecordingError(name, f"unknown importer; choose one of {', '.join(IMPORTERS)}")
    module, func = IMPORTERS[name]
    return getattr(importlib.import_module(module), func)


# ----------------------------------------------------------------------------------------
# raw tables
def read_raw_table(path) -> dict[str, np.ndarray]:
    """Read a (gzip) CSV with a header row into ``{column: float array}``.

    Empty and ``nan`` cells become NaN. Non-numeric cells, ragged rows, duplicated columns and
    empty files raise :class:`RecordingError` naming the file, the column and the 1-based data
    row.
    """
    path = Path(path)
    if not path.exists():
        raise RecordingError(path, "file not found")
    if path.is_dir():
        raise RecordingError(path, "is a directory, expected a log file")
    try:
        opener = gzip.open if path.name.endswith(".gz") else open
        with opener(path, "rt", encoding="utf-8", newline="") as fh:
            reader = csv.reader(fh)
            header = [h.strip() for h in next(reader, [])]
            rows = [r for r in reader if any(c.strip() for c in r)]
    except UnicodeDecodeError:
        raise RecordingError(path, "not UTF-8 text (is this the right file type?)") from None
    except (OSError, EOFError) as exc:
        raise RecordingError(path, f"cannot read: {exc}") from None
    except csv.Error as exc:
        raise RecordingError(path, f"malformed CSV: {exc}") from None
    if not header or not any(header):
        raise RecordingError(path, "file is empty (no header row)")
    if len(set(header)) != len(header):
        dup = next(h for h in header if header.count(h) > 1)
        raise RecordingError(path, "duplicated column", column=dup)
    if not rows:
        raise RecordingError(path, "no data rows")
    width = len(header)
    for i, r in enumerate(rows):
        if len(r) != width:
            raise RecordingError(path, f"has {len(r)} fields, the header has {width}", row=i + 1)
    cells = [[c if c.strip() else "nan" for c in r] for r in rows]
    try:
        data = np.array(cells, dtype=float)
    except ValueError:
        for i, r in enumerate(cells):
            for j, cell in enumerate(r):
                try:
                    float(cell)
                except ValueError:
                    raise RecordingError(
                        path, f"not a number: {cell!r}", column=header[j], row=i + 1
                    ) from None
        raise
    return {h: data[:, i] for i, h in enumerate(header)}


def require_columns(path, table: dict, names) -> None:
    """Raise naming the first of ``names`` missing from ``table``."""
    for name in names:
        if name not in table:
            raise RecordingError(
                path, "missing (this importer needs it; see docs/importers.md)", column=name
            )


def require_finite(path, table: dict, names) -> None:
    """Raise naming the first NaN/inf cell among the columns ``names``."""
    for name in names:
        bad = np.flatnonzero(~np.isfinite(table[name]))
        if bad.size:
            raise RecordingError(
                path, f"NaN or inf value ({table[name][bad[0]]})", column=name, row=int(bad[0]) + 1
            )


def increasing_time_mask(t: np.ndarray) -> np.ndarray:
    """Mask keeping the first sample of each run of equal or backward time stamps, so the
    kept times are strictly increasing (gaps are kept)."""
    keep = np.ones(len(t), dtype=bool)
    if len(t) == 0:
        return keep
    last = t[0]
    # Vectorised when already monotone; the loop only runs for logs with backward jumps.
    if np.all(np.diff(t) > 0):
        return keep
    for i in range(1, len(t)):
        if t[i] > last:
            last = t[i]
        else:
            keep[i] = False
    return keep


def running_span(commands: np.ndarray, threshold: float = 0.0) -> tuple[int, int] | None:
    """``(first, last + 1)`` indices of the rows where any command exceeds ``threshold``, or
    None when the motors never run."""
    on = np.flatnonzero(np.any(commands > threshold, axis=1))
    if on.size == 0:
        return None
    return int(on[0]), int(on[-1]) + 1


def trim_to_flight(
    path,
    arrays: dict,
    commands: np.ndarray,
    keep_all: bool,
    *,
    threshold: float = 0.0,
    never: str = "the motors never run",
    rows: str = "with the motors running",
) -> tuple[dict, tuple, int]:
    """The rows of a log's flight: drops the samples whose time stamp does not increase
    (:func:`increasing_time_mask`), finds the span where any of ``commands`` (one row per
    sample, before the drop) exceeds ``threshold`` (:func:`running_span`) and, unless
    ``keep_all``, keeps only that span. Returns ``(arrays, (t_first, t_last), dropped)``: the
    kept arrays, the span's first and last time stamps and the number of samples dropped.
    Raises naming ``path`` when nothing runs (``never``) or fewer than 20 rows remain (``rows``
    names them)."""
    keep = increasing_time_mask(arrays["t"])
    dropped = int(np.sum(~keep))
    arrays = select(keep, arrays)
    span = running_span(np.asarray(commands)[keep], threshold)
    if span is None:
        raise ConfigError(f"{path}: {never}")
    t_run = (float(arrays["t"][span[0]]), float(arrays["t"][span[1] - 1]))
    if not keep_all:
        arrays = select(slice(*span), arrays)
    if len(arrays["t"]) < 20:
        raise ConfigError(f"{path}: only {len(arrays['t'])} rows {rows}")
    return arrays, t_run, dropped


def gap_stats(t: np.ndarray, factor: float = 2.5) -> dict:
    """Sampling description: median period [s], rate [Hz], number and largest gap, where a gap
    is a step longer than ``factor`` median periods."""
    if len(t) < 2:
        return {"median_dt": None, "rate_hz": None, "gaps": 0, "max_gap_s": None}
    dt = np.diff(t)
    med = float(np.median(dt))
    gaps = int(np.sum(dt > factor * med))
    return {
        "median_dt": med,
        "rate_hz": 1.0 / med if med > 0 else None,
        "gaps": gaps,
        "max_gap_s": float(dt.max()),
    }


def select(mask_or_slice, arrays: dict) -> dict:
    """Apply a row selection to every array of a dict (None stays None)."""
    return {k: (None if v is None else v[mask_or_slice]) for k, v in arrays.items()}


def summary_line(rec) -> str:
    """One line: rows, duration, rate, gaps, dropped samples, what is missing."""
    meta = rec.meta
    g = gap_stats(rec.t)
    parts = [
        f"{len(rec)} rows",
        f"{rec.duration:.2f} s",
        f"{g['rate_hz']:.0f} Hz" if g["rate_hz"] else "rate n/a",
        f"{g['gaps']} gaps (max {g['max_gap_s'] * 1e3:.1f} ms)" if g["gaps"] else "no gaps",
    ]
    dropped = meta.get("import", {}).get("dropped_duplicate_times", 0)
    if dropped:
        parts.append(f"{dropped} duplicate time stamps dropped")
    missing = meta.get("import", {}).get("missing", [])
    parts.append("missing: " + "; ".join(missing) if missing else "nothing missing")
    return ", ".join(parts)
