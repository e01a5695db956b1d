"""Wrench-stage effects: extra force (world) [N] and moment (body) [N m] on the vehicle.

Each is a frozen dataclass of parameters; its physics is its entry in the compiled effect
chain (:mod:`quadfault.effects.chain`, the kernels of :mod:`quadfault.effects.kernels`),
evaluated at every stage of the integrator.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.effects.base import Compiled, Identifiability, number, param, vector
from quadfault.errors import ConfigError


@dataclass(frozen=True)
class Drag(Compiled):
    """Linear (rotor) drag ``k`` [N s/m] per body axis, opposing the air-relative velocity;
    ``air_velocity`` [m/s] (world) is the steady air motion it sees (default still air)."""

    k: tuple = (0.3, 0.3, 0.3)
    air_velocity: tuple = (0.0, 0.0, 0.0)
    name: ClassVar[str] = "drag"
    identifiability: ClassVar[Identifiability] = Identifiability(
        channels=("velocity", "attitude"),
        excitation="speeds through the air of about 1 m/s or more",
        note="the force opposes the velocity through the air: no valid velocity, no drag")
    order: ClassVar[int] = 10

    def __post_init__(self):
        k = vector(self.k, 3, "drag k")
        if min(k) < 0:
            raise ConfigError(f"drag coefficients must be >= 0 [N s/m], got {k}")
        object.__setattr__(self, "k", k)
        object.__setattr__(self, "air_velocity", vector(self.air_velocity, 3, "drag air_velocity"))

    def params(self):
        return {"k_N_s_per_m": list(self.k)}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "k_N_s_per_m", cls.name))


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
    identifiability: ClassVar[Identifiability] = Identifiability(
        channels=("velocity", "attitude"),
        note="a steady world force: it needs the attitude (and the velocity to tell it from "
             "drag)")
    order: ClassVar[int] = 10

    def __post_init__(self):
        object.__setattr__(self, "velocity", vector(self.velocity, 3, "wind velocity"))
        k = vector(self.k, 3, "wind k")
        if min(k) < 0:
            raise ConfigError(f"wind drag k must be >= 0 [N s/m], got {k}")
        object.__setattr__(self, "k", k)
        if not (self.gust >= 0 and self.gust_tau > 0):
            raise ConfigError("wind gust must be >= 0 [m/s] and gust_tau > 0 [s]")
        if self.seed is not None and not (isinstance(self.seed, (int, np.integer))
                                          and 0 <= self.seed < 2 ** 53):
            raise ConfigError(f"wind seed must be a non-negative integer, got {self.seed!r}")

    def air_velocity(self) -> np.ndarray:
        """Air velocity now [m/s] (world): the steady wind plus the gusts (the protocol's
        one-vehicle memory)."""
        single = self.__dict__.get("_single")
        gust = np.zeros(3) if single is None else single.rows.memory[0, :3]
        return np.asarray(self.velocity) + gust

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
class ComOffset(Compiled):
    """Centre of mass at ``offset`` = (r_x, r_y) [m] from the rotor-plane centre (body FRD):
    the rotors act about the CoM, ``M' = M + r x (0, 0, T)``."""

    offset: tuple = (0.0, 0.0)
    name: ClassVar[str] = "com_offset"
    identifiability: ClassVar[Identifiability] = Identifiability(
        note="a thrust-proportional moment: hover needs an unequal rotor split")
    order: ClassVar[int] = 10

    def __post_init__(self):
        off = vector(self.offset, 2, "com_offset")
        if max(abs(x) for x in off) > 1.0:
            raise ConfigError(f"com_offset must be within 1 m, got {off}")
        object.__setattr__(self, "offset", off)

    def params(self):
        return {"offset_m": list(self.offset)}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "offset_m", cls.name))


