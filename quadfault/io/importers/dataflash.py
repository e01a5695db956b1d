"""ArduPilot DataFlash logs as tables: each message type's columns as numpy arrays with a time
stamp, from pymavlink's ``DFReader`` index (needs ``pymavlink``: ``pip install
'quadfault[ardupilot]'``).

pymavlink opens the log and reads its self-description (the ``FMT`` messages: each message's
name, column names and types) and indexes where every message is; the columns are then
decoded in bulk with numpy (binary ``.bin``) or line by line (text ``.log``). Every message
keeps its position in the file, which times the messages that carry no time stamp.

Time stamps [s], from the columns the message definitions give:

1. the board clock: ``TimeUS`` [us], or ``TimeMS`` [ms] -- except in a message with a GPS
   week (``Week``/``GWk``), whose ``TimeMS`` is the GPS time of week; there the board
   clock is its ``T`` [ms] where it has one;
2. without any board clock (old logs), the GPS time of week of the messages with a
   position fix (``Lat``, ``Lng``; ``TimeMS``/``GMS``/``Time`` [ms], with ``Week``/``GWk`` when
   logged, else unwrapped at the week's end), measured from its first fix;
3. every other message is timed by its place in the log (a log writes messages in time
   order): the messages of one type between two timed messages are spread evenly over the
   time between them, the first at the earlier one's time (as when a loop logs its
   messages once per cycle).

A log with neither clock fails with one line that says so.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
from pathlib import Path

import numpy as np

from quadfault.errors import QuadfaultError, RecordingError
from quadfault.io.importers import DATAFLASH_MAGIC

WEEK_MS = 604_800_000.0
_NUMPY = {
    "b": "i1",
    "B": "u1",
    "h": "<i2",
    "H": "<u2",
    "i": "<i4",
    "I": "<u4",
    "f": "<f4",
    "d": "<f8",
    "q": "<i8",
    "Q": "<u8",
    "e": "<f2",
}
_TEXT_COLUMNS = "nNZM"  # format characters of text (name, mode) columns


def open_log(path: Path):
    """``(reader, binary)``: pymavlink's reader of the log, without its own clock (quadfault
    times the messages, module docstring)."""
    try:
        from pymavlink import DFReader
    except ImportError:
        raise QuadfaultError(
            "the ArduPilot importer needs pymavlink: pip install 'quadfault[ardupilot]'"
        ) from None
    if not path.exists():
        raise RecordingError(path, "file not found")
    with open(path, "rb") as fh:
        head = fh.read(8000)
    binary = head.startswith(DATAFLASH_MAGIC)
    if not binary and b"FMT," not in head:
        raise RecordingError(
            path, "not an ArduPilot DataFlash log (no DataFlash header and no FMT lines)"
        )

    class Binary(DFReader.DFReader_binary):
        def init_clock(self):  # no pass over the whole log: time comes from the tables
            self.clock = None

    class Text(DFReader.DFReader_text):
        def init_clock(self):  # pymavlink's GPS clock fails on GPS messages without a week
            self.clock = None

    chatter = io.StringIO()
    try:
        with (
            _quiet_stderr_fd(),
            contextlib.redirect_stderr(chatter),
            contextlib.redirect_stdout(chatter),
        ):
            reader = Binary(str(path)) if binary else Text(str(path))
    except Exception as exc:  # DFReader raises bare Exceptions on corrupt logs
        raise RecordingError(path, f"not a readable DataFlash log: {exc}") from None
    return reader, binary


@contextlib.contextmanager
def _quiet_stderr_fd():
    """Silence file descriptor 2 (pymavlink's compiled indexer prints a line per byte it
    skips in a corrupt log; quadfault reports the skipped bytes once, in its warning)."""
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # not a real file (captured): nothing to do
        yield
        return
    sys.stderr.flush()
    saved = os.dup(fd)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), fd)
            yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)


def binary_table(reader, name: str) -> dict | None:
    """``{column: array, "_ofs": file offsets}`` of every ``name`` message of a binary log."""
    tid = reader.name_to_id.get(name)
    if tid is None or not reader.offsets[tid]:
        return None
    fmt = reader.formats[tid]
    from pymavlink.DFReader import FORMAT_TO_STRUCT

    names, types, mults = [], [], []
    for col, ch, mult in zip(fmt.columns, fmt.msg_fmts, fmt.msg_mults):
        code = FORMAT_TO_STRUCT[ch][0]
        names.append(col)
        types.append("S" + code[:-1] if code.endswith("s") else _NUMPY[code])
        mults.append(mult)
    dtype = np.dtype({"names": names, "formats": types})
    if dtype.itemsize != fmt.len - 3:
        return None
    buf = np.frombuffer(reader.data_map, dtype=np.uint8)
    ofs = np.asarray(reader.offsets[tid], dtype=np.int64)
    ofs = ofs[ofs + fmt.len <= len(buf)]  # a truncated last message is dropped
    rows = buf[ofs[:, None] + 3 + np.arange(fmt.len - 3)].copy().view(dtype)[:, 0]
    out = {"_ofs": ofs.astype(float)}
    for col, mult in zip(names, mults):
        if rows[col].dtype.kind == "S":
            out[col] = np.char.decode(rows[col], "latin-1")
        else:
            out[col] = rows[col].astype(float) * (mult if mult else 1.0)
    return out


def text_table(reader, name: str) -> dict | None:
    """The same for a text log: each line ``NAME, v1, v2, ...`` in its format's columns
    (text logs print values in their units: no multipliers); a line with too few values is
    skipped, a value that is not a number is NaN."""
    fmt = reader.formats.get(name)
    offsets = reader.offsets.get(name) if fmt is not None else None
    if not offsets or not fmt.columns:
        return None
    cols = fmt.columns
    is_text = [c in _TEXT_COLUMNS for c in fmt.format[: len(cols)]]
    data, sep = reader.data_map, reader.delimiter.encode()
    rows, kept = [], []
    for ofs in offsets:
        end = data.find(b"\n", ofs)
        cells = data[ofs : end if end >= 0 else len(data)].rstrip().split(sep)[1:]
        if len(cells) < len(cols):
            continue
        row = []
        for cell, txt in zip(cells, is_text):
            if txt:
                row.append(cell.strip().decode("latin-1"))
                continue
            try:
                row.append(float(cell))
            except ValueError:
                row.append(np.nan)
        rows.append(row)
        kept.append(ofs)
    if not rows:
        return None
    out = {"_ofs": np.asarray(kept, dtype=float)}
    for i, (col, txt) in enumerate(zip(cols, is_text)):
        vals = [r[i] for r in rows]
        out[col] = np.asarray(vals, dtype=object if txt else float)
    return out


def read_tables(path: Path, names, also=()) -> tuple[dict, dict, list, dict | None]:
    """``({name: table}, params, logged, skipped)``: the tables of the message types ``names``, and of every
    message type whose columns include one of the column sets ``also``, that the log has,
    untimed (:func:`set_times` times them); and the log's parameters (the values at the
    start of the log); ``logged`` names every message type with messages in the log;
    ``skipped`` what a binary log's reader skipped (:func:`skipped_bytes`; None for text)."""
    reader, binary = open_log(path)
    table = binary_table if binary else text_table
    wanted = set(names) | set(gps_time_messages(reader))
    for f in reader.formats.values():
        cols = set(getattr(f, "columns", ()))
        if any(set(group) <= cols for group in also):
            wanted.add(f.name)
    tables = {n: t for n in wanted if (t := table(reader, n)) is not None}
    parm = table(reader, "PARM") or {"Name": [], "Value": []}
    params = {}
    for k, v in zip(parm["Name"], parm["Value"]):
        if np.isfinite(v):
            params.setdefault(str(k), float(v))
    if binary:
        logged = {reader.id_to_name.get(i) for i, c in enumerate(reader.counts) if c}
    else:
        logged = {n for n, o in reader.offsets.items() if o}
    logged = sorted(n for n in logged if n and n != "FMT")
    everything = reader.offsets if binary else reader.offsets.values()
    order = np.sort(np.concatenate([np.asarray(o, dtype=float) for o in everything if o]))
    for tb in tables.values():  # file offset -> index among all messages
        tb["_seq"] = np.searchsorted(order, tb.pop("_ofs")).astype(float)
    return tables, params, logged, skipped_bytes(reader) if binary else None


