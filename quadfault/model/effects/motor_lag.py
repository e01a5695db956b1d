"""``motor_lag``: the rotor thrust follows the command through first-order dynamics,
``tau f'' = f - f'``, exact for a held command:
``f'_k = f'_{k-1} + (1 - e^{-dt/tau}) (f_k - f'_{k-1})``."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.jit import jit
from quadfault.layout import ROTORS, fields
from quadfault.model.effects.base import Compiled, Identifiability, number
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.kernels import replaced
from quadfault.model.effects.physics import rows_of, shaped


# kernels ---------------------------------------------------------------------------------
@jit
def lag_gain1(dt, tau):
    """First-order-lag update gain ``1 - exp(-dt / tau)`` for an input held over ``dt``."""
    return -math.expm1(-dt / max(tau, 1e-9))


@jit
def lag_step1(y, f, g):
    """The lagged thrust after a step of held input ``f`` from ``y`` with gain ``g``
    (:func:`lag_gain1`): exact solution of ``tau y' = f - y``."""
    return g * f + (1.0 - g) * y


#: the chain entry's parameters and memory: whether the flight started, the step length and
#: the gain of its last step, the lagged thrust of each rotor
PARAMETERS = fields("MotorLagParameters", "tau")
MEMORY = fields("MotorLagMemory", "started", "dt", "gain", ("thrust", ROTORS))


@jit(inline="always")
def thrust_step(x, q, f, t, dt, p, gen, streams, i):
    """The chain's entry: each rotor's thrust through the lag (the first step starts from
    the commanded thrust)."""
    if q[MEMORY.dt] != dt:  # the gain of this step length (cached)
        q[MEMORY.dt], q[MEMORY.gain] = dt, lag_gain1(dt, x[PARAMETERS.tau])
    g = q[MEMORY.gain]
    started = q[MEMORY.started] != 0.0
    out = f
    for r in range(len(f)):
        y = lag_step1(q[MEMORY.thrust + r] if started else f[r], f[r], g)
        q[MEMORY.thrust + r] = y
        out = replaced(out, r, y)
    q[MEMORY.started] = 1.0
    return out


# over arrays -----------------------------------------------------------------------------
@jit
def _gain_rows(x, tau, out):
    for i in range(x.shape[0]):
        out[i] = lag_gain1(x[i], tau)


def lag_gain(dt, tau: float) -> np.ndarray:
    """First-order-lag update gain ``1 - exp(-dt / tau)`` for a held input."""
    (xs,) = rows_of(np.shape(dt), (dt, ()))
    out = np.empty(len(xs))
    _gain_rows(xs, float(tau), out)
    return shaped(out, np.shape(dt))


@jit
def _lag_rows(f, dt, tau, y0, out):
    for m in range(f.shape[1]):
        y = y0[m]
        for k in range(f.shape[0]):
            y = lag_step1(y, f[k, m], lag_gain1(dt[k], tau))
            out[k, m] = y


def lag_series(f: np.ndarray, dt: np.ndarray, tau: float, y0=None) -> np.ndarray:
    """Rotor thrust after a first-order lag ``tau f'' = f - f'`` with time constant ``tau``
    [s], exact for commands ``f`` (N, n) held for ``dt`` (N,) [s]:
    ``y_k = g_k f_k + (1 - g_k) y_{k-1}``, ``g_k = 1 - exp(-dt_k / tau)``.

    ``y0`` is the thrust before the first step (default: the first command, as the plant
    starts). One call over a recording and one call per plant step are the same kernel
    (:func:`lag_step1`)."""
    f = np.ascontiguousarray(np.atleast_2d(np.asarray(f, dtype=float)))
    dt = np.ascontiguousarray(np.broadcast_to(np.asarray(dt, dtype=float).ravel(), (len(f),)))
    start = f[0] if y0 is None else np.asarray(y0, dtype=float)
    out = np.empty_like(f)
    _lag_rows(f, dt, float(tau), np.ascontiguousarray(np.broadcast_to(start, f.shape[1:])), out)
    return out


# the effect ------------------------------------------------------------------------------
@dataclass(frozen=True)
class MotorLag(Compiled):
    """First-order rotor thrust dynamics ``tau f'' = f - f'`` with time constant ``tau`` [s],
    exact for a held command (the kernel of :func:`lag_series`)."""

    tau: float = 0.05
    name: ClassVar[str] = "motor_lag"
    order: ClassVar[int] = 5
    identifiability: ClassVar[Identifiability] = Identifiability(
        min_command_rate=20.0,
        timescale="tau_s",
        direct=("rotor_speed",),
        excitation="sharp command changes",
        note="a lag shorter than about half a command interval cannot be told from none "
        "(motor outputs at 10 Hz do not show a lag below about 50 ms); measured rotor "
        "speeds show it directly",
    )
    explanation: ClassVar[str] = "the rotor thrust follows the command through first-order dynamics"
    equivalent: ClassVar[str] = "timing"
    syntax: ClassVar[str] = "TAU [s]"
    example: ClassVar[str] = "motor_lag=0.05"
    parameter: ClassVar[tuple] = ("tau", "tau_s")

    def __post_init__(self):
        number(self.tau, "motor_lag tau [s]", 0.0, 5.0, open_lo=True)

    @classmethod
    def candidate(cls, ctx):
        return LagCandidate(
            cls.name,
            ("tau [s]",),
            (1e-4,),
            (0.3,),
            (1e-4,),
            tuple((tau,) for tau in (0.005, 0.01, 0.02, 0.04, 0.07, 0.12, 0.2, 0.28)),
            "thrust",
            cls.order,
            rotor_side=True,
        )


@dataclass(frozen=True)
class LagCandidate(Candidate):
    on_raw: ClassVar[bool] = True
    keys: ClassVar[tuple] = (("tau_s", 0, 1),)

    def thrust(self, x, rp, f, t, dt):
        return lag_series(f, dt, float(x[0]))
