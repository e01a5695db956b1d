"""Generators of broken recordings, shared by the reliability tests and the fuzz benchmark.

A *case* is a CSV payload plus an optional sidecar payload (bytes; ``None`` = no sidecar)
built from one small valid recording (a noise-free hover, :func:`valid_recording`) by one
named mutation. Every mutation here produces a file that breaks ``quadfault-recording/1``
(docs/formats.md), so a reader must reject it with a one-line error; ``expect`` lists the
fragments that error must contain (which column / key / row), the file name being added by
:func:`write_case`. Nothing here reads the true efficiency or any truth.
"""

from __future__ import annotations

import contextlib
import gzip
import json
import signal
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadfault.io.recording import FORMAT, POSE_COLUMNS, RATE_COLUMNS
from quadfault.model.vehicle import PAPER_GRAVITY, PAPER_INERTIA, PAPER_MASS, paper_allocation


class Hang(BaseException):
    """Raised by :func:`time_limit`; a BaseException so that no ``except OSError`` /
    ``except Exception`` in the code under test can mistake a hang for a clean error."""


@contextlib.contextmanager
def time_limit(seconds: float):
    """Raise :class:`Hang` when the block runs longer than ``seconds`` (main thread, POSIX)."""

    def _raise(signum, frame):
        raise Hang(f"took longer than {seconds} s")

    previous = signal.signal(signal.SIGALRM, _raise)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


#: Columns of the valid base recording (pose + rates + thrust commands).
BASE_COLUMNS = ("t", *POSE_COLUMNS, *RATE_COLUMNS, "f1", "f2", "f3", "f4")
#: Columns every base row must carry (all of them; errors must name the broken one).
REQUIRED_COLUMNS = BASE_COLUMNS
#: Cells that are not numbers for Python's ``float`` (the reader must say where they are).
NOT_NUMBERS = ("abc", "", "1.2.3", "one", "#", "[1]", "0x10", "1,5", "--1", "true", "None", "1e")
#: Cells that parse as numbers but are not finite.
NOT_FINITE = ("nan", "NaN", "inf", "-inf", "Infinity", "1e999", "-1e400")


@dataclass(frozen=True)
class BadCase:
    """One broken recording.

    Attributes:
        name: the mutation that produced it.
        csv: bytes of the CSV file (possibly empty or not text).
        sidecar: bytes of the JSON sidecar, or None for a missing sidecar.
        expect: fragments the error message must contain (besides the file name).
        blame: "csv" or "sidecar": the file the error must name.
        gz: write the CSV gzip-compressed (``.csv.gz``).
    """

    name: str
    csv: bytes
    sidecar: bytes | None
    expect: tuple = ()
    blame: str = "csv"
    gz: bool = False
    note: str = field(default="", compare=False)


def valid_recording(rows: int = 40, rate: float = 100.0) -> tuple[list[str], list[list[str]], dict]:
    """A small valid recording: the paper vehicle hovering 1 m up, noise-free.

    Returns ``(header, rows as lists of cell strings, sidecar dict)``.
    """
    f = PAPER_MASS * PAPER_GRAVITY / 4.0
    table = []
    for k in range(rows):
        t = k / rate
        values = [t, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, f, f, f, f]
        table.append([repr(float(v)) for v in values])
    side = {
        "format": FORMAT,
        "frame": "NED",
        "gravity": PAPER_GRAVITY,
        "vehicle": {
            "mass": PAPER_MASS,
            "inertia": list(PAPER_INERTIA),
            "allocation": paper_allocation().tolist(),
        },
        "source": "fuzzing hover",
    }
    return list(BASE_COLUMNS), table, side


def csv_bytes(header, rows) -> bytes:
    return ("\n".join(",".join(r) for r in [header, *rows]) + "\n").encode("utf-8")


def json_bytes(obj) -> bytes:
    return json.dumps(obj).encode("utf-8")


def _col(header, rng, columns=REQUIRED_COLUMNS) -> tuple[int, str]:
    name = str(rng.choice(list(columns)))
    return header.index(name), name


# -- CSV mutations ---------------------------------------------------------------------------
def _empty(rng, header, rows, side):
    return BadCase("empty_csv", b"", json_bytes(side), ("empty",))


