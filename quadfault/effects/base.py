"""The effect protocol's defaults and parameter checks shared by every effect class."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from quadfault.errors import ConfigError


def vector(value, n, what) -> tuple:
    """``value`` as ``n`` finite floats (a scalar is repeated); a one-line error otherwise."""
    try:
        arr = np.asarray(value, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be numeric, got {value!r}") from None
    if arr.size == 1 and n > 1:
        arr = np.repeat(arr, n)
    if arr.size != n or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{what} needs {n} finite values, got {value!r}")
    return tuple(float(x) for x in arr)


def number(value, what, lo=-np.inf, hi=np.inf, *, open_lo=False) -> float:
    """``value`` as a finite float in ``[lo, hi]`` (``(lo, hi]`` with ``open_lo``)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a number, got {value!r}") from None
    low_ok = x > lo if open_lo else x >= lo
    if not (np.isfinite(x) and low_ok and x <= hi):
        raise ConfigError(f"{what} must be in {'(' if open_lo else '['}{lo:g}, {hi:g}], "
                          f"got {value!r}")
    return x


class Effect:
    """Default (no-op) plant hooks of an effect; subclasses are frozen dataclasses.

    Protocol (called by :class:`quadfault.plant.Plant`): ``reset(n_rotors)`` at the start of a
    flight; ``rotor_thrust(f, t, dt, state)`` once per physics step (produced rotor thrusts
    [N] for the step starting at ``t``); ``wrench(state, f, t)`` at every integrator stage
    (extra force, world [N], and moment, body [N m]); ``true_vehicle(vehicle)`` once at reset
    (the rigid body the plant flies; the controller and the recording keep the nominal one).

    Class attributes: ``name`` (canonical, CONTRACT.md sec. 4) and ``order`` (the canonical
    position of the effect in the chain command -> thrust -> wrench -> body, used to sort a
    model's effects so that it means the same physics as the diagnosis' library).
    """

    name: ClassVar[str] = ""
    order: ClassVar[int] = 0

    def reset(self, n_rotors: int) -> None:
        pass

    def rotor_thrust(self, f, t, dt, state):
        return f

    def wrench(self, state, f, t):
        return np.zeros(np.shape(state.p)), np.zeros(np.shape(state.w))

    def true_vehicle(self, vehicle):
        return vehicle

    def params(self) -> dict:
        raise NotImplementedError

    @classmethod
    def from_params(cls, params: dict) -> Effect:
        """The effect from its ``params()`` (the keys the diagnosis reports)."""
        raise NotImplementedError

    def describe(self) -> dict:
        """JSON-able ``{"name", "params"}`` (stored as truth in a recording's meta)."""
        return {"name": self.name, "params": self.params()}


def param(params: dict, key: str, name: str):
    """``params[key]``, or a one-line error naming the effect and the key."""
    if not isinstance(params, dict) or key not in params:
        raise ConfigError(f"effect {name}: params need {key!r}")
    return params[key]
