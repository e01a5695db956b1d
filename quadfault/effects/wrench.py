"""Wrench-stage effects: extra force (world) [N] and moment (body) [N m] on the vehicle."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from quadfault.effects.base import Effect, number, param, vector
from quadfault.effects.physics import (
    blade_flapping_wrench,
    com_offset_moment,
    drag_force,
    rate_damping_moment,
    rotor_inertia_moment,
    thrust_rate,
)
from quadfault.errors import ConfigError

_ZERO3 = np.zeros(3)


def _force_only(F, state):
    return F, np.zeros(np.shape(state.w))


def _moment_only(M, state):
    return np.zeros(np.shape(state.p)), np.broadcast_to(M, np.shape(state.w)).copy()


@dataclass(frozen=True)
class Drag(Effect):
    """Linear (rotor) drag ``k`` [N s/m] per body axis, opposing the air-relative velocity;
    ``air_velocity`` [m/s] (world) is the steady air motion it sees (default still air)."""

    k: tuple = (0.3, 0.3, 0.3)
    air_velocity: tuple = (0.0, 0.0, 0.0)
    name: ClassVar[str] = "drag"
    order: ClassVar[int] = 10

    def __post_init__(self):
        k = vector(self.k, 3, "drag k")
        if min(k) < 0:
            raise ConfigError(f"drag coefficients must be >= 0 [N s/m], got {k}")
        object.__setattr__(self, "k", k)
        object.__setattr__(self, "air_velocity", vector(self.air_velocity, 3, "drag air_velocity"))

    def wrench(self, state, f, t):
        return _force_only(drag_force(state.R, state.v - np.asarray(self.air_velocity), self.k),
                           state)

    def params(self):
        return {"k_N_s_per_m": list(self.k)}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "k_N_s_per_m", cls.name))


@dataclass(frozen=True)
class Wind(Effect):
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
    order: ClassVar[int] = 10

    def __post_init__(self):
        object.__setattr__(self, "velocity", vector(self.velocity, 3, "wind velocity"))
        k = vector(self.k, 3, "wind k")
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
        return _force_only(-drag_force(state.R, vw, self.k), state)

    def steady_force(self) -> np.ndarray:
        """Force [N] of the steady wind on a level vehicle (the diagnosis' ``force_N``)."""
        return np.asarray(self.k) * np.asarray(self.velocity)

    def params(self):
        return {"velocity_m_per_s": list(self.velocity), "gust_m_per_s": self.gust,
                "gust_tau_s": self.gust_tau, "k_N_s_per_m": list(self.k),
                "force_N": self.steady_force().tolist()}

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


@dataclass(frozen=True)
class ComOffset(Effect):
    """Centre of mass at ``offset`` = (r_x, r_y) [m] from the rotor-plane centre (body FRD):
    the rotors act about the CoM, ``M' = M + r x (0, 0, T)``."""

    offset: tuple = (0.0, 0.0)
    name: ClassVar[str] = "com_offset"
    order: ClassVar[int] = 10

    def __post_init__(self):
        off = vector(self.offset, 2, "com_offset")
        if max(abs(x) for x in off) > 1.0:
            raise ConfigError(f"com_offset must be within 1 m, got {off}")
        object.__setattr__(self, "offset", off)

    def wrench(self, state, f, t):
        return _moment_only(com_offset_moment(np.sum(f, axis=-1), self.offset), state)

    def params(self):
        return {"offset_m": list(self.offset)}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "offset_m", cls.name))


@dataclass(frozen=True)
class BladeFlapping(Effect):
    """Rotor drag and blade flapping proportional to thrust and in-plane airspeed
    (:func:`~quadfault.effects.physics.blade_flapping_wrench`): force coefficient
    ``k_force`` [s/m], moment coefficient ``k_moment`` [s], still air by default."""

    k_force: float = 0.05
    k_moment: float = 0.002
    air_velocity: tuple = (0.0, 0.0, 0.0)
    name: ClassVar[str] = "blade_flapping"
    order: ClassVar[int] = 10

    def __post_init__(self):
        number(self.k_force, "blade_flapping k_force [s/m]", 0.0, 10.0)
        number(self.k_moment, "blade_flapping k_moment [s]", -1.0, 1.0)
        object.__setattr__(self, "air_velocity",
                           vector(self.air_velocity, 3, "blade_flapping air_velocity"))

    def wrench(self, state, f, t):
        v = state.v - np.asarray(self.air_velocity)
        return blade_flapping_wrench(state.R, v, np.sum(f, axis=-1), self.k_force, self.k_moment)

    def params(self):
        return {"k_force_s_per_m": self.k_force, "k_moment_s": self.k_moment}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "k_force_s_per_m", cls.name),
                   param(params, "k_moment_s", cls.name))


