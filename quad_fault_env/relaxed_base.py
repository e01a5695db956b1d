"""The ``allocation="relaxed-hover"`` base of the environments: the estimate-aware allocation
until the observation's estimate isolates a lost rotor, then the relaxed-hover controller on
the other three (:mod:`quadfault.model.relaxed_hover_control`), per row of a batch.

The switch sees only the estimate the observation carries (never the truth unless the
estimator is the labelled oracle); it latches until the row's episode ends. The controller
is designed with the spin physics of the env's ``effects`` (their ``rate_damping`` and
``rotor_inertia``; the complete-loss vehicle's when the effects are drawn from ranges or
absent) and held over the control period.
"""

from __future__ import annotations

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.relaxed_hover import SpinPhysics
from quadfault.model.relaxed_hover_control import (
    RotorLossDetector,
    RotorLossSwitch,
    relaxed_hover_controller,
)


def spin_physics_of(effects) -> SpinPhysics:
    """The spin physics of an env's ``effects`` keyword (specs or objects); the default
    (the complete-loss vehicle's) when there are none or they are ranges."""
    if not effects:
        return SpinPhysics()
    try:
        return SpinPhysics.of(effects)
    except ConfigError:  # ranges (a:b) are drawn per episode: design for the defaults
        return SpinPhysics()


class RelaxedHoverBase:
    """Per-row switches and the relaxed-hover commands that replace the base controller's
    once a row's switch has fired."""

    def __init__(self, vehicle, effects, control_period: float, rows: int = 1, detector=None):
        self.vehicle = vehicle
        self.physics = spin_physics_of(effects)
        self.period = float(control_period)
        self.detector = detector or RotorLossDetector()
        self.switches = [RotorLossSwitch(self.detector) for _ in range(int(rows))]

    def batch(self, rows: int) -> RelaxedHoverBase:
        """The same base with ``rows`` switches (the vector env's)."""
        out = RelaxedHoverBase.__new__(RelaxedHoverBase)
        out.vehicle, out.physics, out.period = self.vehicle, self.physics, self.period
        out.detector = self.detector
        out.switches = [RotorLossSwitch(self.detector) for _ in range(int(rows))]
        return out

    def reset(self, rows=None) -> None:
        for i in range(len(self.switches)) if rows is None else np.atleast_1d(rows).tolist():
            self.switches[int(i)].reset()

    def update(self, t, eta_hat) -> np.ndarray:
        """Feed each row's estimate at its time ``t`` [s]; the lost rotor per row (-1: none)."""
        eta = np.atleast_2d(eta_hat)
        t = np.broadcast_to(np.asarray(t, float), (len(self.switches),))
        return np.array(
            [sw.update(eta[i], float(t[i])) for i, sw in enumerate(self.switches)], dtype=int
        )

    def commands(self, lost: int, p, v, R, w, refs) -> np.ndarray:
        """The relaxed hover's rotor commands [N] of one row (``refs``: the controller's
        reference rows, position, velocity, acceleration first)."""
        ctrl = relaxed_hover_controller(self.vehicle, lost, self.physics, self.period)
        return ctrl.command(p, v, R, w, refs[0], refs[1], refs[2])
