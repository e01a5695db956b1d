"""Decoder of the blackbox log format of Betaflight, INDIflight and their kin (``.bfl``,
``.bbl``), written from the format's description (Cleanflight's "Blackbox internals" and the
header a log carries); no third-party decoder is used.

A file holds one or more logs, each starting with ``H Product:Blackbox flight data recorder``.
A log is a text header of ``H name:value`` lines, then binary frames, each one byte of frame
type then its fields:

- ``I`` (intra) frames carry every main field, ``P`` (inter) frames the same fields predicted
  from the previous one or two main frames; ``S`` slow, ``G`` GPS, ``H`` GPS home and ``E``
  event frames carry the rest. The header's ``Field X name/signed/predictor/encoding`` lines
  define each frame type's fields.
- Encodings: 0 signed variable byte (zig-zag), 1 unsigned variable byte, 3 negative 14-bit,
  6 tag8_8svb (up to 8 fields, a bitmap byte then the non-zero ones), 7 tag2_3s32 and 10
  tag2_3svariable (3 fields, sizes in the lead byte), 8 tag8_4s16 (4 fields, 2-bit sizes,
  data version 2 nibble packing), 9 null.
- Predictors: 0 none, 1 previous, 2 straight line, 3 average of the last two, 4 minthrottle,
  5 motor[0] of this frame, 6 increment (loop iteration), 7 GPS home, 8 1500, 9 vbatref,
  10 the last main frame's time, 11 the low end of motorOutput.

A frame is accepted when the byte after it starts a frame (or the log ends); otherwise it is
corrupt, decoding resumes at the next frame-type byte, and P frames wait for the next I
frame. The decoding loop is compiled (:mod:`quadfault.jit`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadfault.jit import jit

PRODUCT = b"H Product:Blackbox flight data recorder"
FRAME_I, FRAME_P, FRAME_S, FRAME_G, FRAME_H, FRAME_E = (ord(c) for c in "IPSGHE")
EVENT_SYNC_BEEP, EVENT_INFLIGHT_ADJUSTMENT, EVENT_LOGGING_RESUME = 0, 13, 14
EVENT_DISARM, EVENT_FLIGHT_MODE, EVENT_LOG_END = 15, 30, 255
ENC_SVB, ENC_UVB, ENC_NEG14, ENC_TAG8_8SVB, ENC_TAG2_3S32 = 0, 1, 3, 6, 7
ENC_TAG8_4S16, ENC_NULL, ENC_TAG2_3SVAR = 8, 9, 10
PRED_ZERO, PRED_PREVIOUS, PRED_STRAIGHT, PRED_AVERAGE2, PRED_MINTHROTTLE = 0, 1, 2, 3, 4
PRED_MOTOR0, PRED_INCREMENT, PRED_HOME, PRED_1500, PRED_VBATREF = 5, 6, 7, 8, 9
PRED_LAST_TIME, PRED_MINMOTOR = 10, 11


@dataclass(frozen=True)
class FrameDef:
    """Fields of one frame type: names, signedness, predictors, encodings."""

    names: tuple
    signed: np.ndarray
    predictor: np.ndarray
    encoding: np.ndarray

    @staticmethod
    def empty() -> FrameDef:
        z = np.zeros(0, dtype=np.int64)
        return FrameDef((), z, z, z)


@dataclass(frozen=True)
class BlackboxLog:
    """One decoded log.

    Attributes:
        header: ``{name: value}`` text of the ``H`` lines.
        main_names: main (I/P) field names; ``main``: (n, fields) int64 values.
        slow_names, slow: slow-frame fields and values; ``slow_at``: index of the main frame
            each slow frame follows (-1: before the first).
        events: (k, 3) int64 rows ``(main index, event type, value)``.
        corrupt: number of frames dropped as corrupt.
        size: bytes of the log in its file.
        skipped_bytes: bytes between whole frames that were skipped (corrupt or unknown).
        tail_bytes: bytes after the last whole frame (a cut log's unfinished frame).
        ended: the log has its end-of-log event (a log cut short has not).
    """

    header: dict
    main_names: tuple
    main: np.ndarray
    slow_names: tuple
    slow: np.ndarray
    slow_at: np.ndarray
    events: np.ndarray
    corrupt: int
    size: int
    skipped_bytes: int = 0
    tail_bytes: int = 0
    ended: bool = True

    def field(self, name: str) -> np.ndarray | None:
        """The main field ``name`` as float, or None."""
        if name in self.main_names:
            return self.main[:, self.main_names.index(name)].astype(float)
        return None


# ----------------------------------------------------------------------------------------
# the compiled byte-level decoder
@jit
def _uvb(buf, pos):
    """Unsigned variable-byte integer at ``pos``: (value, next pos), pos -1 on error."""
    result = 0
    shift = 0
    for _ in range(5):
        if pos >= len(buf):
            return 0, -1
        b = np.int64(buf[pos])
        pos += 1
        result |= (b & 0x7F) << shift
        if b < 128:
            return result, pos
        shift += 7
    return 0, -1


@jit
def _zigzag(v):
    return (v >> 1) ^ -(v & 1)


@jit
def _svb(buf, pos):
    v, pos = _uvb(buf, pos)
    return _zigzag(v), pos


@jit
def _sx(v, bits):
    """Sign-extend the low ``bits`` of ``v``."""
    m = 1 << (bits - 1)
    v = v & ((1 << bits) - 1)
    return (v ^ m) - m


@jit
def _byte(buf, pos):
    if pos >= len(buf):
        return np.int64(0), -1
    return np.int64(buf[pos]), pos + 1


@jit
def _sized(buf, pos, selector, out, k):
    """Three values of 8/16/24/32 bits (little-endian) chosen by 2-bit selectors."""
    for i in range(3):
        s = selector & 3
        n = s + 1
        if pos + n > len(buf):
            return -1
        v = 0
        for j in range(n):
            v |= np.int64(buf[pos + j]) << (8 * j)
        out[k + i] = _sx(v, 8 * n)
        pos += n
        selector >>= 2
    return pos


@jit
def _tag2_3s32(buf, pos, out, k):
    lead, pos = _byte(buf, pos)
    if pos < 0:
        return -1
    kind = lead >> 6
    if kind == 0:
        out[k] = _sx(lead >> 4, 2)
        out[k + 1] = _sx(lead >> 2, 2)
        out[k + 2] = _sx(lead, 2)
    elif kind == 1:
        out[k] = _sx(lead, 4)
        b, pos = _byte(buf, pos)
        if pos < 0:
            return -1
        out[k + 1] = _sx(b >> 4, 4)
        out[k + 2] = _sx(b, 4)
    elif kind == 2:
        out[k] = _sx(lead, 6)
        for i in range(1, 3):
            b, pos = _byte(buf, pos)
            if pos < 0:
                return -1
            out[k + i] = _sx(b, 6)
    else:
        pos = _sized(buf, pos, lead, out, k)
    return pos


@jit
def _tag2_3svariable(buf, pos, out, k):
    lead, pos = _byte(buf, pos)
    if pos < 0:
        return -1
    kind = lead >> 6
    if kind == 0:
        out[k] = _sx(lead >> 4, 2)
        out[k + 1] = _sx(lead >> 2, 2)
        out[k + 2] = _sx(lead, 2)
    elif kind == 1:  # 5-5-4 bits
        b1, pos = _byte(buf, pos)
        if pos < 0:
            return -1
        out[k] = _sx((lead & 0x3E) >> 1, 5)
        out[k + 1] = _sx(((lead & 0x01) << 4) | (b1 >> 4), 5)
        out[k + 2] = _sx(b1, 4)
    elif kind == 2:  # 8-7-7 bits
        b1, pos = _byte(buf, pos)
        if pos < 0:
            return -1
        b2, pos = _byte(buf, pos)
        if pos < 0:
            return -1
        out[k] = _sx(((lead & 0x3F) << 2) | (b1 >> 6), 8)
        out[k + 1] = _sx(((b1 & 0x3F) << 1) | (b2 >> 7), 7)
        out[k + 2] = _sx(b2, 7)
    else:
        pos = _sized(buf, pos, lead, out, k)
    return pos


@jit
def _tag8_4s16(buf, pos, out, k):
    selector, pos = _byte(buf, pos)
    if pos < 0:
        return -1
    nibble = False
    held = np.int64(0)
    for i in range(4):
        v = np.int64(0)
        s = selector & 3
        if s == 0:
            v = 0
        elif s == 1:
            if not nibble:
                held, pos = _byte(buf, pos)
                v = _sx(held >> 4, 4)
                nibble = True
            else:
                v = _sx(held, 4)
                nibble = False
        elif s == 2:
            if not nibble:
                b, pos = _byte(buf, pos)
                v = _sx(b, 8)
            else:
                c = (held << 4) & 0xFF
                held, pos = _byte(buf, pos)
                v = _sx(c | (held >> 4), 8)
        else:
            if not nibble:
                b1, pos = _byte(buf, pos)
                b2 = np.int64(0)
                if pos >= 0:
                    b2, pos = _byte(buf, pos)
                v = _sx((b1 << 8) | b2, 16)
            else:
                c1 = (held << 4) & 0xFF
                held, pos = _byte(buf, pos)
                c1 |= held >> 4
                c2 = (held << 4) & 0xFF
                if pos >= 0:
                    held, pos = _byte(buf, pos)
                c2 |= held >> 4
                v = _sx((c1 << 8) | c2, 16)
        if pos < 0:
            return -1
        out[k + i] = v
        selector >>= 2
    return pos


@jit
def _read_fields(buf, pos, enc, out):
    """Raw (unpredicted) values of one frame's fields; the next pos, or -1."""
    n = len(enc)
    i = 0
    while i < n:
        e = enc[i]
        if e == ENC_SVB:
            out[i], pos = _svb(buf, pos)
            i += 1
        elif e == ENC_UVB:
            out[i], pos = _uvb(buf, pos)
            i += 1
        elif e == ENC_NEG14:
            v, pos = _uvb(buf, pos)
            out[i] = -_sx(v, 14)
            i += 1
        elif e == ENC_NULL:
            out[i] = 0
            i += 1
        elif e == ENC_TAG8_8SVB:
            c = 1
            while c < 8 and i + c < n and enc[i + c] == ENC_TAG8_8SVB:
                c += 1
            if c == 1:
                out[i], pos = _svb(buf, pos)
            else:
                head, pos = _byte(buf, pos)
                for j in range(c):
                    if pos < 0:
                        break
                    if head & 1:
                        out[i + j], pos = _svb(buf, pos)
                    else:
                        out[i + j] = 0
                    head >>= 1
            i += c
        elif e == ENC_TAG2_3S32 or e == ENC_TAG2_3SVAR or e == ENC_TAG8_4S16:
            m = 4 if e == ENC_TAG8_4S16 else 3
            if i + m > n:
                return -1
            if e == ENC_TAG2_3S32:
                pos = _tag2_3s32(buf, pos, out, i)
            elif e == ENC_TAG2_3SVAR:
                pos = _tag2_3svariable(buf, pos, out, i)
            else:
                pos = _tag8_4s16(buf, pos, out, i)
            i += m
        else:
            return -1
        if pos < 0:
            return -1
    return pos


@jit
def _predict(raw, pred, signed, prev, prev2, has_prev, consts, skipped, out):
    """Apply the predictors to ``raw`` (``consts``: minthrottle, motorOutput low, vbatref,
    motor[0] index, last main time, home 0, home 1, index of GPS_coord[0]). False when a
    predictor needs a previous frame that is missing."""
    for i in range(len(raw)):
        p = pred[i]
        v = raw[i]
        if p == PRED_ZERO:
            pass
        elif p == PRED_PREVIOUS or p == PRED_STRAIGHT or p == PRED_AVERAGE2 or p == PRED_INCREMENT:
            if not has_prev:
                return False
            if p == PRED_PREVIOUS:
                v += prev[i]
            elif p == PRED_STRAIGHT:
                v += 2 * prev[i] - prev2[i]
            elif p == PRED_AVERAGE2:
                s = prev[i] + prev2[i]
                v += int(s / 2) if signed[i] else s // 2
            else:
                v = prev[i] + skipped + 1
        elif p == PRED_MINTHROTTLE:
            v += consts[0]
        elif p == PRED_MINMOTOR:
            v += consts[1]
        elif p == PRED_VBATREF:
            v += consts[2]
        elif p == PRED_MOTOR0:
            if consts[3] < 0 or consts[3] >= i:
                return False
            v += out[consts[3]]
        elif p == PRED_LAST_TIME:
            v += consts[4]
        elif p == PRED_HOME:
            v += consts[5] if i <= consts[7] else consts[6]
        elif p == PRED_1500:
            v += 1500
        else:
            return False
        out[i] = v
    return True


@jit
def _is_marker(b):
    return (
        b == FRAME_I or b == FRAME_P or b == FRAME_S or b == FRAME_G or b == FRAME_H or b == FRAME_E
    )


@jit
def _event(buf, pos):
    """``(type, value, next pos)`` of an event frame body; pos -1 if unknown or corrupt,
    -2 at the log's end."""
    kind, pos = _byte(buf, pos)
    if pos < 0:
        return np.int64(0), np.int64(0), -1
    value = np.int64(0)
    if kind == EVENT_SYNC_BEEP or kind == EVENT_DISARM:
        value, pos = _uvb(buf, pos)
    elif kind == EVENT_INFLIGHT_ADJUSTMENT:
        func, pos = _byte(buf, pos)
        if pos >= 0:
            if func & 128:
                pos = pos + 4 if pos + 4 <= len(buf) else -1
            else:
                value, pos = _svb(buf, pos)
    elif kind == EVENT_LOGGING_RESUME:
        value, pos = _uvb(buf, pos)
        if pos >= 0:
            _, pos = _uvb(buf, pos)
    elif kind == EVENT_FLIGHT_MODE:
        value, pos = _uvb(buf, pos)
        if pos >= 0:
            _, pos = _uvb(buf, pos)
    elif kind == EVENT_LOG_END:
        return kind, value, -2
    else:
        return kind, value, -1
    return kind, value, pos


@jit
def _should_have_frame(index, i_interval, p_num, p_denom):
    return (index % i_interval + p_num - 1) % p_denom < p_num


@jit
def decode_frames(
    buf,
    start,
    defs_enc,
    defs_pred,
    defs_signed,
    sizes,
    consts,
    intervals,
    main,
    slow,
    slow_at,
    events,
    store,
):
    """Decode the frames of one log from ``buf[start:]``.

    ``defs_*``: (6, max fields) per frame type, rows I, P, S, G, H, (unused); ``sizes``:
    field count per row. ``intervals``: I interval, P num, P denom, index of the loop
    iteration and time fields. With ``store`` False only counts. Returns (main frames,
    slow frames, events, corrupt frames, bytes skipped between whole frames, bytes after
    the last whole frame, 1 if the end-of-log event was reached else 0)."""
    n_main = sizes[0]
    prev = np.zeros(n_main, dtype=np.int64)
    prev2 = np.zeros(n_main, dtype=np.int64)
    cur = np.zeros(n_main, dtype=np.int64)
    width = max(1, np.max(sizes))
    raw = np.zeros(width + 4, dtype=np.int64)
    other = np.zeros(width + 4, dtype=np.int64)
    has_prev = False
    last_iter = -1
    n_m = n_s = n_e = corrupt = 0
    gap_bytes = 0
    ended = 0
    good_end = start
    pos = start
    cst = consts.copy()
    n = len(buf)
    while pos < n:
        b = buf[pos]
        if not _is_marker(b):
            pos += 1
            continue
        frame_start = pos
        pos += 1
        ok = True
        kind = 0
        value = 0
        if b == FRAME_I or b == FRAME_P:
            row = 0 if b == FRAME_I else 1
            enc = defs_enc[row, :n_main]
            pos = _read_fields(buf, pos, enc, raw[:n_main])
            if pos < 0:
                ok = False
            else:
                skipped = 0
                if row == 1 and last_iter >= 0:
                    k = last_iter + 1
                    while (
                        not _should_have_frame(k, intervals[0], intervals[1], intervals[2])
                        and skipped < 100000
                    ):
                        skipped += 1
                        k += 1
                ok = _predict(
                    raw[:n_main],
                    defs_pred[row, :n_main],
                    defs_signed[0, :n_main],
                    prev,
                    prev2,
                    row == 0 or has_prev,
                    cst,
                    skipped,
                    cur,
                )
        elif b == FRAME_S or b == FRAME_G or b == FRAME_H:
            row = 2 if b == FRAME_S else (3 if b == FRAME_G else 4)
            m = sizes[row]
            if m == 0:
                ok = False
            else:
                pos = _read_fields(buf, pos, defs_enc[row, :m], raw[:m])
                if pos < 0:
                    ok = False
                else:
                    ok = _predict(
                        raw[:m],
                        defs_pred[row, :m],
                        defs_signed[row, :m],
                        raw[:m],
                        raw[:m],
                        True,
                        cst,
                        0,
                        other[:m],
                    )
        else:
            kind, value, pos = _event(buf, pos)
            if pos == -2:
                ended = 1
                good_end = n
                break
            if pos < 0:
                ok = False
        if ok and pos < n and not _is_marker(buf[pos]):
            ok = False
        if not ok:
            corrupt += 1
            has_prev = False
            pos = frame_start + 1
            continue
        if frame_start > good_end:
            gap_bytes += frame_start - good_end
        good_end = pos
        if b == FRAME_I or b == FRAME_P:
            if store:
                main[n_m, :] = cur
            if b == FRAME_P:
                prev2[:] = prev
            else:
                prev2[:] = cur
            prev[:] = cur
            has_prev = True
            if intervals[3] >= 0:
                last_iter = cur[intervals[3]]
            if intervals[4] >= 0:
                cst[4] = cur[intervals[4]]
            n_m += 1
        elif b == FRAME_S:
            if store:
                slow[n_s, : sizes[2]] = other[: sizes[2]]
                slow_at[n_s] = n_m - 1
            n_s += 1
        elif b == FRAME_H:
            cst[5] = other[0]
            cst[6] = other[1] if sizes[4] > 1 else 0
        elif b == FRAME_E:
            if store:
                events[n_e, 0] = n_m - 1
                events[n_e, 1] = kind
                events[n_e, 2] = value
            n_e += 1
            if kind == EVENT_LOGGING_RESUME:
                has_prev = False
    return n_m, n_s, n_e, corrupt, gap_bytes, n - good_end, ended


# ----------------------------------------------------------------------------------------
def split_logs(data: bytes) -> list:
    """``[(start, end)]`` byte spans of the logs in a file."""
    starts = []
    i = data.find(PRODUCT)
    while i >= 0:
        starts.append(i)
        i = data.find(PRODUCT, i + 1)
    return [(a, b) for a, b in zip(starts, starts[1:] + [len(data)])]


def parse_header(data: bytes, start: int) -> tuple:
    """``({name: value}, offset of the first frame)`` of the log at ``start``."""
    header = {}
    pos = start
    while data.startswith(b"H ", pos):
        end = data.find(b"\n", pos)
        if end < 0:
            break
        line = data[pos + 2 : end].decode("latin-1")
        name, _, value = line.partition(":")
        header[name.strip()] = value.strip()
        pos = end + 1
    return header, pos


def frame_def(header: dict, kind: str) -> FrameDef:
    """The fields of frame type ``kind`` from the header (P frames take I's names)."""
    names = header.get(f"Field {kind} name") or (
        header.get("Field I name") if kind == "P" else None
    )
    if not names:
        return FrameDef.empty()
    names = tuple(names.split(","))

    def ints(key, default=0):
        text = header.get(f"Field {kind} {key}")
        if not text:
            return np.full(len(names), default, dtype=np.int64)
        vals = [int(x) for x in text.split(",")]
        vals = (vals + [default] * len(names))[: len(names)]
        return np.asarray(vals, dtype=np.int64)

    return FrameDef(names, ints("signed"), ints("predictor"), ints("encoding"))


def _number(text, default=0):
    try:
        return int(str(text).split(",")[0])
    except ValueError:
        return default


def decode_log(data: bytes, start: int, end: int) -> BlackboxLog:
    """Decode the log occupying ``data[start:end]``."""
    header, first = parse_header(data, start)
    defs = [frame_def(header, k) for k in "IPSGH"]
    if not defs[0].names:
        raise ValueError("the header has no 'Field I name' line")
    width = max(len(d.names) for d in defs)
    enc = np.full((6, width), ENC_NULL, dtype=np.int64)
    pred = np.zeros((6, width), dtype=np.int64)
    sign = np.zeros((6, width), dtype=np.int64)
    sizes = np.zeros(6, dtype=np.int64)
    for r, d in enumerate(defs):
        m = len(d.names)
        sizes[r] = m
        enc[r, :m], pred[r, :m], sign[r, :m] = d.encoding, d.predictor, d.signed
    names = defs[0].names
    motor0 = names.index("motor[0]") if "motor[0]" in names else -1
    gps = defs[3].names
    coord0 = gps.index("GPS_coord[0]") if "GPS_coord[0]" in gps else -1
    consts = np.array(
        [
            _number(header.get("minthrottle")),
            _number(header.get("motorOutput")),
            _number(header.get("vbatref")),
            motor0,
            0,
            0,
            0,
            coord0,
        ],
        dtype=np.int64,
    )
    p_text = header.get("P interval", "1")
    p_num, _, p_den = p_text.partition("/")
    p_num, p_den = (_number(p_num, 1), _number(p_den, 1)) if p_den else (1, _number(p_num, 1))
    intervals = np.array(
        [
            max(1, _number(header.get("I interval"), 1)),
            max(1, p_num),
            max(1, p_den),
            names.index("loopIteration") if "loopIteration" in names else -1,
            names.index("time") if "time" in names else -1,
        ],
        dtype=np.int64,
    )
    buf = np.frombuffer(data, dtype=np.uint8)[:end]
    empty2 = np.zeros((0, 1), dtype=np.int64)
    counts = decode_frames(
        buf,
        first,
        enc,
        pred,
        sign,
        sizes,
        consts,
        intervals,
        empty2,
        empty2,
        np.zeros(0, dtype=np.int64),
        empty2,
        False,
    )
    n_m, n_s, n_e, corrupt, gap_bytes, tail, ended = (int(c) for c in counts)
    main = np.zeros((n_m, max(1, sizes[0])), dtype=np.int64)
    slow = np.zeros((n_s, max(1, sizes[2])), dtype=np.int64)
    slow_at = np.zeros(n_s, dtype=np.int64)
    events = np.zeros((n_e, 3), dtype=np.int64)
    decode_frames(
        buf, first, enc, pred, sign, sizes, consts, intervals, main, slow, slow_at, events, True
    )
    return BlackboxLog(
        header=header,
        main_names=names,
        main=main[:, : len(names)],
        slow_names=defs[2].names,
        slow=slow[:, : len(defs[2].names)],
        slow_at=slow_at,
        events=events,
        corrupt=corrupt,
        size=end - start,
        skipped_bytes=gap_bytes,
        tail_bytes=tail,
        ended=bool(ended),
    )
