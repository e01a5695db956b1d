"""Controllers for the closed loop: the plain geometric baseline and the estimate-aware one.

Both wrap :class:`quadfault.model.controller.GeometricController` (paper eqs. 9-10) on the
*nominal* vehicle and differ only in how the desired wrench becomes rotor commands:

* :class:`GeometricBaseline` -- the nominal allocation inverse (eq. 12), ``f = A^-1 w``,
  clipped to the rotor limits ``[0, f_max]``; it ignores ``eta_hat``.
* :class:`EstimateAwareController` -- the estimate-aware allocation of
  :mod:`quadfault.model.allocation`: ``A diag(eta_hat) f = w`` within ``[0, f_max]``, yaw given up
  first. Optionally (``max_heading_error``, off by default) the controller bounds the
  heading error it asks for: the desired heading ``b1d`` becomes the current heading turned
  toward the reference one by at most that angle. The motivation: when a weak motor forces
  the vehicle to spin, the heading error sweeps through 180 degrees, where the geometric
  attitude error loses its roll/pitch part (``e_R`` of eq. 10 vanishes for ``R = R_d R_z(pi)
  R_x(eps)``). Measured, the spin is fast enough to pass through that point harmlessly (a
  30 s flight with one motor at eta = 0.3 keeps millimetre tracking while spinning up to
  35 rad/s), and a 30 degree bound *raises* the circle's RMSE from 2.6 mm to 11 mm, so it is
  off by default.

* :class:`RelaxedHoverFallback` -- the estimate-aware controller until the estimate isolates
  one rotor below a threshold (:class:`~quadfault.model.relaxed_hover_control.RotorLossDetector`),
  then the relaxed-hover controller of
  :mod:`quadfault.model.relaxed_hover_control` on the three remaining rotors (the vehicle
  spins about a tilted axis and holds its position; the switch latches).

``eta_hat`` always comes from an estimator (or the explicitly labelled oracle of
:func:`agents.rollout.fly`); these classes never see the plant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.allocation import EXACT, AllocationConfig, EstimateAwareAllocator
from quadfault.model.controller import ControllerConfig, ControlOutput, GeometricController
from quadfault.model.relaxed_hover import SpinPhysics
from quadfault.model.relaxed_hover_control import (
    RelaxedHoverGains,
    RotorLossDetector,
    RotorLossSwitch,
    relaxed_hover_controller,
)
from quadfault.model.trajectory import FlatOutput, Trajectory
from quadfault.model.vehicle import Vehicle


class ControlStep(NamedTuple):
    f: np.ndarray  # rotor thrust commands [N], within [0, f_max]
    out: ControlOutput  # the geometric controller's details (errors, R_d)
    mode: str  # allocation mode (quadfault.model.allocation.MODES)
    heading_clamped: bool  # True when the desired heading was bounded


@dataclass(frozen=True)
class FaultTolerantConfig:
    """Options of :class:`EstimateAwareController`.

    Attributes:
        allocation: the estimate-aware allocation (eta floor, priority weights).
        max_heading_error: largest heading error the controller asks to correct [rad]
            (``None``: unbounded, the plain geometric behaviour).
        detector: when :class:`RelaxedHoverFallback` switches (the estimate isolates a rotor);
            None: chosen for the sensors flown (``RotorLossDetector.for_sensors``; the
            noise-free default where they are not known).
        spin_physics: the spin physics the relaxed-hover controller is designed with (the
            complete-loss vehicle's by default).
        relaxed_gains: the relaxed-hover controller's gains.
    """

    allocation: AllocationConfig = field(default_factory=AllocationConfig)
    max_heading_error: float | None = None
    detector: RotorLossDetector | None = None
    spin_physics: SpinPhysics = field(default_factory=SpinPhysics)
    relaxed_gains: RelaxedHoverGains = field(default_factory=RelaxedHoverGains)

    def __post_init__(self):
        h = self.max_heading_error
        if h is not None and not (math.isfinite(h) and 0 < h <= math.pi):
            raise ConfigError(f"max_heading_error must be in (0, pi] [rad], got {h!r}")


def _wrench(out: ControlOutput) -> np.ndarray:
    return np.concatenate((np.atleast_1d(out.thrust), out.moment))


def bounded_heading(R, b1d, max_error: float):
    """``b1d`` turned toward the current heading (body x projected on the horizontal) so
    that the heading error is at most ``max_error`` [rad]; ``b1d`` itself when it already is
    (or when the body x-axis is near vertical)."""
    cx, cy = R[0, 0], R[1, 0]
    if cx * cx + cy * cy < 0.01:
        return b1d
    psi = math.atan2(cy, cx)
    err = math.remainder(math.atan2(b1d[1], b1d[0]) - psi, 2 * math.pi)
    if abs(err) <= max_error:
        return b1d
    psi_d = psi + math.copysign(max_error, err)
    return np.array([math.cos(psi_d), math.sin(psi_d), 0.0])


class GeometricWrenchController:
    """What both controllers share: the geometric controller (eqs. 9-10) on the *nominal*
    vehicle computes the desired wrench ``w = (T, M)``; a subclass turns it into rotor
    commands (:meth:`_allocate`) and may adjust the reference first (:meth:`_reference`).

    Args:
        vehicle: the nominal vehicle.
        trajectory: the reference.
        config: geometric controller options (gains, feed-forward).
    """

    name = "geometric-wrench"

    def __init__(
        self, vehicle: Vehicle, trajectory: Trajectory, config: ControllerConfig | None = None
    ):
        self.vehicle = vehicle
        self.geometric = GeometricController(vehicle, trajectory, config)

    @property
    def trajectory(self) -> Trajectory:
        return self.geometric.trajectory

    def reset(self) -> None:
        """No internal state."""

    def _reference(self, t, R, reference: FlatOutput | None):
        """``(reference, clamped)``: the reference the geometric controller tracks (``None``:
        the trajectory's) and whether it was changed."""
        return reference, False

    def _allocate(self, wrench: np.ndarray, eta_hat) -> tuple[np.ndarray, str]:
        """Rotor commands [N] within ``[0, f_max]`` for ``wrench`` and the allocation mode."""
        raise NotImplementedError

    def command(
        self, t, p, v, R, w, eta_hat=None, reference: FlatOutput | None = None, feedforward=None
    ) -> ControlStep:
        """Rotor commands [N] for the measured state and the efficiency estimate ``eta_hat``
        (``None`` = nominal)."""
        reference, clamped = self._reference(t, R, reference)
        out = self.geometric.compute(t, p, v, R, w, reference, feedforward)
        f, mode = self._allocate(_wrench(out), eta_hat)
        return ControlStep(f, out, mode, clamped)


class GeometricBaseline(GeometricWrenchController):
    """The plain geometric controller: nominal allocation (eq. 12), blind to motor faults."""

    name = "geometric"

    def _allocate(self, wrench, eta_hat):
        f = self.vehicle.rotor_thrust(wrench)
        return np.clip(f, 0.0, self.vehicle.rotor_max_thrust), EXACT


class EstimateAwareController(GeometricWrenchController):
    """Geometric control with estimate-aware, saturation-aware allocation.

    Args:
        vehicle: the nominal vehicle.
        trajectory: the reference.
        config: geometric controller options (gains, feed-forward).
        fault_tolerant: allocation and heading-release options.
    """

    name = "estimate-aware"

    def __init__(
        self,
        vehicle: Vehicle,
        trajectory: Trajectory,
        config: ControllerConfig | None = None,
        fault_tolerant: FaultTolerantConfig | None = None,
    ):
        super().__init__(vehicle, trajectory, config)
        self.ft = fault_tolerant or FaultTolerantConfig()
        self.allocator = EstimateAwareAllocator(vehicle, self.ft.allocation)

    def _reference(self, t, R, reference):
        if self.ft.max_heading_error is None:
            return reference, False
        ref = self.trajectory(t) if reference is None else reference
        b1d = bounded_heading(R, ref.b1d, self.ft.max_heading_error)
        return ref._replace(b1d=b1d), b1d is not ref.b1d

    def _allocate(self, wrench, eta_hat):
        res = self.allocator.allocate(wrench, eta_hat)  # A diag(eta_hat) f = w (eqs. 12-13)
        return res.f, res.mode


class RelaxedHoverFallback(EstimateAwareController):
    """The estimate-aware controller until the estimate isolates a lost rotor, then the
    relaxed hover on the other three (mode ``"relaxed-hover"``).

    The switch (:attr:`switch`, a :class:`~quadfault.model.relaxed_hover_control.RotorLossSwitch`)
    sees only ``eta_hat``: ``switch.first_seen`` is the time of the first estimate of the
    run that isolated the rotor, ``switch.switched`` the time of the switch.

    Args:
        control_period: the period the commands are held [s] (the relaxed-hover gains are
            designed for it).
    """

    name = "relaxed-hover"

    def __init__(
        self,
        vehicle: Vehicle,
        trajectory: Trajectory,
        config: ControllerConfig | None = None,
        fault_tolerant: FaultTolerantConfig | None = None,
        control_period: float = 1e-3,
    ):
        super().__init__(vehicle, trajectory, config, fault_tolerant)
        self.control_period = float(control_period)
        self.switch = RotorLossSwitch(self.ft.detector or RotorLossDetector())

    def reset(self) -> None:
        self.switch.reset()

    def command(
        self, t, p, v, R, w, eta_hat=None, reference: FlatOutput | None = None, feedforward=None
    ) -> ControlStep:
        step = super().command(t, p, v, R, w, eta_hat, reference, feedforward)
        lost = -1 if eta_hat is None else self.switch.update(eta_hat, t)
        if lost < 0:
            return step
        ctrl = relaxed_hover_controller(
            self.vehicle, lost, self.ft.spin_physics, self.control_period, self.ft.relaxed_gains
        )
        ref = self.trajectory(t) if reference is None else reference
        f = ctrl.command(p, v, R, w, ref.position, ref.velocity, ref.acceleration)
        return ControlStep(f, step.out, "relaxed-hover", step.heading_clamped)


CONTROLLERS = {
    "geometric": GeometricBaseline,
    "estimate-aware": EstimateAwareController,
    "relaxed-hover": RelaxedHoverFallback,
}


def make_controller(
    kind: str,
    vehicle: Vehicle,
    trajectory: Trajectory,
    config: ControllerConfig | None = None,
    fault_tolerant: FaultTolerantConfig | None = None,
    control_period: float = 1e-3,
):
    """``"geometric"``, ``"estimate-aware"`` or ``"relaxed-hover"`` for ``trajectory``
    (``control_period`` [s]: the period of the relaxed hover's gains)."""
    if kind == "geometric":
        return GeometricBaseline(vehicle, trajectory, config)
    if kind == "estimate-aware":
        return EstimateAwareController(vehicle, trajectory, config, fault_tolerant)
    if kind == "relaxed-hover":
        return RelaxedHoverFallback(vehicle, trajectory, config, fault_tolerant, control_period)
    raise ConfigError(f"unknown controller {kind!r}; choose from {', '.join(CONTROLLERS)}")
