"""Vehicle parameters and thrust allocation.

Internal convention everywhere in quadfault: world frame NED, body frame FRD, collective
thrust positive along ``-z_body``. The allocation matrix maps rotor thrusts [N] to the body
wrench ``[collective thrust; Mx; My; Mz]`` (paper eq. 12, ``wrench = A @ f``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from quadfault.errors import ConfigError

#: The paper's F450 table (and the reference code's g = 9.8).
PAPER_MASS = 1.0  # [kg]
PAPER_INERTIA = (0.01466, 0.01466, 0.02848)  # [kg m^2]
PAPER_ARM = 0.225  # [m] per-axis rotor offset d
PAPER_TORQUE_COEFFICIENT = 0.009012  # [m] c_tau_f, yaw torque per newton of thrust
PAPER_GRAVITY = 9.8  # [m/s^2]

#: Yaw-row signs of the paper's layout (eq. 12): rotors 1..4 -> (-c, +c, -c, +c).
PAPER_YAW_SIGNS = (-1.0, 1.0, -1.0, 1.0)
#: Rotor (x, y) positions of the paper's layout in units of d (FRD): FR, FL, RL, RR.
PAPER_ROTOR_XY = ((1.0, 1.0), (1.0, -1.0), (-1.0, -1.0), (-1.0, 1.0))


def allocation_from_rotors(positions, yaw_signs, torque_coefficient: float) -> np.ndarray:
    """Allocation matrix from rotor positions and spin directions (FRD body frame).

    Args:
        positions: ``(n, 2)`` or ``(n, 3)`` rotor positions ``(x, y[, z])`` [m] relative to
            the centre of mass. A thrust ``f`` along ``-z_body`` at ``(x, y)`` gives the moment
            ``(-y f, x f, 0)``.
        yaw_signs: ``(n,)`` sign of each rotor's reaction torque about ``+z_body`` (+1 or -1).
        torque_coefficient: yaw torque per newton of thrust, c_tau_f [m].

    Returns:
        ``(4, n)`` matrix; rows ``[collective thrust; Mx; My; Mz]``.
    """
    pos = np.asarray(positions, dtype=float)
    signs = np.asarray(yaw_signs, dtype=float)
    if pos.ndim != 2 or pos.shape[1] not in (2, 3):
        raise ConfigError(f"rotor positions must have shape (n, 2) or (n, 3), got {pos.shape}")
    if signs.shape != (pos.shape[0],):
        raise ConfigError(f"yaw_signs must have shape ({pos.shape[0]},), got {signs.shape}")
    x, y = pos[:, 0], pos[:, 1]
    return np.stack((np.ones_like(x), -y, x, signs * torque_coefficient))


def paper_allocation(
    arm: float = PAPER_ARM, torque_coefficient: float = PAPER_TORQUE_COEFFICIENT
) -> np.ndarray:
    """The paper's allocation matrix Lambda (eq. 12) for per-axis offset ``d`` [m]."""
    pos = np.asarray(PAPER_ROTOR_XY) * arm
    return allocation_from_rotors(pos, PAPER_YAW_SIGNS, torque_coefficient)


