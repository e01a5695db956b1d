"""Kernels the effects share: a world vector in body axes and back, and the rotors' thrusts
as a tuple.

Plain, allocation-free Python under :func:`quadfault.jit.jit` (vectors are 3-tuples, ``R`` a
row-major 9-tuple, as in :mod:`quadfault.model.dynamics`). Frames: world NED, body FRD. Each
effect's own kernels live in its module.

The chain's thrust stage carries the rotors' thrusts as a tuple ``f`` of n numbers (n fixed
by the rows, :mod:`quadfault.model.effects.chain`): a ``thrust_step`` returns the new tuple,
built with :func:`replaced` or :func:`scaled` (no array is written per effect, and the
compiler keeps the numbers in registers).
"""

from __future__ import annotations

import quadfault.jit as _jit
from quadfault.jit import jit


@jit
def body_velocity3(R, v):
    """``R^T v``: a world vector in body axes."""
    return (
        R[0] * v[0] + R[3] * v[1] + R[6] * v[2],
        R[1] * v[0] + R[4] * v[1] + R[7] * v[2],
        R[2] * v[0] + R[5] * v[1] + R[8] * v[2],
    )


@jit
def world_vector3(R, b):
    """``R b``: a body vector in world axes."""
    return (
        R[0] * b[0] + R[1] * b[1] + R[2] * b[2],
        R[3] * b[0] + R[4] * b[1] + R[5] * b[2],
        R[6] * b[0] + R[7] * b[1] + R[8] * b[2],
    )


def replaced(f, r, x):
    """The tuple ``f`` with item ``r`` replaced by ``x``."""
    return f[:r] + (x,) + f[r + 1 :]


@jit(inline="always")
def scaled(f, k):
    """Each of the thrusts ``f`` (a tuple) times ``k``."""
    out = f
    for r in range(len(f)):
        out = replaced(out, r, f[r] * k)
    return out


def _register() -> None:
    from numba.cpython.unsafe.tuple import tuple_setitem
    from numba.extending import overload

    @overload(replaced)
    def _replaced(f, r, x):
        return lambda f, r, x: tuple_setitem(f, r, x)


if _jit.AVAILABLE:
    _register()
