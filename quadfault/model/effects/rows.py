"""The compiled effect chain's numbers: each built-in effect as an entry, N vehicles as rows.

:func:`entry` turns an effect (its parameters, the flown vehicle's rotors, the physics step)
into the numbers the chain's kernels read: its class (the layout's slot) and what its
``pack`` lays out by its module's declared ``PARAMETERS`` and ``MEMORY``
(:mod:`quadfault.model.effects.chain` has the layout); :func:`build` makes the
:class:`~quadfault.model.effects.chain.EffectRows` of N vehicles, each with its own effects;
:func:`write` replaces one vehicle's effects (domain randomisation: new parameters per
episode) and :func:`reset` clears vehicles' memory for a new flight.
:class:`Single` runs one vehicle's chain from Python: the effect protocol's numpy form of the
built-in effects (``rotor_thrust`` / ``wrench`` outside a loop, and inside the interpreted
loop beside effects written in Python).
"""

from __future__ import annotations

import numpy as np

import quadfault.model.effects.chain as C
from quadfault.errors import ConfigError
from quadfault.jit import jit
from quadfault.model.effects.chain import ChainLayout, has_term, has_thrust
from quadfault.model.generator_table import generator_table

#: the generator a row's stream holds when it has no seeded wind (never drawn from)
_NEVER = np.random.default_rng(0)


def entry(effect, n_rotors: int, dt: float, yaw_signs=None):
    """``(effect class, parameters, memory slots)`` of a built-in ``effect`` on a vehicle
    with ``n_rotors`` flown at physics step ``dt`` [s] (``yaw_signs``: the flown rotors'
    yaw-torque signs, for effects that need them); None for an effect without an entry
    (mass and inertia set the flown vehicle)."""
    cls = type(effect)
    if not (has_thrust(cls) or has_term(cls)):
        return None
    params, memory = effect.pack(int(n_rotors), dt, yaw_signs)
    return cls, tuple(float(x) for x in params), int(memory)


def _slot(entry) -> type:
    """The layout slot (an effect class) an entry flies in."""
    return entry[0]


def _place(layout, entries) -> list | None:
    """The slot of each of one vehicle's ``entries`` in ``layout``, or None when they do
    not fit: each entry in a slot of its effect and width, the thrust-stage entries in
    increasing slots in their order, and the wrench entries likewise (the order of the
    thrust stage and of the wrench sum is the vehicle's; a wrench-only entry and a
    thrust-only one may trade places)."""
    used, last_thrust, last_wrench, out = set(), -1, -1, []
    for entry in entries:
        cls = entry[0]
        thrust, wrench = has_thrust(cls), has_term(cls)
        low = max(last_thrust if thrust else -1, last_wrench if wrench else -1)
        key = _slot(entry)
        k = next(
            (k for k in range(low + 1, len(layout)) if k not in used and layout[k] == key), None
        )
        if k is None:
            return None
        used.add(k)
        out.append(k)
        last_thrust, last_wrench = (k if thrust else last_thrust), (k if wrench else last_wrench)
    return out


def _merged(layout, entries) -> tuple:
    """The shortest layout holding ``layout`` and one vehicle's ``entries``, in their
    orders (a shortest common supersequence)."""
    a, b = list(layout), [_slot(e) for e in entries]
    n, m = len(a), len(b)
    L = [[0] * (m + 1) for _ in range(n + 1)]  # L[i][j]: SCS length of a[i:], b[j:]
    for i in range(n, -1, -1):
        for j in range(m, -1, -1):
            L[i][j] = (
                m - j
                if i == n
                else n - i
                if j == m
                else 1 + L[i + 1][j + 1]
                if a[i] == b[j]
                else 1 + min(L[i + 1][j], L[i][j + 1])
            )
    out, i, j = [], 0, 0
    while i < n or j < m:
        if i < n and j < m and a[i] == b[j]:
            out.append(a[i])
            i, j = i + 1, j + 1
        elif j == m or (i < n and L[i + 1][j] <= L[i][j + 1]):
            out.append(a[i])
            i += 1
        else:
            out.append(b[j])
            j += 1
    return tuple(out)


