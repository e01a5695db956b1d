"""The effect chain of the closed loop: the built-in effects of every vehicle, compiled.

Per vehicle ``i`` the effects are a list of entries -- a code (which effect: its row in the
registry, :mod:`quadfault.effects.registry`), the column of its first parameter and of its
first memory slot -- over one row of numbers each (:class:`EffectRows`; built by
:mod:`quadfault.effects.rows` from each effect's ``pack``). The closed loop
(:func:`quadfault.closed_loop.fly_vehicle`) calls the chain once per physics step,
:func:`step_effects` (inlined into the loop, so the rows' arrays are taken once per step
and no call passes them: every array a compiled call takes costs reference counting), which
does the two points of the effect protocol:

* the thrust stage (:func:`thrust_effects`), on the thrusts the motor model produced (in
  the order of the entries, each one's output the next one's input);
* the step's wrench terms (:func:`wrench_terms`): the numbers the RK stages need, so that
  :func:`effects_wrench` gives at every stage of the RKMK4 step the sum of the wrench
  entries' external force (world) [N] and moment (body) [N m] from numbers alone; a step
  without wrench entries skips the stages' call (:func:`has_wrench`).

Each entry runs the kernels of its effect's module (``thrust_step``, ``wrench_term``,
``wrench_stage``; each documents its parameters and memory), picked by code in dispatchers
generated from the registry (:mod:`quadfault.effects.dispatch`) for the rows' effects alone:
rows are built as the class :func:`rows_class` of the effects they hold (and of the most
wrench entries a vehicle flies), and this module's functions compile, for each such class,
the chain of :func:`chain_for` those effects (the step's terms likewise, :func:`terms_class`).
So an effect no vehicle flies costs the loop nothing, a flight without effects compiles
none, and the RK stages sum only as many terms as a vehicle may have.

Random numbers: a wind's gusts draw three standard normals per step, after the motors'
draws, from the vehicle's generator (the loop's), or from the wind's own seeded generator
(``streams[i]``) when it has a seed.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

import quadfault.effects.dispatch as dispatch
import quadfault.effects.registry as registry
from quadfault.effects.dispatch import NO_TERMS, TERM, WRENCH_TERMS
import quadfault.jit as jit

#: effect name -> code of its entry (body effects -- mass, inertia -- have none: they set
#: the flown vehicle's mass and inertia)
CODES = {cls.name: k for k, cls in enumerate(registry.TABLE)
         if dispatch.has_thrust(cls) or dispatch.has_term(cls)}


class EffectRows(NamedTuple):
    """The compiled effects of N vehicles (row ``i`` = vehicle ``i``; see the module
    docstring). ``memory`` is updated in place by the loop. Rows are built as the subclass
    :func:`rows_class` of the effects they hold (its type picks the compiled chain)."""

    code: np.ndarray  # (N, E) int64: entry codes in chain order, -1 after the last
    param: np.ndarray  # (N, E) int64: column of each entry's first parameter
    mem: np.ndarray  # (N, E) int64: column of each entry's first memory slot
    params: np.ndarray  # (N, P) parameters
    memory: np.ndarray  # (N, Q) memory (zeros: a flight's start)
    streams: object  # typed list of N generators: a seeded wind's own (else never drawn)

    #: the effects the rows may hold (names, registry order) and the most wrench entries a
    #: vehicle flies (set on each :func:`rows_class`; class attributes, not fields)
    effects = ()
    n_terms = WRENCH_TERMS


class Terms(NamedTuple):
    """A vehicle's wrench terms over one step (``terms``: one :data:`TERM`-number tuple per
    wrench entry, code -1 past the last), as the subclass :func:`terms_class` of the rows'
    effects (its type picks the compiled RK-stage sum)."""

    terms: tuple

    effects = ()
    n_terms = WRENCH_TERMS


_FAMILIES = {"EffectRows": EffectRows, "Terms": Terms}
_CLASSES: dict = {}


def _class(base: str, effects, n_terms: int) -> type:
    """The subclass of ``base`` for ``effects`` (names) and ``n_terms``, made once and kept
    in this module under its name (so that numba's cache finds it again by name)."""
    effects = tuple(cls.name for cls in registry.TABLE if cls.name in set(effects))
    name = "__".join((base, *effects, str(int(n_terms))))
    cls = _CLASSES.get(name)
    if cls is None:
        cls = type(name, (_FAMILIES[base],), {"__slots__": (), "__module__": __name__,
                                               "effects": effects, "n_terms": int(n_terms)})
        _CLASSES[name] = globals()[name] = cls
    return cls


def rows_class(effects, n_terms: int) -> type:
    """The :class:`EffectRows` of vehicles flying entries of ``effects`` (names), at most
    ``n_terms`` of them with a wrench."""
    return _class("EffectRows", effects, n_terms)


def terms_class(effects, n_terms: int) -> type:
    """The :class:`Terms` of a step of rows of :func:`rows_class` ``(effects, n_terms)``."""
    return _class("Terms", effects, n_terms)


def __getattr__(name):  # a class of a family, asked for by name (numba's cache, pickle)
    base, _, rest = name.partition("__")
    if base in _FAMILIES and rest:
        *effects, n_terms = rest.split("__")
        if all(e in registry.EFFECTS for e in effects) and n_terms.isdigit():
            return _class(base, effects, int(n_terms))
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def chain_for(names=None, n_terms: int = WRENCH_TERMS):
    """The compiled chain (a module with ``thrust_effects``, ``wrench_terms``,
    ``step_effects``, ``has_wrench``, ``effects_wrench``) of the effects ``names`` (default:
    every registered effect), a vehicle flying at most ``n_terms`` wrench entries; rows with
    other effects must not fly under it."""
    table = registry.TABLE if names is None else tuple(
        cls for cls in registry.TABLE if cls.name in {registry.effect_class(n).name
                                                       for n in names})
    return dispatch.compiled(table, [registry.TABLE.index(cls) for cls in table], n_terms)


def _chain_of(typ):
    """The compiled chain of a numba type of :func:`rows_class` or :func:`terms_class`."""
    cls = typ.instance_class
    return chain_for(cls.effects, cls.n_terms)


# What the loop calls: each picks, by the type of its rows or terms, the chain compiled for
# their effects alone (plain Python: the interpreted loop swaps them for an effects hook).
def step_effects(fx, i, f, t, dt, p, v, R, w, gen):
    """The chain's work for physics step ``[t, t + dt)`` [s] of vehicle ``i`` (compiled code
    only): the thrust stage on ``f`` in place, then the step's wrench terms."""
    raise NotImplementedError("compiled code only")


def thrust_effects(fx, i, f, t, dt, p, v, R, w, gen):
    """The chain's thrust stage (compiled code only)."""
    raise NotImplementedError("compiled code only")


def wrench_terms(fx, i, f, t):
    """The step's wrench terms of vehicle ``i`` (compiled code only)."""
    raise NotImplementedError("compiled code only")


def has_wrench(W):
    """Whether the step's terms hold a wrench entry (compiled code only)."""
    raise NotImplementedError("compiled code only")


def effects_wrench(W, p, v, R, w, f, t):
    """The summed external force (world) and moment (body) at one RK stage (compiled code
    only)."""
    raise NotImplementedError("compiled code only")


def _register() -> None:
    """Compile each of the functions above as the chain of its rows' (or terms') type."""
    from numba import types
    from numba.extending import overload

    def pick(name):
        return lambda typ: getattr(_chain_of(typ), name).py_func

    none = terms_class((), 0)

    def nothing(fx, i, f, t, dt, p, v, R, w, gen):  # no effects: no terms
        return none(())

    @overload(step_effects, inline="always")
    def _step(fx, i, f, t, dt, p, v, R, w, gen):
        return nothing if isinstance(fx, types.NoneType) else pick("step_effects")(fx)

    @overload(thrust_effects, inline="always")
    def _thrust(fx, i, f, t, dt, p, v, R, w, gen):
        return pick("thrust_effects")(fx)

    @overload(wrench_terms, inline="always")
    def _terms(fx, i, f, t):
        return pick("wrench_terms")(fx)

    @overload(has_wrench, inline="always")
    def _has(W):
        return pick("has_wrench")(W)

    @overload(effects_wrench, inline="always")
    def _wrench(W, p, v, R, w, f, t):
        return pick("effects_wrench")(W)


if jit.AVAILABLE:
    _register()

__all__ = ["CODES", "EffectRows", "Terms", "WRENCH_TERMS", "TERM", "NO_TERMS", "chain_for",
           "rows_class", "terms_class", "thrust_effects", "wrench_terms", "step_effects",
           "has_wrench", "effects_wrench"]
