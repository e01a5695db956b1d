"""The effect chain of the closed loop: the built-in effects of every vehicle, compiled.

Per vehicle ``i`` the effects are a list of entries -- a code (which effect), the column of
its first parameter and of its first memory slot -- over one row of numbers each
(:class:`EffectRows`; built by :mod:`quadfault.effects.rows`). The closed loop
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

Each entry runs the kernels of :mod:`quadfault.effects.kernels`, the code the diagnosis runs
over whole recordings (:mod:`quadfault.effects.physics`). Parameters (``P``, from the entry's
first column) and memory (``Q``; zeros at a flight's start), ``n`` the number of rotors:

==============  ==============================================  ============================
code            parameters                                      memory
==============  ==============================================  ============================
CURVE           a, b, c of the curve; a, b, c of the nominal    --
BATTERY         exponent, v_start, v_end, duration, v_ref       --
EFFICIENCY      eta_1 .. eta_n                                  --
SCALE           s                                               --
GROUND          rotor radius, ground_z                          --
DELAY           delay, knots kept (cap)                         lost, dropped, head, count,
                                                                knots (t; integrals; values)
LAG             tau                                             started, dt, gain, y_1 .. y_n
DRAG            k (3), air velocity (3)                         --
WIND            velocity (3), gust, gust_tau, k (3), own        gust (3), dt, a, c
                stream (0/1), seed
COM             r_x, r_y                                        --
FLAPPING        k_force, k_moment, air velocity (3)             --
ROTOR_INERTIA   kappa, yaw signs s_1 .. s_n                     fresh, seen, dt, rate (n),
                                                                previous thrust (n)
DAMPING         D1 (3), D2 (3)                                  --
==============  ==============================================  ============================

Random numbers: a wind's gusts draw three standard normals per step, after the motors'
draws, from the vehicle's generator (the loop's), or from the wind's own seeded generator
(``streams[i]``) when it has a seed.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from quadfault.effects.kernels import (
    battery_factor1,
    battery_voltage1,
    blade_flapping3,
    com_offset_moment3,
    drag_force3,
    ground_effect_factor1,
    gust_step3,
    lag_gain1,
    lag_step1,
    rate_damping3,
    recurve1,
    rotor_inertia_moment1,
    thrust_rate1,
    zoh_integral,
    zoh_next1,
)
from quadfault.jit import jit

CURVE, BATTERY, EFFICIENCY, SCALE, GROUND, DELAY, LAG = 0, 1, 2, 3, 4, 5, 6
DRAG, WIND, COM, FLAPPING, ROTOR_INERTIA, DAMPING = 10, 11, 12, 13, 14, 15
#: effect name -> code of its entry (body effects -- mass, inertia -- have none: they set
#: the flown vehicle's mass and inertia)
CODES = {"thrust_curve": CURVE, "battery_thrust": BATTERY, "motor_efficiency": EFFICIENCY,
         "thrust_scale": SCALE, "ground_effect": GROUND, "delay": DELAY, "motor_lag": LAG,
         "drag": DRAG, "wind": WIND, "com_offset": COM, "blade_flapping": FLAPPING,
         "rotor_inertia": ROTOR_INERTIA, "rate_damping": DAMPING}
#: memory slots of a delay before its knots
DELAY_HEADER = 4


class EffectRows(NamedTuple):
    """The compiled effects of N vehicles (row ``i`` = vehicle ``i``; see the module
    docstring). ``memory`` is updated in place by the loop."""

    code: np.ndarray  # (N, E) int64: entry codes in chain order, -1 after the last
    param: np.ndarray  # (N, E) int64: column of each entry's first parameter
    mem: np.ndarray  # (N, E) int64: column of each entry's first memory slot
    params: np.ndarray  # (N, P) parameters
    memory: np.ndarray  # (N, Q) memory (zeros: a flight's start)
    streams: object  # typed list of N generators: a seeded wind's own (else never drawn)


@jit
def _delay(P, Q, i, a, m, f, t, dt):
    """Store the step's thrusts as a knot, then replace them by the mean over the step of
    the zero-order hold delayed by ``P[i, a]`` [s]."""
    n = f.shape[0]
    cap = int(P[i, a + 1])
    base = m + DELAY_HEADER
    head, count = int(Q[i, m + 2]), int(Q[i, m + 3])
    if count < cap:
        slot = (head + count) % cap
        count += 1
    else:  # the oldest knot gives way
        slot = head
        head = (head + 1) % cap
        Q[i, m + 1] = 1.0
    last = (slot + cap - 1) % cap
    for r in range(n):
        c = 0.0
        if count > 1:
            c = zoh_next1(Q[i, base + cap + last * n + r], Q[i, base + cap + cap * n + last * n + r],
                          Q[i, base + last], t)
        Q[i, base + cap + slot * n + r] = c
        Q[i, base + cap + cap * n + slot * n + r] = f[r]
    Q[i, base + slot] = t
    Q[i, m + 2], Q[i, m + 3] = head, count
    d = P[i, a]
    if d == 0.0:
        return
    lo, hi = t - d, t + dt - d
    if Q[i, m + 1] != 0.0 and lo < Q[i, base + head]:
        Q[i, m] = 1.0  # a knot the mean needs was dropped (see rows.delay_capacity)
    for r in range(n):
        f[r] = (zoh_integral(Q, i, base, cap, n, head, count, hi, r)
                - zoh_integral(Q, i, base, cap, n, head, count, lo, r)) / (hi - lo)


@jit(inline="always")
def _thrust_entry(c, P, Q, i, a, m, f, t, dt, p, gen):
    """One entry's thrust-stage work for vehicle ``i`` (see the module docstring)."""
    n = f.shape[0]
    if c == CURVE:
        curve = (P[i, a], P[i, a + 1], P[i, a + 2])
        nominal = (P[i, a + 3], P[i, a + 4], P[i, a + 5])
        for r in range(n):
            f[r] = recurve1(f[r], nominal, curve)
    elif c == BATTERY:
        volts = battery_voltage1(t + 0.5 * dt, P[i, a + 1], P[i, a + 2], P[i, a + 3])
        k = battery_factor1(volts, P[i, a + 4], P[i, a])
        for r in range(n):
            f[r] = f[r] * k
    elif c == EFFICIENCY:
        for r in range(n):
            f[r] = f[r] * P[i, a + r]
    elif c == SCALE:
        for r in range(n):
            f[r] = f[r] * P[i, a]
    elif c == GROUND:
        k = ground_effect_factor1(P[i, a + 1] - p[2], P[i, a])
        for r in range(n):
            f[r] = f[r] * k
    elif c == DELAY:
        _delay(P, Q, i, a, m, f, t, dt)
    elif c == LAG:
        if Q[i, m + 1] != dt:  # the gain of this step length (cached)
            Q[i, m + 1], Q[i, m + 2] = dt, lag_gain1(dt, P[i, a])
        g = Q[i, m + 2]
        started = Q[i, m] != 0.0
        for r in range(n):
            y = lag_step1(Q[i, m + 3 + r] if started else f[r], f[r], g)
            Q[i, m + 3 + r] = y
            f[r] = y
        Q[i, m] = 1.0
    elif c == WIND:
        sigma = P[i, a + 3]
        if sigma > 0.0:  # the gust process advances once per step
            if Q[i, m + 3] != dt:
                decay = math.exp(-dt / P[i, a + 4])
                Q[i, m + 3], Q[i, m + 4], Q[i, m + 5] = dt, decay, sigma * math.sqrt(1 - decay * decay)
            g = gust_step3((Q[i, m], Q[i, m + 1], Q[i, m + 2]), Q[i, m + 4], Q[i, m + 5], gen)
            Q[i, m], Q[i, m + 1], Q[i, m + 2] = g[0], g[1], g[2]
    elif c == ROTOR_INERTIA:  # the next wrench call opens this step
        Q[i, m], Q[i, m + 2] = 1.0, dt