def _header_only(rng, header, rows, side):
    return BadCase("header_only", csv_bytes(header, []), json_bytes(side), ("no data rows",))


def _one_row(rng, header, rows, side):
    return BadCase("one_row", csv_bytes(header, rows[:1]), json_bytes(side), ("at least 2 rows",))


def _truncated(rng, header, rows, side):
    """Cut the file inside a data row, before that row's last comma (a short last row)."""
    k = int(rng.integers(2, len(rows)))
    head = csv_bytes(header, rows[:k])
    line = ",".join(rows[k])
    commas = [i for i, ch in enumerate(line) if ch == ","]
    cut = int(rng.integers(0, commas[-1] + 1))  # keeps fewer fields than the header
    data = head + line[:cut].encode()
    n_fields = line[:cut].count(",") + 1
    return BadCase("truncated", data, json_bytes(side), (f"row {k + 1}", f"has {n_fields} fields"))


def _truncated_header(rng, header, rows, side):
    line = ",".join(header)
    cut = int(rng.integers(1, len(line) - 4))
    return BadCase("truncated_header", line[:cut].encode(), json_bytes(side), ())


def _not_a_number(rng, header, rows, side):
    rows = [list(r) for r in rows]
    j, name = _col(header, rng)
    k = int(rng.integers(0, len(rows)))
    token = str(rng.choice(NOT_NUMBERS))
    if "," in token:
        token = f'"{token}"'
    rows[k][j] = token
    return BadCase(
        "not_a_number",
        csv_bytes(header, rows),
        json_bytes(side),
        (f"column '{name}'", f"row {k + 1}"),
    )


def _not_finite(rng, header, rows, side):
    rows = [list(r) for r in rows]
    j, name = _col(header, rng)
    k = int(rng.integers(0, len(rows)))
    rows[k][j] = str(rng.choice(NOT_FINITE))
    return BadCase(
        "not_finite",
        csv_bytes(header, rows),
        json_bytes(side),
        (f"column '{name}'", f"row {k + 1}"),
    )


def _time_repeat(rng, header, rows, side):
    rows = [list(r) for r in rows]
    k = int(rng.integers(1, len(rows)))
    rows[k][0] = rows[k - 1][0]
    return BadCase(
        "duplicated_time", csv_bytes(header, rows), json_bytes(side), ("column 't'", f"row {k + 1}")
    )


def _time_backwards(rng, header, rows, side):
    rows = [list(r) for r in rows]
    k = int(rng.integers(1, len(rows)))
    rows[k][0] = repr(float(rows[k - 1][0]) - float(rng.uniform(1e-6, 1.0)))
    return BadCase(
        "decreasing_time", csv_bytes(header, rows), json_bytes(side), ("column 't'", f"row {k + 1}")
    )


def _quaternion_scale(rng, header, rows, side):
    rows = [list(r) for r in rows]
    k = int(rng.integers(0, len(rows)))
    scale = float(rng.choice([rng.uniform(0.0, 0.99), rng.uniform(1.01, 100.0), 0.0]))
    q = rng.standard_normal(4)
    q = scale * q / np.linalg.norm(q)
    for i, c in enumerate(("qw", "qx", "qy", "qz")):
        rows[k][header.index(c)] = repr(float(q[i]))
    return BadCase(
        "quaternion_norm",
        csv_bytes(header, rows),
        json_bytes(side),
        ("column 'qw'", f"row {k + 1}", "quaternion norm"),
    )


def _drop_column(rng, header, rows, side):
    j, name = _col(header, rng, ("t", "wx", "wy", "wz", "f1", "f2", "f3", "f4", "px", "qw", "vz"))
    header = [h for i, h in enumerate(header) if i != j]
    rows = [[c for i, c in enumerate(r) if i != j] for r in rows]
    return BadCase("missing_column", csv_bytes(header, rows), json_bytes(side), ("missing",))


def _duplicate_column(rng, header, rows, side):
    j, name = _col(header, rng)
    header = list(header) + [name]
    rows = [list(r) + [r[j]] for r in rows]
    return BadCase(
        "duplicated_column",
        csv_bytes(header, rows),
        json_bytes(side),
        (f"column '{name}'", "duplicated"),
    )


