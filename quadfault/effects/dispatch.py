"""The compiled effect chain, generated from the registry: one dispatcher per set of effects.

numba compiles no call through a table of functions, so the chain picks an entry's kernels
with an ``if`` on its code. Those ``if`` chains are written here, from the effect classes
given (the registry's :data:`~quadfault.effects.registry.TABLE` by default, or only the
effects a flight uses, which compiles less): :func:`source` is the text of a module with

* ``_thrust_entry(c, ...)``: effect ``c``'s ``thrust_step`` (the effects whose module has
  one: the thrust stage, once per physics step);
* ``_is_wrench(c)``, ``_term(c, ...)`` and ``_stage_term(s, ...)``: effect ``c``'s
  ``wrench_term`` (the step's numbers, a term ``(code, six numbers)``) and
  ``wrench_stage`` (the force and moment at each RK stage from a term);

and the chain over a vehicle's entries (:data:`SKELETON`: ``thrust_effects``,
``wrench_terms``, ``step_effects``, ``has_wrench``, ``effects_wrench``; the layout of the
rows is in :mod:`quadfault.effects.chain`). :func:`compiled` writes that text to a file
named by its hash -- beside numba's cache, so numba caches it like any module -- and
imports it; the same effects give the same module. An effect's code is its row in the
registry, so rows built from the registry fly under every dispatcher that has their
effects.
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

#: wrench entries a vehicle may have (e.g. one of each wrench effect); each becomes a term
#: of :data:`TERM` numbers
WRENCH_TERMS = 6
TERM = 7
_NO_TERM = (-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
#: the terms of a vehicle without wrench entries
NO_TERMS = (_NO_TERM,) * WRENCH_TERMS

#: the chain over a vehicle's entries, the same for every set of effects (``_thrust_entry``,
#: ``_is_wrench``, ``_term``, ``_stage_term``, ``_collect`` and ``_sum`` are generated)
SKELETON = '''
@jit(inline="always", cache=CACHE)
def _thrust_stage(code, param, mem, P, Q, streams, i, f, t, dt, p, gen):
    """The thrust stage of vehicle ``i`` over its entries, in chain order."""
    for e in range(code.shape[1]):
        c = code[i, e]
        if c < 0:
            break
        _thrust_entry(c, P, Q, streams, i, param[i, e], mem[i, e], f, t, dt, p, gen)


@jit(cache=CACHE)
def thrust_effects(fx, i, f, t, dt, p, v, R, w, gen):
    """The chain's thrust stage for the step ``[t, t + dt)`` [s]: ``f`` (n,), the thrusts
    [N] the motors produced, replaced in place; ``(p, v, R, w)`` the state at the step's
    start; ``gen`` the vehicle's generator; ``fx`` the rows, ``i`` the vehicle."""
    _thrust_stage(fx.code, fx.param, fx.mem, fx.params, fx.memory, fx.streams, i, f, t, dt,
                  p, gen)


@jit(cache=CACHE)
def wrench_terms(fx, i, f, t):
    """Vehicle ``i``'s wrench entries over the step starting at ``t`` [s] whose produced
    thrusts are ``f``: the rows' terms (:data:`TERMS`, code -1 past the last), numbers only,
    so that the RK stages (``effects_wrench``) take no arrays (an array argument costs
    reference counting at every call)."""
    return _collect(fx.code, fx.param, fx.mem, fx.params, fx.memory, i, f)


@jit(inline="always", cache=CACHE)
def step_effects(fx, i, f, t, dt, p, v, R, w, gen):
    """The chain's work for physics step ``[t, t + dt)`` [s] of vehicle ``i``: the thrust
    stage on ``f`` (``thrust_effects``; same arguments), then the step's wrench terms
    (``wrench_terms``) returned for the RK stages. Inlined into the loop with the rows'
    arrays taken once (each array a compiled call takes costs reference counting)."""
    code, param, mem, P, Q = fx.code, fx.param, fx.mem, fx.params, fx.memory
    _thrust_stage(code, param, mem, P, Q, fx.streams, i, f, t, dt, p, gen)
    return _collect(code, param, mem, P, Q, i, f)


