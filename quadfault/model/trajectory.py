"""Reference trajectories (flat outputs: position, its derivatives, heading).

All positions are world NED [m]; ``altitude`` is height above the origin (z = -altitude).
A trajectory is a callable ``t -> FlatOutput``; ``t`` may be a scalar or an array.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np

from quadfault.errors import ConfigError


class FlatOutput(NamedTuple):
    """Desired position [m], velocity [m/s], acceleration [m/s^2] and heading b1d."""

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    b1d: np.ndarray


class Trajectory(Protocol):
    def __call__(self, t) -> FlatOutput: ...


def _heading(yaw) -> np.ndarray:
    yaw = np.asarray(yaw, dtype=float)
    return np.stack((np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)), axis=-1)


@dataclass(frozen=True)
class Circle:
    """The paper's circle: radius 3 m at 0.1 Hz, 1 m altitude, heading turning at 0.05 Hz.

    ``x_d = (r cos wt, r sin wt, -h)``, ``b1d = (cos psi, sin psi, 0)`` with
    ``psi = 2 pi f_yaw (t - yaw_start)`` (the reference code starts its heading ramp at its
    first sample, t = dt).
    """

    radius: float = 3.0
    frequency: float = 0.1  # [Hz]
    altitude: float = 1.0  # [m]
    yaw_frequency: float = 0.05  # [Hz]
    yaw_start: float = 0.0  # [s]
    center: tuple = (0.0, 0.0)

    def __call__(self, t) -> FlatOutput:
        t = np.asarray(t, dtype=float)
        w = 2 * math.pi * self.frequency
        c, s = np.cos(w * t), np.sin(w * t)
        r, z = self.radius, np.zeros_like(t)
        pos = np.stack((self.center[0] + r * c, self.center[1] + r * s, z - self.altitude), -1)
        vel = np.stack((-r * w * s, r * w * c, z), -1)
        acc = np.stack((-r * w * w * c, -r * w * w * s, z), -1)
        yaw = 2 * math.pi * self.yaw_frequency * (t - self.yaw_start)
        return FlatOutput(pos, vel, acc, _heading(yaw))


@dataclass(frozen=True)
class Hover:
    """Hold a set-point [m] (NED) with fixed heading ``yaw`` [rad]."""

    position: tuple = (0.0, 0.0, -1.0)
    yaw: float = 0.0

    def __call__(self, t) -> FlatOutput:
        t = np.asarray(t, dtype=float)
        pos = np.broadcast_to(np.asarray(self.position, dtype=float), t.shape + (3,)).copy()
        zero = np.zeros(t.shape + (3,))
        return FlatOutput(pos, zero, zero.copy(), _heading(np.full(t.shape, self.yaw)))


@dataclass(frozen=True)
class Lissajous:
    """A figure-eight-like Lissajous curve that excites all three axes.

    ``x = A_x sin(w t), y = A_y sin(2 w t), z = -h + A_z sin(3 w t)``; heading follows
    ``yaw_rate`` [rad/s].
    """

    amplitude: tuple = (1.5, 1.0, 0.2)
    frequency: float = 0.1  # [Hz]
    altitude: float = 1.0  # [m]
    yaw_rate: float = 0.0  # [rad/s]

    def __call__(self, t) -> FlatOutput:
        t = np.asarray(t, dtype=float)
        w = 2 * math.pi * self.frequency
        ax, ay, az = self.amplitude
        k = np.array([1.0, 2.0, 3.0])
        A = np.array([ax, ay, az])
        ph = t[..., None] * w * k
        pos = A * np.sin(ph) + np.array([0.0, 0.0, -self.altitude])
        vel = A * w * k * np.cos(ph)
        acc = -A * (w * k) ** 2 * np.sin(ph)
        return FlatOutput(pos, vel, acc, _heading(self.yaw_rate * t))


@dataclass(frozen=True)
class SmoothTrack:
    """``p_i(t) = center_i + amplitude_i (1 - cos(omega_i t))`` per axis (NED, signed
    amplitudes [m], angular frequencies [rad/s]), heading ``yaw0 + yaw_rate t`` [rad].

    Starts at rest at ``center``; smooth (every derivative is bounded); position, velocity
    and acceleration are exact derivatives of each other (the controller's feed-forward).
    """

    center: tuple = (0.0, 0.0, -1.0)
    amplitude: tuple = (1.0, 1.0, 0.0)
    omega: tuple = (0.5, 0.5, 0.0)
    yaw0: float = 0.0
    yaw_rate: float = 0.0

    def __post_init__(self):
        for key in ("center", "amplitude", "omega"):
            v = tuple(float(x) for x in getattr(self, key))
            if len(v) != 3 or not all(math.isfinite(x) for x in v):
                raise ConfigError(
                    f"SmoothTrack {key} must be 3 finite numbers, got {getattr(self, key)!r}"
                )
            object.__setattr__(self, key, v)
        if any(w < 0 for w in self.omega):
            raise ConfigError(f"SmoothTrack omega must be >= 0 [rad/s], got {self.omega!r}")

    def __call__(self, t) -> FlatOutput:
        t = np.asarray(t, dtype=float)
        A, w, c = (np.asarray(x) for x in (self.amplitude, self.omega, self.center))
        ph = t[..., None] * w
        pos = c + A * (1.0 - np.cos(ph))
        vel = A * w * np.sin(ph)
        acc = A * w * w * np.cos(ph)
        return FlatOutput(pos, vel, acc, _heading(self.yaw0 + self.yaw_rate * t))
