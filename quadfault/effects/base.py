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


#: the physics step a standalone effect's chain is built for when ``wrench`` comes first [s]
_STANDALONE_DT = 1e-3


class Compiled(Effect):
    """A built-in effect with an entry in the compiled effect chain
    (:mod:`quadfault.effects.chain`). The closed loop runs that entry compiled, from the
    plant's rows; the protocol methods here run the same entry for one vehicle from Python
    (its memory -- lag, delay, gusts -- kept on the object from one call to the next and
    cleared by ``reset``). ``rotor_thrust`` takes the loop's generator as ``gen`` (a wind
    without a seed draws its gusts from it; alone, from a generator seeded 0)."""

    def reset(self, n_rotors: int) -> None:
        for key in ("_single", "_fallback"):
            self.__dict__.pop(key, None)

    def _yaw_signs(self, n_rotors: int):
        return None

    def chain(self, n_rotors: int, dt: float):
        """This effect's one-vehicle chain (:class:`quadfault.effects.rows.Single`), built at
        the first call after ``reset``."""
        single = self.__dict__.get("_single")
        if single is None:
            from quadfault.effects.rows import Single, entry

            single = Single([entry(self, n_rotors, dt, self._yaw_signs(n_rotors))])
            self.__dict__["_single"] = single  # frozen dataclass: memory beside the fields
            self.__dict__["_fallback"] = np.random.default_rng(0)
        return single

    def rotor_thrust(self, f, t, dt, state, gen=None):
        out = np.array(f, dtype=float).ravel()
        single = self.chain(len(out), dt)
        single.rotor_thrust(out, t, dt, state.p, state.v, state.R, state.w,
                            self.__dict__["_fallback"] if gen is None else gen)
        return out

    def wrench(self, state, f, t):
        F, M = self.chain(len(np.ravel(f)), _STANDALONE_DT).wrench(
            state.p, state.v, state.R, state.w, f, t)
        return np.array(F), np.array(M)

    def __getstate__(self):  # the memory stays behind (a copy starts a new flight)
        return {k: v for k, v in self.__dict__.items() if k not in ("_single", "_fallback")}


def param(params: dict, key: str, name: str):
    """``params[key]``, or a one-line error naming the effect and the key."""
    if not isinstance(params, dict) or key not in params:
        raise ConfigError(f"effect {name}: params need {key!r}")
    return params[key]
