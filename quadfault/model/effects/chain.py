"""The effect chain of the closed loop: the built-in effects of every vehicle, compiled.

The effects of N vehicles are rows of numbers (:class:`EffectRows`; built by
:mod:`quadfault.model.effects.rows` from each effect's declared layout) under one
:class:`ChainLayout`: slots in chain order, each an effect class, on vehicles of n rotors.
A slot's columns are the same for every vehicle -- a marker (0: the vehicle does not fly
the slot; else one more than the column of the entry's first memory slot), then the
effect's parameters as its module declares them (``PARAMETERS``, :mod:`quadfault.layout`) --
so the compiled chain reads them at constant columns. Vehicles with other parameters, or
flying fewer of the layout's effects, share the compiled chain: randomising parameters per
vehicle costs what flying them costs.

The layout is part of the rows' numba type (:class:`LayoutType`), so the loop compiles one
chain per layout, and for it straight-line code over its slots: each stage below is a fold
over the layout's slots of small compiled closures (one per slot, inlined into the next),
each calling its effect's kernel with its constant columns. An effect no vehicle flies costs
the loop nothing, a flight without effects compiles none, and a vehicle pays, per step, one
test of each slot it does not fly.

The closed loop (:func:`quadfault.model.closed_loop.fly_vehicle`) calls the chain once per
physics step, :func:`step_effects` (inlined into the loop), which does the two points of the
effect protocol:

* the thrust stage (:func:`thrust_effects`), on the thrusts the motor model produced (in
  slot order, each one's output the next one's input: a tuple of the n thrusts, which each
  ``thrust_step`` returns anew; the loop's array is written once, at the end);
* the step's wrench terms (:func:`wrench_terms`): the numbers the RK stages need, so that
  :func:`effects_wrench` gives at every stage of the RKMK4 step the sum of the flown wrench
  slots' external force (world) [N] and moment (body) [N m] from numbers alone; a step
  without a flown wrench skips the stages' call (:func:`has_wrench`).

Each slot runs the kernels of its effect's module (``thrust_step``, ``wrench_term``,
``wrench_stage``; docs/effects.md, "Writing a new effect"):

* ``thrust_step(x, q, f, t, dt, p, gen, streams, i) -> f``: ``x`` the effect's parameters
  and ``q`` its memory (1-D arrays laid out as the module's ``PARAMETERS`` and ``MEMORY``),
  ``f`` the n thrusts [N] (a tuple), ``(t, dt)`` the step [s], ``p`` the position at its
  start, ``gen`` the vehicle's generator, ``generator_at(streams, i)`` the effect's own;
* ``wrench_term(x, q, f) -> six numbers`` fixed over the step, and
  ``wrench_stage(s, v, R, w) -> (F_world, M_body)`` at one RK stage from the term ``s``
  (its flown flag, then the six numbers).

Random numbers: a wind's gusts draw three standard normals per step, after the motors'
draws, from the vehicle's generator (the loop's), or from the wind's own seeded generator
(row ``i`` of ``streams``, a :class:`~quadfault.model.generator_table.GeneratorTable` like
the loop's own) when it has a seed.
"""

from __future__ import annotations

import importlib
import sys
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

import quadfault.jit as jit
from quadfault import layout as named

try:  # numba: the layout's type (the loop compiles one chain per layout)
    from numba.core import types as _types
except ImportError:  # pragma: no cover - exercised only without numba
    _types = None

