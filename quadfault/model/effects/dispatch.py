"""The compiled effect chain, generated from a layout: straight-line code per set of effects.

numba compiles no call through a table of functions, and a loop over a vehicle's entries
that picks each one's kernels by its code costs more than the kernels of a cheap effect. So
the chain is written out here for a *layout* (:mod:`quadfault.model.effects.chain`): its slots in
chain order, each an effect and the width of its parameters, on vehicles of n rotors. Slot
``k``'s columns of the
parameter rows are fixed by the layout -- a marker (0: the vehicle does not fly the slot;
else one more than the column of the entry's first memory slot) and then the effect's
parameters -- so :func:`source` writes, with every column a constant:

* ``_thrust_stage``: for each slot whose module has ``thrust_step``, in slot order, that
  kernel when the vehicle flies it (the thrust stage, once per physics step), the n
  thrusts carried from kernel to kernel as a tuple (read from the loop's array once and
  written back once: per effect, an array write before the next one's read would stall the
  step, and a loop over an array the compiler vectorises with run-time checks);
* ``_collect``: for each slot whose module has ``wrench_term``, its term -- ``(code, six
  numbers)``, or ``(-1, ...)`` when the vehicle does not fly it -- the numbers the RK stages
  need; ``_sum``: each flown term's ``wrench_stage`` at one RK stage, added in slot order;
  ``has_wrench``: whether any term is flown;

and the chain's functions over them (:data:`SKELETON`: ``thrust_effects``, ``wrench_terms``,
``step_effects``, ``has_wrench``, ``effects_wrench``). No loop over entries, no dispatch on
codes and no array lookup of an offset at run time. :func:`compiled` writes that text to a
file named by its hash -- beside numba's cache, so numba caches it like any module -- and
imports it; the same layout gives the same module.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import tempfile
import types
from pathlib import Path

from quadfault.fileio import atomic_write_text

#: numbers in a wrench term: the effect's code (-1: not flown) and six numbers
TERM = 7
NO_TERM = (-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

#: the chain's functions, the same for every layout (``_thrust_stage``, ``_collect``,
#: ``_sum`` and ``has_wrench`` are generated)
SKELETON = '''
@jit(cache=CACHE)
def thrust_effects(fx, i, f, t, dt, p, v, R, w, gen):
    """The chain's thrust stage for the step ``[t, t + dt)`` [s]: ``f`` (n,), the thrusts
    [N] the motors produced, replaced in place; ``(p, v, R, w)`` the state at the step's
    start; ``gen`` the vehicle's generator; ``fx`` the rows, ``i`` the vehicle."""
    _thrust_stage(borrowed(fx.params), borrowed(fx.memory), borrowed(fx.streams), i, f, t,
                  dt, p, gen)


@jit(cache=CACHE)
def wrench_terms(fx, i, f, t):
    """Vehicle ``i``'s wrench terms over the step starting at ``t`` [s] whose produced
    thrusts are ``f``: numbers only, so that the RK stages (``effects_wrench``) take no
    arrays (an array argument costs reference counting at every call)."""
    return _collect(fx.params, fx.memory, i, f)


@jit(inline="always", cache=CACHE)
def step_effects(fx, i, f, t, dt, p, v, R, w, gen):
    """The chain's work for physics step ``[t, t + dt)`` [s] of vehicle ``i``: the thrust
    stage on ``f`` (``thrust_effects``; same arguments), then the step's wrench terms
    (``wrench_terms``) returned for the RK stages. Inlined into the loop, the rows' arrays
    taken once and read through views without a reference count (``borrowed``: an array
    used in a branch takes and drops a reference at every step)."""
    P, Q = borrowed(fx.params), borrowed(fx.memory)
    _thrust_stage(P, Q, borrowed(fx.streams), i, f, t, dt, p, gen)
    return _collect(P, Q, i, f)


@jit(inline="always", cache=CACHE)
def effects_wrench(W, p, v, R, w, f, t):
    """The summed external force (world) [N] and moment (body) [N m] of a vehicle's wrench
    entries at one RK stage's state, from the step's terms ``W`` (``p``, ``f``, ``t``: the
    protocol's arguments, already in the terms)."""
    return _sum(W.terms, v, R, w)
