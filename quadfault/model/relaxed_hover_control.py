"""Flying on three rotors: reduced-attitude control about the relaxed hover, and the switch to
it when the efficiency estimate isolates a dead rotor.

:class:`RelaxedHoverController` follows the construction of Mueller & D'Andrea (ICRA 2014),
written here from the model: the vehicle spins about a body-fixed axis ``nbar`` (the relaxed
hover of :mod:`quadfault.model.relaxed_hover`), and it moves by tilting that axis.

* Position (outer loop): the desired acceleration ``a = a_ref + k_p (p_ref - p) + k_d
  (v_ref - v)`` (horizontal part bounded) asks for the specific force ``a - g e_3``; its
  direction ``u`` (world) is where the spin axis must point, its size sets the collective
  thrust ``T = m |a - g e_3| / cos(angle between u and the thrust axis)``.
* Reduced attitude (inner loop): in body coordinates ``u`` turns as ``du/dt = -w x u``; the
  state ``x = (u_x - nbar_x, u_y - nbar_y, w - wbar)`` is regulated by a discrete LQR on
  the linearisation of :func:`~quadfault.model.relaxed_hover.linearised` (constant in the
  body frame: the periodic solution is an equilibrium there), held over the control period.
  Its inputs are the three rotors' thrust changes that keep their sum; the collective
  change goes along the one thrust direction that leaves roll and pitch alone.

The controller knows the nominal vehicle and the spin physics it was designed with
(:class:`~quadfault.model.relaxed_hover.SpinPhysics`); which rotor is gone comes from the
estimate through :class:`RotorLossDetector`, never from the plant.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import expm, solve_discrete_are

from quadfault.errors import ConfigError
from quadfault.model.relaxed_hover import (
    DEFAULT_RHO,
    RelaxedHover,
    SpinPhysics,
    linearised,
    relaxed_hover,
    rotor_roles,
)
from quadfault.model.vehicle import Vehicle


@dataclass(frozen=True)
class RelaxedHoverGains:
    """Gains of :class:`RelaxedHoverController`.

    Attributes:
        kp: position gain [1/s^2]. kd: velocity gain [1/s]. The defaults come from a sweep
            on the complete-loss vehicle (``benchmarks/rotor_loss_survival.py``,
            docs/rotor_loss.md): every neighbour of (4, 3) within 0.5 holds the hover point.
        max_horizontal: bound of the horizontal acceleration asked for [m/s^2].
        q_axis: LQR weight of the spin axis' error [-]. q_rate: of the body rate's [s^2].
        r_thrust: of the thrust changes [1/N^2].
        rho: the opposite rotor's thrust over the neighbours' at the solution flown.
    """

    kp: float = 4.0
    kd: float = 3.0
    max_horizontal: float = 4.0
    q_axis: float = 400.0
    q_rate: float = 2.0
    r_thrust: float = 1.0
    rho: float = DEFAULT_RHO

    def __post_init__(self):
        for key in ("kp", "kd", "max_horizontal", "q_axis", "q_rate", "r_thrust"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"RelaxedHoverGains.{key} must be positive, got {v!r}")


def _dlqr(A, B, Q, R, period):
    """Discrete LQR gain of the continuous ``(A, B)`` held over ``period`` (zero-order
    hold)."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A, B
    E = expm(M * period)
    Ad, Bd = E[:n, :n], E[:n, n:]
    P = solve_discrete_are(Ad, Bd, Q, R)
    return np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)


#: the spin-up schedule: fractions of the solution's yaw rate with their own gains
SPIN_UP = (0.1, 0.25, 0.4, 0.55, 0.7, 0.85, 1.0)


def _solution_at(vehicle, physics, lost, rho, yaw_rate) -> RelaxedHover:
    """The relaxed hover of ``physics`` with the yaw damping that makes it spin at
    ``yaw_rate`` [rad/s] (the quasi-steady state of a spin-up)."""
    gamma = physics.linear[2]
    h = relaxed_hover(vehicle, physics, lost, rho)
    for _ in range(4):
        gamma *= abs(h.yaw_rate) / yaw_rate
        ph = replace(physics, linear=(physics.linear[0], physics.linear[1], gamma))
        h = relaxed_hover(vehicle, ph, lost, rho)
    return h


