"""Unmodelled physical effects: one model for the simulator's plant and the diagnosis.

Each effect is a small frozen dataclass of physical parameters. The pure functions below
are the physics; the plant calls them one step at a time through the
:class:`~quadfault.plant.Effect` protocol (``reset``, ``rotor_thrust``, ``wrench``), and the
mismatch diagnosis (:mod:`quadfault.diagnosis.library`) calls the *same* functions over a
whole recording. Internal frames: world NED, body FRD.

==================  =======================================================================
name                model
==================  =======================================================================
motor_efficiency    ``f_i' = eta_i f_i`` (per-rotor thrust loss, paper eq. 13)
thrust_scale        ``f_i' = s f_i`` (all rotors)
ground_effect       ``f_i' = f_i / (1 - (r / 4h)^2)`` (Cheeseman-Bennett), ``h`` = height of
                    the centre of mass above the ground plane ``z = ground_z`` (NED), clipped
                    to ``h >= r / 2``
delay               ``f'(t) = f(t - d)``; over a step the mean of the delayed zero-order-hold
                    command, so fractional delays are exact
motor_lag           ``tau f' ' = f - f'``, discretised exactly for a held input:
                    ``f'_k = f'_{k-1} + (1 - exp(-dt_k / tau)) (f_k - f'_{k-1})``
drag                ``F = -R diag(k) R^T (v - v_air)`` [N], ``k`` in [N s/m] (body axes)
wind                air moving at ``v_air(t)`` (steady + Ornstein-Uhlenbeck gusts) seen
                    through wind drag ``k_w``: ``F = R diag(k_w) R^T v_air`` [N]
com_offset          centre of mass at ``r`` from the rotor-plane centre (body FRD): the rotors
                    act about the CoM, ``M' = M + r x (0, 0, T)`` [N m]
inertia             true inertia ``J_t = D J D``, ``D = diag(sqrt(s))``: the moment that makes
                    the nominal body follow ``J_t w' + w x J_t w = M``
==================  =======================================================================

``parse_effect("drag=0.3")`` builds an effect from the ``quadfault simulate --effect`` syntax:
``NAME=V1,V2,...[,key=value...]``.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from quadfault.errors import ConfigError
from quadfault.rotation import cross

_ZERO3 = np.zeros(3)


# ----------------------------------------------------------------------------------------
# physics (pure functions, batched over leading axes)
def ground_effect_factor(height, rotor_radius: float) -> np.ndarray:
    """Cheeseman-Bennett thrust ratio ``1 / (1 - (r / 4h)^2)`` for height ``h`` [m] above the
    ground and rotor radius ``r`` [m]; ``h`` is clipped to ``r / 2`` (ratio at most 4/3)."""
    h = np.maximum(np.asarray(height, dtype=float), max(0.5 * rotor_radius, 1e-6))
    return 1.0 / (1.0 - (rotor_radius / (4.0 * h)) ** 2)


def zoh_mean(t_knots: np.ndarray, values: np.ndarray, cumulative: np.ndarray,
             a, b) -> np.ndarray:
    """Mean over ``[a, b]`` of the zero-order-hold signal ``values[j]`` on
    ``[t_knots[j], t_knots[j+1])`` (constant before the first and after the last knot).

    ``cumulative[j]`` is the integral from ``t_knots[0]`` to ``t_knots[j]``.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)

    def integral(x):
        j = np.clip(np.searchsorted(t_knots, x, side="right") - 1, 0, len(t_knots) - 1)
        return cumulative[j] + values[j] * (x - t_knots[j])[..., None]

    return (integral(b) - integral(a)) / (b - a)[..., None]


