"""The compiled effect chain's numbers: each built-in effect as an entry, N vehicles as rows.

:func:`entry` turns an effect (its parameters, the flown vehicle's rotors, the physics step)
into the numbers the chain's kernels read: its code (the registry's) and what its ``pack``
lays out (:mod:`quadfault.effects.chain` has the layout); :func:`build` makes the
:class:`~quadfault.effects.chain.EffectRows` of N vehicles, each with its own effects;
:func:`write` replaces one vehicle's effects (domain randomisation: new parameters per
episode) and :func:`reset` clears vehicles' memory for a new flight.
:class:`Single` runs one vehicle's chain from Python: the effect protocol's numpy form of the
built-in effects (``rotor_thrust`` / ``wrench`` outside a loop, and inside the interpreted
loop beside effects written in Python).
"""

from __future__ import annotations

import numpy as np

import quadfault.effects.chain as C
import quadfault.effects.registry as registry
from quadfault.effects.base import Compiled
from quadfault.effects.dispatch import has_term
from quadfault.effects.delay import delay_capacity
from quadfault.errors import ConfigError
from quadfault.jit import jit, typed_list

#: the generator a row's stream holds when it has no seeded wind (never drawn from)
_NEVER = np.random.default_rng(0)


def entry(effect, n_rotors: int, dt: float, yaw_signs=None):
    """``(code, parameters, memory slots)`` of a built-in ``effect`` on a vehicle with
    ``n_rotors`` flown at physics step ``dt`` [s] (``yaw_signs``: the flown rotors' yaw-torque
    signs, for effects that need them); None for an effect without an entry (mass and
    inertia set the flown vehicle)."""
    if effect.name not in C.CODES:
        if registry.EFFECTS.get(effect.name) is type(effect):
            return None
        raise ConfigError(f"effect {effect.name!r} has no compiled form")
    params, memory = effect.pack(int(n_rotors), dt, yaw_signs)
    return C.CODES[effect.name], tuple(float(x) for x in params), int(memory)


def _size(entries) -> tuple[int, int, int]:
    return (len(entries), sum(len(p) for _, p, _ in entries), sum(m for _, _, m in entries))


def _kinds(entries) -> tuple[set, int]:
    """The effect names of ``entries`` and how many of them have a wrench."""
    names = {registry.TABLE[code].name for code, _, _ in entries}
    return names, sum(has_term(registry.TABLE[code]) for code, _, _ in entries)


def empty(n_rows: int, n_entries: int, n_params: int, n_memory: int, effects=(),
          n_terms: int = 0) -> C.EffectRows:
    """Rows without effects, room for ``n_entries`` entries of ``n_params`` parameters and
    ``n_memory`` memory slots in all per vehicle, of ``effects`` (names) with at most
    ``n_terms`` wrench entries per vehicle (:func:`~quadfault.effects.chain.rows_class`:
    the loop compiles the chain of these effects alone)."""
    N = int(n_rows)
    return C.rows_class(effects, n_terms)(
        np.full((N, n_entries), -1, dtype=np.int64), np.zeros((N, n_entries), dtype=np.int64),
        np.zeros((N, n_entries), dtype=np.int64), np.zeros((N, max(n_params, 1))),
        np.zeros((N, max(n_memory, 1))), typed_list([_NEVER] * N))


def fits(fx: C.EffectRows, entries) -> bool:
    """Whether one vehicle's ``entries`` fit the rows' room and effects."""
    E, P, Q = _size(entries)
    names, wrenches = _kinds(entries)
    return (E <= fx.code.shape[1] and P <= fx.params.shape[1] and Q <= fx.memory.shape[1]
            and names <= set(type(fx).effects) and wrenches <= type(fx).n_terms)


def write(fx: C.EffectRows, i: int, entries) -> None:
    """Vehicle ``i`` flies ``entries`` (a list of :func:`entry` results, in chain order)
    from a fresh start (memory cleared); they must :func:`fits`."""
    if _kinds(entries)[1] > C.WRENCH_TERMS:
        wrenches = ", ".join(cls.name for cls in registry.TABLE if has_term(cls))
        raise ConfigError(f"a vehicle flies at most {C.WRENCH_TERMS} effects with a wrench "
                          f"({wrenches})")
    if not fits(fx, entries):
        raise ConfigError("these effects need more room than the rows were built with")
    fx.code[i] = -1
    a = m = 0
    for e, (code, params, memory) in enumerate(entries):
        fx.code[i, e], fx.param[i, e], fx.mem[i, e] = code, a, m
        fx.params[i, a:a + len(params)] = params
        a, m = a + len(params), m + memory
    reset(fx, [i])