@jit(inline="always", cache=CACHE)
def _add_term(F, M, s, v, R, w):
    """``(F, M)`` plus term ``s``'s force and moment (unchanged past the last term)."""
    if s[0] < 0.0:
        return F, M
    dF, dM = _stage_term(s, v, R, w)
    return ((F[0] + dF[0], F[1] + dF[1], F[2] + dF[2]),
            (M[0] + dM[0], M[1] + dM[1], M[2] + dM[2]))


@jit(inline="always", cache=CACHE)
def effects_wrench(W, p, v, R, w, f, t):
    """The summed external force (world) [N] and moment (body) [N m] of a vehicle's wrench
    entries at one RK stage's state, from the step's terms ``W`` (``p``, ``f``, ``t``: the
    protocol's arguments, already in the terms)."""
    return _sum(W.terms, v, R, w)
'''


def _collect_source(n_terms: int) -> list:
    """``_collect``: a vehicle's wrench entries as the ``n_terms`` terms of :data:`TERMS`."""
    out = ['@jit(inline="always", cache=CACHE)', "def _collect(code, param, mem, P, Q, i, f):",
           '    """Vehicle ``i``\'s wrench entries in chain order as the terms (code -1 past '
           'the last), in one pass over the entries."""']
    if n_terms == 0:
        return out + ["    return TERMS(())", "", ""]
    names = [f"W{k}" for k in range(n_terms)]
    out += [f"    {' = '.join(names)} = NO_TERMS[0]", "    k = 0", "    for e in range(code.shape[1]):", "        c = code[i, e]",
            "        if c < 0:", "            break", "        if not _is_wrench(c):",
            "            continue", "        s = _term(c, P, Q, i, param[i, e], mem[i, e], f)"]
    for k, name in enumerate(names):
        if n_terms == 1:
            out += [f"        {name} = s"]
            break
        out += ([f"        {'if' if k == 0 else 'elif'} k == {k}:"] if k < n_terms - 1
                else ["        else:"])
        out += [f"            {name} = s"]
    out += ["        k += 1", f"    return TERMS(({', '.join(names)},))", "", ""]
    return out


def _sum_source(n_terms: int) -> list:
    """``_sum`` and ``has_wrench`` over ``n_terms`` terms."""
    out = ['@jit(inline="always", cache=CACHE)', "def has_wrench(W):",
           '    """Whether the step\'s terms ``W`` hold a wrench entry (else the RK stages need '
           'not call ``effects_wrench``)."""',
           f"    return {'W.terms[0][0] >= 0.0' if n_terms else 'False'}", "", "",
           '@jit(inline="always", cache=CACHE)', "def _sum(terms, v, R, w):",
           '    """The summed force and moment of the terms at a stage\'s state."""',
           "    F = M = (0.0, 0.0, 0.0)"]
    out += [f"    F, M = _add_term(F, M, terms[{k}], v, R, w)" for k in range(n_terms)]
    return out + ["    return F, M", "", ""]


def kernels(cls) -> types.ModuleType:
    """The module of effect class ``cls``: where its kernels are."""
    return sys.modules[cls.__module__]


def has_thrust(cls) -> bool:
    """Whether the effect has a thrust-stage kernel (``thrust_step``)."""
    return hasattr(kernels(cls), "thrust_step")


def has_term(cls) -> bool:
    """Whether the effect has a wrench (``wrench_term`` and ``wrench_stage``)."""
    return hasattr(kernels(cls), "wrench_term")


def source(table, codes, n_terms: int = WRENCH_TERMS, cache: bool = True) -> str:
    """The text of the chain's module for the effect classes ``table`` with their ``codes``
    (both in registry order), a vehicle flying at most ``n_terms`` wrench entries."""
    rows = [(code, cls, f"e{code}") for code, cls in zip(codes, table)
            if has_thrust(cls) or has_term(cls)]
    names = ", ".join(cls.name for _, cls, _ in rows) or "no effects"
    out = [f'"""The compiled effect chain of {names} (generated by '
           'quadfault.effects.dispatch; do not edit)."""', "",
           "from quadfault.effects.chain import terms_class",
           "from quadfault.jit import jit"]
    out += [f"import {cls.__module__} as {alias}" for _, cls, alias in rows]
    out += ["", f"CACHE = {cache!r}", f"NO_TERMS = {NO_TERMS!r}",
            f"TERMS = terms_class({tuple(cls.name for _, cls, _ in rows)!r}, {n_terms})",
            "", ""]
    out += ['@jit(inline="always", cache=CACHE)',
            "def _thrust_entry(c, P, Q, streams, i, a, m, f, t, dt, p, gen):",
            '    """Entry ``c``\'s thrust-stage kernel for vehicle ``i``."""']
    branch = "if"
    for code, cls, alias in rows:
        if has_thrust(cls):
            out += [f"    {branch} c == {code}:  # {cls.name}",
                    f"        {alias}.thrust_step(P, Q, streams, i, a, m, f, t, dt, p, gen)"]
            branch = "elif"
    out += ["    return", "", ""]
    wrench = [(code, cls, alias) for code, cls, alias in rows if has_term(cls)]
    test = " or ".join(f"c == {code}" for code, _, _ in wrench) or "False"
    out += ['@jit(inline="always", cache=CACHE)', "def _is_wrench(c):",
            '    """Whether entry ``c`` has a wrench."""', f"    return {test}", "", ""]
    out += ['@jit(inline="always", cache=CACHE)', "def _term(c, P, Q, i, a, m, f):",
            '    """Wrench entry ``c`` as the numbers the RK stages need: ``(code, six '
            'numbers)``."""',
            "    s = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)"]
    branch = "if"
    for code, cls, alias in wrench:
        out += [f"    {branch} c == {code}:  # {cls.name}",
                f"        s = {alias}.wrench_term(P, Q, i, a, m, f)"]
        branch = "elif"
    out += ["    return (float(c), s[0], s[1], s[2], s[3], s[4], s[5])", "", ""]
    out += ['@jit(inline="always", cache=CACHE)', "def _stage_term(s, v, R, w):",
            '    """One term\'s external force (world) [N] and moment (body) [N m] at a '
            'stage\'s state."""',
            "    c = int(s[0])"]
    for code, cls, alias in wrench:
        out += [f"    if c == {code}:  # {cls.name}",
                f"        return {alias}.wrench_stage(s, v, R, w)"]
    out += ["    return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)", "", ""]
    out += _collect_source(n_terms) + _sum_source(n_terms)
    return "\n".join(out) + SKELETON


def _directory() -> Path | None:
    """Where generated chains are written: beside numba's cache (``NUMBA_CACHE_DIR``, which
    :func:`quadfault.jit.configure_cache` sets per version of the sources), else in the
    temporary directory; None when neither is writable."""
    base = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        tempfile.gettempdir(), f"quadfault-numba-{os.getuid() if hasattr(os, 'getuid') else 0}")
    path = Path(base) / "effect-chains"
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return path if os.access(path, os.W_OK) else None


_LOADED: dict = {}  # source hash -> module


def compiled(table, codes, n_terms: int = WRENCH_TERMS) -> types.ModuleType:
    """The chain's module for the effect classes ``table`` with their ``codes`` and at most
    ``n_terms`` wrench entries per vehicle: generated, written to a file named by its hash
    and imported (numba caches it like any module); run uncached from memory when no
    directory is writable."""
    text = source(table, codes, n_terms)
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    if digest in _LOADED:
        return _LOADED[digest]
    name = f"quadfault.effects._chain_{digest}"
    folder = _directory()
    if folder is None:
        module = types.ModuleType(name)
        module.__file__ = f"<{name}>"
        sys.modules[name] = module
        exec(compile(source(table, codes, n_terms, cache=False), module.__file__, "exec"),
             module.__dict__)
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


__all__ = ["SKELETON", "WRENCH_TERMS", "TERM", "NO_TERMS", "source", "compiled", "kernels",
           "has_thrust", "has_term"]