#: numbers in a wrench term: a flown flag (>= 0 flown, -1 not) and six numbers
TERM = 7
NO_TERM = (-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


class Borrowed(np.ndarray):
    """A float array of the rows that compiled code reads and writes without reference
    counts (:class:`BorrowedType`): the rows outlive every call of the chain (the plant, or
    the caller, holds them), and a count taken and dropped at every use -- inside the
    branch of each slot, at every vehicle-step -- costs atomic operations that the threads
    of a parallel loop contend for."""


def borrowed(a) -> Borrowed:
    """``a`` as a :class:`Borrowed` view."""
    return np.asarray(a).view(Borrowed)


def kernels(effect_class):
    """The module of an effect class: where its kernels and layouts are."""
    return sys.modules[effect_class.__module__]


def has_thrust(effect_class) -> bool:
    """Whether the effect has a thrust-stage kernel (``thrust_step``)."""
    return hasattr(kernels(effect_class), "thrust_step")


def has_term(effect_class) -> bool:
    """Whether the effect has a wrench (``wrench_term`` and ``wrench_stage``)."""
    return hasattr(kernels(effect_class), "wrench_term")


@dataclass(frozen=True)
class ChainLayout:
    """The slots of a chain: ``effects``, effect classes in chain order (one may appear in
    several slots), on vehicles of ``n_rotors`` rotors."""

    effects: tuple = ()
    n_rotors: int = 4

    def width(self, k: int) -> int:
        """Parameters of slot ``k`` (its module's ``PARAMETERS`` on ``n_rotors`` rotors)."""
        return named.size(kernels(self.effects[k]).PARAMETERS, self.n_rotors)

    def columns(self) -> list:
        """The column of each slot's marker (its parameters follow it)."""
        out, a = [], 0
        for k in range(len(self.effects)):
            out.append(a)
            a += 1 + self.width(k)
        return out

    @property
    def size(self) -> int:
        """Columns of the parameter rows."""
        return sum(1 + self.width(k) for k in range(len(self.effects)))

    @property
    def names(self) -> tuple:
        return tuple(cls.name for cls in self.effects)


class EffectRows(NamedTuple):
    """The compiled effects of N vehicles (row ``i`` = vehicle ``i``; see the module
    docstring). ``memory`` is updated in place by the loop. ``slot``, ``param`` and ``mem``
    list each vehicle's entries in its own order, for Python (the compiled chain reads the
    layout's columns)."""

    slot: np.ndarray  # (N, E) int64: the layout slot of each entry, in the vehicle's order,
    #                   -1 after the last
    param: np.ndarray  # (N, E) int64: column of each entry's first parameter
    mem: np.ndarray  # (N, E) int64: column of each entry's first memory slot
    params: Borrowed  # (N, P) the layout's columns: per slot a marker, then parameters
    memory: Borrowed  # (N, Q) memory (zeros: a flight's start)
    streams: np.ndarray  # (N, 6) GeneratorTable: a seeded wind's own generator per vehicle
    #                      (quadfault.model.generator_table; else one never drawn from)
    layout: ChainLayout  # the slots (part of the compiled type: one chain per layout)


class Terms(NamedTuple):
    """A vehicle's wrench terms over one step: one :data:`TERM`-number tuple per wrench slot
    of ``layout`` (flag -1 when not flown)."""

    layout: ChainLayout
    terms: tuple


# What the loop calls: plain Python stubs, each compiled (below) as the chain of the layout
# of its rows (or terms). The interpreted loop swaps them for an effects hook.
def step_effects(fx, i, f, t, dt, p, v, R, w, gen):
    """The chain's work for physics step ``[t, t + dt)`` [s] of vehicle ``i`` (compiled code
    only): the thrust stage on ``f`` in place, then the step's wrench terms."""
    raise NotImplementedError("compiled code only")


def has_wrench(W):
    """Whether the step's terms hold a flown wrench entry (compiled code only)."""
    raise NotImplementedError("compiled code only")


def effects_wrench(W, p, v, R, w, f, t):
    """The summed external force (world) and moment (body) at one RK stage (compiled code
    only)."""
    raise NotImplementedError("compiled code only")


@jit.jit(inner=True)
def plus_if(on, FM, dFM):
    """``(F + dF, M + dM)`` when ``on``, else ``(F, M)`` (3-tuples): a flown slot's stage
    added to the sum, as a call (LLVM inlines it as a select; numba does not type the branch
    again in each of the four RK stages)."""
    (F, M), (dF, dM) = FM, dFM
    if on:
        return (
            (F[0] + dF[0], F[1] + dF[1], F[2] + dF[2]),
            (M[0] + dM[0], M[1] + dM[1], M[2] + dM[2]),
        )
    return FM


# the stages of a layout: folds of one closure per slot --------------------------------
def _inlined(fn):
    """``fn`` compiled to be inlined into its caller (a stage of one layout: never compiled,
    nor cached, on its own; the loop that inlines it is cached)."""
    return jit.jit(inline="always", cache=False)(fn)


def _slots(chain: ChainLayout, has) -> list:
    """``(k, module, first parameter column, width)`` of the slots whose effect ``has``."""
    return [
        (k, kernels(cls), a + 1, chain.width(k))
        for k, (cls, a) in enumerate(zip(chain.effects, chain.columns()))
        if has(cls)
    ]


def _thrust_stage(chain: ChainLayout):
    """``stage(P, Q, streams, i, x, t, dt, p, gen) -> x``: each flown thrust slot's
    ``thrust_step`` in slot order on the thrusts ``x`` (a tuple)."""

    def done(P, Q, streams, i, x, t, dt, p, gen):
        return x

    stage = _inlined(done)
    for _k, module, a, width in reversed(_slots(chain, has_thrust)):
        stage = _thrust_slot(module.thrust_step, a, width, stage)
    return stage


def _thrust_slot(kernel, a, width, rest):
    b = a + width

    def stage(P, Q, streams, i, x, t, dt, p, gen):
        on = P[i, a - 1]
        if on != 0.0:
            x = kernel(P[i, a:b], Q[i, int(on) - 1 :], x, t, dt, p, gen, streams, i)
        return rest(P, Q, streams, i, x, t, dt, p, gen)

    return _inlined(stage)


def _term_stage(chain: ChainLayout):
    """``collect(P, Q, i, f) -> terms``: one term per wrench slot (flag -1: not flown)."""

    def done(P, Q, i, f, terms):
        return terms

    stage = _inlined(done)
    for k, module, a, width in reversed(_slots(chain, has_term)):
        stage = _term_slot(module.wrench_term, float(k), a, width, stage)

    def collect(P, Q, i, f):
        return stage(P, Q, i, f, ())

    return _inlined(collect)


def _term_slot(kernel, flag, a, width, rest):
    b = a + width

    def stage(P, Q, i, f, terms):
        W = NO_TERM
        on = P[i, a - 1]
        if on != 0.0:
            s = kernel(P[i, a:b], Q[i, int(on) - 1 :], f)
            W = (flag, s[0], s[1], s[2], s[3], s[4], s[5])
        return rest(P, Q, i, f, terms + (W,))

    return _inlined(stage)


def _sum_stage(chain: ChainLayout):
    """``total(terms, v, R, w) -> (F, M)``: every flown term's ``wrench_stage`` at one RK
    stage's state, added in slot order (straight-line: a select per slot, no branch, which
    numba would type again in each of the four RK stages it is inlined into)."""

    def done(terms, v, R, w, FM):
        return FM

    stage = _inlined(done)
    slots = _slots(chain, has_term)
    for j in reversed(range(len(slots))):
        stage = _sum_slot(slots[j][1].wrench_stage, j, stage)

    def total(terms, v, R, w):
        return stage(terms, v, R, w, ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))

    return _inlined(total)


