"""Controllers for the closed loop: the plain geometric baseline and the estimate-aware one.

Both wrap :class:`quadfault.controller.GeometricController` (paper eqs. 9-10) on the
*nominal* vehicle and differ only in how the desired wrench becomes rotor commands:

* :class:`GeometricBaseline` -- the nominal allocation inverse (eq. 12), ``f = A^-1 w``,
  clipped to the rotor limits ``[0, f_max]``; it ignores ``eta_hat``.
* :class:`EstimateAwareController` -- the estimate-aware allocation of
  :mod:`agents.allocation`: ``A diag(eta_hat) f = w`` within ``[0, f_max]``, yaw given up
  first. When yaw has to be given up, the controller also stops asking for the reference
  heading (``release_heading``): it tracks its own current heading until the allocation has
  been exact for ``heading_hold`` seconds. Without this the vehicle would spin up while the
  attitude error still measured heading, and at 180 degrees of heading error the geometric
  attitude error loses its roll/pitch part (``e_R`` of eq. 10 vanishes for ``R = R_d R_z(pi)
  R_x(eps)``), which crashes the vehicle.

``eta_hat`` always comes from an estimator (or the explicitly labelled oracle of
:func:`agents.rollout.fly`); these classes never see the plant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from agents.allocation import EXACT, AllocationConfig, EstimateAwareAllocator
from quadfault.controller import ControllerConfig, ControlOutput, GeometricController
from quadfault.errors import ConfigError
from quadfault.trajectory import FlatOutput, Trajectory
from quadfault.vehicle import Vehicle


class ControlStep(NamedTuple):
    f: np.ndarray  # rotor thrust commands [N], within [0, f_max]
    out: ControlOutput  # the geometric controller's details (errors, R_d)
    mode: str  # allocation mode (agents.allocation.MODES)
    heading_released: bool  # True when the reference heading was not tracked


@dataclass(frozen=True)
class FaultTolerantConfig:
    """Options of :class:`EstimateAwareController`.

    Attributes:
        allocation: the estimate-aware allocation (eta floor, priority weights).
        release_heading: track the current heading while yaw is saturated.
        heading_hold: time the allocation must stay exact before the reference heading is
            tracked again [s].
    """

    allocation: AllocationConfig = field(default_factory=AllocationConfig)
    release_heading: bool = True
    heading_hold: float = 1.0

    def __post_init__(self):
        if not (math.isfinite(self.heading_hold) and self.heading_hold >= 0):
            raise ConfigError(f"heading_hold must be >= 0 [s], got {self.heading_hold!r}")


def _wrench(out: ControlOutput) -> np.ndarray:
    return np.concatenate((np.atleast_1d(out.thrust), out.moment))


class GeometricBaseline:
    """The plain geometric controller: nominal allocation, blind to motor faults."""

    name = "geometric"

    def __init__(self, vehicle: Vehicle, trajectory: Trajectory,
                 config: ControllerConfig | None = None):
        self.vehicle = vehicle
        self.geometric = GeometricController(vehicle, trajectory, config)

    @property
    def trajectory(self) -> Trajectory:
        return self.geometric.trajectory

    def reset(self) -> None:
        """No internal state."""

    def command(self, t, p, v, R, w, eta_hat=None, reference: FlatOutput | None = None,
                feedforward=None) -> ControlStep:
        out = self.geometric.compute(t, p, v, R, w, reference, feedforward)
        f = self.vehicle.rotor_thrust(_wrench(out))
        f = np.clip(f, 0.0, self.vehicle.rotor_max_thrust)
        return ControlStep(f, out, EXACT, False)


class EstimateAwareController:
    """Geometric control with estimate-aware, saturation-aware allocation.

    Args:
        vehicle: the nominal vehicle.
        trajectory: the reference.
        config: geometric controller options (gains, feed-forward).
        fault_tolerant: allocation and heading-release options.
    """

    name = "estimate-aware"

    def __init__(self, vehicle: Vehicle, trajectory: Trajectory,
                 config: ControllerConfig | None = None,
                 fault_tolerant: FaultTolerantConfig | None = None):
        self.vehicle = vehicle
        self.geometric = GeometricController(vehicle, trajectory, config)
        self.ft = fault_tolerant or FaultTolerantConfig()
        self.allocator = EstimateAwareAllocator(vehicle, self.ft.allocation)
        self.reset()

    @property
    def trajectory(self) -> Trajectory:
        return self.geometric.trajectory

    def reset(self) -> None:
        self._release_until = -math.inf

    @staticmethod
    def _current_heading(R, fallback):
        b1 = np.array([R[0, 0], R[1, 0], 0.0])
        n = np.linalg.norm(b1)
        return b1 / n if n > 0.3 else fallback

    def command(self, t, p, v, R, w, eta_hat=None, reference: FlatOutput | None = None,
                feedforward=None) -> ControlStep:
        """Rotor commands [N] for the measured state and the efficiency estimate ``eta_hat``
        (``None`` = nominal)."""
        released = self.ft.release_heading and t < self._release_until
        if released:
            ref = self.trajectory(t) if reference is None else reference
            reference = ref._replace(b1d=self._current_heading(R, ref.b1d))
            if self.geometric.config.angular_feedforward:
                feedforward = (np.zeros(3), np.zeros(3))
        out = self.geometric.compute(t, p, v, R, w, reference, feedforward)
        res = self.allocator.allocate(_wrench(out), eta_hat)
        if res.mode != EXACT:
            self._release_until = t + self.ft.heading_hold
        return ControlStep(res.f, out, res.mode, released)


CONTROLLERS = {"geometric": GeometricBaseline, "estimate-aware": EstimateAwareController}


def make_controller(kind: str, vehicle: Vehicle, trajectory: Trajectory,
                    config: ControllerConfig | None = None,
                    fault_tolerant: FaultTolerantConfig | None = None):
    """``"geometric"`` or ``"estimate-aware"`` for ``trajectory``."""
    if kind == "geometric":
        return GeometricBaseline(vehicle, trajectory, config)
    if kind == "estimate-aware":
        return EstimateAwareController(vehicle, trajectory, config, fault_tolerant)
    raise ConfigError(f"unknown controller {kind!r}; choose from {', '.join(CONTROLLERS)}")
