"""The observation: a named layout of slots, flat (float32 Box) or as a Dict.

Each slot has a name, a size, bounds and a meaning; the flat vector is their concatenation
in the order of :data:`SLOTS`. ``env.unwrapped.observation_names`` lists one name per element
(``"pos_err_x"``, ..., ``"eta_sd_4"``) and ``layout.slice("eta_hat")`` gives where a slot sits.

All quantities are in the internal frames (world NED, body FRD) and measured, i.e. they carry
the sensor noise; only the ``eta_hat`` / ``eta_sd`` slots come from the estimator.

=====================  ====  ===========================================================
slot                   size  meaning
=====================  ====  ===========================================================
``pos_err``            3     p - p_ref, world NED [m], clipped to [-10, 10]
``vel_err``            3     v - v_ref, world NED [m/s], clipped to [-50, 50]
``rot6``               6     first two columns of R (body->world): R[:, 0], R[:, 1]
``omega``              3     body rate, FRD [rad/s], clipped to [-50, 50]
``eta_hat``            4     estimated motor efficiency (1 = nominal), clipped to [0, 2]
``eta_sd``             4     one-sigma uncertainty of eta_hat, clipped to [0, 10]
``ref_acc`` (optional) 3     reference acceleration a_ref, world NED [m/s^2], in [-50, 50]
=====================  ====  ===========================================================
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from quadfault.jit import jit
from quadfault.model.rotation import mat3

# Bounds of the Box. Values are clipped into them; with the default termination limits
# (5 m position error) only the step that terminates can reach the position bound.
POS_MAX = 10.0  # [m]
VEL_MAX = 50.0  # [m/s]
RATE_MAX = 50.0  # [rad/s]
ACC_MAX = 50.0  # [m/s^2]
ETA_MAX = 2.0  # upper clip of the eta_hat slot [-]
SD_MAX = 10.0  # upper clip of the eta_sd slot [-]; also the value when the estimator gives none


@dataclass(frozen=True)
class Slot:
    """One named block of the observation."""

    name: str
    labels: tuple  # element suffixes, e.g. ("x", "y", "z")
    low: float
    high: float
    meaning: str

    @property
    def size(self) -> int:
        return len(self.labels)


_XYZ = ("x", "y", "z")
_MOTORS = ("1", "2", "3", "4")
SLOTS = (
    Slot("pos_err", _XYZ, -POS_MAX, POS_MAX, "p - p_ref, world NED [m]"),
    Slot("vel_err", _XYZ, -VEL_MAX, VEL_MAX, "v - v_ref, world NED [m/s]"),
    Slot(
        "rot6",
        ("r11", "r21", "r31", "r12", "r22", "r32"),
        -1.0,
        1.0,
        "first two columns of R (body FRD -> world NED)",
    ),
    Slot("omega", _XYZ, -RATE_MAX, RATE_MAX, "body rate, FRD [rad/s]"),
    Slot("eta_hat", _MOTORS, 0.0, ETA_MAX, "estimated motor efficiency (1 = nominal)"),
    Slot("eta_sd", _MOTORS, 0.0, SD_MAX, "one-sigma uncertainty of eta_hat"),
)
REF_ACC_SLOT = Slot("ref_acc", _XYZ, -ACC_MAX, ACC_MAX, "reference acceleration, world NED [m/s^2]")


class ObservationLayout:
    """The slots in use and the conversions between values, flat vectors and dicts."""

    def __init__(self, reference_acceleration: bool = True):
        self.slots = SLOTS + ((REF_ACC_SLOT,) if reference_acceleration else ())
        self._slices = {}
        start = 0
        for s in self.slots:
            self._slices[s.name] = slice(start, start + s.size)
            start += s.size
        self.size = start

        def per(f):
            return np.concatenate([np.full(s.size, f(s), dtype=float) for s in self.slots])

        self._low, self._high = per(lambda s: s.low), per(lambda s: s.high)
        self._fill = per(lambda s: SD_MAX if s.name == "eta_sd" else 0.0)
        # where each of _ARGS starts in the flat vector (-1: not in this layout)
        self._at = np.array(
            [self._slices[name].start if name in self._slices else -1 for name in _ARGS],
            dtype=np.int64,
        )

    def bounds(self) -> tuple:
        """Where each slot starts (-1: not held), the elements' bounds and NaN fills, as the
        compiled observation (:func:`observation_row`) takes them."""
        return self._at, self._low, self._high, self._fill

    @property
    def names(self) -> list[str]:
        """One name per element of the flat vector, e.g. ``"eta_hat_1"``."""
        return [f"{s.name}_{label}" for s in self.slots for label in s.labels]

    def slice(self, name: str) -> slice:
        return self._slices[name]

    def flat_space(self) -> spaces.Box:
        low = np.concatenate([np.full(s.size, s.low) for s in self.slots]).astype(np.float32)
        high = np.concatenate([np.full(s.size, s.high) for s in self.slots]).astype(np.float32)
        return spaces.Box(low, high, dtype=np.float32)

    def dict_space(self) -> spaces.Dict:
        return spaces.Dict(
            {
                s.name: spaces.Box(
                    np.float32(s.low), np.float32(s.high), shape=(s.size,), dtype=np.float32
                )
                for s in self.slots
            }
        )

    def flat(self, *, pos_err, vel_err, R, omega, eta_hat, eta_sd=None, ref_acc=None) -> np.ndarray:
        """The flat observation, float32 ``(..., size)`` for a leading batch shape: the slots'
        values concatenated, NaN replaced by the slot's fill (``SD_MAX`` for ``eta_sd``, else
        0), everything (infinities included) clipped into the slot's bounds. ``eta_sd`` None
        means "none given" (``SD_MAX``)."""
        R = np.asarray(R, dtype=float)
        batch = R.shape[:-2]
        shape = (-1, 3, 3)
        values = (
            pos_err,
            vel_err,
            omega,
            eta_hat,
            SD_MAX if eta_sd is None else eta_sd,
            0.0 if ref_acc is None else ref_acc,
        )
        out = np.empty(batch + (self.size,), dtype=np.float32)
        _observation_rows(
            tuple(_rows(x, batch, size) for x, size in zip(values, _SIZES)),
            np.ascontiguousarray(R.reshape(shape)),
            *self.bounds(),  # arrays, not a tuple: a tuple argument costs numba's dispatch
            out.reshape(-1, self.size),
        )
        return out

    def _bounded(self, x: np.ndarray, where=None) -> np.ndarray:
        """``x`` (elements ``where`` of the flat layout; all by default) with NaN -> fill,
        clipped, float32."""
        low, high, fill = self._low, self._high, self._fill
        if where is not None:
            low, high, fill = (np.ascontiguousarray(a[where]) for a in (low, high, fill))
        x = np.asarray(x, dtype=float)
        x = np.broadcast_to(x, x.shape[:-1] + low.shape) if x.shape[-1:] != low.shape else x
        out = np.empty(x.shape, dtype=np.float32)
        _bound_rows(x.reshape(-1, low.shape[0]), low, high, fill, out.reshape(-1, low.shape[0]))
        return out

    def values(self, **slots) -> dict:
        """Slot values (float32, NaN filled, clipped into their bounds) as a dict; the
        keywords of :meth:`flat`."""
        return self.split(self.flat(**slots))

    def split(self, flat: np.ndarray) -> dict:
        """A flat observation ``(..., size)`` as a dict of slots."""
        return {s.name: flat[..., self._slices[s.name]].copy() for s in self.slots}

    def flatten(self, values: dict) -> np.ndarray:
        return np.concatenate([values[s.name] for s in self.slots], axis=-1).astype(np.float32)

    def replace(self, obs, name: str, value):
        """A copy of ``obs`` (flat vector or dict) with slot ``name`` set to ``value``
        (filled and clipped like :meth:`flat`)."""
        if isinstance(obs, dict):
            out = dict(obs)
            out[name] = self._bounded(np.asarray(value, dtype=float), self._slices[name])
            return out
        out = np.array(obs, dtype=np.float32, copy=True)
        self.write(out, name, value)
        return out

    def write(self, obs: np.ndarray, name: str, value) -> None:
        """Slot ``name`` of the flat observations ``obs`` (float32 ``(..., size)``) set to
        ``value`` in place, NaN filled and clipped into the slot's bounds as :meth:`flat`
        does."""
        sl = self._slices[name]
        obs[..., sl] = self._bounded(np.asarray(value, dtype=float), sl)

    def get(self, obs, name: str) -> np.ndarray:
        """Slot ``name`` of ``obs`` (flat vector or dict)."""
        if isinstance(obs, dict):
            return np.asarray(obs[name])
        return np.asarray(obs)[self._slices[name]]

    def markdown_table(self) -> str:
        rows = ["| slot | elements | bounds | meaning |", "|---|---|---|---|"]
        for s in self.slots:
            sl = self._slices[s.name]
            rows.append(
                f"| `{s.name}` | {sl.start}..{sl.stop - 1} | [{s.low}, {s.high}] | {s.meaning} |"
            )
        return "\n".join(rows)


@jit(inner=True)
def _bound(v, low, high, fill):
    """One element: NaN -> ``fill``, clipped into ``[low, high]``, as float32 (the
    observation's one rule for every slot; scalars only: arrays passed per element would
    cost their reference counts)."""
    if np.isnan(v):
        v = fill
    return np.float32(min(max(v, low), high))


@jit
def _bound_rows(x, low, high, fill, out):
    """``out[i, j]``: ``x[i, j]`` bounded (:func:`_bound`) by element j's bounds, rows (B, w)."""
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            out[i, j] = _bound(x[i, j], low[j], high[j], fill[j])