'''


def kernels(cls) -> types.ModuleType:
    """The module of effect class ``cls``: where its kernels are."""
    return sys.modules[cls.__module__]


def has_thrust(cls) -> bool:
    """Whether the effect has a thrust-stage kernel (``thrust_step``)."""
    return hasattr(kernels(cls), "thrust_step")


def has_term(cls) -> bool:
    """Whether the effect has a wrench (``wrench_term`` and ``wrench_stage``)."""
    return hasattr(kernels(cls), "wrench_term")


def columns(widths) -> list:
    """The column of each slot's marker for slots of parameter ``widths`` (its parameters
    follow it)."""
    out, a = [], 0
    for width in widths:
        out.append(a)
        a += 1 + int(width)
    return out


def source(slots, n_rotors: int, cache: bool = True) -> str:
    """The text of the chain's module for a layout: ``slots`` ``(code, effect class, width)``
    in chain order (the code: the effect's row in the registry), on vehicles of
    ``n_rotors`` rotors."""
    at = columns(width for _, _, width in slots)
    names = ", ".join(cls.name for _, cls, _ in slots) or "no effects"
    out = [
        f'"""The compiled effect chain of the slots {names} (generated by '
        'quadfault.model.effects.dispatch; do not edit)."""',
        "",
        "from quadfault.model.effects.chain import borrowed, plus_if, terms_class",
        "from quadfault.jit import jit",
    ]
    modules = sorted({cls.__module__ for _, cls, _ in slots})
    alias = {m: f"e{k}" for k, m in enumerate(modules)}
    out += [f"import {m} as {alias[m]}" for m in modules]
    layout = tuple((cls.name, int(width)) for _, cls, width in slots)
    n = int(n_rotors)
    out += [
        "",
        f"CACHE = {cache!r}",
        f"NO_TERM = {NO_TERM!r}",
        f"TERMS = terms_class({layout!r}, {n})",
        "",
        "",
    ]
    out += [
        '@jit(inline="always", cache=CACHE)',
        "def _thrust_stage(P, Q, streams, i, f, t, dt, p, gen):",
        '    """The thrust stage of vehicle ``i``: each flown slot\'s kernel, in slot '
        'order, on the thrusts ``f`` as a tuple (written back at the end)."""',
    ]
    thrust = [(cls, a) for (_, cls, _), a in zip(slots, at) if has_thrust(cls)]
    if thrust:
        out += ["    x = (" + "".join(f"f[{r}], " for r in range(n)) + ")"]
    for cls, a in thrust:
        out += [
            f"    on = P[i, {a}]  # {cls.name}",
            "    if on != 0.0:",
            f"        x = {alias[cls.__module__]}.thrust_step(P, Q, streams, i, {a + 1}, "
            "int(on) - 1, x, t, dt, p, gen)",
        ]
    if thrust:
        out += [f"    f[{r}] = x[{r}]" for r in range(n)]
    out += ["    return", "", ""]
    wrench = [(code, cls, a) for (code, cls, _), a in zip(slots, at) if has_term(cls)]
    out += [
        '@jit(inline="always", cache=CACHE)',
        "def _collect(P, Q, i, f):",
        '    """Vehicle ``i``\'s wrench terms, one per wrench slot (code -1: not flown)."""',
    ]
    for k, (code, cls, a) in enumerate(wrench):
        out += [
            f"    W{k} = NO_TERM",
            f"    on = P[i, {a}]  # {cls.name}",
            "    if on != 0.0:",
            f"        s = {alias[cls.__module__]}.wrench_term(P, Q, i, {a + 1}, int(on) - 1, f)",
            f"        W{k} = ({float(code)!r}, s[0], s[1], s[2], s[3], s[4], s[5])",
        ]
    terms = "".join(f"W{k}, " for k in range(len(wrench)))
    out += [f"    return TERMS(({terms}))", "", ""]
    out += [
        '@jit(inline="always", cache=CACHE)',
        "def has_wrench(W):",
        '    """Whether the step\'s terms ``W`` hold a flown wrench (else the RK stages '
        'need not call ``effects_wrench``)."""',
        "    return "
        + (" or ".join(f"W.terms[{k}][0] >= 0.0" for k in range(len(wrench))) or "False"),
        "",
        "",
    ]
    # straight-line code, each name assigned once: every slot's stage is evaluated (an
    # unflown slot's on its NO_TERM numbers) and added when flown (``plus_if``, a select).
    # numba inlines this sum into the four RK stages: a branch there costs more than a
    # cheap effect's stage, and its SSA pass warns of a name reassigned in a branch of an
    # inlined copy ("variable ... is not in scope")
    out += [
        '@jit(inline="always", cache=CACHE)',
        "def _sum(terms, v, R, w):",
        '    """The summed force and moment of the flown terms at a stage\'s state, in '
        'slot order."""',
        "    FM0 = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))",
    ]
    for k, (_code, cls, _a) in enumerate(wrench):
        out += [
            f"    s{k} = terms[{k}]  # {cls.name}",
            f"    FM{k + 1} = plus_if(s{k}[0] >= 0.0, FM{k}, "
            f"{alias[cls.__module__]}.wrench_stage(s{k}, v, R, w))",
        ]
    out += [f"    return FM{len(wrench)}", "", ""]
    return "\n".join(out) + SKELETON


def _directory() -> Path | None:
    """Where generated chains are written: beside numba's cache (``NUMBA_CACHE_DIR``, which
    :func:`quadfault.jit.configure_cache` sets per version of the sources), else in the
    temporary directory; None when neither is writable."""
    base = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        tempfile.gettempdir(), f"quadfault-numba-{os.getuid() if hasattr(os, 'getuid') else 0}"
    )
    path = Path(base) / "effect-chains"
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return path if os.access(path, os.W_OK) else None


_LOADED: dict = {}  # source hash -> module


def compiled(slots, n_rotors: int) -> types.ModuleType:
    """The chain's module for the layout ``slots`` on vehicles of ``n_rotors`` rotors (see
    :func:`source`): generated, written to a file named by its hash and imported (numba
    caches it like any module); run uncached from memory when no directory is writable."""
    text = source(slots, n_rotors)
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    if digest in _LOADED:
        return _LOADED[digest]
    name = f"quadfault.model.effects._chain_{digest}"
    folder = _directory()
    if folder is None:
        module = types.ModuleType(name)
        module.__file__ = f"<{name}>"
        sys.modules[name] = module
        exec(
            compile(source(slots, n_rotors, cache=False), module.__file__, "exec"), module.__dict__
        )
    else:
        path = folder / f"chain_{digest}.py"
        if not path.is_file() or path.read_text(encoding="utf-8") != text:
            # atomic: concurrent processes write the same text
            atomic_write_text(path, text, force=True)
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    _LOADED[digest] = module
    return module


__all__ = [
    "SKELETON",
    "TERM",
    "NO_TERM",
    "columns",
    "source",
    "compiled",
    "kernels",
    "has_thrust",
    "has_term",
]
