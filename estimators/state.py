"""Named state: declared layouts of the estimators' flat buffers, offsets derived (the
mechanism, shared with the effects' parameters and memory, is :mod:`quadfault.layout`).

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

from quadfault.jit import jit
from quadfault.layout import FlatState, Layout, counts, fields, pack, piece, piece_rows


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
