"""The effect chain of the closed loop: the built-in effects of every vehicle, compiled.

The effects of N vehicles are rows of numbers (:class:`EffectRows`; built by
:mod:`quadfault.model.effects.rows` from each effect's ``pack``) under one *layout*: slots in
chain order, each an effect and the width of its parameters, on vehicles of n rotors (the
thrust stage carries the n thrusts as a tuple). A slot's columns are the same
for every vehicle -- a marker (0: the vehicle does not fly it; else one more than the
column of the entry's first memory slot) then the effect's parameters -- so the compiled
chain reads them at constant columns. The rows are built as the class :func:`rows_class` of
their layout and rotor count, and this module's functions compile, for each, straight-line code over
its slots (:mod:`quadfault.model.effects.dispatch`; :func:`chain_for`): an effect no vehicle
flies costs the loop nothing, a flight without effects compiles none, and a vehicle pays,
per step, one test of each slot it does not fly. Vehicles with other parameters, or flying
fewer of the layout's effects, share the compiled chain: randomising parameters per vehicle
costs what flying them costs.

The closed loop (:func:`quadfault.model.closed_loop.fly_vehicle`) calls the chain once per
physics step, :func:`step_effects` (inlined into the loop, so the rows' arrays are taken
once per step and no call passes them: every array a compiled call takes costs reference
counting), which does the two points of the effect protocol:

* the thrust stage (:func:`thrust_effects`), on the thrusts the motor model produced (in
  slot order, each one's output the next one's input: a tuple of the n thrusts, which
  each ``thrust_step`` returns anew; the loop's array is written once, at the end);
* the step's wrench terms (:func:`wrench_terms`): the numbers the RK stages need, so that
  :func:`effects_wrench` gives at every stage of the RKMK4 step the sum of the flown wrench
  slots' external force (world) [N] and moment (body) [N m] from numbers alone; a step
  without a flown wrench skips the stages' call (:func:`has_wrench`).

Each slot runs the kernels of its effect's module (``thrust_step``, ``wrench_term``,
``wrench_stage``; each documents its parameters and memory).

Random numbers: a wind's gusts draw three standard normals per step, after the motors'
draws, from the vehicle's generator (the loop's), or from the wind's own seeded generator
(row ``i`` of ``streams``, a :class:`~quadfault.model.generator_table.GeneratorTable` like the
loop's own) when it has a seed.
"""

from __future__ import annotations

import re
from typing import NamedTuple

import numpy as np

import quadfault.jit as jit
import quadfault.model.effects.dispatch as dispatch
import quadfault.model.effects.registry as registry
from quadfault.model.effects.dispatch import NO_TERM, TERM

#: effect name -> code of its entry (body effects -- mass, inertia -- have none: they set
#: the flown vehicle's mass and inertia)
CODES = {
    cls.name: k
    for k, cls in enumerate(registry.TABLE)
    if dispatch.has_thrust(cls) or dispatch.has_term(cls)
}


class EffectRows(NamedTuple):
    """The compiled effects of N vehicles (row ``i`` = vehicle ``i``; see the module
    docstring). ``memory`` is updated in place by the loop. Rows are built as the subclass
    :func:`rows_class` of their layout (its type picks the compiled chain). ``code``,
    ``param`` and ``mem`` list each vehicle's entries in its own order, for Python (the
    compiled chain reads the layout's columns)."""

    code: np.ndarray  # (N, E) int64: entry codes in the vehicle's order, -1 after the last
    param: np.ndarray  # (N, E) int64: column of each entry's first parameter
    mem: np.ndarray  # (N, E) int64: column of each entry's first memory slot
    params: np.ndarray  # (N, P) the layout's columns: per slot a marker, then parameters
    memory: np.ndarray  # (N, Q) memory (zeros: a flight's start)
    streams: np.ndarray  # (N, 6) GeneratorTable: a seeded wind's own generator per vehicle
    #                      (quadfault.model.generator_table; else one never drawn from)

    #: the layout: ``(effect name, parameter width)`` per slot, in chain order, and the
    #: vehicles' number of rotors (set on each :func:`rows_class`; class attributes, not
    #: fields)
    layout = ()
    n_rotors = 0


class Terms(NamedTuple):
    """A vehicle's wrench terms over one step (``terms``: one :data:`TERM`-number tuple per
    wrench slot of the layout, code -1 when not flown), as the subclass :func:`terms_class`
    of the rows' layout (its type picks the compiled RK-stage sum)."""

    terms: tuple

    layout = ()
    n_rotors = 0