class RelaxedHoverController:
    """Position control on three rotors about the relaxed hover (see the module docstring).

    Args:
        vehicle: the nominal vehicle.
        lost: the lost rotor (0-based).
        physics: the spin physics the controller is designed with.
        period: the control period [s] (the commands are held over it).
        gains: :class:`RelaxedHoverGains`.
    """

    def __init__(
        self,
        vehicle: Vehicle,
        lost: int,
        physics: SpinPhysics | None = None,
        period: float = 1e-3,
        gains: RelaxedHoverGains | None = None,
    ):
        if not (math.isfinite(period) and period > 0):
            raise ConfigError(f"control period must be positive [s], got {period!r}")
        self.vehicle, self.lost = vehicle, int(lost)
        self.physics = physics or SpinPhysics()
        self.gains = gains or RelaxedHoverGains()
        self.hover: RelaxedHover = relaxed_hover(vehicle, self.physics, lost, self.gains.rho)
        a, b, o = rotor_roles(vehicle, lost)
        self.rotors = np.array([a, b, o])
        # thrust changes that keep the sum (2 inputs) and the collective direction
        self.N = np.array([[1.0, -1.0, 0.0], [1.0, 1.0, -2.0]]).T / np.array(
            [math.sqrt(2.0), math.sqrt(6.0)]
        )
        c = np.linalg.svd(vehicle.allocation[1:3][:, self.rotors])[2][-1]  # no roll, pitch
        self.collective = c / c.sum()
        g = self.gains
        Q = np.diag([g.q_axis, g.q_axis, g.q_rate, g.q_rate, g.q_rate])
        # gain schedule over the spin-up: solutions at lower yaw rates (a virtual yaw
        # damping), the opposite rotor's share rising from 0 with the spin
        r_bar = abs(self.hover.yaw_rate)
        self.schedule = []
        for frac in SPIN_UP:
            h = self.hover
            if frac < 1.0:
                rho = g.rho * min(1.0, max(0.0, (frac - 0.4) / 0.6))
                h = _solution_at(vehicle, self.physics, lost, rho, frac * r_bar)
            A, B = linearised(vehicle, self.physics, h)
            K = _dlqr(A, B[:, self.rotors] @ self.N, Q, g.r_thrust * np.eye(2), float(period))
            self.schedule.append((abs(h.yaw_rate), h, K))

    def command(self, p, v, R, w, p_ref, v_ref=None, a_ref=None) -> np.ndarray:
        """Rotor thrust commands [N] (the lost rotor's 0) for the measured state and the
        reference position, velocity and acceleration (NED)."""
        veh, g = self.vehicle, self.gains
        v_ref = np.zeros(3) if v_ref is None else v_ref
        a = (
            (0.0 if a_ref is None else np.asarray(a_ref, float))
            + g.kp * (np.asarray(p_ref, float) - p)
            + g.kd * (v_ref - np.asarray(v, float))
        )
        h = math.hypot(a[0], a[1])
        if h > g.max_horizontal:
            a[:2] *= g.max_horizontal / h
        F = a - np.array([0.0, 0.0, veh.gravity])  # specific force asked for (world)
        size = float(np.linalg.norm(F))
        u_body = R.T @ (F / size)
        # the spin axis carries m |F| when it points along u (the thrust axis is tilted from
        # it by the solution's tilt)
        r = abs(float(w[2]))
        _, h, K = next((e for e in self.schedule if e[0] >= r), self.schedule[-1])
        align = max(0.2, float(u_body @ h.n))  # a misaligned axis gets less, not more
        T = veh.mass * size * align / -float(h.n[2])
        x = np.concatenate((u_body[:2] - h.n[:2], np.asarray(w, float) - h.w))
        x[4] = 0.0  # the spin rate follows the yaw torques: not regulated
        df = self.N @ (-K @ x) + self.collective * (T - float(np.sum(h.f)))
        f0 = h.f
        f = np.zeros(veh.n_rotors)
        f[self.rotors] = f0[self.rotors] + df
        return np.clip(f, 0.0, veh.rotor_max_thrust)


