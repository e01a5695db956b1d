"""The effect chain of the closed loop: the built-in effects of every vehicle, compiled.

Per vehicle ``i`` the effects are a list of entries -- a code (which effect), the column of
its first parameter and of its first memory slot -- over one row of numbers each
(:class:`EffectRows`; built by :mod:`quadfault.effects.rows`). The closed loop
(:func:`quadfault.closed_loop.fly_vehicle`) calls the chain at the two points of the effect
protocol:

* :func:`thrust_effects` once per physics step, on the thrusts the motor model produced
  (in the order of the entries, each one's output the next one's input);
* :func:`effects_wrench` at every stage of the RKMK4 step, the sum of the entries' external
  force (world) [N] and moment (body) [N m] at the stage's state.

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
def effect_row(fx, i):
    """What the kernels pass on for vehicle ``i``: ``(fx, i)`` (None without effects)."""
    if fx is None:
        return None
    return (fx, i)


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


@jit
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


@jit
def thrust_effects(ex, f, t, dt, p, v, R, w, gen):
    """The chain's thrust stage for the step ``[t, t + dt)`` [s]: ``f`` (n,), the thrusts
    [N] the motors produced, replaced in place; ``(p, v, R, w)`` the state at the step's
    start; ``gen`` the vehicle's generator."""
    fx, i = ex
    for e in range(fx.code.shape[1]):
        c = fx.code[i, e]
        if c < 0:
            break
        if c == WIND and fx.params[i, fx.param[i, e] + 8] != 0.0:
            _thrust_entry(c, fx.params, fx.memory, i, fx.param[i, e], fx.mem[i, e], f, t, dt,
                          p, fx.streams[i])
        else:
            _thrust_entry(c, fx.params, fx.memory, i, fx.param[i, e], fx.mem[i, e], f, t, dt,
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


@jit
def _wrench_entry(c, P, Q, i, a, m, p, v, R, w, f):
    """One entry's external force (world) [N] and moment (body) [N m]."""
    zero = (0.0, 0.0, 0.0)
    if c == DRAG:
        va = (v[0] - P[i, a + 3], v[1] - P[i, a + 4], v[2] - P[i, a + 5])
        return drag_force3(R, va, (P[i, a], P[i, a + 1], P[i, a + 2])), zero
    if c == WIND:
        va = (P[i, a] + Q[i, m], P[i, a + 1] + Q[i, m + 1], P[i, a + 2] + Q[i, m + 2])
        F = drag_force3(R, va, (P[i, a + 5], P[i, a + 6], P[i, a + 7]))
        return (-F[0], -F[1], -F[2]), zero
    if c == ROTOR_INERTIA:
        return zero, (0.0, 0.0, rotor_inertia_moment1(_rotor_rate(P, Q, i, a, m, f), P[i, a]))
    if c == DAMPING:
        return zero, rate_damping3(w, (P[i, a], P[i, a + 1], P[i, a + 2]),
                                   (P[i, a + 3], P[i, a + 4], P[i, a + 5]))
    thrust = 0.0
    for r in range(f.shape[0]):
        thrust += f[r]
    if c == COM:
        return zero, com_offset_moment3(thrust, P[i, a], P[i, a + 1])
    if c == FLAPPING:
        va = (v[0] - P[i, a + 2], v[1] - P[i, a + 3], v[2] - P[i, a + 4])
        return blade_flapping3(R, va, thrust, P[i, a], P[i, a + 1])
    return zero, zero


@jit
def effects_wrench(ex, p, v, R, w, f, t):
    """The chain's summed external force (world) [N] and moment (body) [N m] at one RK
    stage's state, for the produced thrusts ``f`` of the step starting at ``t``."""
    fx, i = ex
    F0 = F1 = F2 = M0 = M1 = M2 = 0.0
    for e in range(fx.code.shape[1]):
        c = fx.code[i, e]
        if c < 0:
            break
        if c < DRAG:
            continue
        F, M = _wrench_entry(c, fx.params, fx.memory, i, fx.param[i, e], fx.mem[i, e], p, v,
                             R, w, f)
        F0, F1, F2 = F0 + F[0], F1 + F[1], F2 + F[2]
        M0, M1, M2 = M0 + M[0], M1 + M[1], M2 + M[2]
    return (F0, F1, F2), (M0, M1, M2)


__all__ = ["CODES", "EffectRows", "effect_row", "thrust_effects", "effects_wrench"]