#: the values :meth:`ObservationLayout.flat` takes, in the order :func:`_observation_rows` does
_ARGS = ("pos_err", "vel_err", "rot6", "omega", "eta_hat", "eta_sd", "ref_acc")
#: the sizes of the ``values`` of :func:`_observation_rows` (``_ARGS`` but rot6)
_SIZES = tuple(
    {s.name: s.size for s in SLOTS + (REF_ACC_SLOT,)}[name] for name in _ARGS if name != "rot6"
)


def _rows(x, batch: tuple, size: int) -> np.ndarray:
    """``x`` broadcast to ``batch + (size,)`` as contiguous float rows (B, size)."""
    x = np.asarray(x, dtype=float)
    if x.shape != batch + (size,):
        x = np.broadcast_to(x, batch + (size,))
    return np.ascontiguousarray(x.reshape(-1, size))


@jit(inline="always")
def _put(x, size, k0, low, high, fill, out):
    """Slot values ``x[0 .. size-1]`` bounded (:func:`_bound`) into ``out`` from ``k0``
    (a slot the layout does not hold, ``k0 < 0``, is skipped)."""
    if k0 >= 0:
        for j in range(size):
            k = k0 + j
            out[k] = _bound(x[j], low[k], high[k], fill[k])


@jit(inline="always")
def observation_row(pos_err, vel_err, R, omega, eta_hat, eta_sd, ref_acc, bounds, out):
    """One flat observation into ``out`` (size,): the one definition of what the observation
    holds and how it is bounded, compiled (:meth:`ObservationLayout.flat` and the vector
    env's fused step call it). ``pos_err``, ``vel_err``, ``omega``, ``ref_acc`` three numbers
    each (any indexable), ``R`` the attitude as 9 numbers row by row (its first two columns
    are ``rot6``), ``eta_hat``,
    ``eta_sd`` (n,); ``bounds`` :meth:`ObservationLayout.bounds`."""
    at, low, high, fill = bounds
    _put(pos_err, 3, at[0], low, high, fill, out)
    _put(vel_err, 3, at[1], low, high, fill, out)
    k0 = at[2]
    if k0 >= 0:
        for c in range(2):
            for j in range(3):
                k = k0 + 3 * c + j
                out[k] = _bound(R[3 * j + c], low[k], high[k], fill[k])
    _put(omega, 3, at[3], low, high, fill, out)
    _put(eta_hat, eta_hat.shape[0], at[4], low, high, fill, out)
    _put(eta_sd, eta_sd.shape[0], at[5], low, high, fill, out)
    _put(ref_acc, 3, at[6], low, high, fill, out)


@jit
def _observation_rows(values, R, at, low, high, fill, out):
    """The flat observations (B, size) of B rows (:func:`observation_row`): ``values`` the
    slots of :data:`_ARGS` but ``rot6`` ((B, size) each), ``R`` (B, 3, 3)."""
    pe, ve, w, eta, sd, acc = values
    bounds = (at, low, high, fill)
    for i in range(out.shape[0]):
        observation_row(pe[i], ve[i], mat3(R[i]), w[i], eta[i], sd[i], acc[i], bounds, out[i])