@functools.lru_cache(maxsize=64)
def relaxed_hover_controller(
    vehicle: Vehicle,
    lost: int,
    physics: SpinPhysics | None = None,
    period: float = 1e-3,
    gains: RelaxedHoverGains | None = None,
) -> RelaxedHoverController:
    """The :class:`RelaxedHoverController` of these arguments, built once (its gains come
    from Riccati equations; it holds no state between commands)."""
    return RelaxedHoverController(vehicle, int(lost), physics, float(period), gains)


#: the detector's hold with noisy sensors [s]: a noisy estimate dips below the threshold
#: for a few milliseconds before any loss (measured: ``benchmarks/rotor_loss_survival.py
#: --sensor-noise px4``, docs/results.md)
NOISY_HOLD = 0.05


@dataclass(frozen=True)
class RotorLossDetector:
    """When the estimate says a rotor is gone: one rotor's efficiency estimate below
    ``threshold`` while every other rotor's is at least ``others`` (isolated), in every
    estimate for ``hold`` seconds. A detection latches (a lost rotor does not come back).

    Attributes:
        threshold: efficiency below which a rotor counts as lost [-].
        others: least efficiency of every other rotor [-].
        hold: how long the estimates must agree [s] (0: the first isolating estimate).
            The default suits noise-free sensors; :meth:`for_sensors` chooses it for the
            sensors flown.
    """

    threshold: float = 0.15
    others: float = 0.5
    hold: float = 0.004

    def __post_init__(self):
        if not (0.0 < self.threshold < self.others <= 1.5):
            raise ConfigError(
                f"need 0 < threshold < others <= 1.5, got {self.threshold!r}, {self.others!r}"
            )
        if not (math.isfinite(self.hold) and self.hold >= 0):
            raise ConfigError(f"hold must be >= 0 [s], got {self.hold!r}")

    @classmethod
    def for_sensors(cls, sensor_noise) -> RotorLossDetector:
        """The default detector for ``sensor_noise`` (a
        :class:`~quadfault.model.sensors.SensorNoise`): a hold of :data:`NOISY_HOLD` when the
        sensors have any noise, else the default's."""
        return cls(hold=NOISY_HOLD) if sensor_noise is not None and sensor_noise.any else cls()

    def candidate(self, eta_hat) -> int:
        """The rotor the estimate isolates below the threshold now, or -1."""
        eta = np.asarray(eta_hat, dtype=float)
        if not np.all(np.isfinite(eta)):
            return -1
        k = int(np.argmin(eta))
        rest = np.delete(eta, k)
        return k if eta[k] < self.threshold and np.min(rest) >= self.others else -1


class RotorLossSwitch:
    """The detector's state over a flight: feed it each estimate (:meth:`update`); once a
    rotor has been isolated by every estimate for ``hold`` seconds, :attr:`lost` names it
    (latched) and
    :attr:`first_seen` / :attr:`switched` give the times [s] of the first isolating
    estimate of that run and of the switch."""

    def __init__(self, detector: RotorLossDetector | None = None):
        self.detector = detector or RotorLossDetector()
        self.reset()

    def reset(self) -> None:
        self.lost, self.candidate_rotor = -1, -1
        self.first_seen = self.switched = None

    def update(self, eta_hat, t: float) -> int:
        """The lost rotor (-1: none yet) after the estimate ``eta_hat`` at time ``t`` [s]."""
        if self.lost >= 0:
            return self.lost
        k = self.detector.candidate(eta_hat)
        if k != self.candidate_rotor:
            self.candidate_rotor = k
            self.first_seen = None if k < 0 else float(t)
        if k >= 0 and float(t) - self.first_seen >= self.detector.hold - 1e-12:
            self.lost, self.switched = k, float(t)
        return self.lost