def empty(n_rows: int, n_entries: int, n_memory: int, layout=(), *, n_rotors: int) -> C.EffectRows:
    """Rows without effects, room for ``n_entries`` entries and ``n_memory`` memory slots
    per vehicle, of ``layout`` (effect classes, one per slot: the loop compiles the chain of
    this layout) on vehicles of ``n_rotors`` rotors."""
    chain = ChainLayout(tuple(layout), int(n_rotors))
    N = int(n_rows)
    return C.EffectRows(
        np.full((N, n_entries), -1, dtype=np.int64),
        np.zeros((N, n_entries), dtype=np.int64),
        np.zeros((N, n_entries), dtype=np.int64),
        C.borrowed(np.zeros((N, max(chain.size, 1)))),
        C.borrowed(np.zeros((N, max(n_memory, 1)))),
        generator_table([_NEVER] * N),
        chain,
    )


def fits(fx: C.EffectRows, entries) -> bool:
    """Whether one vehicle's ``entries`` fit the rows' room and layout."""
    return (
        len(entries) <= fx.slot.shape[1]
        and sum(m for _, _, m in entries) <= fx.memory.shape[1]
        and _place(fx.layout.effects, entries) is not None
    )


def write(fx: C.EffectRows, i: int, entries) -> None:
    """Vehicle ``i`` flies ``entries`` (a list of :func:`entry` results, in chain order)
    from a fresh start (memory cleared); they must :func:`fits`."""
    slots = _place(fx.layout.effects, entries) if fits(fx, entries) else None
    if slots is None:
        raise ConfigError("these effects need more room than the rows were built with")
    at = fx.layout.columns()
    fx.slot[i], fx.params[i] = -1, 0.0
    m = 0
    for e, ((_cls, params, memory), k) in enumerate(zip(entries, slots)):
        a = at[k]
        fx.slot[i, e], fx.param[i, e], fx.mem[i, e] = k, a + 1, m
        fx.params[i, a] = m + 1.0  # flown, its memory from column m
        fx.params[i, a + 1 : a + 1 + len(params)] = params
        m += memory
    reset(fx, [i])


def build(entries_per_row, n_rotors: int) -> C.EffectRows:
    """The rows of N vehicles of ``n_rotors`` rotors, row ``i`` flying
    ``entries_per_row[i]`` (:func:`entry` results for that many rotors)."""
    layout = ()
    for entries in entries_per_row:
        if _place(layout, entries) is None:
            layout = _merged(layout, entries)
    fx = empty(
        len(entries_per_row),
        max((len(e) for e in entries_per_row), default=0),
        max((sum(m for _, _, m in e) for e in entries_per_row), default=0),
        layout,
        n_rotors=n_rotors,
    )
    for i, e in enumerate(entries_per_row):
        write(fx, i, e)
    return fx


def grown(fx: C.EffectRows, entries) -> C.EffectRows:
    """``fx`` with room for ``entries`` too (a copy when it needs more; rows, their memory
    and generators kept)."""
    if fits(fx, entries):
        return fx
    old = fx.layout.effects
    layout = old if _place(old, entries) is not None else _merged(old, entries)
    out = empty(
        len(fx.slot),
        max(len(entries), fx.slot.shape[1]),
        max(sum(m for _, _, m in entries), fx.memory.shape[1]),
        layout,
        n_rotors=fx.layout.n_rotors,
    )
    # the old slots keep their order in the merged layout: map their slots and columns
    cols, k = np.zeros(fx.params.shape[1], dtype=np.int64), 0
    moved = np.zeros(max(len(old), 1), dtype=np.int64)
    new_at = out.layout.columns()
    for j, (cls, a) in enumerate(zip(old, fx.layout.columns())):
        while layout[k] is not cls:
            k += 1
        width = fx.layout.width(j)
        cols[a : a + 1 + width] = np.arange(new_at[k], new_at[k] + 1 + width)
        moved[j] = k
        k += 1
    if old:
        out.params[:, cols] = fx.params[:, : len(cols)]
    E = fx.slot.shape[1]
    out.mem[:, :E] = fx.mem
    out.slot[:, :E] = np.where(fx.slot >= 0, moved[np.maximum(fx.slot, 0)], -1)
    out.param[:, :E] = np.where(fx.slot >= 0, cols[np.minimum(fx.param, len(cols) - 1)], 0)
    out.memory[:, : fx.memory.shape[1]] = fx.memory
    out.streams.put(np.arange(len(fx.slot)), fx.streams.generators)
    return out


