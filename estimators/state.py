"""The state of N online estimators in two flat buffers (the compiled updates' layout).

An estimator's state is a list of named pieces (arrays of given shapes). For N estimators
(one for a single estimator, N for a batch) every piece gets a leading batch axis and the
pieces are stored piece-major in one float buffer, with the int counters in an (N, k)
buffer: the compiled update takes both buffers and the pieces' offsets, and forms each piece
as a view (:func:`piece_rows`) once per call. :class:`FlatState` keeps the same views on the
Python side.
"""

from __future__ import annotations

import math

import numpy as np

from quadfault.jit import jit


class FlatState:
    """The float and int buffers of ``num`` estimators whose state has pieces of the given
    ``shapes``, with ``n_ints`` int counters each.

    Attributes:
        offsets: start of each piece in ``floats`` (and the total at the end), int64.
        floats: the float buffer; ints: the (num, n_ints) int buffer.
        views: piece ``k`` as a ``(num, *shapes[k])`` view of ``floats``.
    """

    def __init__(self, shapes, num: int, n_ints: int):
        sizes = [num * int(np.prod(s)) for s in shapes]
        self.offsets = np.concatenate(([0], np.cumsum(sizes))).astype(np.int64)
        self.floats = np.zeros(int(self.offsets[-1]))
        self.ints = np.zeros((num, n_ints), dtype=np.int64)
        self.views = [self.floats[a:b].reshape((num,) + tuple(s)) for a, b, s in
                      zip(self.offsets[:-1], self.offsets[1:], shapes)]


@jit
def piece_rows(fs, a, b, N):
    """The piece ``fs[a:b]`` of the float state of ``N`` estimators, one row each (N, size)."""
    return fs[a:b].reshape((N, (b - a) // N))


@jit
def piece(fs, offsets, k, shape):
    """Piece ``k`` of the float state (``offsets`` its start offsets) as an array of ``shape``
    (leading axis: the estimators), in one reshape."""
    return fs[offsets[k]:offsets[k + 1]].reshape(shape)


@jit
def all_finite(a) -> bool:
    """True when every entry of ``a`` is finite."""
    for x in a.flat:
        if not math.isfinite(x):
            return False
    return True


__all__ = ["FlatState", "all_finite", "piece", "piece_rows"]
