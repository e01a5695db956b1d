"""The Crazyflie uSD-deck event log as bytes: its header, event definitions and records
(:mod:`quadfault.io.importers.crazyflie_usd` makes a recording of them).

Written from Bitcraze's public description of the format (the deck's documentation; all
numbers little-endian): the byte ``0xBC``, ``uint16`` version (1: time stamps in ms,
``uint32``; 2: in us, ``uint64``), ``uint16`` number of event types, then per event type its
``uint16`` id, its name (null-terminated), ``uint16`` number of variables and each variable
as ``name(type)`` (null-terminated; the type one ``struct`` format character); then the
records: ``uint16`` event id, the time stamp, the event's variables packed in order; and a
CRC32 of everything before it when logging was stopped.

A record whose event id is not declared, or whose time stamp jumps implausibly, is corrupt
data: reading resumes at the next byte from which :data:`RESYNC_RECORDS` records in a row
parse, and what was skipped is reported.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

MAGIC = 0xBC
VERSIONS = {1: ("<I", 1e-3), 2: ("<Q", 1e-6)}  # time stamp format, seconds per count
#: variable types the firmware declares (``struct`` format characters)
TYPES = set("bBhHiIqQfde")
RESYNC_RECORDS = 8
#: a record's time stamp this far [s] before the last one, or after it, is corrupt
BACK_S, JUMP_S = 1.0, 600.0


@dataclass
class EventType:
    """One declared event: ``name``, ``variables`` (names) and the record's payload struct."""

    name: str
    variables: tuple
    payload: struct.Struct


def is_usd_log(head: bytes) -> bool:
    """Does ``head`` (the file's first bytes) start a uSD event log?"""
    if len(head) < 8 or head[0] != MAGIC:
        return False
    version, count = struct.unpack_from("<HH", head, 1)
    if version not in VERSIONS or not 0 < count < 1000:
        return False
    try:
        parse_header(head)
    except ValueError:
        return False
    except (struct.error, IndexError):  # cut inside the header: the importer says so
        return True
    return True


def _cstring(data: bytes, pos: int) -> tuple:
    end = data.find(b"\x00", pos)
    if end < 0:
        raise IndexError("the header ends inside a name")
    return data[pos:end].decode("ascii"), end + 1


def parse_header(data: bytes) -> tuple:
    """``(version, {event id: EventType}, first record's offset)``; ValueError when the
    bytes are not a uSD event log's header."""
    if not data or data[0] != MAGIC:
        raise ValueError("no 0xBC header byte")
    version, count = struct.unpack_from("<HH", data, 1)
    if version not in VERSIONS:
        raise ValueError(f"unknown version {version}")
    pos, events = 5, {}
    for _ in range(count):
        (eid,) = struct.unpack_from("<H", data, pos)
        name, pos = _cstring(data, pos + 2)
        (n_vars,) = struct.unpack_from("<H", data, pos)
        pos += 2
        names, fmt = [], "<"
        for _ in range(n_vars):
            text, pos = _cstring(data, pos)
            var, _, kind = text.rpartition("(")
            kind = kind.rstrip(")")
            if not var or kind not in TYPES:
                raise ValueError(f"event {name!r}: variable {text!r} is not name(type)")
            names.append(var)
            fmt += kind
        events[eid] = EventType(name, tuple(names), struct.Struct(fmt))
    return version, events, pos


def _record_sizes(events: dict, stamp: struct.Struct) -> dict:
    return {eid: 2 + stamp.size + ev.payload.size for eid, ev in events.items()}


def _plausible(t, last_t, per_s) -> bool:
    return last_t - BACK_S * per_s <= t <= last_t + JUMP_S * per_s


def _chain_ok(data, pos, end, sizes, stamp, last_t, per_s) -> bool:
    """Do :data:`RESYNC_RECORDS` records from ``pos`` parse (declared ids, plausible time
    stamps)?"""
    for _ in range(RESYNC_RECORDS):
        if pos + 2 + stamp.size > end:
            return pos == end
        (eid,) = struct.unpack_from("<H", data, pos)
        if eid not in sizes:
            return False
        (t,) = stamp.unpack_from(data, pos + 2)
        if not _plausible(t, last_t, per_s):
            return False
        last_t, pos = max(t, last_t), pos + sizes[eid]
    return True


def read_records(data: bytes, start: int, end: int, events: dict, version: int) -> tuple:
    """``({event id: (t [s], {variable: values})}, skipped)``: every record of
    ``data[start:end]`` by event, and what was skipped (``{"bytes", "gaps": [(t_before,
    t_after)], "tail"}``)."""
    stamp = struct.Struct(VERSIONS[version][0])
    per_s = 1.0 / VERSIONS[version][1]
    sizes = _record_sizes(events, stamp)
    offsets = {eid: [] for eid in events}
    pos, last_t, gaps, gap_bytes = start, 0, [], 0
    while pos + 2 + stamp.size <= end:
        (eid,) = struct.unpack_from("<H", data, pos)
        size = sizes.get(eid)
        if size is not None and pos + size > end:  # the last record is incomplete
            break
        t = stamp.unpack_from(data, pos + 2)[0] if size is not None else None
        if size is None or (last_t and not _plausible(t, last_t, per_s)):
            resume = pos + 1
            while resume < end and not _chain_ok(data, resume, end, sizes, stamp, last_t, per_s):
                resume += 1
            gap_bytes += resume - pos
            gaps.append([last_t, None, resume])
            pos = resume
            continue
        if gaps and gaps[-1][1] is None:
            gaps[-1][1] = t
        offsets[eid].append(pos)
        last_t, pos = max(t, last_t), pos + size
    tail = end - pos
    scale = VERSIONS[version][1]
    buf = np.frombuffer(data, dtype=np.uint8)
    out = {}
    for eid, ofs in offsets.items():
        if not ofs:
            continue
        ev = events[eid]
        ofs = np.asarray(ofs, dtype=np.int64)
        t = buf[ofs[:, None] + 2 + np.arange(stamp.size)].copy().view(f"<u{stamp.size}")
        t = t[:, 0].astype(np.float64) * scale
        dtype = np.dtype(
            {
                "names": list(ev.variables),
                "formats": ["<" + c for c in ev.payload.format[1:]],
            }
        )
        first = 2 + stamp.size
        rows = buf[ofs[:, None] + first + np.arange(ev.payload.size)].copy().view(dtype)[:, 0]
        out[eid] = (t, {v: rows[v].astype(float) for v in ev.variables})
    spans = [
        (a * scale, b * scale) for a, b, _ in gaps if b is not None and a is not None and a > 0
    ]
    return out, {"bytes": int(gap_bytes + tail), "gaps": spans, "tail": int(tail)}
