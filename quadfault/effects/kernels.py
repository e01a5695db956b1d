"""Kernels the effects share: a world vector in body axes and back.

Plain, allocation-free Python under :func:`quadfault.jit.jit` (vectors are 3-tuples, ``R`` a
row-major 9-tuple, as in :mod:`quadfault.dynamics`). Frames: world NED, body FRD. Each
effect's own kernels live in its module.
"""

from __future__ import annotations

from quadfault.jit import jit


@jit
def body_velocity3(R, v):
    """``R^T v``: a world vector in body axes."""
    return (R[0] * v[0] + R[3] * v[1] + R[6] * v[2],
            R[1] * v[0] + R[4] * v[1] + R[7] * v[2],
            R[2] * v[0] + R[5] * v[1] + R[8] * v[2])


@jit
def world_vector3(R, b):
    """``R b``: a body vector in world axes."""
    return (R[0] * b[0] + R[1] * b[1] + R[2] * b[2],
            R[3] * b[0] + R[4] * b[1] + R[5] * b[2],
            R[6] * b[0] + R[7] * b[1] + R[8] * b[2])