def _frozen_array(value, shape, name) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"vehicle {name} must be numeric: {exc}") from None
    if shape is not None and arr.shape != shape:
        raise ConfigError(f"vehicle {name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"vehicle {name} contains NaN or inf")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Vehicle:
    """Rigid-body and propulsion parameters of a multirotor.

    Attributes:
        mass: total mass [kg].
        inertia: ``(3, 3)`` inertia about the centre of mass, FRD body axes [kg m^2]
            (a length-3 sequence means a diagonal).
        allocation: ``(4, n)`` map from rotor thrusts [N] to ``[T; Mx; My; Mz]`` [N, N m].
        gravity: gravitational acceleration [m/s^2] (9.8 as in the reference code).
        max_thrust: per-rotor thrust limit [N]; ``None`` means ``thrust_to_weight * m g / n``;
            ``math.inf`` disables saturation.
        thrust_to_weight: used only when ``max_thrust`` is ``None`` (default 2).
        name: free text.
    """

    mass: float = PAPER_MASS
    inertia: np.ndarray = field(default_factory=lambda: np.diag(PAPER_INERTIA))
    allocation: np.ndarray = field(default_factory=paper_allocation)
    gravity: float = PAPER_GRAVITY
    max_thrust: float | None = None
    thrust_to_weight: float = 2.0
    name: str = "F450 (paper)"

    def __post_init__(self):
        for key in ("mass", "gravity", "thrust_to_weight"):
            value = getattr(self, key)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ConfigError(f"vehicle {key} must be a number, got {value!r}") from None
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"vehicle {key} must be positive and finite, got {value!r}")
            object.__setattr__(self, key, value)
        inertia = np.asarray(self.inertia, dtype=float)
        if inertia.shape == (3,):
            inertia = np.diag(inertia)
        inertia = _frozen_array(inertia, (3, 3), "inertia")
        if not np.allclose(inertia, inertia.T, rtol=1e-9, atol=1e-12):
            raise ConfigError("vehicle inertia must be symmetric")
        if np.min(np.linalg.eigvalsh(inertia)) <= 0:
            raise ConfigError("vehicle inertia must be positive definite")
        alloc = _frozen_array(self.allocation, None, "allocation")
        if alloc.ndim != 2 or alloc.shape[0] != 4 or alloc.shape[1] < 4:
            raise ConfigError(f"vehicle allocation must have shape (4, n>=4), got {alloc.shape}")
        if np.linalg.matrix_rank(alloc) < 4:
            raise ConfigError(
                "vehicle allocation is singular (rank < 4): the rotors cannot "
                "produce independent thrust, roll, pitch and yaw"
            )
        if self.max_thrust is not None and not (self.max_thrust > 0):
            raise ConfigError(f"max_thrust must be positive [N], got {self.max_thrust!r}")
        object.__setattr__(self, "inertia", inertia)
        object.__setattr__(self, "allocation", alloc)
        inv = np.linalg.pinv(alloc)
        inv.setflags(write=False)
        object.__setattr__(self, "_allocation_inverse", inv)
        jinv = np.linalg.inv(inertia)
        jinv.setflags(write=False)
        object.__setattr__(self, "_inertia_inverse", jinv)

    # constructors ------------------------------------------------------------------------
    @classmethod
    def from_arm(cls, arm: float, torque_coefficient: float, **kwargs) -> Vehicle:
        """The paper's layout (eq. 12) with per-axis rotor offset ``arm`` = d [m]."""
        if not (arm > 0 and torque_coefficient > 0):
            raise ConfigError("arm and torque_coefficient must be positive")
        return cls(allocation=paper_allocation(arm, torque_coefficient), **kwargs)

    @classmethod
    def from_rotors(cls, positions, yaw_signs, torque_coefficient: float, **kwargs) -> Vehicle:
        """Any layout from rotor positions [m] and yaw-torque signs (see
        :func:`allocation_from_rotors`)."""
        return cls(
            allocation=allocation_from_rotors(positions, yaw_signs, torque_coefficient), **kwargs
        )

    def replace(self, **changes) -> Vehicle:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    # derived values ----------------------------------------------------------------------
    @property
    def n_rotors(self) -> int:
        return self.allocation.shape[1]

    @property
    def allocation_inverse(self) -> np.ndarray:
        """``(n, 4)`` (pseudo-)inverse of the allocation: wrench -> rotor thrusts."""
        return self._allocation_inverse  # type: ignore[attr-defined]

    @property
    def inertia_inverse(self) -> np.ndarray:
        return self._inertia_inverse  # type: ignore[attr-defined]

    @property
    def weight(self) -> float:
        """m g [N]."""
        return self.mass * self.gravity

    @property
    def hover_thrust(self) -> float:
        """Per-rotor thrust at hover [N] (equal split)."""
        return self.weight / self.n_rotors

    @property
    def rotor_max_thrust(self) -> float:
        """Per-rotor saturation limit f_max [N] (4.9 N for the paper's vehicle)."""
        if self.max_thrust is not None:
            return float(self.max_thrust)
        return self.thrust_to_weight * self.weight / self.n_rotors

    def wrench(self, rotor_thrust: np.ndarray) -> np.ndarray:
        """``(..., n) -> (..., 4)``: ``[T, Mx, My, Mz]`` for rotor thrusts [N]."""
        return np.asarray(rotor_thrust, dtype=float) @ self.allocation.T

    def rotor_thrust(self, wrench: np.ndarray) -> np.ndarray:
        """``(..., 4) -> (..., n)``: rotor thrusts realising a wrench (least-norm)."""
        return np.asarray(wrench, dtype=float) @ self.allocation_inverse.T

    def to_dict(self) -> dict:
        """JSON-ready description (the recording sidecar's ``vehicle``)."""
        out = {
            "mass": self.mass,
            "inertia": self.inertia.tolist(),
            "allocation": self.allocation.tolist(),
            "gravity": self.gravity,
        }
        if math.isfinite(self.rotor_max_thrust):
            out["max_thrust"] = self.rotor_max_thrust
        return out

    def __eq__(self, other) -> bool:
        if not isinstance(other, Vehicle):
            return NotImplemented
        return (
            self.mass == other.mass
            and self.gravity == other.gravity
            and np.array_equal(self.inertia, other.inertia)
            and np.array_equal(self.allocation, other.allocation)
            and self.rotor_max_thrust == other.rotor_max_thrust
        )

    def __hash__(self):
        return hash((self.mass, self.gravity, self.inertia.tobytes(), self.allocation.tobytes()))