_FAMILIES = {"EffectRows": EffectRows, "Terms": Terms}
_CLASSES: dict = {}


def _class(base: str, layout, n_rotors: int) -> type:
    """The subclass of ``base`` for ``layout`` on ``n_rotors`` rotors, made once and kept in
    this module under its name (so that numba's cache finds it again by name)."""
    layout = tuple((str(name), int(width)) for name, width in layout)
    n_rotors = int(n_rotors)
    name = "__".join((base, f"r{n_rotors}", *(f"{n}{w}" for n, w in layout)))
    cls = _CLASSES.get(name)
    if cls is None:
        cls = type(
            name,
            (_FAMILIES[base],),
            {"__slots__": (), "__module__": __name__, "layout": layout, "n_rotors": n_rotors},
        )
        _CLASSES[name] = globals()[name] = cls
    return cls


def rows_class(layout, n_rotors: int) -> type:
    """The :class:`EffectRows` of the layout ``layout`` (``(effect name, parameter width)``
    per slot, in chain order) on vehicles of ``n_rotors`` rotors."""
    return _class("EffectRows", layout, n_rotors)


def terms_class(layout, n_rotors: int) -> type:
    """The :class:`Terms` of a step of rows of :func:`rows_class` ``(layout, n_rotors)``."""
    return _class("Terms", layout, n_rotors)


def __getattr__(name):  # a class of a family, asked for by name (numba's cache, pickle)
    base, _, rest = name.partition("__")
    rotors, _, rest = rest.partition("__")
    if base in _FAMILIES and re.fullmatch(r"r\d+", rotors):
        slots = [re.fullmatch(r"([a-z_]+?)(\d+)", s) for s in rest.split("__") if rest]
        if all(m and m[1] in registry.EFFECTS for m in slots):
            return _class(base, [(m[1], int(m[2])) for m in slots], int(rotors[1:]))
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def chain_for(layout, n_rotors: int):
    """The compiled chain (a module with ``thrust_effects``, ``wrench_terms``,
    ``step_effects``, ``has_wrench``, ``effects_wrench``) of ``layout`` on vehicles of
    ``n_rotors`` rotors; rows of another layout must not fly under it."""
    return dispatch.compiled(
        [(registry.code(name), registry.effect_class(name), width) for name, width in layout],
        n_rotors,
    )


def _chain_of(typ):
    """The compiled chain of a numba type of :func:`rows_class` or :func:`terms_class`."""
    cls = typ.instance_class
    return chain_for(cls.layout, cls.n_rotors)


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


def borrowed(a):
    """``a`` itself (compiled: the same array without its reference count, see
    :func:`_compiled_borrowed`)."""
    return a


def _compiled_borrowed():
    """``borrowed(a)`` for compiled code: array ``a`` as a view that holds no reference.

    Each use of an array inside a branch of the loop's step takes and drops a reference to
    it (atomic operations, which the threads of a parallel loop contend for when all the
    vehicles read one array). The chain's rows stay alive while the loop runs (its caller
    holds them), so the chain reads them through views without a reference count (as
    :mod:`quadfault.model.generator_table` reads the generators)."""
    from numba.core import cgutils
    from numba.extending import intrinsic

    @intrinsic
    def _borrowed(typingctx, a):
        def codegen(context, builder, sig, args):
            view = context.make_array(sig.args[0])(context, builder, args[0])
            view.meminfo = cgutils.get_null_value(view.meminfo.type)
            view.parent = cgutils.get_null_value(view.parent.type)
            return view._getvalue()

        return a(a), codegen

    return _borrowed


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
    from numba.core import ir_utils
    from numba.extending import overload

    def pick(name):
        return lambda typ: getattr(_chain_of(typ), name).py_func

    none = terms_class((), 0)
    view = _compiled_borrowed()

    @overload(borrowed)
    def _borrow(a):
        if isinstance(a, types.Array):
            return lambda a: view(a)

    def _aliases(lhs, args, alias_map, arg_aliases):  # the view is its argument
        ir_utils._add_alias(lhs, args[0].name, alias_map, arg_aliases)

    ir_utils.alias_func_extensions[("borrowed", __name__)] = _aliases

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

__all__ = [
    "CODES",
    "EffectRows",
    "Terms",
    "TERM",
    "NO_TERM",
    "borrowed",
    "chain_for",
    "rows_class",
    "terms_class",
    "thrust_effects",
    "wrench_terms",
    "step_effects",
    "has_wrench",
    "effects_wrench",
]
