"""``delay``: the rotor thrust follows the command after a pure delay, ``f'(t) = f(t - d)``;
over a physics step, the mean of the delayed zero-order hold (so fractional delays are
exact)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.jit import jit
from quadfault.layout import REST, fields
from quadfault.model.effects.base import Compiled, Identifiability, number
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.kernels import replaced
from quadfault.model.effects.physics import batch_of, rows_of

#: the chain entry's parameters (the delay [s], the knots kept) and memory: whether a knot
#: the mean needed was dropped (``lost``), whether any was (``dropped``), the ring of knots'
#: first slot and count, then the knots (:func:`zoh_integral`)
PARAMETERS = fields("DelayParameters", "delay", "capacity")
MEMORY = fields("DelayMemory", "lost", "dropped", "head", "count", ("knots", REST))


# kernels ---------------------------------------------------------------------------------
@jit
def zoh_next1(c, f, t_prev, t):
    """Integral up to knot ``t`` of a zero-order-hold signal: ``c`` up to the previous knot
    ``t_prev`` plus its value ``f`` held since."""
    return c + f * (t - t_prev)


@jit
def zoh_knot(buf, base, cap, head, count, x):
    """Slot of the last knot at or before ``x`` (the first knot when none is) of the knots
    stored as in :func:`zoh_integral`, by bisection."""
    lo, hi = 0, count  # the number of knots at or before x
    while lo < hi:
        mid = (lo + hi) // 2
        if buf[base + (head + mid) % cap] <= x:
            lo = mid + 1
        else:
            hi = mid
    return (head + max(lo - 1, 0)) % cap


@jit
def zoh_from(buf, base, cap, n, s, x, col):
    """Integral up to ``x`` of column ``col`` from knot slot ``s`` at or before it."""
    k = base + cap + s * n + col
    return buf[k] + buf[k + cap * n] * (x - buf[base + s])


@jit
def zoh_integral(buf, base, cap, n, head, count, x, col):
    """Integral up to ``x`` of column ``col`` of a zero-order-hold signal stored as knots in
    ``buf`` from index ``base``: times ``[0, cap)``, integrals up to each knot
    ``[cap, cap + cap n)`` and values ``[cap + cap n, cap + 2 cap n)`` (``n`` columns per
    knot), knot ``j`` (0 the oldest of ``count``) in slot ``(head + j) % cap``. The signal
    holds its first value before the first knot and its last after the last."""
    return zoh_from(buf, base, cap, n, zoh_knot(buf, base, cap, head, count, x), x, col)


@jit
def _delay(x, q, f, t, dt):
    """Store the step's thrusts ``f`` (a tuple) as a knot, then return the mean over the
    step of the zero-order hold delayed by ``x[PARAMETERS.delay]`` [s]."""
    n = len(f)
    cap = int(x[PARAMETERS.capacity])
    base = MEMORY.knots
    head, count = int(q[MEMORY.head]), int(q[MEMORY.count])
    if count < cap:
        slot = (head + count) % cap
        count += 1
    else:  # the oldest knot gives way
        slot = head
        head = (head + 1) % cap
        q[MEMORY.dropped] = 1.0
    last = (slot + cap - 1) % cap
    for r in range(n):
        c = 0.0
        if count > 1:
            c = zoh_next1(
                q[base + cap + last * n + r],
                q[base + cap + cap * n + last * n + r],
                q[base + last],
                t,
            )
        q[base + cap + slot * n + r] = c
        q[base + cap + cap * n + slot * n + r] = f[r]
    q[base + slot] = t
    q[MEMORY.head], q[MEMORY.count] = head, count
    d = x[PARAMETERS.delay]
    if d == 0.0:
        return f
    lo, hi = t - d, t + dt - d
    if q[MEMORY.dropped] != 0.0 and lo < q[base + head]:
        q[MEMORY.lost] = 1.0  # a knot the mean needs was dropped (see delay_capacity)
    out = f
    for r in range(n):
        out = replaced(
            out,
            r,
            (
                zoh_integral(q, base, cap, n, head, count, hi, r)
                - zoh_integral(q, base, cap, n, head, count, lo, r)
            )
            / (hi - lo),
        )
    return out


@jit(inline="always")
def thrust_step(x, q, f, t, dt, p, gen, streams, i):
    """The chain's entry: each thrust the mean over the step of the delayed commands."""
    return _delay(x, q, f, t, dt)


def delay_capacity(delay: float, dt: float) -> int:
    """Knots a delay of ``delay`` [s] keeps at physics step ``dt`` [s]: twice those its mean
    needs at that step, so steps down to half as long stay exact (a replay's uneven
    intervals); with shorter ones the loop flags the vehicle (:meth:`Delay.lost`)."""
    return 2 * int(math.ceil(delay / dt - 1e-9)) + 4


# over arrays -----------------------------------------------------------------------------
@jit
def _zoh_cumulative_rows(t, values, out):
    for j in range(1, t.shape[0]):
        for m in range(values.shape[1]):
            out[j, m] = zoh_next1(out[j - 1, m], values[j - 1, m], t[j - 1], t[j])