def reset(fx: C.EffectRows, rows) -> None:
    """Clear the memory of vehicles ``rows`` (a new flight): lag and delay start empty, the
    gusts at 0, a seeded wind's generator restarts from its seed."""
    for i in np.atleast_1d(np.asarray(rows, dtype=np.int64)):
        fx.memory[i] = 0.0
        stream = _NEVER
        for e in range(fx.slot.shape[1]):
            if fx.slot[i, e] < 0:
                break
            cls = fx.layout.effects[fx.slot[i, e]]
            seed = cls.stream_seed(fx.params[i, fx.param[i, e] :])
            if seed is not None:
                stream = np.random.default_rng(seed)
        fx.streams.put([i], [stream])


def lost(fx: C.EffectRows) -> np.ndarray:
    """Vehicles (N,) bool with an entry that lost history it needed (a delay flown at steps
    much shorter than the physics step the rows were built for,
    ``Delay.lost``)."""
    out = np.zeros(len(fx.slot), dtype=bool)
    for i, e in zip(*np.nonzero(fx.slot >= 0)):
        cls = fx.layout.effects[fx.slot[i, e]]
        out[i] |= cls.lost(fx.memory[i, fx.mem[i, e] :])
    return out


@jit
def _thrust_one(fx, f, t, dt, p, v, R, w, gen):
    C.thrust_effects(fx, 0, f, t, dt, p, v, R, w, gen)


@jit
def _wrench_one(fx, p, v, R, w, f, t):
    return C.effects_wrench(C.wrench_terms(fx, 0, f, t), p, v, R, w, f, t)


class Single:
    """One vehicle's chain run from Python (arrays in, arrays out), for the built-in effects
    outside a loop or in the interpreted loop (:class:`quadfault.model.plant.EffectsHook`)."""

    def __init__(self, entries, n_rotors: int):
        self.rows = build([list(entries)], n_rotors)

    def rotor_thrust(self, f, t, dt, p, v, R, w, gen) -> None:
        """The thrust stage, ``f`` (n,) float array replaced in place."""
        _thrust_one(self.rows, f, float(t), float(dt), _vec(p), _vec(v), _vec(R, 9), _vec(w), gen)

    def wrench(self, p, v, R, w, f, t):
        """The summed external force (world) and moment (body) as 3-tuples."""
        return _wrench_one(
            self.rows,
            _vec(p),
            _vec(v),
            _vec(R, 9),
            _vec(w),
            np.ascontiguousarray(f, dtype=float),
            float(t),
        )


def _vec(x, n=3) -> tuple:
    return tuple(float(a) for a in np.ravel(x)[:n])


def single(effect, n_rotors: int, dt: float, yaw_signs=None) -> Single:
    """One vehicle's chain of the one built-in ``effect`` (its protocol methods from Python)."""
    return Single([entry(effect, n_rotors, dt, yaw_signs)], n_rotors)


__all__ = [
    "entry",
    "empty",
    "fits",
    "write",
    "build",
    "grown",
    "reset",
    "lost",
    "Single",
    "single",
]