def _extra_field(rng, header, rows, side):
    rows = [list(r) for r in rows]
    k = int(rng.integers(0, len(rows)))
    rows[k] = rows[k] + ["0.0"] * int(rng.integers(1, 4))
    return BadCase(
        "extra_field", csv_bytes(header, rows), json_bytes(side), (f"row {k + 1}", "fields")
    )


def _not_utf8(rng, header, rows, side):
    data = bytearray(csv_bytes(header, rows))
    pos = int(rng.integers(len(",".join(header)) + 1, len(data) - 1))
    data[pos:pos] = bytes([0xFF, 0xFE, 0xC3])
    return BadCase("not_utf8", bytes(data), json_bytes(side), ("UTF-8",))


def _binary_garbage(rng, header, rows, side):
    n = int(rng.integers(1, 4096))
    return BadCase(
        "binary_garbage", rng.integers(0, 256, n, dtype=np.uint8).tobytes(), json_bytes(side), ()
    )


def _truncated_gzip(rng, header, rows, side):
    data = gzip.compress(csv_bytes(header, rows))
    cut = int(rng.integers(10, len(data) - 8))
    return BadCase("truncated_gzip", data[:cut], json_bytes(side), (), gz=True)


# -- sidecar mutations -----------------------------------------------------------------------
def _side(name, header, rows, side, expect):
    return BadCase(
        name,
        csv_bytes(header, rows),
        json_bytes(side) if not isinstance(side, bytes) else side,
        expect,
        blame="sidecar",
    )


def _missing_sidecar(rng, header, rows, side):
    return BadCase(
        "missing_sidecar",
        csv_bytes(header, rows),
        None,
        ("sidecar JSON not found",),
        blame="sidecar",
    )


def _truncated_sidecar(rng, header, rows, side):
    text = json_bytes(side)
    cut = int(rng.integers(0, len(text) - 1))
    return _side("truncated_sidecar", header, rows, text[:cut], ("invalid JSON",))


def _sidecar_not_object(rng, header, rows, side):
    other = [[1, 2], "text", 3.5, None, True][int(rng.integers(0, 5))]
    return _side("sidecar_not_object", header, rows, other, ("JSON object",))


def _bad_format_or_frame(rng, header, rows, side):
    side = json.loads(json.dumps(side))
    key = str(rng.choice(["format", "frame"]))
    side[key] = [None, "quadfault-recording/2", "ned", 1, ""][int(rng.integers(0, 5))]
    if rng.uniform() < 0.3:
        del side[key]
    return _side("bad_" + key, header, rows, side, (f"key '{key}'",))


#: vehicle keys -> generators of values that break them
_ABSURD = {
    "mass": lambda rng: [
        0,
        -1.0,
        -rng.uniform(0, 10),
        float("nan"),
        float("inf"),
        "1.0",
        None,
        True,
        [1.0],
    ][int(rng.integers(0, 9))],
    "gravity": lambda rng: [0, -9.81, float("nan"), "g"][int(rng.integers(0, 4))],
    "inertia": lambda rng: [
        [1.0, 2.0],
        [0.0, 0.0, 0.0],
        [-0.01, 0.01, 0.02],
        [[1, 2, 3], [4, 5, 6], [7, 8, 9]],
        "diag",
        [float("nan"), 1, 1],
        [[0.01, 0.5, 0], [0, 0.01, 0], [0, 0, 0.02]],
    ][int(rng.integers(0, 7))],
    "max_thrust": lambda rng: [0, -2.0, float("nan"), "max"][int(rng.integers(0, 4))],
}


def _absurd_vehicle(rng, header, rows, side):
    side = json.loads(json.dumps(side))
    key = str(rng.choice(list(_ABSURD)))
    value = _ABSURD[key](rng)
    if key == "gravity":
        side["gravity"] = value
        expect = ("key 'gravity'",)
    else:
        side["vehicle"][key] = value
        expect = ("vehicle",)
    if key == "mass" and rng.uniform() < 0.2:
        del side["vehicle"]["mass"]
    return _side(f"absurd_{key}", header, rows, side, expect)


