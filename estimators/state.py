"""Named state: declared layouts of the estimators' flat buffers, offsets derived.

An estimator's state is a list of named pieces (arrays of given shapes, :class:`Layout`). For
N estimators (one for a single estimator, N for a batch) every piece gets a leading batch
axis and the pieces are stored piece-major in one float buffer, with the int counters in an
(N, k) buffer: the compiled update takes both buffers and the pieces' offsets, and forms each
piece as a view (:func:`piece`, :func:`piece_rows`) once per call. :class:`FlatState` keeps
the same views on the Python side, by name.

Inside a piece, and in the flat arrays of constants and settings, rows are named with
:func:`fields`: a declared list of names and row counts whose start rows are derived (a
namedtuple of ints, which compiled code reads as constants). :func:`pack` fills such an array
by name, so nothing is tied to a concatenation order.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit


def fields(name: str, *entries):
    """The start rows of named entries laid end to end: each entry is ``"name"`` (one row)
    or ``("name", count)``; a count of 0, last only, means "the rest" (any length). Returns
    a namedtuple instance (class ``name``) of the start rows with a final ``size``: the rows
    of the fixed entries."""
    names, starts, k = [], [], 0
    for i, entry in enumerate(entries):
        key, count = (entry, 1) if isinstance(entry, str) else entry
        if count == 0 and i != len(entries) - 1:
            raise ValueError(f"{name}: only the last entry may have the open count 0")
        names.append(key)
        starts.append(k)
        k += count
    return namedtuple(name, names + ["size"])(*starts, k)


def counts(rows) -> dict:
    """Entry -> its row count in a :func:`fields` layout (0 for an open last entry)."""
    values = list(rows)
    return {
        key: (values[i + 1] - values[i] if i + 1 < len(values) - 1 else rows.size - values[i])
        for i, key in enumerate(rows._fields[:-1])
    }


def pack(rows, **values) -> np.ndarray:
    """A float array laid out as ``rows`` (:func:`fields`) with every entry given by name
    (scalars or arrays, raveled row-major); the open last entry takes any length."""
    sizes = counts(rows)
    if set(values) != set(sizes):
        raise ConfigError(
            f"{type(rows).__name__}: entries {sorted(sizes)} expected, got {sorted(values)}"
        )
    out = []
    for key, count in sizes.items():
        a = np.asarray(values[key], dtype=np.float64).ravel()
        if count and a.size != count:
            raise ConfigError(f"{type(rows).__name__}.{key}: {count} values expected, got {a.size}")
        out.append(a)
    return np.concatenate(out)


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
        self.pieces = namedtuple(name, list(shapes))
        self.index = self.pieces(*range(len(shapes)))

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
        self.views = pieces(views) if pieces is tuple else pieces(*views)


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


@jit(inline="always")
def reset_rows(offsets, eta0_piece, initialised, n, fs, ks, rows, eta0) -> None:
    """Forget the filters ``rows`` of the state ``(fs, ks)`` (``offsets``: its pieces' start
    offsets): every piece of theirs zeroed, their int counter ``initialised`` 0, so that the
    next good sample initialises them, with the efficiencies ``eta0`` (N, n) written to piece
    ``eta0_piece``. (The Kalman filters' reset.)"""
    N = ks.shape[0]
    for i in rows:
        ks[i, initialised] = 0
        for k in range(offsets.shape[0] - 1):  # every piece
            row = piece_rows(fs, offsets[k], offsets[k + 1], N)[i]
            for a in range(row.shape[0]):
                row[a] = 0.0
        e0 = piece_rows(fs, offsets[eta0_piece], offsets[eta0_piece + 1], N)[i]
        for j in range(n):
            e0[j] = eta0[i, j]


@jit(inner=True)
def all_finite(a) -> bool:
    """True when every entry of ``a`` is finite."""
    for x in a.flat:
        if not math.isfinite(x):
            return False
    return True


__all__ = [
    "FlatState",
    "Layout",
    "all_finite",
    "counts",
    "fields",
    "pack",
    "piece",
    "piece_rows",
    "reset_rows",
]
