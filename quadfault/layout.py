"""Named layouts of flat float arrays: one mechanism for the estimators' state and the
effects' parameters and memory.

Compiled kernels read flat arrays; this module names their entries so that no kernel writes
an offset by hand. :func:`fields` declares a list of named entries and their counts and
derives their start rows (a namedtuple of ints, which compiled code reads as constants):
``x[PARAMETERS.tau]``, ``q[MEMORY.thrust + r]``. :func:`pack` fills such an array by name,
so nothing is tied to a concatenation order; :func:`size` gives its length.

A count is an int, or one of two open counts, allowed on the last entry only (so every
start stays a constant): :data:`ROTORS` -- one value per rotor of the vehicle, bound when the
array is packed or sized -- and :data:`REST` -- any length.

An estimator's state is a list of named pieces (arrays of given shapes, :class:`Layout`). For
N estimators every piece gets a leading batch axis and the pieces are stored piece-major in
one float buffer (:class:`FlatState`); the compiled update forms each piece as a view
(:func:`piece`, :func:`piece_rows`) once per call.
"""

from __future__ import annotations

from collections import namedtuple
from typing import Any

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit

#: an open count: one value per rotor of the vehicle (last entry only)
ROTORS = "rotors"
#: an open count: any length (last entry only; also written 0)
REST = "rest"


def fields(name: str, *entries):
    """The start rows of named entries laid end to end: each entry is ``"name"`` (one row)
    or ``("name", count)``; the count of the last entry may be open, :data:`ROTORS` or
    :data:`REST` (or 0). Returns a namedtuple instance (class ``name``) of the start rows
    with a final ``size``: the rows of the fixed entries."""
    names, starts, k, open_count = [], [], 0, None
    for i, entry in enumerate(entries):
        key, count = (entry, 1) if isinstance(entry, str) else entry
        if count == 0:
            count = REST
        if count in (ROTORS, REST):
            if i != len(entries) - 1:
                raise ValueError(f"{name}: only the last entry may have an open count")
            open_count = count
            count = 0
        elif not (isinstance(count, int) and count > 0):
            raise ValueError(f"{name}.{key}: a count is a positive int, ROTORS or REST")
        names.append(key)
        starts.append(k)
        k += count
    cls = namedtuple(name, names + ["size"])
    cls.open = open_count  # the open count of the last entry (None: every count fixed)
    return cls(*starts, k)


def counts(rows) -> dict:
    """Entry -> its row count in a :func:`fields` layout (0 for an open last entry)."""
    values = list(rows)
    return {
        key: (values[i + 1] - values[i] if i + 1 < len(values) - 1 else rows.size - values[i])
        for i, key in enumerate(rows._fields[:-1])
    }


def size(rows, n_rotors: int | None = None, rest: int = 0) -> int:
    """The length of an array laid out as ``rows``: its fixed entries, plus ``n_rotors``
    values for a :data:`ROTORS` last entry, or ``rest`` for a :data:`REST` one."""
    kind = type(rows).open
    if kind == ROTORS:
        if n_rotors is None:
            raise ConfigError(f"{type(rows).__name__}: the size needs the rotor count")
        return rows.size + int(n_rotors)
    return rows.size + (int(rest) if kind == REST else 0)


def pack(rows, n_rotors: int | None = None, **values) -> np.ndarray:
    """A float array laid out as ``rows`` (:func:`fields`) with every entry given by name
    (scalars or arrays, raveled row-major); an open last entry takes ``n_rotors`` values
    (:data:`ROTORS`) or any length (:data:`REST`)."""
    sizes = counts(rows)
    what = type(rows).__name__
    if set(values) != set(sizes):
        raise ConfigError(f"{what}: entries {sorted(sizes)} expected, got {sorted(values)}")
    if type(rows).open == ROTORS:
        sizes[rows._fields[-2]] = size(rows, n_rotors) - rows.size
    out = []
    for key, count in sizes.items():
        a = np.asarray(values[key], dtype=np.float64).ravel()
        if count and a.size != count:
            raise ConfigError(f"{what}.{key}: {count} values expected, got {a.size}")
        out.append(a)
    return np.concatenate(out) if out else np.zeros(0)