def zoh_cumulative(t_knots: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Cumulative integrals of a zero-order-hold signal at its knots (see :func:`zoh_mean`)."""
    out = np.zeros_like(values, dtype=float)
    out[1:] = np.cumsum(values[:-1] * np.diff(t_knots)[:, None], axis=0)
    return out


def lag_gain(dt, tau: float) -> np.ndarray:
    """First-order-lag update gain ``1 - exp(-dt / tau)`` for a held input."""
    return -np.expm1(-np.asarray(dt, dtype=float) / max(tau, 1e-9))


def lag_series(f: np.ndarray, dt: np.ndarray, tau: float) -> np.ndarray:
    """Rotor thrust after first-order lag ``tau`` [s] for commands ``f`` ``(N, n)`` held for
    ``dt`` ``(N,)`` [s]; starts at the first command (as the plant does)."""
    f = np.asarray(f, dtype=float)
    g = lag_gain(dt, tau)
    if len(g) > 1 and np.ptp(g) <= 1e-9 * max(g.max(), 1e-12):  # uniform: a linear filter
        from scipy.signal import lfilter

        a = float(g[0])
        zi = ((1.0 - a) * f[0])[None, :]
        return lfilter([a], [1.0, a - 1.0], f, axis=0, zi=zi)[0]
    out = np.empty_like(f)
    y = f[0].copy()
    for k in range(len(f)):
        y += g[k] * (f[k] - y)
        out[k] = y
    return out


def drag_force(R: np.ndarray, v_air: np.ndarray, k) -> np.ndarray:
    """``-R diag(k) R^T v_air`` [N] for air-relative velocity ``v_air`` (world) [m/s]."""
    R = np.asarray(R, dtype=float)
    vb = (np.swapaxes(R, -1, -2) @ np.asarray(v_air, dtype=float)[..., None])[..., 0]
    return -(R @ (vb * np.asarray(k, dtype=float))[..., None])[..., 0]


def com_offset_moment(thrust, offset) -> np.ndarray:
    """Extra body moment [N m] of collective thrust ``thrust`` [N] when the CoM sits at
    ``offset`` = (r_x, r_y[, r_z]) [m] from the rotor-plane centre: ``r x (0, 0, T)``."""
    T = np.asarray(thrust, dtype=float)
    r = np.asarray(offset, dtype=float)
    return np.stack((r[1] * T, -r[0] * T, np.zeros_like(T)), axis=-1)


def scaled_inertia(inertia: np.ndarray, scale) -> np.ndarray:
    """``D J D`` with ``D = diag(sqrt(scale))``: diagonal entries scaled by ``scale``."""
    d = np.sqrt(np.asarray(scale, dtype=float))
    return inertia * d[:, None] * d[None, :]


def inertia_moment(w, moment, inertia, true_inertia) -> np.ndarray:
    """Moment [N m] that makes a body of inertia ``inertia`` move like one of
    ``true_inertia`` under ``moment`` (paper eq. 4 solved for both)."""
    w = np.asarray(w, dtype=float)
    alpha_true = (moment - cross(w, w @ true_inertia.T)) @ np.linalg.inv(true_inertia).T
    return alpha_true @ inertia.T - moment + cross(w, w @ inertia.T)


# ----------------------------------------------------------------------------------------
# effects (plant side)
def _vector(value, n, what) -> tuple:
    try:
        arr = np.asarray(value, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be numeric, got {value!r}") from None
    if arr.size == 1 and n > 1:
        arr = np.repeat(arr, n)
    if arr.size != n or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{what} needs {n} finite values, got {value!r}")
    return tuple(float(x) for x in arr)


class _Base:
    """Default no-op plant hooks."""

    name: ClassVar[str] = ""

    def reset(self, n_rotors: int) -> None:
        pass

    def rotor_thrust(self, f, t, dt, state):
        return f

    def wrench(self, state, f, t):
        return np.zeros(np.shape(state.p)), np.zeros(np.shape(state.w))

    def params(self) -> dict:
        raise NotImplementedError

    def describe(self) -> dict:
        """JSON-able ``{"name", "params"}`` (stored as truth in a recording's meta)."""
        return {"name": self.name, "params": self.params()}


@dataclass(frozen=True)
class MotorEfficiency(_Base):
    """Per-rotor thrust factor ``eta`` [-] (1 = nominal)."""

    eta: tuple = (1.0, 1.0, 1.0, 1.0)
    name: ClassVar[str] = "motor_efficiency"

    def __post_init__(self):
        eta = _vector(self.eta, 4, "motor_efficiency eta")
        if not all(0.0 <= e <= 2.0 for e in eta):
            raise ConfigError(f"motor_efficiency eta must be in [0, 2], got {eta}")
        object.__setattr__(self, "eta", eta)

    def rotor_thrust(self, f, t, dt, state):
        return f * np.asarray(self.eta)

    def params(self):
        return {"eta": list(self.eta)}


@dataclass(frozen=True)
class ThrustScale(_Base):
    """Common thrust factor ``scale`` [-] of all rotors."""

    scale: float = 1.0
    name: ClassVar[str] = "thrust_scale"

    def __post_init__(self):
        if not (0.0 < self.scale <= 3.0):
            raise ConfigError(f"thrust_scale must be in (0, 3], got {self.scale!r}")

    def rotor_thrust(self, f, t, dt, state):
        return f * self.scale

    def params(self):
        return {"scale": self.scale}


@dataclass(frozen=True)
class GroundEffect(_Base):
    """Cheeseman-Bennett ground effect: rotor radius [m], ground plane ``z = ground_z`` [m]
    (world NED; 0 = the height where the recording's z is 0)."""

    rotor_radius: float = 0.1
    ground_z: float = 0.0
    name: ClassVar[str] = "ground_effect"

    def __post_init__(self):
        if not (0.0 <= self.rotor_radius <= 2.0):
            raise ConfigError(f"ground_effect rotor radius must be in [0, 2] m, got {self.rotor_radius!r}")

    def rotor_thrust(self, f, t, dt, state):
        return f * ground_effect_factor(self.ground_z - state.p[..., 2], self.rotor_radius)[..., None]

    def params(self):
        return {"rotor_radius_m": self.rotor_radius, "ground_z_m": self.ground_z}


@dataclass(frozen=True)
class Delay(_Base):
    """Pure input delay [s] of the rotor thrust."""

    delay: float = 0.02
    _hist: dict = field(default_factory=dict, repr=False, compare=False)
    name: ClassVar[str] = "delay"

    def __post_init__(self):
        if not (0.0 <= self.delay <= 2.0):
            raise ConfigError(f"delay must be in [0, 2] s, got {self.delay!r}")

    def reset(self, n_rotors):
        self._hist.clear()
        self._hist.update(t=[], f=[], c=[])

    def rotor_thrust(self, f, t, dt, state):
        h = self._hist
        if "t" not in h:
            self.reset(len(f))
        if h["t"]:
            c = h["c"][-1] + h["f"][-1] * (t - h["t"][-1])
        else:
            c = np.zeros(len(f))
        h["t"].append(float(t))
        h["f"].append(np.array(f, dtype=float))
        h["c"].append(c)
        if self.delay == 0.0:
            return f
        # only the knots that can matter: those after t - delay - dt
        lo = max(bisect.bisect_right(h["t"], t - self.delay - dt) - 1, 0)
        tk = np.asarray(h["t"][lo:])
        out = zoh_mean(tk, np.asarray(h["f"][lo:]), np.asarray(h["c"][lo:]),
                       np.array([t - self.delay]), np.array([t + dt - self.delay]))[0]
        if lo > 1000:  # forget the distant past
            for key in ("t", "f", "c"):
                del h[key][: lo - 1]
        return out

    def params(self):
        return {"delay_s": self.delay}


@dataclass(frozen=True)
class MotorLag(_Base):
    """First-order rotor thrust dynamics with time constant ``tau`` [s]."""

    tau: float = 0.05
    _state: dict = field(default_factory=dict, repr=False, compare=False)
    name: ClassVar[str] = "motor_lag"

    def __post_init__(self):
        if not (0.0 < self.tau <= 5.0):
            raise ConfigError(f"motor_lag tau must be in (0, 5] s, got {self.tau!r}")

    def reset(self, n_rotors):
        self._state.clear()

    def rotor_thrust(self, f, t, dt, state):
        y = self._state.get("y")
        y = np.array(f, dtype=float) if y is None else y + lag_gain(dt, self.tau) * (f - y)
        self._state["y"] = y
        return y.copy()

    def params(self):
        return {"tau_s": self.tau}


@dataclass(frozen=True)
class Drag(_Base):
    """Linear (rotor) drag ``k`` [N s/m] per body axis, opposing the air-relative velocity;
    ``air_velocity`` [m/s] (world) is the steady air motion it sees (default still air)."""

    k: tuple = (0.3, 0.3, 0.3)
    air_velocity: tuple = (0.0, 0.0, 0.0)
    name: ClassVar[str] = "drag"

    def __post_init__(self):
        k = _vector(self.k, 3, "drag k")
        if min(k) < 0:
            raise ConfigError(f"drag coefficients must be >= 0 [N s/m], got {k}")
        object.__setattr__(self, "k", k)
        object.__setattr__(self, "air_velocity", _vector(self.air_velocity, 3, "drag air_velocity"))

    def wrench(self, state, f, t):
        F = drag_force(state.R, state.v - np.asarray(self.air_velocity), self.k)
        return F, np.zeros(np.shape(state.w))

    def params(self):
        return {"k_N_s_per_m": list(self.k)}


@dataclass(frozen=True)
class Wind(_Base):
    """Air moving at ``velocity`` [m/s] (world) plus Ornstein-Uhlenbeck gusts (std ``gust``
    [m/s], correlation time ``gust_tau`` [s], seeded by ``seed``), pushing the vehicle through
    the wind drag ``k`` [N s/m] (body axes): ``F = R diag(k) R^T v_air``. Combine with
    :class:`Drag` of the same ``k`` for ``-R diag(k) R^T (v - v_air)``."""

    velocity: tuple = (1.0, 0.0, 0.0)
    gust: float = 0.0
    gust_tau: float = 2.0
    k: tuple = (0.3, 0.3, 0.3)
    seed: int = 0
    _state: dict = field(default_factory=dict, repr=False, compare=False)
    name: ClassVar[str] = "wind"

    def __post_init__(self):
        object.__setattr__(self, "velocity", _vector(self.velocity, 3, "wind velocity"))
        k = _vector(self.k, 3, "wind k")
        if min(k) < 0:
            raise ConfigError(f"wind drag k must be >= 0 [N s/m], got {k}")
        object.__setattr__(self, "k", k)
        if not (self.gust >= 0 and self.gust_tau > 0):
            raise ConfigError("wind gust must be >= 0 [m/s] and gust_tau > 0 [s]")

    def reset(self, n_rotors):
        self._state.clear()
        self._state.update(rng=np.random.default_rng(self.seed), g=np.zeros(3))

    def air_velocity(self) -> np.ndarray:
        return np.asarray(self.velocity) + self._state.get("g", _ZERO3)

    def rotor_thrust(self, f, t, dt, state):
        if self.gust > 0:  # advance the gust process once per step
            if "rng" not in self._state:
                self.reset(len(f))
            a = math.exp(-dt / self.gust_tau)
            g = self._state["g"]
            self._state["g"] = a * g + self.gust * math.sqrt(1 - a * a) * \
                self._state["rng"].standard_normal(3)
        return f

    def wrench(self, state, f, t):
        vw = np.broadcast_to(self.air_velocity(), np.shape(state.v))
        return -drag_force(state.R, vw, self.k), np.zeros(np.shape(state.w))

    def steady_force(self) -> np.ndarray:
        """Force [N] of the steady wind on a level vehicle (the diagnosis' ``force_N``)."""
        return np.asarray(self.k) * np.asarray(self.velocity)

    def params(self):
        return {"velocity_m_per_s": list(self.velocity), "gust_m_per_s": self.gust,
                "gust_tau_s": self.gust_tau, "k_N_s_per_m": list(self.k),
                "force_N": self.steady_force().tolist()}


@dataclass(frozen=True)
class ComOffset(_Base):
    """Centre of mass at ``offset`` = (r_x, r_y) [m] from the rotor-plane centre (body FRD)."""

    offset: tuple = (0.0, 0.0)
    name: ClassVar[str] = "com_offset"

    def __post_init__(self):
        off = _vector(self.offset, 2, "com_offset")
        if max(abs(x) for x in off) > 1.0:
            raise ConfigError(f"com_offset must be within 1 m, got {off}")
        object.__setattr__(self, "offset", off)

    def wrench(self, state, f, t):
        T = np.sum(f, axis=-1)
        M = com_offset_moment(T, self.offset)
        return np.zeros(np.shape(state.p)), np.broadcast_to(M, np.shape(state.w)).copy()

    def params(self):
        return {"offset_m": list(self.offset)}


@dataclass(frozen=True)
class Inertia(_Base):
    """True inertia ``D J D``, ``D = diag(sqrt(scale))`` (diagonal scaled by ``scale``).

    The plant flies its nominal vehicle, so this effect needs that vehicle (``vehicle``;
    default: the paper's F450, the one ``quadfault simulate`` flies) to turn the rotor moment
    into the moment that reproduces the true rotational dynamics. Moments of other effects
    (com_offset) are not rescaled.
    """

    scale: tuple = (1.0, 1.0, 1.0)
    vehicle: object = None
    name: ClassVar[str] = "inertia"

    def __post_init__(self):
        s = _vector(self.scale, 3, "inertia scale")
        if not all(0.05 <= x <= 20 for x in s):
            raise ConfigError(f"inertia scale must be in [0.05, 20], got {s}")
        object.__setattr__(self, "scale", s)
        if self.vehicle is None:
            from quadfault.vehicle import Vehicle

            object.__setattr__(self, "vehicle", Vehicle())

    def wrench(self, state, f, t):
        veh = self.vehicle
        M = np.asarray(f) @ veh.allocation[1:].T
        Jt = scaled_inertia(veh.inertia, self.scale)
        return np.zeros(np.shape(state.p)), inertia_moment(state.w, M, veh.inertia, Jt)

    def params(self):
        return {"scale": list(self.scale)}


EFFECTS = {cls.name: cls for cls in (MotorEfficiency, ThrustScale, Drag, MotorLag, Delay, Wind,
                                     GroundEffect, ComOffset, Inertia)}
EFFECT_NAMES = tuple(EFFECTS)

#: positional values of each ``--effect`` spec -> constructor keywords
_POSITIONAL = {
    "motor_efficiency": ("eta", (1, 4)),
    "thrust_scale": ("scale", (1,)),
    "drag": ("k", (1, 3)),
    "motor_lag": ("tau", (1,)),
    "delay": ("delay", (1,)),
    "wind": ("velocity", (3,)),
    "ground_effect": ("rotor_radius", (1,)),
    "com_offset": ("offset", (2,)),
    "inertia": ("scale", (1, 3)),
}
_KEYWORDS = {"wind": {"gust": float, "gust_tau": float, "k": float, "seed": int},
             "ground_effect": {"ground_z": float}, "drag": {}}


def parse_effect(spec: str):
    """An effect from ``NAME=V1[,V2...][,key=value...]``, e.g. ``drag=0.3``,
    ``wind=2,0,0,gust=0.5``, ``motor_efficiency=1,1,0.7,1``, ``inertia=1.3,1.3,1``."""
    if not isinstance(spec, str) or "=" not in spec:
        raise ConfigError(f"--effect expects NAME=VALUES, got {spec!r}")
    name, _, rest = spec.partition("=")
    name = name.strip().replace("-", "_")
    if name not in EFFECTS:
        raise ConfigError(f"unknown effect {name!r}; choose from {', '.join(EFFECT_NAMES)}")
    values, kwargs = [], {}
    allowed = _KEYWORDS.get(name, {})
    for tok in (s.strip() for s in rest.split(",")):
        if "=" in tok:
            key, _, val = tok.partition("=")
            if key not in allowed:
                raise ConfigError(f"effect {name}: unknown option {key!r} "
                                  f"(options: {', '.join(allowed) or 'none'})")
            try:
                kwargs[key] = allowed[key](val)
            except ValueError:
                raise ConfigError(f"effect {name}: option {key} needs a number, got {val!r}") from None
            continue
        try:
            values.append(float(tok))
        except ValueError:
            raise ConfigError(f"effect {name}: not a number: {tok!r}") from None
        if not math.isfinite(values[-1]):
            raise ConfigError(f"effect {name}: values must be finite, got {tok!r}")
    key, counts = _POSITIONAL[name]
    if len(values) not in counts:
        raise ConfigError(f"effect {name} expects {' or '.join(map(str, counts))} value(s), "
                          f"got {len(values)} in {spec!r}")
    if "k" in kwargs:
        kwargs["k"] = (kwargs["k"],) * 3
    value = values[0] if counts == (1,) else tuple(values)
    return EFFECTS[name](**{key: value}, **kwargs)