def _sum_slot(kernel, j, rest):
    def stage(terms, v, R, w, FM):
        s = terms[j]
        return rest(terms, v, R, w, plus_if(s[0] >= 0.0, FM, kernel(s, v, R, w)))

    return _inlined(stage)


def _any_stage(chain: ChainLayout):
    """``flown(terms) -> bool``: whether any term is flown."""
    n = len(_slots(chain, has_term))

    def none(terms):
        return False

    stage = _inlined(none)
    for j in reversed(range(n)):
        stage = _any_slot(j, stage)
    return stage


def _any_slot(j, rest):
    def stage(terms):
        return terms[j][0] >= 0.0 or rest(terms)

    return _inlined(stage)


def _write_back(n: int):
    """``store(f, x)``: the thrusts ``x`` (a tuple of n) into the array ``f``, once."""

    def store(f, x):
        for r in range(n):
            f[r] = x[r]

    return _inlined(store)


_STAGES: dict = {}  # ChainLayout -> its stages


def stages(chain: ChainLayout) -> dict:
    """The compiled stages of a layout (made once per process)."""
    out = _STAGES.get(chain)
    if out is None:
        n = chain.n_rotors
        thrust, collect, total, flown = (
            _thrust_stage(chain),
            _term_stage(chain),
            _sum_stage(chain),
            _any_stage(chain),
        )
        store, thrusts = _write_back(n), _tuple_stage(n)
        any_thrust = bool(_slots(chain, has_thrust))

        def thrust_effects(fx, i, f, t, dt, p, v, R, w, gen):
            if any_thrust:
                x = thrust(fx.params, fx.memory, fx.streams, i, thrusts(f), t, dt, p, gen)
                store(f, x)

        def wrench_terms(fx, i, f, t):
            return Terms(fx.layout, collect(fx.params, fx.memory, i, f))

        def step(fx, i, f, t, dt, p, v, R, w, gen):
            P, Q = fx.params, fx.memory
            if any_thrust:
                x = thrust(P, Q, fx.streams, i, thrusts(f), t, dt, p, gen)
                store(f, x)
            return Terms(fx.layout, collect(P, Q, i, f))

        def has(W):
            return flown(W.terms)

        def wrench(W, p, v, R, w, f, t):
            return total(W.terms, v, R, w)

        out = _STAGES[chain] = {
            "thrust_effects": thrust_effects,
            "wrench_terms": wrench_terms,
            "step_effects": step,
            "has_wrench": has,
            "effects_wrench": wrench,
        }
    return out