def _singular_allocation(rng, header, rows, side):
    side = json.loads(json.dumps(side))
    A = np.array(side["vehicle"]["allocation"])
    kind = int(rng.integers(0, 5))
    if kind == 0:
        A[int(rng.integers(0, 4))] = 0.0  # a wrench row the rotors cannot produce
    elif kind == 1:
        i, j = rng.choice(4, size=2, replace=False)
        A[:, j] = A[:, i]  # two rotors identical
    elif kind == 2:
        A = np.outer(rng.standard_normal(4), rng.standard_normal(4))  # rank 1
    elif kind == 3:
        A = A[:, :3]  # three rotor columns
    else:
        A[int(rng.integers(0, 4)), int(rng.integers(0, 4))] = float("nan")
    side["vehicle"]["allocation"] = A.tolist()
    return _side("singular_allocation", header, rows, side, ("vehicle",))


def _bad_arm_layout(rng, header, rows, side):
    """The arm / torque-coefficient layout with at least one of the two broken or missing."""
    side = json.loads(json.dumps(side))
    del side["vehicle"]["allocation"]
    bad = [0.0, -0.2, float("inf"), float("nan"), "0.2", None]
    arm, torque = 0.225, 0.009012
    which = int(rng.integers(0, 4))
    if which in (0, 2):
        arm = bad[int(rng.integers(0, len(bad)))]
    if which in (1, 2):
        torque = bad[int(rng.integers(0, len(bad)))]
    side["vehicle"].update(arm=arm, torque_coefficient=torque)
    if which == 3:
        del side["vehicle"][str(rng.choice(["arm", "torque_coefficient"]))]
    return _side("bad_arm_layout", header, rows, side, ("vehicle",))


def _u_without_curve(rng, header, rows, side):
    header = ["u" + h[1:] if h in ("f1", "f2", "f3", "f4") else h for h in header]
    return _side("u_without_thrust_curve", header, rows, side, ("key 'vehicle'", "thrust"))


CSV_MUTATIONS = (
    _empty,
    _header_only,
    _one_row,
    _truncated,
    _truncated_header,
    _not_a_number,
    _not_finite,
    _time_repeat,
    _time_backwards,
    _quaternion_scale,
    _drop_column,
    _duplicate_column,
    _extra_field,
    _not_utf8,
    _binary_garbage,
    _truncated_gzip,
)
SIDECAR_MUTATIONS = (
    _missing_sidecar,
    _truncated_sidecar,
    _sidecar_not_object,
    _bad_format_or_frame,
    _absurd_vehicle,
    _singular_allocation,
    _bad_arm_layout,
    _u_without_curve,
)
MUTATIONS = CSV_MUTATIONS + SIDECAR_MUTATIONS
MUTATION_NAMES = tuple(m.__name__.lstrip("_") for m in MUTATIONS)


def bad_case(rng: np.random.Generator, mutation: int | None = None, rows: int = 40) -> BadCase:
    """One broken recording; ``mutation`` indexes :data:`MUTATIONS` (random if None)."""
    header, table, side = valid_recording(rows)
    k = int(rng.integers(0, len(MUTATIONS))) if mutation is None else mutation
    return MUTATIONS[k](rng, header, table, side)


def write_case(case: BadCase, folder, stem: str = "flight") -> tuple[Path, Path]:
    """Write ``case`` into ``folder``; returns ``(csv path, sidecar path)``."""
    folder = Path(folder)
    csv_path = folder / (f"{stem}.csv.gz" if case.gz else f"{stem}.csv")
    side_path = folder / f"{stem}.json"
    csv_path.write_bytes(case.csv)
    if case.sidecar is not None:
        side_path.write_bytes(case.sidecar)
    return csv_path, side_path


def error_is_clean(message: str, case: BadCase, csv_path: Path, side_path: Path) -> str | None:
    """None when ``message`` is a proper one-line error for ``case``, else what is wrong."""
    if "\n" in message.strip():
        return "more than one line"
    if "Traceback" in message:
        return "traceback"
    blamed = side_path if case.blame == "sidecar" else csv_path
    if blamed.name not in message:
        return f"does not name {blamed.name}"
    for frag in case.expect:
        if frag not in message:
            return f"does not say {frag!r}"
    return None
