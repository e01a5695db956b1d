"""What the effects' array forms share: broadcasting arguments to rows, and the rigid body a
body-stage effect flies.

Each effect's module has its physics over arrays -- compiled loops over its kernels, the
code the closed loop runs step by step -- which the mismatch diagnosis calls over a whole
recording; these helpers broadcast their (batched) arguments to C-contiguous rows and shape
the result back (a scalar argument gives a scalar).
"""

from __future__ import annotations

import numpy as np


def rows_of(batch: tuple, *arrays):
    """Each ``(array, width)`` broadcast to ``batch + width`` as C-contiguous float rows."""
    out = []
    for a, width in arrays:
        a = np.broadcast_to(np.asarray(a, dtype=float), batch + width)
        out.append(np.ascontiguousarray(a.reshape((-1,) + width)))
    return out


def batch_of(*arrays) -> tuple:
    """The common batch shape of ``(array, width)`` pairs (``width`` trailing axes each)."""
    return np.broadcast_shapes(*(np.shape(a)[: np.ndim(a) - len(w)] for a, w in arrays))


def shaped(out: np.ndarray, batch: tuple, width: tuple = ()):
    """``out`` reshaped to ``batch + width`` (a scalar for an empty shape)."""
    out = out.reshape(batch + width)
    return out[()] if out.ndim == 0 else out


def scaled_inertia(inertia: np.ndarray, scale) -> np.ndarray:
    """``D J D`` with ``D = diag(sqrt(scale))``: diagonal entries scaled by ``scale``."""
    d = np.sqrt(np.asarray(scale, dtype=float))
    return inertia * d[:, None] * d[None, :]


def vehicle_with(vehicle, mass_scale: float = 1.0, inertia_scale=(1.0, 1.0, 1.0)):
    """The vehicle with mass ``mass_scale m`` and inertia ``D J D`` (:func:`scaled_inertia`);
    the rotors (allocation, per-rotor thrust limit) are unchanged."""
    return vehicle.replace(
        mass=vehicle.mass * float(mass_scale),
        inertia=scaled_inertia(vehicle.inertia, inertia_scale),
        max_thrust=vehicle.rotor_max_thrust,
    )