def unpack(rows, array) -> dict:
    """Entry -> its values (a float, or an array for an entry of several rows) of an array
    laid out as ``rows``: the inverse of :func:`pack`."""
    a = np.asarray(array, dtype=np.float64)
    out = {}
    for key, count in counts(rows).items():
        start = getattr(rows, key)
        out[key] = (
            a[start:] if count == 0 else (a[start] if count == 1 else a[start : start + count])
        )
    return out


class Layout:
    """The pieces of a flat state: ``Layout("IRLSPieces", t=(1,), H=("m", "n", "n"))``, each
    a name and a shape whose entries are ints or dimension names bound by :meth:`shapes`.

    Attributes:
        index: a namedtuple of the pieces' positions (``index.H``), the order of the offsets.
        pieces: the namedtuple class of the pieces by name (the compiled ``state_pieces``
            returns one).
    """

    def __init__(self, name: str, **shapes):
        self.declared = dict(shapes)
        # named tuples made at run time: their fields are the declaration's names, which a
        # static checker cannot see (typed Any)
        self.pieces: Any = namedtuple(name, list(shapes))
        self.index: Any = self.pieces(*range(len(shapes)))

    def shapes(self, **dims) -> tuple:
        """The pieces' shapes with the dimensions bound (``dims``: name -> int)."""
        return tuple(
            tuple(d if isinstance(d, int) else int(dims[d]) for d in shape)
            for shape in self.declared.values()
        )


class FlatState:
    """The float and int buffers of ``num`` estimators whose state has pieces of the given
    ``shapes``, with ``n_ints`` int counters each (from a declared :class:`Layout`:
    ``FlatState(layout.shapes(**dims), num, n_ints, layout.pieces)``).

    Attributes:
        offsets: start of each piece in ``floats`` (and the total at the end), int64.
        floats: the float buffer; ints: the (num, n_ints) int buffer.
        views: piece ``k`` as a ``(num, *shapes[k])`` view of ``floats``; a named tuple of the
            layout's pieces (``views.x``) when ``pieces`` (its class) is given.
    """

    def __init__(self, shapes, num: int, n_ints: int, pieces=tuple):
        sizes = [num * int(np.prod(s)) for s in shapes]
        self.offsets = np.concatenate(([0], np.cumsum(sizes))).astype(np.int64)
        self.floats = np.zeros(int(self.offsets[-1]))
        self.ints = np.zeros((num, n_ints), dtype=np.int64)
        views = (
            self.floats[a:b].reshape((num,) + tuple(s))
            for a, b, s in zip(self.offsets[:-1], self.offsets[1:], shapes)
        )
        self.views: Any = pieces(views) if pieces is tuple else pieces(*views)


@jit(inline="always")
def piece_rows(fs, a, b, N):
    """The piece ``fs[a:b]`` of the float state of ``N`` estimators, one row each (N, size)."""
    return fs[a:b].reshape((N, (b - a) // N))


@jit(inline="always")
def piece(fs, offsets, k, shape):
    """Piece ``k`` of the float state (``offsets`` its start offsets) as an array of ``shape``
    (leading axis: the estimators), in one reshape. (Inlined, as :func:`piece_rows`: each
    caller's shapes -- tuples of different lengths and constants -- would otherwise compile a
    specialisation of their own.)"""
    return fs[offsets[k] : offsets[k + 1]].reshape(shape)


__all__ = [
    "REST",
    "ROTORS",
    "FlatState",
    "Layout",
    "counts",
    "fields",
    "pack",
    "piece",
    "piece_rows",
    "size",
    "unpack",
]
