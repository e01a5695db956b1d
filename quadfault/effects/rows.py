"""The compiled effect chain's numbers: each built-in effect as an entry, N vehicles as rows.

:func:`entry` turns an effect (its parameters, the flown vehicle's rotors, the physics step)
into the numbers the chain's kernels read (:mod:`quadfault.effects.chain` has the layout);
:func:`build` makes the :class:`~quadfault.effects.chain.EffectRows` of N vehicles, each with
its own effects; :func:`write` replaces one vehicle's effects (domain randomisation: new
parameters per episode) and :func:`reset` clears vehicles' memory for a new flight.
:class:`Single` runs one vehicle's chain from Python: the effect protocol's numpy form of the
built-in effects (``rotor_thrust`` / ``wrench`` outside a loop, and inside the interpreted
loop beside effects written in Python).
"""

from __future__ import annotations

import math

import numpy as np

import quadfault.effects.chain as C
from quadfault.errors import ConfigError
from quadfault.jit import jit, typed_list

#: the generator a row's stream holds when it has no seeded wind (never drawn from)
_NEVER = np.random.default_rng(0)


def delay_capacity(delay: float, dt: float) -> int:
    """Knots a delay of ``delay`` [s] keeps at physics step ``dt`` [s]: twice those its mean
    needs at that step, so steps down to half as long stay exact (a replay's uneven
    intervals); with shorter ones the loop flags the vehicle (:func:`lost`)."""
    return 2 * int(math.ceil(delay / dt - 1e-9)) + 4


def entry(effect, n_rotors: int, dt: float, yaw_signs=None):
    """``(code, parameters, memory slots)`` of a built-in ``effect`` on a vehicle with
    ``n_rotors`` flown at physics step ``dt`` [s] (``yaw_signs``: the flown rotors' yaw-torque
    signs, for ``rotor_inertia``); None for mass and inertia (they set the flown vehicle)."""
    e, n, name = effect, int(n_rotors), effect.name
    if name in ("mass", "inertia"):
        return None
    if name == "thrust_curve":
        return C.CURVE, (*e.curve, *e.nominal), 0
    if name == "battery_thrust":
        return C.BATTERY, (e.exponent, e.v_start, e.v_end, e.duration, e.v_ref), 0
    if name == "motor_efficiency":
        if len(e.eta) != n:
            raise ConfigError(f"motor_efficiency has {len(e.eta)} rotors, the vehicle {n}")
        return C.EFFICIENCY, tuple(e.eta), 0
    if name == "thrust_scale":
        return C.SCALE, (e.scale,), 0
    if name == "ground_effect":
        return C.GROUND, (e.rotor_radius, e.ground_z), 0
    if name == "delay":
        cap = delay_capacity(e.delay, dt)
        return C.DELAY, (e.delay, float(cap)), C.DELAY_HEADER + cap * (1 + 2 * n)
    if name == "motor_lag":
        return C.LAG, (e.tau,), 3 + n
    if name == "drag":
        return C.DRAG, (*e.k, *e.air_velocity), 0
    if name == "wind":
        own = e.seed is not None
        return C.WIND, (*e.velocity, e.gust, e.gust_tau, *e.k, float(own),
                        float(e.seed if own else 0)), 6
    if name == "com_offset":
        return C.COM, tuple(e.offset), 0
    if name == "blade_flapping":
        return C.FLAPPING, (e.k_force, e.k_moment, *e.air_velocity), 0
    if name == "rotor_inertia":
        signs = e.yaw_signs if e.yaw_signs is not None else yaw_signs
        if signs is None:
            signs = np.resize([-1.0, 1.0], n)
        if len(signs) != n:
            raise ConfigError(f"rotor_inertia has {len(signs)} yaw signs, the vehicle {n} rotors")
        return C.ROTOR_INERTIA, (e.kappa, *(float(s) for s in signs)), 3 + 2 * n
    if name == "rate_damping":
        return C.DAMPING, (*e.linear, *e.quadratic), 0
    raise ConfigError(f"effect {name!r} has no compiled form")


def _size(entries) -> tuple[int, int, int]:
    return (len(entries), sum(len(p) for _, p, _ in entries), sum(m for _, _, m in entries))


def empty(n_rows: int, n_entries: int, n_params: int, n_memory: int) -> C.EffectRows:
    """Rows without effects, room for ``n_entries`` entries of ``n_params`` parameters and
    ``n_memory`` memory slots in all per vehicle."""
    N = int(n_rows)
    return C.EffectRows(np.full((N, n_entries), -1, dtype=np.int64),
                        np.zeros((N, n_entries), dtype=np.int64),
                        np.zeros((N, n_entries), dtype=np.int64),
                        np.zeros((N, max(n_params, 1))), np.zeros((N, max(n_memory, 1))),
                        typed_list([_NEVER] * N))


def fits(fx: C.EffectRows, entries) -> bool:
    """Whether one vehicle's ``entries`` fit the rows' room."""
    E, P, Q = _size(entries)
    return E <= fx.code.shape[1] and P <= fx.params.shape[1] and Q <= fx.memory.shape[1]


def write(fx: C.EffectRows, i: int, entries) -> None:
    """Vehicle ``i`` flies ``entries`` (a list of :func:`entry` results, in chain order)
    from a fresh start (memory cleared); they must :func:`fits`."""
    if not fits(fx, entries):
        raise ConfigError("these effects need more room than the rows were built with")
    if sum(code >= C.DRAG for code, _, _ in entries) > C.WRENCH_TERMS:
        raise ConfigError(f"a vehicle flies at most {C.WRENCH_TERMS} effects with a wrench "
                          "(drag, wind, com_offset, blade_flapping, rotor_inertia, "
                          "rate_damping)")
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
    fx = empty(len(sizes), *(max((s[k] for s in sizes), default=0) for k in range(3)))
    for i, e in enumerate(entries_per_row):
        write(fx, i, e)
    return fx


def grown(fx: C.EffectRows, entries) -> C.EffectRows:
    """``fx`` with room for ``entries`` too (a copy when it needs more; rows kept)."""
    if fits(fx, entries):
        return fx
    E, P, Q = (max(a, b) for a, b in zip(_size(entries), (fx.code.shape[1], fx.params.shape[1],
                                                           fx.memory.shape[1])))
    out = empty(len(fx.code), E, P, Q)
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
            a = fx.param[i, e]
            if fx.code[i, e] == C.WIND and fx.params[i, a + 8] != 0.0:
                fx.streams[i] = np.random.default_rng(int(fx.params[i, a + 9]))


def lost(fx: C.EffectRows) -> np.ndarray:
    """Vehicles (N,) bool whose delay needed a knot it had dropped: steps much shorter than
    the physics step the rows were built for (:func:`delay_capacity`)."""
    out = np.zeros(len(fx.code), dtype=bool)
    for i, e in zip(*np.nonzero(fx.code == C.DELAY)):
        out[i] |= fx.memory[i, fx.mem[i, e]] != 0.0
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


__all__ = ["entry", "empty", "fits", "write", "build", "grown", "reset", "lost", "Single",
           "delay_capacity"]