@dataclass(frozen=True)
class BladeFlapping(Compiled):
    """Rotor drag and blade flapping proportional to thrust and in-plane airspeed
    (:func:`~quadfault.effects.kernels.blade_flapping3`): force coefficient
    ``k_force`` [s/m], moment coefficient ``k_moment`` [s], still air by default."""

    k_force: float = 0.05
    k_moment: float = 0.002
    air_velocity: tuple = (0.0, 0.0, 0.0)
    name: ClassVar[str] = "blade_flapping"
    identifiability: ClassVar[Identifiability] = Identifiability(
        channels=("velocity", "attitude"),
        excitation="in-plane airspeed (forward flight)",
        note="force and moment grow with the in-plane airspeed")
    order: ClassVar[int] = 10

    def __post_init__(self):
        number(self.k_force, "blade_flapping k_force [s/m]", 0.0, 10.0)
        number(self.k_moment, "blade_flapping k_moment [s]", -1.0, 1.0)
        object.__setattr__(self, "air_velocity",
                           vector(self.air_velocity, 3, "blade_flapping air_velocity"))

    def params(self):
        return {"k_force_s_per_m": self.k_force, "k_moment_s": self.k_moment}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "k_force_s_per_m", cls.name),
                   param(params, "k_moment_s", cls.name))


@dataclass(frozen=True)
class RotorInertia(Compiled):
    """Yaw reaction of the rotors' inertia when their thrust changes:
    ``M_z = kappa sum_i s_i df_i/dt`` (``kappa`` [m s]; ``s_i`` the sign of rotor i's yaw
    torque: ``yaw_signs``, by default read from the flown vehicle's allocation at reset). The
    rate over a step is the step from the previous step's produced thrust
    (:func:`~quadfault.effects.kernels.thrust_rate1`), so a jump in thrust gives the yaw-rate
    kick ``kappa sum_i s_i df_i / J_z``."""

    kappa: float = 0.001
    yaw_signs: tuple | None = None
    name: ClassVar[str] = "rotor_inertia"
    identifiability: ClassVar[Identifiability] = Identifiability(
        excitation="thrust changes (the yaw kick of rotors speeding up or down)",
        note="shows in the yaw rate when the rotors change speed")
    order: ClassVar[int] = 10

    def __post_init__(self):
        number(self.kappa, "rotor_inertia kappa [m s]", 0.0, 10.0)
        if self.yaw_signs is not None:
            signs = np.sign(vector(self.yaw_signs, len(np.ravel(self.yaw_signs)),
                                   "rotor_inertia yaw_signs"))
            object.__setattr__(self, "yaw_signs", tuple(float(s) for s in signs))

    def true_vehicle(self, vehicle):
        self.__dict__["_signs"] = np.sign(vehicle.allocation[3])  # the flown rotors' spins
        self.__dict__.pop("_single", None)
        return vehicle

    def signs(self, n_rotors: int) -> np.ndarray:
        """Yaw-torque sign of each rotor: ``yaw_signs``, else the flown vehicle's (seen by
        ``true_vehicle``), else alternating -1, +1."""
        if self.yaw_signs is not None:
            return np.asarray(self.yaw_signs)
        s = self.__dict__.get("_signs")
        return s if s is not None and len(s) == n_rotors else np.resize([-1.0, 1.0], n_rotors)

    def _yaw_signs(self, n_rotors):
        return self.signs(n_rotors)

    def params(self):
        return {"kappa_m_s": self.kappa}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "kappa_m_s", cls.name))


@dataclass(frozen=True)
class RateDamping(Compiled):
    """Aerodynamic damping of the body rate, ``M = -(D1 + D2 |w|) w`` per body axis:
    ``linear`` D1 [N m s/rad] and ``quadratic`` D2 [N m s^2/rad^2] (3 values each)."""

    linear: tuple = (0.0, 0.0, 0.0)
    quadratic: tuple = (0.0, 0.0, 0.0)
    name: ClassVar[str] = "rate_damping"
    identifiability: ClassVar[Identifiability] = Identifiability(
        excitation="body rotation (roll, pitch or yaw rates)",
        note="the moment grows with the body rate")
    order: ClassVar[int] = 10

    def __post_init__(self):
        for key in ("linear", "quadratic"):
            d = vector(getattr(self, key), 3, f"rate_damping {key}")
            if min(d) < 0:
                raise ConfigError(f"rate_damping {key} must be >= 0, got {d}")
            object.__setattr__(self, key, d)

    def params(self):
        return {"linear_N_m_s_per_rad": list(self.linear),
                "quadratic_N_m_s2_per_rad2": list(self.quadratic)}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "linear_N_m_s_per_rad", cls.name),
                   params.get("quadratic_N_m_s2_per_rad2", (0.0, 0.0, 0.0)))