def zoh_cumulative(t_knots: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Cumulative integrals of a zero-order-hold signal at its knots (see :func:`zoh_mean`)."""
    t = np.ascontiguousarray(t_knots, dtype=float)
    v = np.ascontiguousarray(values, dtype=float)
    out = np.zeros(v.shape)
    if len(t):
        _zoh_cumulative_rows(t, v.reshape(len(t), -1), out.reshape(len(t), -1))
    return out


@jit
def _knot_after(buf, cap, s, x):
    """:func:`zoh_knot` of knots in order in ``buf[0, :cap]``, walking on from slot ``s``
    (the answer for a nearby earlier ``x``); a bisection when ``x`` is before it."""
    if buf[s] > x:
        return zoh_knot(buf, 0, cap, 0, cap, x)
    while s + 1 < cap and buf[s + 1] <= x:
        s += 1
    return s


@jit
def _zoh_mean_rows(buf, cap, n, a, b, out):
    sa = sb = 0
    for i in range(a.shape[0]):  # one search per end of the interval, for every column
        sb = _knot_after(buf, cap, sb, b[i])
        sa = _knot_after(buf, cap, sa, a[i])
        for m in range(n):
            hi = zoh_from(buf, 0, cap, n, sb, b[i], m)
            lo = zoh_from(buf, 0, cap, n, sa, a[i], m)
            out[i, m] = (hi - lo) / (b[i] - a[i])


def zoh_mean(t_knots: np.ndarray, values: np.ndarray, cumulative: np.ndarray, a, b) -> np.ndarray:
    """Mean over ``[a, b]`` of the zero-order-hold signal ``values[j]`` on
    ``[t_knots[j], t_knots[j+1])`` (constant before the first and after the last knot).

    ``cumulative[j]`` is the integral from ``t_knots[0]`` to ``t_knots[j]``. A pure delay
    ``d`` over a step ``[t, t + dt]`` is ``zoh_mean(..., t - d, t + dt - d)``.
    """
    t = np.asarray(t_knots, dtype=float)
    v = np.asarray(values, dtype=float).reshape(len(t), -1)
    c = np.asarray(cumulative, dtype=float).reshape(len(t), -1)
    buf = np.concatenate((t, c.ravel(), v.ravel()))
    batch = batch_of((a, ()), (b, ()))
    ra, rb = rows_of(batch, (a, ()), (b, ()))
    out = np.empty((len(ra), v.shape[1]))
    _zoh_mean_rows(buf, len(t), v.shape[1], ra, rb, out)
    return out.reshape(batch + np.shape(values)[1:])


# the effect ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Delay(Compiled):
    """Pure input delay [s] of the rotor thrust (over a step: the mean of the delayed
    zero-order-hold command, so fractional delays are exact)."""

    delay: float = 0.02
    name: ClassVar[str] = "delay"
    order: ClassVar[int] = 4
    identifiability: ClassVar[Identifiability] = Identifiability(
        min_command_rate=20.0,
        timescale="delay_s",
        direct=("rotor_speed",),
        excitation="sharp command changes",
        note="a delay shorter than about half a command interval cannot be told from none",
    )
    explanation: ClassVar[str] = "the rotor thrust follows the command after a pure delay"
    equivalent: ClassVar[str] = "timing"
    syntax: ClassVar[str] = "DELAY [s]"
    example: ClassVar[str] = "delay=0.03"
    parameter: ClassVar[tuple] = ("delay", "delay_s")

    def __post_init__(self):
        number(self.delay, "delay [s]", 0.0, 2.0)

    def parameters(self, n_rotors, dt, yaw_signs=None):
        return {"delay": self.delay, "capacity": float(delay_capacity(self.delay, dt))}

    def memory_rest(self, values, n_rotors):
        """The knots: for each, its time and each rotor's integral and value."""
        return int(values["capacity"]) * (1 + 2 * n_rotors)

    @classmethod
    def lost(cls, memory) -> bool:
        """Whether the delay needed a knot it had dropped: steps much shorter than the
        physics step the rows were built for (:func:`delay_capacity`)."""
        return bool(memory[MEMORY.lost] != 0.0)

    @classmethod
    def candidate(cls, ctx):
        starts = np.unique(np.r_[np.arange(0.0, 0.15, max(ctx.dt, 0.01)), 0.19])
        return DelayCandidate(
            cls.name,
            ("delay [s]",),
            (0.0,),
            (0.2,),
            (0.0,),
            tuple((d,) for d in starts),
            "thrust",
            cls.order,
            rotor_side=True,
        )


@dataclass(frozen=True)
class DelayCandidate(Candidate):
    on_raw: ClassVar[bool] = True
    keys: ClassVar[tuple] = (("delay_s", 0, 1),)

    def thrust(self, x, rp, f, t, dt):
        tk = t[:-1]
        return zoh_mean(tk, f, zoh_cumulative(tk, f), tk - x[0], t[1:] - x[0])
