"""``wind``: air at ``v_air(t)`` (steady + Ornstein-Uhlenbeck gusts) pushing the vehicle
through a wind drag ``k_w``: ``F = R diag(k_w) R^T v_air`` [N]; the diagnosis fits a steady
world force."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit
from quadfault.layout import fields
from quadfault.model.effects.base import Compiled, Identifiability, param, vector
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.drag import Drag, drag_force3
from quadfault.model.generator_table import generator_at


@jit
def gust_step3(g, a, c, gen):
    """Ornstein-Uhlenbeck gust velocity [m/s] after one step: ``a g + c z`` with ``a =
    exp(-dt / tau)``, ``c = sigma sqrt(1 - a^2)`` and three standard normals from ``gen``."""
    z0 = gen.standard_normal()
    z1 = gen.standard_normal()
    z2 = gen.standard_normal()
    return (a * g[0] + c * z0, a * g[1] + c * z1, a * g[2] + c * z2)


#: the chain entry's parameters (``own_stream`` 1: the gusts draw from the wind's own
#: generator, seeded ``seed``) and memory: the gust velocity, the step length and the gust
#: update's decay and spread for it
PARAMETERS = fields(
    "WindParameters", ("velocity", 3), "gust", "gust_tau", ("k", 3), "own_stream", "seed"
)
MEMORY = fields("WindMemory", ("gust", 3), "dt", "decay", "spread")


@jit(inline="always")
def thrust_step(x, q, f, t, dt, p, gen, streams, i):
    """The gusts advance once per step, drawing from the wind's own seeded stream (row ``i``
    of the generator table ``streams``) when it has one, else from the vehicle's generator
    ``gen``; the thrusts pass unchanged."""
    sigma = x[PARAMETERS.gust]
    if sigma > 0.0:
        if q[MEMORY.dt] != dt:
            decay = math.exp(-dt / x[PARAMETERS.gust_tau])
            q[MEMORY.dt], q[MEMORY.decay] = dt, decay
            q[MEMORY.spread] = sigma * math.sqrt(1 - decay * decay)
        g0 = MEMORY.gust
        g = gust_step3(
            (q[g0], q[g0 + 1], q[g0 + 2]),
            q[MEMORY.decay],
            q[MEMORY.spread],
            generator_at(streams, i) if x[PARAMETERS.own_stream] != 0.0 else gen,
        )
        q[g0], q[g0 + 1], q[g0 + 2] = g[0], g[1], g[2]
    return f


@jit(inline="always")
def wrench_term(x, q, f):
    """The step's numbers: wind drag k (3), air velocity with the step's gust (3)."""
    k, v, g = PARAMETERS.k, PARAMETERS.velocity, MEMORY.gust
    return (
        x[k],
        x[k + 1],
        x[k + 2],
        x[v] + q[g],
        x[v + 1] + q[g + 1],
        x[v + 2] + q[g + 2],
    )


@jit(inline="always")
def wrench_stage(s, v, R, w):
    """Force (world) and moment (body) at a stage's state from the step's term ``s``."""
    F = drag_force3(R, (s[4], s[5], s[6]), (s[1], s[2], s[3]))
    return (-F[0], -F[1], -F[2]), (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Wind(Compiled):
    """Air moving at ``velocity`` [m/s] (world) plus Ornstein-Uhlenbeck gusts (std ``gust``
    [m/s], correlation time ``gust_tau`` [s]), pushing the vehicle through the wind drag
    ``k`` [N s/m] (body axes): ``F = R diag(k) R^T v_air``. Combine with :class:`Drag` of the
    same ``k`` for ``-R diag(k) R^T (v - v_air)``. The gusts advance once per physics step
    with three standard normals drawn from the vehicle's generator after the motors' draws,
    or from their own generator ``numpy.random.default_rng(seed)`` when ``seed`` is given."""

    velocity: tuple = (1.0, 0.0, 0.0)
    gust: float = 0.0
    gust_tau: float = 2.0
    k: tuple = (0.3, 0.3, 0.3)
    seed: int | None = None
    name: ClassVar[str] = "wind"
    order: ClassVar[int] = 10
    identifiability: ClassVar[Identifiability] = Identifiability(
        scales_with=("mass",),
        channels=("velocity", "attitude"),
        note="a steady world force: it needs the attitude (and the velocity to tell it from drag)",
    )
    explanation: ClassVar[str] = "a steady external force pushes the vehicle (moving air)"
    values: ClassVar[tuple] = (3,)
    syntax: ClassVar[str] = "VX,VY,VZ [m/s]"
    example: ClassVar[str] = "wind=2,-1,0,k=0.3"
    options: ClassVar[dict] = {"gust": float, "gust_tau": float, "k": float, "seed": int}

    def __post_init__(self):
        object.__setattr__(self, "velocity", vector(self.velocity, 3, "wind velocity"))
        k = vector(self.k, 3, "wind k")
        if min(k) < 0:
            raise ConfigError(f"wind drag k must be >= 0 [N s/m], got {k}")
        object.__setattr__(self, "k", k)
        if not (self.gust >= 0 and self.gust_tau > 0):
            raise ConfigError("wind gust must be >= 0 [m/s] and gust_tau > 0 [s]")
        if self.seed is not None and not (
            isinstance(self.seed, (int, np.integer)) and 0 <= self.seed < 2**53
        ):
            raise ConfigError(f"wind seed must be a non-negative integer, got {self.seed!r}")

    def air_velocity(self) -> np.ndarray:
        """Air velocity now [m/s] (world): the steady wind plus the gusts (the protocol's
        one-vehicle memory)."""
        memory = self.memory()
        gust = np.zeros(3) if memory is None else memory["gust"]
        return np.asarray(self.velocity) + gust

    def steady_force(self) -> np.ndarray:
        """Force [N] of the steady wind on a level vehicle (the diagnosis' ``force_N``)."""
        return np.asarray(self.k) * np.asarray(self.velocity)

    def params(self):
        return {
            "velocity_m_per_s": list(self.velocity),
            "gust_m_per_s": self.gust,
            "gust_tau_s": self.gust_tau,
            "k_N_s_per_m": list(self.k),
            "force_N": self.steady_force().tolist(),
        }

    @classmethod
    def from_params(cls, params):
        """A steady world force ``force_N`` (the diagnosis' model): air at ``force / k`` seen
        through an isotropic wind drag ``k`` (``air_velocity_m_per_s`` gives ``k`` when the
        diagnosis also found drag, else ``k`` = 1 N s/m)."""
        F = np.asarray(vector(param(params, "force_N", cls.name), 3, "wind force_N"))
        k = 1.0
        if "air_velocity_m_per_s" in params:
            v = np.asarray(vector(params["air_velocity_m_per_s"], 3, "wind air_velocity_m_per_s"))
            big = np.abs(v) > 1e-9
            if big.any():
                k = float(np.median(np.abs(F[big] / v[big])))
        k = k if k > 0 else 1.0
        return cls(tuple(F / k), k=(k, k, k))

    @classmethod
    def from_values(cls, values, options):
        """``VX,VY,VZ``; the option ``k`` is an isotropic wind drag."""
        if "k" in options:
            options = {**options, "k": (options["k"],) * 3}
        return cls(velocity=tuple(values), **options)

    @classmethod
    def fit_note(cls, params, selected):
        if Drag.name in selected:
            return " Air velocity = force / drag coefficient (horizontal mean of kx, ky)."
        return " Force on the vehicle; no drag identified, so no air velocity."

    def parameters(self, n_rotors, dt, yaw_signs=None):
        own = self.seed is not None
        return {
            "velocity": self.velocity,
            "gust": self.gust,
            "gust_tau": self.gust_tau,
            "k": self.k,
            "own_stream": float(own),
            "seed": float(self.seed if own else 0),
        }

    @classmethod
    def stream_seed(cls, params):
        if params[PARAMETERS.own_stream] == 0.0:
            return None
        return int(params[PARAMETERS.seed])

    @classmethod
    def candidate(cls, ctx):
        m, g, zero3 = ctx.mass, ctx.gravity, (0.0,) * 3
        return WindCandidate(
            cls.name,
            ("Fx [N]", "Fy [N]", "Fz [N]"),
            (-0.5 * m * g,) * 2 + (-0.25 * m * g,),
            (0.5 * m * g,) * 2 + (0.25 * m * g,),
            zero3,
            (zero3,),
            "wrench",
            needs_pose=True,
            affine=True,
            frames=(("force_N", "world"), ("air_velocity_m_per_s", "world")),
        )


@dataclass(frozen=True)
class WindCandidate(Candidate):
    """A steady world force; the air velocity when drag is selected too."""

    keys: ClassVar[tuple] = (("force_N", 0, 3),)

    def wrench(self, x, inp):
        return np.broadcast_to(np.asarray(x, dtype=float), inp.v.shape), None

    def public(self, x, sd, ctx):
        x, sd = np.asarray(x, dtype=float), np.asarray(sd, dtype=float)
        params, unc = {"force_N": x.tolist()}, {"force_N": sd.tolist()}
        if Drag.name in ctx.selected:
            k = np.asarray(ctx.selected[Drag.name], dtype=float)
            kk = np.maximum(np.array([0.5 * (k[0] + k[1])] * 2 + [k[2]]), 1e-9)
            params["air_velocity_m_per_s"] = (x / kk).tolist()
            unc["air_velocity_m_per_s"] = (sd / kk).tolist()
        return params, unc