def skipped_bytes(reader) -> dict:
    """What the binary reader skipped: ``{"bytes": total, "gaps": [(index of the next
    message, bytes)], "tail": bytes after the last whole message}``. pymavlink steps over
    bytes that do not start a message one at a time and stops at an unknown message type;
    every byte not inside an indexed message was skipped."""
    ofs, lens = [], []
    for tid, offsets in enumerate(reader.offsets):
        if offsets and tid in reader.formats:
            ofs.append(np.asarray(offsets, dtype=np.int64))
            lens.append(np.full(len(offsets), reader.formats[tid].len, dtype=np.int64))
    size = int(reader.data_len)
    if not ofs:
        return {"bytes": size, "gaps": [], "tail": size}
    ofs, lens = np.concatenate(ofs), np.concatenate(lens)
    order = np.argsort(ofs, kind="stable")
    ofs, ends = ofs[order], (ofs + lens)[order]
    whole = ends <= size
    tail = int(size - (ends[whole][-1] if whole.any() else 0))
    gap = ofs[1:] - ends[:-1]
    at = np.flatnonzero(gap > 0)
    gaps = [(int(i + 1), int(gap[i])) for i in at]
    lead = int(ofs[0])
    total = lead + int(gap[gap > 0].sum()) + tail
    return {"bytes": total, "gaps": ([(0, lead)] if lead else []) + gaps, "tail": tail}


