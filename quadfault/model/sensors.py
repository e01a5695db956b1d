"""Sensors: white measurement noise on the state and the accelerometer.

Per physics step the loop measures the true state -- position, velocity, attitude (a
rotation-vector perturbation ``R exp([std z]x)``), body rate -- and, after the plant step,
the accelerometer (the specific force at the step's start, body FRD). The standard normals
come from the caller's generator in this order: ``p`` (3), ``v`` (3), attitude (3, only when
its std is non-zero), ``w`` (3) -- all of them whenever any std is non-zero -- and then,
after the motors' draws, the accelerometer (3, when its std is non-zero).

:func:`measure3` and :func:`accelerometer3` are the kernels; :meth:`SensorNoise.measure` runs
them on one state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.rotation import expm3, mat3, matmul3, store3, store33, vec3


@dataclass(frozen=True)
class SensorNoise:
    """Standard deviations of white measurement noise (all zero by default, as in the paper).

    Attributes:
        position [m], velocity [m/s], attitude [rad] (rotation-vector noise), gyro [rad/s],
        accel [m/s^2].
    """

    position: float = 0.0
    velocity: float = 0.0
    attitude: float = 0.0
    gyro: float = 0.0
    accel: float = 0.0

    def __post_init__(self):
        for k in ("position", "velocity", "attitude", "gyro", "accel"):
            v = getattr(self, k)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"sensor noise {k} must be >= 0, got {v!r}")

    @property
    def any(self) -> bool:
        return any((self.position, self.velocity, self.attitude, self.gyro, self.accel))

    @property
    def constants(self) -> tuple:
        """The kernels' form: ``(position, velocity, attitude, gyro, accel, any)``."""
        return (
            float(self.position),
            float(self.velocity),
            float(self.attitude),
            float(self.gyro),
            float(self.accel),
            bool(self.any),
        )

    def measure(self, state, specific_force, rng: np.random.Generator):
        """Noisy copy of one ``state`` (a ``RigidBodyState``) and of the accelerometer
        reading ``specific_force`` (None: not measured), drawn from ``rng``."""
        out = (np.empty(3), np.empty(3), np.empty((3, 3)), np.empty(3))
        _measure_one(*(np.asarray(x, dtype=float) for x in state), self.constants, rng, *out)
        sf = None
        if specific_force is not None:
            sf = np.array(
                _accelerometer_one(np.asarray(specific_force, dtype=float), self.constants, rng)
            )
        return RigidBodyState(*out), sf


@jit(inner=True)
def _normal3(std, gen):
    """``std z`` with three standard normals drawn in component order."""
    a = std * gen.standard_normal()
    b = std * gen.standard_normal()
    c = std * gen.standard_normal()
    return (a, b, c)


@jit(inner=True)
def _noisy3(x, std, gen):
    """``x + std z`` with three standard normals drawn in component order."""
    a = x[0] + std * gen.standard_normal()
    b = x[1] + std * gen.standard_normal()
    c = x[2] + std * gen.standard_normal()
    return (a, b, c)


@jit(inner=True)
def measure3(p, v, R, w, noise, gen):
    """The measured state ``(p, v, R, w)`` (tuples; see the module docstring for the draws)
    with ``noise`` = :attr:`SensorNoise.constants`."""
    if not noise[5]:
        return p, v, R, w
    pm = _noisy3(p, noise[0], gen)
    vm = _noisy3(v, noise[1], gen)
    Rm = R
    if noise[2] != 0.0:
        Rm = matmul3(R, expm3(_normal3(noise[2], gen)))
    wm = _noisy3(w, noise[3], gen)
    return pm, vm, Rm, wm


@jit(inner=True)
def accelerometer3(sf, noise, gen):
    """The accelerometer reading of the specific force ``sf`` [m/s^2] (body FRD)."""
    if noise[4] == 0.0:
        return sf
    return _noisy3(sf, noise[4], gen)


@jit
def _measure_one(p, v, R, w, noise, gen, out_p, out_v, out_R, out_w):
    pm, vm, Rm, wm = measure3(vec3(p), vec3(v), mat3(R), vec3(w), noise, gen)
    store3(out_p, pm)
    store3(out_v, vm)
    store33(out_R, Rm)
    store3(out_w, wm)


@jit
def _accelerometer_one(sf, noise, gen):
    return accelerometer3(vec3(sf), noise, gen)