def build(entries_per_row) -> C.EffectRows:
    """The rows of N vehicles, row ``i`` flying ``entries_per_row[i]``."""
    sizes = [_size(e) for e in entries_per_row]
    kinds = [_kinds(e) for e in entries_per_row]
    fx = empty(len(sizes), *(max((s[k] for s in sizes), default=0) for k in range(3)),
               set().union(*(n for n, _ in kinds)), max((w for _, w in kinds), default=0))
    for i, e in enumerate(entries_per_row):
        write(fx, i, e)
    return fx


def grown(fx: C.EffectRows, entries) -> C.EffectRows:
    """``fx`` with room for ``entries`` too (a copy when it needs more; rows kept)."""
    if fits(fx, entries):
        return fx
    names, wrenches = _kinds(entries)
    E, P, Q = (max(a, b) for a, b in zip(_size(entries), (fx.code.shape[1], fx.params.shape[1],
                                                           fx.memory.shape[1])))
    out = empty(len(fx.code), E, P, Q, names | set(type(fx).effects),
                min(max(wrenches, type(fx).n_terms), C.WRENCH_TERMS))
    for old, new in zip(fx[:5], out[:5]):
        new[:, :old.shape[1]] = old
    for i in range(len(fx.code)):
        out.streams[i] = fx.streams[i]
    return out


def reset(fx: C.EffectRows, rows) -> None:
    """Clear the memory of vehicles ``rows`` (a new flight): lag and delay start empty, the
    gusts at 0, a seeded wind's generator restarts from its seed."""
    for i in np.atleast_1d(np.asarray(rows, dtype=np.int64)):
        fx.memory[i] = 0.0
        fx.streams[i] = _NEVER
        for e in range(fx.code.shape[1]):
            if fx.code[i, e] < 0:
                break
            seed = registry.TABLE[fx.code[i, e]].stream_seed(fx.params[i, fx.param[i, e]:])
            if seed is not None:
                fx.streams[i] = np.random.default_rng(seed)


def lost(fx: C.EffectRows) -> np.ndarray:
    """Vehicles (N,) bool with an entry that lost history it needed (a delay flown at steps
    much shorter than the physics step the rows were built for,
    :func:`~quadfault.effects.delay.delay_capacity`)."""
    out = np.zeros(len(fx.code), dtype=bool)
    for i, e in zip(*np.nonzero(fx.code >= 0)):
        out[i] |= registry.TABLE[fx.code[i, e]].lost(fx.memory[i, fx.mem[i, e]:])
    return out


@jit
def _thrust_one(fx, f, t, dt, p, v, R, w, gen):
    C.thrust_effects(fx, 0, f, t, dt, p, v, R, w, gen)


@jit
def _wrench_one(fx, p, v, R, w, f, t):
    return C.effects_wrench(C.wrench_terms(fx, 0, f, t), p, v, R, w, f, t)


class Single:
    """One vehicle's chain run from Python (arrays in, arrays out), for the built-in effects
    outside a loop or in the interpreted loop (:class:`quadfault.plant.EffectsHook`)."""

    def __init__(self, entries):
        self.rows = build([list(entries)])

    def rotor_thrust(self, f, t, dt, p, v, R, w, gen) -> None:
        """The thrust stage, ``f`` (n,) float array replaced in place."""
        _thrust_one(self.rows, f, float(t), float(dt), _vec(p), _vec(v), _vec(R, 9), _vec(w),
                    gen)

    def wrench(self, p, v, R, w, f, t):
        """The summed external force (world) and moment (body) as 3-tuples."""
        return _wrench_one(self.rows, _vec(p), _vec(v), _vec(R, 9), _vec(w),
                           np.ascontiguousarray(f, dtype=float), float(t))


def _vec(x, n=3) -> tuple:
    return tuple(float(a) for a in np.ravel(x)[:n])


def single(effect, n_rotors: int, dt: float, yaw_signs=None) -> Single:
    """One vehicle's chain of the one built-in ``effect`` (its protocol methods from Python)."""
    return Single([entry(effect, n_rotors, dt, yaw_signs)])


Compiled.one_vehicle = staticmethod(single)


__all__ = ["entry", "empty", "fits", "write", "build", "grown", "reset", "lost", "Single",
           "single", "delay_capacity"]