@dataclass(frozen=True)
class RotorInertia(Effect):
    """Yaw reaction of the rotors' inertia when their thrust changes:
    ``M_z = kappa sum_i s_i df_i/dt`` (``kappa`` [m s]; ``s_i`` the sign of rotor i's yaw
    torque: ``yaw_signs``, by default read from the flown vehicle's allocation at reset). The
    rate over a step is the step from the previous step's produced thrust
    (:func:`~quadfault.effects.physics.thrust_rate`), so a jump in thrust gives the yaw-rate
    kick ``kappa sum_i s_i df_i / J_z``."""

    kappa: float = 0.001
    yaw_signs: tuple | None = None
    _state: dict = field(default_factory=dict, repr=False, compare=False)
    _signs: dict = field(default_factory=dict, repr=False, compare=False)
    name: ClassVar[str] = "rotor_inertia"
    order: ClassVar[int] = 10

    def __post_init__(self):
        number(self.kappa, "rotor_inertia kappa [m s]", 0.0, 10.0)
        if self.yaw_signs is not None:
            signs = np.sign(vector(self.yaw_signs, len(np.ravel(self.yaw_signs)),
                                   "rotor_inertia yaw_signs"))
            object.__setattr__(self, "yaw_signs", tuple(float(s) for s in signs))

    def reset(self, n_rotors):
        self._state.clear()

    def true_vehicle(self, vehicle):
        self._signs["s"] = np.sign(vehicle.allocation[3])  # the flown rotors' spin directions
        return vehicle

    def signs(self, n_rotors: int) -> np.ndarray:
        if self.yaw_signs is not None:
            return np.asarray(self.yaw_signs)
        s = self._signs.get("s")
        return s if s is not None and len(s) == n_rotors else np.resize([-1.0, 1.0], n_rotors)

    def rotor_thrust(self, f, t, dt, state):
        self._state.update(dt=float(dt), fresh=True)  # the next wrench call opens this step
        return f

    def wrench(self, state, f, t):
        st = self._state
        f = np.asarray(f, dtype=float)
        if st.pop("fresh", False):  # first stage of a step: the rate of the final thrust
            prev = st.get("f")
            st["rate"] = (np.zeros_like(f) if prev is None
                          else thrust_rate(np.stack((prev, f)), np.array([0.0, st["dt"]]))[1])
            st["f"] = f.copy()
        rate = st.get("rate")
        if rate is None:
            rate = np.zeros_like(f)
        M = rotor_inertia_moment(rate, self.signs(f.shape[-1]), self.kappa)
        return _moment_only(M, state)

    def params(self):
        return {"kappa_m_s": self.kappa}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "kappa_m_s", cls.name))


@dataclass(frozen=True)
class RateDamping(Effect):
    """Aerodynamic damping of the body rate, ``M = -(D1 + D2 |w|) w`` per body axis:
    ``linear`` D1 [N m s/rad] and ``quadratic`` D2 [N m s^2/rad^2] (3 values each)."""

    linear: tuple = (0.0, 0.0, 0.0)
    quadratic: tuple = (0.0, 0.0, 0.0)
    name: ClassVar[str] = "rate_damping"
    order: ClassVar[int] = 10

    def __post_init__(self):
        for key in ("linear", "quadratic"):
            d = vector(getattr(self, key), 3, f"rate_damping {key}")
            if min(d) < 0:
                raise ConfigError(f"rate_damping {key} must be >= 0, got {d}")
            object.__setattr__(self, key, d)

    def wrench(self, state, f, t):
        return _moment_only(rate_damping_moment(state.w, self.linear, self.quadratic), state)

    def params(self):
        return {"linear_N_m_s_per_rad": list(self.linear),
                "quadratic_N_m_s2_per_rad2": list(self.quadratic)}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "linear_N_m_s_per_rad", cls.name),
                   params.get("quadratic_N_m_s2_per_rad2", (0.0, 0.0, 0.0)))