def gps_time_messages(reader) -> list:
    """Message types with a GPS time of week and a position fix (module docstring, 2)."""
    out = []
    for f in reader.formats.values():
        cols = set(getattr(f, "columns", ()))
        if {"Lat", "Lng"} <= cols and cols & {"TimeMS", "GMS", "Time"}:
            out.append(f.name)
    return out


def _board_time(table: dict) -> np.ndarray | None:
    if "TimeUS" in table:
        return table["TimeUS"] * 1e-6
    if "Week" in table or "GWk" in table:  # TimeMS is GPS time of week here
        return table["T"] * 1e-3 if "T" in table else None
    if "TimeMS" in table:
        return table["TimeMS"] * 1e-3
    return None


def _gps_time(table: dict) -> np.ndarray | None:
    """GPS time [s] of a fix message (NaN where it has no time), or None."""
    ms = next((table[c] for c in ("GMS", "TimeMS", "Time") if c in table), None)
    if ms is None:
        return None
    week = next((table[c] for c in ("GWk", "Week") if c in table), None)
    ms = np.where(ms > 0, ms, np.nan)
    if week is not None:
        return (week * WEEK_MS + ms) * 1e-3
    ok = np.isfinite(ms)
    wraps = np.cumsum(np.r_[0, np.diff(ms[ok]) < -0.5 * WEEK_MS])
    out = np.full(len(ms), np.nan)
    out[ok] = (ms[ok] + wraps * WEEK_MS) * 1e-3
    return out


def _anchors(ofs: np.ndarray, t: np.ndarray) -> tuple:
    """Timed messages in log order, keeping those later than every one before them."""
    ok = np.isfinite(t)
    ofs, t = ofs[ok], t[ok]
    order = np.argsort(ofs, kind="stable")
    ofs, t = ofs[order], t[order]
    if len(t) == 0:
        return ofs, t
    keep = np.r_[True, t[1:] > np.maximum.accumulate(t)[:-1]]
    return ofs[keep], t[keep]


def set_times(tables: dict, path) -> None:
    """Give every table its ``_t`` [s] (module docstring), or fail naming what is missing."""
    own = {n: _board_time(tb) for n, tb in tables.items()}
    timed = {n: t for n, t in own.items() if t is not None}
    if timed:
        ofs = np.concatenate([tables[n]["_seq"] for n in timed])
        t = np.concatenate(list(timed.values()))
    else:
        gps = {n: g for n, tb in tables.items() if (g := _gps_time(tb)) is not None}
        if not gps or not any(np.isfinite(g).any() for g in gps.values()):
            raise RecordingError(
                path,
                "no time stamps: no message carries TimeUS or TimeMS, "
                "and no GPS message a time of week",
            )
        ofs = np.concatenate([tables[n]["_seq"] for n in gps])
        t = np.concatenate(list(gps.values()))
        t = t - np.nanmin(t)
    a_ofs, a_t = _anchors(ofs, t)
    if len(a_t) < 2:
        raise RecordingError(path, "fewer than two time stamps in the log")
    for n, tb in tables.items():
        tb["_t"] = own[n] if own.get(n) is not None else _spread(tb["_seq"], a_ofs, a_t)


def _spread(seq: np.ndarray, a_seq: np.ndarray, a_t: np.ndarray) -> np.ndarray:
    """Times [s] of untimed messages at log indices ``seq`` (module docstring, 3)."""
    before = np.searchsorted(seq, a_seq)  # messages of this type before each timed one
    last = np.r_[before[1:] != before[:-1], True]  # of timed ones with none between: the last
    xp, fp = before[last].astype(float), a_t[last]
    j = np.arange(len(seq), dtype=float)
    t = np.interp(j, xp, fp)
    if len(xp) > 1:  # before the first and after the last timed one: their neighbours' pace
        t = np.where(j < xp[0], fp[0] + (j - xp[0]) * (fp[1] - fp[0]) / (xp[1] - xp[0]), t)
        t = np.where(j > xp[-1], fp[-1] + (j - xp[-1]) * (fp[-1] - fp[-2]) / (xp[-1] - xp[-2]), t)
    return t