def _tuple_stage(n: int):
    """``thrusts(f) -> x``: the first ``n`` entries of the array ``f`` as a tuple, read once
    (the thrust stage carries them from kernel to kernel in registers)."""

    def done(f, x):
        return x

    stage = _inlined(done)
    for r in reversed(range(n)):
        stage = _tuple_slot(r, stage)

    def thrusts(f):
        return stage(f, ())

    return _inlined(thrusts)


def _tuple_slot(r, rest):
    def stage(f, x):
        return rest(f, x + (f[r],))

    return _inlined(stage)


# Python entry points over rows (tests, the one-vehicle protocol): the same stages, compiled
@jit.jit
def thrust_effects(fx, i, f, t, dt, p, v, R, w, gen):
    """The chain's thrust stage for the step ``[t, t + dt)`` [s]: ``f`` (n,), the thrusts
    [N] the motors produced, replaced in place; ``(p, v, R, w)`` the state at the step's
    start; ``gen`` the vehicle's generator; ``fx`` the rows, ``i`` the vehicle."""
    _thrust_effects(fx, i, f, t, dt, p, v, R, w, gen)


@jit.jit
def wrench_terms(fx, i, f, t):
    """Vehicle ``i``'s wrench terms over the step starting at ``t`` [s] whose produced
    thrusts are ``f``: numbers only, so that the RK stages (``effects_wrench``) take no
    arrays."""
    return _wrench_terms(fx, i, f, t)


@jit.jit
def summed_wrench(W, p, v, R, w, f, t):
    """:func:`effects_wrench` from Python."""
    return effects_wrench(W, p, v, R, w, f, t)


def _thrust_effects(fx, i, f, t, dt, p, v, R, w, gen):
    raise NotImplementedError("compiled code only")


def _wrench_terms(fx, i, f, t):
    raise NotImplementedError("compiled code only")


# numba: the layout's type and the stubs' compiled forms -------------------------------
if _types is not None:

    class LayoutType(_types.Dummy):
        """The numba type of a :class:`ChainLayout`: the layout itself (no run-time data),
        so that rows of another layout compile another chain."""

        def __init__(self, chain: ChainLayout):
            self.chain = chain
            slots = ", ".join(f"{c.__module__}.{c.__qualname__}" for c in chain.effects)
            super().__init__(f"ChainLayout(({slots}), n_rotors={chain.n_rotors})")

        def __reduce__(self):  # numba's cache pickles the loop's signature: by names
            names = tuple((c.__module__, c.__qualname__) for c in self.chain.effects)
            return (_layout_type, (names, self.chain.n_rotors))

    class BorrowedType(_types.Array):
        """The numba type of a :class:`Borrowed` array: an array (every array operation
        applies; its views are arrays) whose native form holds no reference count."""

        def __init__(self, dtype, ndim, layout, readonly=False, aligned=True):
            super().__init__(
                dtype,
                ndim,
                layout,
                readonly=readonly,
                aligned=aligned,
                name=f"borrowed({dtype}, {ndim}d, {layout})",
            )

        def copy(self, dtype=None, ndim=None, layout=None, readonly=None):
            return _types.Array(
                self.dtype if dtype is None else dtype,
                self.ndim if ndim is None else ndim,
                self.layout if layout is None else layout,
                readonly=not self.mutable if readonly is None else readonly,
                aligned=self.aligned,
            )