@jit(inline="always")
def _thrust_stage(code, param, mem, P, Q, streams, i, f, t, dt, p, gen):
    """The thrust stage of vehicle ``i`` over its entries, in chain order."""
    for e in range(code.shape[1]):
        c = code[i, e]
        if c < 0:
            break
        a = param[i, e]
        own = c == WIND and P[i, a + 8] != 0.0  # a seeded wind draws from its own stream
        _thrust_entry(c, P, Q, i, a, mem[i, e], f, t, dt, p, streams[i] if own else gen)


@jit
def thrust_effects(fx, i, f, t, dt, p, v, R, w, gen):
    """The chain's thrust stage for the step ``[t, t + dt)`` [s]: ``f`` (n,), the thrusts
    [N] the motors produced, replaced in place; ``(p, v, R, w)`` the state at the step's
    start; ``gen`` the vehicle's generator; ``fx`` the rows, ``i`` the vehicle."""
    _thrust_stage(fx.code, fx.param, fx.mem, fx.params, fx.memory, fx.streams, i, f, t, dt,
                  p, gen)


@jit
def _rotor_rate(P, Q, i, a, m, f):
    """The yaw-signed sum of the rotors' thrust rates over the current step [N/s] (computed
    at the step's first wrench call, from the thrusts the chain produced)."""
    n = f.shape[0]
    if Q[i, m] != 0.0:
        for r in range(n):
            rate = 0.0
            if Q[i, m + 1] != 0.0:
                rate = thrust_rate1(f[r], Q[i, m + 3 + n + r], Q[i, m + 2])
            Q[i, m + 3 + r] = rate
            Q[i, m + 3 + n + r] = f[r]
        Q[i, m], Q[i, m + 1] = 0.0, 1.0
    s = 0.0
    for r in range(n):
        s += Q[i, m + 3 + r] * P[i, a + 1 + r]
    return s


