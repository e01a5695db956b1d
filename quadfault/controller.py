"""Geometric tracking controller on SE(3) (Lee, Leok, McClamroch 2010; paper eqs. 5-10).

NED world, FRD body: the thrust acts along ``-b3`` so the desired body z-axis is
``b3d = f_n / |f_n|`` with ``f_n = k_x e_x + k_v e_v + m g e3 - m a_d`` and the collective
thrust is ``T = f_n . R e3`` (eq. 9). The moment is eq. (10).

The controller knows only the *nominal* vehicle. Options reproduce the reference code:
``acceleration_feedforward=False`` (its a_d = 0), ``angular_feedforward=False`` (its
Omega_d = 0) and ``normalize_b2d=False`` (its un-normalised b2d).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from quadfault.rotation import cross, hat, vee
from quadfault.trajectory import FlatOutput, Trajectory
from quadfault.vehicle import Vehicle

E3 = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class GeometricGains:
    """Diagonal gains of eqs. (9)-(10); the paper's Table I by default."""

    kx: tuple = (9.0, 9.0, 12.0)
    kv: tuple = (7.0, 7.0, 12.0)
    kR: tuple = (10.0, 10.0, 10.0)
    kW: tuple = (2.0, 2.0, 2.0)


@dataclass(frozen=True)
class ControllerConfig:
    """Geometric controller options.

    Attributes:
        gains: the diagonal gains.
        acceleration_feedforward: use the reference acceleration a_d in eq. (9).
        angular_feedforward: use Omega_d and Omega_d' of the feed-forward attitude (computed by
            central differences of the trajectory's desired attitude, step ``ff_step`` [s]).
        normalize_b2d: normalise ``b2d = b3d x b1d`` (Lee et al.); the reference code does not.
    """

    gains: GeometricGains = field(default_factory=GeometricGains)
    acceleration_feedforward: bool = True
    angular_feedforward: bool = True
    normalize_b2d: bool = True
    ff_step: float = 1e-3

    @classmethod
    def reference(cls) -> "ControllerConfig":
        """The authors' MATLAB controller: a_d = 0, Omega_d = 0, b2d not normalised."""
        return cls(acceleration_feedforward=False, angular_feedforward=False, normalize_b2d=False)


class ControlOutput(NamedTuple):
    thrust: np.ndarray  # collective thrust T [N]
    moment: np.ndarray  # body moment M [N m]
    position_error: np.ndarray  # e_x [m]
    velocity_error: np.ndarray  # e_v [m/s]
    attitude_error: np.ndarray  # e_R
    rate_error: np.ndarray  # e_Omega [rad/s]
    Rd: np.ndarray  # desired attitude


class GeometricController:
    """The SE(3) tracking controller; works on a leading batch axis too.

    Args:
        vehicle: the nominal vehicle (mass, inertia, allocation).
        trajectory: reference trajectory ``t -> FlatOutput``.
        config: options and gains.
    """

    def __init__(self, vehicle: Vehicle, trajectory: Trajectory,
                 config: ControllerConfig | None = None):
        self.vehicle = vehicle
        self.trajectory = trajectory
        self.config = config or ControllerConfig()
        g = self.config.gains
        self.kx, self.kv = np.asarray(g.kx, float), np.asarray(g.kv, float)
        self.kR, self.kW = np.asarray(g.kR, float), np.asarray(g.kW, float)

    def _desired_attitude(self, f_n: np.ndarray, b1d: np.ndarray) -> np.ndarray:
        b3d = f_n / np.linalg.norm(f_n, axis=-1, keepdims=True)
        b2d = cross(b3d, b1d)
        if self.config.normalize_b2d:
            b2d = b2d / np.linalg.norm(b2d, axis=-1, keepdims=True)
        b1 = cross(b2d, b3d)
        return np.stack((b1, b2d, b3d), axis=-1)

    def feedforward_rates(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Omega_d [rad/s] and Omega_d' [rad/s^2] of the feed-forward attitude at ``t``."""
        h = self.config.ff_step
        t = np.asarray(t, dtype=float)
        ts = np.stack((t - h, t, t + h), axis=-1)
        ref = self.trajectory(ts)
        m, g = self.vehicle.mass, self.vehicle.gravity
        acc = ref.acceleration if self.config.acceleration_feedforward else 0.0 * ref.acceleration
        Rd = self._desired_attitude(m * g * E3 - m * acc, ref.b1d)
        R0T = np.swapaxes(Rd[..., 1, :, :], -1, -2)
        w_d = vee(R0T @ (Rd[..., 2, :, :] - Rd[..., 0, :, :])) / (2 * h)
        w_dot_d = vee(R0T @ (Rd[..., 2, :, :] - 2 * Rd[..., 1, :, :] + Rd[..., 0, :, :])) / (h * h)
        return w_d, w_dot_d

    def compute(self, t, p, v, R, w, reference: FlatOutput | None = None,
                feedforward: tuple | None = None) -> ControlOutput:
        """Thrust and moment (eqs. 9, 10) for the measured state at time ``t`` [s].

        ``reference`` and ``feedforward`` (Omega_d, Omega_d') may be passed precomputed (the
        simulator evaluates them for all times at once); otherwise they are computed here.
        """
        veh = self.vehicle
        ref = self.trajectory(t) if reference is None else reference
        ex = p - ref.position
        ev = v - ref.velocity
        f_n = self.kx * ex + self.kv * ev + veh.mass * veh.gravity * E3
        if self.config.acceleration_feedforward:
            f_n = f_n - veh.mass * ref.acceleration
        Rd = self._desired_attitude(f_n, ref.b1d)
        thrust = np.einsum("...i,...i->...", f_n, R[..., :, 2])
        RT = np.swapaxes(R, -1, -2)
        eR = 0.5 * vee(np.swapaxes(Rd, -1, -2) @ R - RT @ Rd)
        J = veh.inertia
        Jw = w @ J.T
        if self.config.angular_feedforward:
            w_d, w_dot_d = self.feedforward_rates(t) if feedforward is None else feedforward
            RtRd = RT @ Rd
            w_d_body = np.einsum("...ij,...j->...i", RtRd, w_d)
            eW = w - w_d_body
            ff = cross(w, Jw) - (cross(w, w_d_body)
                                 - np.einsum("...ij,...j->...i", RtRd, w_dot_d)) @ J.T
        else:
            eW = w
            ff = cross(w, Jw)
        M = -self.kR * eR - self.kW * eW + ff
        return ControlOutput(thrust, M, ex, ev, eR, eW, Rd)

    def motor_commands(self, t, p, v, R, w, reference: FlatOutput | None = None,
                       feedforward: tuple | None = None) -> tuple[np.ndarray, ControlOutput]:
        """Rotor thrust commands [N] through the nominal allocation inverse, and the details."""
        out = self.compute(t, p, v, R, w, reference, feedforward)
        wrench = np.concatenate((np.asarray(out.thrust)[..., None], out.moment), axis=-1)
        return self.vehicle.rotor_thrust(wrench), out


__all__ = ["GeometricGains", "ControllerConfig", "GeometricController", "ControlOutput", "hat"]