def _layout_type(names, n_rotors):
    """The :class:`LayoutType` of effect classes named ``(module, qualname)`` (numba's cache
    index unpickles signatures with it); a layout no rows have when a class is gone (an
    effect module renamed or removed: that cache entry is never used)."""
    try:
        effects = []
        for module, qualname in names:
            obj = importlib.import_module(module)
            for part in qualname.split("."):
                obj = getattr(obj, part)
            effects.append(obj)
    except (ImportError, AttributeError):
        return LayoutType(ChainLayout((), -1))
    return LayoutType(ChainLayout(tuple(effects), n_rotors))


def _register() -> None:
    from numba.core import cgutils
    from numba.extending import (
        NativeValue,
        box,
        models,
        overload,
        register_model,
        typeof_impl,
        unbox,
    )

    @typeof_impl.register(ChainLayout)
    def _typeof(value, c):
        return LayoutType(value)

    register_model(LayoutType)(models.OpaqueModel)

    @unbox(LayoutType)
    def _unbox(typ, obj, c):  # the type is the layout: no run-time data
        return NativeValue(cgutils.get_null_value(c.context.get_value_type(typ)))

    @box(LayoutType)
    def _box(typ, val, c):  # the layout of the type (terms returned to Python)
        return c.pyapi.unserialize(c.pyapi.serialize_object(typ.chain))

    @typeof_impl.register(Borrowed)
    def _typeof_borrowed(value, c):
        plain = typeof_impl(value.view(np.ndarray), c)
        return BorrowedType(plain.dtype, plain.ndim, plain.layout, not plain.mutable)

    register_model(BorrowedType)(models.ArrayModel)

    @unbox(BorrowedType)
    def _unbox_borrowed(typ, obj, c):  # an array's native form, its reference released
        plain = typ.copy()
        native = c.unbox(plain, obj)
        if c.context.enable_nrt:  # (a kernel compiled without reference counts has none)
            c.context.nrt.decref(c.builder, plain, native.value)
        ary = c.context.make_array(plain)(c.context, c.builder, value=native.value)
        ary.meminfo = cgutils.get_null_value(ary.meminfo.type)
        return NativeValue(ary._getvalue(), is_error=native.is_error)

    def chain_of(typ):
        """The layout of a numba type of rows or terms (None: no effects)."""
        field = typ.types[typ.fields.index("layout")]
        return field.chain if isinstance(field, LayoutType) else None

    def pick(name):
        return lambda typ: stages(chain_of(typ))[name]

    def nothing(fx, i, f, t, dt, p, v, R, w, gen):  # no effects: no terms
        return Terms(None, ())

    def no_wrench(W):
        return False

    def zero_wrench(W, p, v, R, w, f, t):
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)

    @overload(step_effects, inline="always")
    def _step(fx, i, f, t, dt, p, v, R, w, gen):
        if isinstance(fx, _types.NoneType):
            return nothing
        return pick("step_effects")(fx)

    @overload(_thrust_effects, inline="always")
    def _thrust(fx, i, f, t, dt, p, v, R, w, gen):
        return pick("thrust_effects")(fx)

    @overload(_wrench_terms, inline="always")
    def _terms(fx, i, f, t):
        return pick("wrench_terms")(fx)

    @overload(has_wrench, inline="always")
    def _has(W):
        return no_wrench if chain_of(W) is None else pick("has_wrench")(W)

    @overload(effects_wrench, inline="always")
    def _wrench(W, p, v, R, w, f, t):
        return zero_wrench if chain_of(W) is None else pick("effects_wrench")(W)


if jit.AVAILABLE:
    _register()

__all__ = [
    "NO_TERM",
    "TERM",
    "Borrowed",
    "ChainLayout",
    "EffectRows",
    "Terms",
    "effects_wrench",
    "has_term",
    "has_thrust",
    "has_wrench",
    "kernels",
    "stages",
    "step_effects",
    "summed_wrench",
    "thrust_effects",
    "wrench_terms",
]