#: wrench entries a vehicle may have (e.g. one of each wrench effect); each becomes a term
#: of :data:`TERM` numbers (:func:`wrench_terms`)
WRENCH_TERMS = 6
TERM = 7
_NO_TERM = (-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
#: the terms of a vehicle without wrench entries
NO_TERMS = (_NO_TERM,) * WRENCH_TERMS


@jit(inline="always")
def _term(c, P, Q, i, a, m, f):
    """Wrench entry ``c`` (parameters from column ``a``, memory from ``m``) of vehicle ``i``
    as the numbers the RK stages need, fixed over the step: ``(code, six numbers)``; DRAG:
    k (3), air velocity (3); WIND: wind drag k (3), air velocity with the step's gust (3);
    FLAPPING: k_force, k_moment, thrust, air velocity (3); DAMPING: D1 (3), D2 (3); COM and
    ROTOR_INERTIA: their body moment (3), fixed by the step's thrusts ``f`` (code COM)."""
    if c == DRAG or c == DAMPING:
        return (float(c), P[i, a], P[i, a + 1], P[i, a + 2], P[i, a + 3], P[i, a + 4],
                P[i, a + 5])
    if c == WIND:
        return (float(c), P[i, a + 5], P[i, a + 6], P[i, a + 7], P[i, a] + Q[i, m],
                P[i, a + 1] + Q[i, m + 1], P[i, a + 2] + Q[i, m + 2])
    if c == ROTOR_INERTIA:
        Mz = rotor_inertia_moment1(_rotor_rate(P, Q, i, a, m, f), P[i, a])
        return (float(COM), 0.0, 0.0, Mz, 0.0, 0.0, 0.0)
    thrust = 0.0
    for r in range(f.shape[0]):
        thrust += f[r]
    if c == COM:
        M = com_offset_moment3(thrust, P[i, a], P[i, a + 1])
        return (float(c), M[0], M[1], M[2], 0.0, 0.0, 0.0)
    return (float(c), P[i, a], P[i, a + 1], thrust, P[i, a + 2], P[i, a + 3], P[i, a + 4])


@jit(inline="always")
def _terms(code, param, mem, P, Q, i, f):
    """Vehicle ``i``'s wrench entries in chain order as :data:`WRENCH_TERMS` terms
    (:func:`_term`; code -1 past the last), in one pass over the entries."""
    W0, W1, W2, W3, W4, W5 = NO_TERMS
    k = 0
    for e in range(code.shape[1]):
        c = code[i, e]
        if c < 0:
            break
        if c < DRAG:
            continue
        s = _term(c, P, Q, i, param[i, e], mem[i, e], f)
        if k == 0:
            W0 = s
        elif k == 1:
            W1 = s
        elif k == 2:
            W2 = s
        elif k == 3:
            W3 = s
        elif k == 4:
            W4 = s
        else:
            W5 = s
        k += 1
    return (W0, W1, W2, W3, W4, W5)


@jit
def wrench_terms(fx, i, f, t):
    """Vehicle ``i``'s wrench entries over the step starting at ``t`` [s] whose produced
    thrusts are ``f``: :data:`WRENCH_TERMS` terms (:func:`_term`), numbers only, so that the
    RK stages (:func:`effects_wrench`) take no arrays (an array argument costs reference
    counting at every call)."""
    return _terms(fx.code, fx.param, fx.mem, fx.params, fx.memory, i, f)


@jit(inline="always")
def step_effects(fx, i, f, t, dt, p, v, R, w, gen):
    """The chain's work for physics step ``[t, t + dt)`` [s] of vehicle ``i``: the thrust
    stage on ``f`` (:func:`thrust_effects`; same arguments), then the step's wrench terms
    (:func:`wrench_terms`) returned for the RK stages. Inlined into the loop with the rows'
    arrays taken once (each array a compiled call takes costs reference counting)."""
    code, param, mem, P, Q = fx.code, fx.param, fx.mem, fx.params, fx.memory
    _thrust_stage(code, param, mem, P, Q, fx.streams, i, f, t, dt, p, gen)
    return _terms(code, param, mem, P, Q, i, f)


@jit(inline="always")
def has_wrench(W) -> bool:
    """Whether the step's terms ``W`` (:func:`step_effects`) hold a wrench entry (else the
    RK stages need not call :func:`effects_wrench`)."""
    return W[0][0] >= 0.0


@jit(inline="always")
def _stage_term(s, v, R, w):
    """One term's external force (world) [N] and moment (body) [N m] at a stage's state."""
    zero = (0.0, 0.0, 0.0)
    c = int(s[0])
    if c == DRAG:
        va = (v[0] - s[4], v[1] - s[5], v[2] - s[6])
        return drag_force3(R, va, (s[1], s[2], s[3])), zero
    if c == WIND:
        F = drag_force3(R, (s[4], s[5], s[6]), (s[1], s[2], s[3]))
        return (-F[0], -F[1], -F[2]), zero
    if c == DAMPING:
        return zero, rate_damping3(w, (s[1], s[2], s[3]), (s[4], s[5], s[6]))
    if c == COM:
        return zero, (s[1], s[2], s[3])
    if c == FLAPPING:
        va = (v[0] - s[4], v[1] - s[5], v[2] - s[6])
        return blade_flapping3(R, va, s[3], s[1], s[2])
    return zero, zero


@jit(inline="always")
def _add_term(F, M, s, v, R, w):
    """``(F, M)`` plus term ``s``'s force and moment (unchanged past the last term)."""
    if s[0] < 0.0:
        return F, M
    dF, dM = _stage_term(s, v, R, w)
    return ((F[0] + dF[0], F[1] + dF[1], F[2] + dF[2]),
            (M[0] + dM[0], M[1] + dM[1], M[2] + dM[2]))


@jit(inline="always")
def effects_wrench(W, p, v, R, w, f, t):
    """The summed external force (world) [N] and moment (body) [N m] of a vehicle's wrench
    entries at one RK stage's state, from the step's :func:`wrench_terms` ``W`` (``p``,
    ``f``, ``t``: the protocol's arguments, already in the terms)."""
    zero = (0.0, 0.0, 0.0)
    F, M = _add_term(zero, zero, W[0], v, R, w)
    F, M = _add_term(F, M, W[1], v, R, w)
    F, M = _add_term(F, M, W[2], v, R, w)
    F, M = _add_term(F, M, W[3], v, R, w)
    F, M = _add_term(F, M, W[4], v, R, w)
    return _add_term(F, M, W[5], v, R, w)


__all__ = ["CODES", "EffectRows", "WRENCH_TERMS", "thrust_effects",
           "NO_TERMS", "wrench_terms", "step_effects", "has_wrench", "effects_wrench"]
