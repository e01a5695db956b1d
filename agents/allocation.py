"""Estimate-aware, saturation-aware thrust allocation.

The geometric controller asks for a body wrench ``w = [T, Mx, My, Mz]`` (paper eqs. 9-10).
The nominal allocation realises it with ``f = A^-1 w`` (eq. 12). With motor efficiencies
``E = diag(eta)`` (eq. 13) the rotors actually produce ``A E f``, so the estimate-aware
allocation solves the *effective* allocation instead::

    A diag(eta_hat) f = w,        0 <= f_i <= f_max                          (eqs. 12-13)

i.e. each rotor is commanded ``f_i / eta_hat_i`` of the thrust the nominal split would give
it. When a weak rotor would have to exceed ``f_max`` (or a strong one go below zero) the
wrench is not reachable; the allocation then gives up objectives by priority:

1. **yaw first** (closed form, 4 rotors): keep ``T, Mx, My`` exact and move along the
   one-dimensional null space of their rows, ``f(s) = f0 + s n``; the feasible interval of
   ``s`` follows from the bounds, and the yaw moment is linear in ``s``, so the best yaw is
   the unconstrained yaw solution clipped to that interval;
2. if even ``T, Mx, My`` cannot be met, a bounded weighted least-squares problem on the whole
   wrench (:func:`scipy.optimize.lsq_linear`, BVLS) with weights that favour roll/pitch and
   thrust and nearly ignore yaw.

``eta_hat`` is guarded: values below ``eta_floor`` (default 0.1) are raised to it, and
non-finite values count as 1 (nominal), so a bad estimate can at most make a rotor ask for
10x its nominal command, which saturation then bounds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.optimize import lsq_linear

from quadfault.errors import ConfigError
from quadfault.vehicle import Vehicle

#: Allocation outcome codes (``AllocationResult.mode``).
EXACT = "exact"  # the wrench is realised exactly within the bounds
YAW_RELEASED = "yaw_released"  # T, Mx, My exact, yaw moment reduced
WEIGHTED = "weighted"  # bounded weighted least squares on the whole wrench
MODES = (EXACT, YAW_RELEASED, WEIGHTED)


@dataclass(frozen=True)
class AllocationConfig:
    """Options of :class:`EstimateAwareAllocator`.

    Attributes:
        eta_floor: smallest efficiency the allocation believes [-] (guards ``f / eta``).
        weights: priority weights of ``[T, Mx, My, Mz]`` in the fallback least-squares
            problem, applied to the wrench error expressed in newtons (moments divided by
            the rotor lever arm). Large = kept, small = given up first.
        yaw_first: try the closed-form yaw release before the weighted fallback.
        saturate: respect ``[0, f_max]`` (``False``: exact solve, bounds ignored).
    """

    eta_floor: float = 0.1
    weights: tuple = (3.0, 10.0, 10.0, 0.1)
    yaw_first: bool = True
    saturate: bool = True

    def __post_init__(self):
        if not (0.0 < self.eta_floor <= 1.0):
            raise ConfigError(f"eta_floor must be in (0, 1], got {self.eta_floor!r}")
        w = tuple(float(x) for x in self.weights)
        if len(w) != 4 or any(not (math.isfinite(x) and x > 0) for x in w):
            raise ConfigError(f"weights must be 4 positive numbers, got {self.weights!r}")
        object.__setattr__(self, "weights", w)


class AllocationResult(NamedTuple):
    f: np.ndarray  # rotor thrust commands [N] (before the motors' efficiency)
    wrench: np.ndarray  # wrench the commands give if eta_hat is right [N, N m]
    mode: str  # one of MODES


def guard_eta(eta_hat, floor: float = 0.1) -> np.ndarray:
    """Efficiency estimate made safe for division: NaN/inf -> 1, clipped to ``[floor, 1.5]``."""
    eta = np.array(eta_hat, dtype=float)
    eta = np.where(np.isfinite(eta), eta, 1.0)
    return np.clip(eta, floor, 1.5)


class EstimateAwareAllocator:
    """Wrench -> rotor commands for the degraded actuators (see module docstring).

    Args:
        vehicle: the nominal vehicle (allocation ``A`` and ``f_max``); 4 rotors.
        config: options.
    """

    def __init__(self, vehicle: Vehicle, config: AllocationConfig | None = None):
        if vehicle.n_rotors != 4:
            raise ConfigError(f"the estimate-aware allocation needs 4 rotors, got {vehicle.n_rotors}")
        self.vehicle = vehicle
        self.config = config or AllocationConfig()
        self.f_max = vehicle.rotor_max_thrust
        A = vehicle.allocation
        # moments expressed in newtons through the mean lever arm of the roll/pitch rows
        arm = float(np.mean(np.abs(A[1:3])))
        yaw = float(np.mean(np.abs(A[3]))) or 1.0
        self._scale = np.array([1.0, 1.0 / arm, 1.0 / arm, 1.0 / yaw])

    def effective_allocation(self, eta_hat) -> np.ndarray:
        """``A diag(eta_hat)`` with the guarded estimate (eq. 13)."""
        return self.vehicle.allocation * guard_eta(eta_hat, self.config.eta_floor)

    def _feasible(self, f) -> bool:
        tol = 1e-9 * max(1.0, self.f_max if math.isfinite(self.f_max) else 1.0)
        return bool(np.all(f >= -tol) and np.all(f <= self.f_max + tol))

    def allocate(self, wrench, eta_hat=None) -> AllocationResult:
        """Rotor commands [N] realising ``wrench`` = [T, Mx, My, Mz] with efficiency ``eta_hat``
        (``None``: nominal)."""
        w = np.asarray(wrench, dtype=float)
        B = self.vehicle.allocation if eta_hat is None else self.effective_allocation(eta_hat)
        f = np.linalg.solve(B, w)  # eqs. 12-13: A diag(eta) f = w
        if not self.config.saturate or self._feasible(f):
            return AllocationResult(f, w, EXACT)
        if self.config.yaw_first:
            f_yaw = self._release_yaw(B, w)
            if f_yaw is not None:
                return AllocationResult(f_yaw, B @ f_yaw, YAW_RELEASED)
        f_ls = self._weighted(B, w)
        return AllocationResult(f_ls, B @ f_ls, WEIGHTED)

    def _release_yaw(self, B, w) -> np.ndarray | None:
        """T, Mx, My exact along the null space of ``B[:3]``; best yaw within the bounds."""
        B3 = B[:3]
        f0 = np.linalg.lstsq(B3, w[:3], rcond=None)[0]
        n = np.linalg.svd(B3)[2][-1]  # B3 n = 0
        lo, hi = -np.inf, np.inf
        for fi, ni in zip(f0, n):
            if abs(ni) < 1e-12:
                if fi < -1e-9 or fi > self.f_max + 1e-9:
                    return None
                continue
            a, b = (0.0 - fi) / ni, (self.f_max - fi) / ni
            lo, hi = max(lo, min(a, b)), min(hi, max(a, b))
        if lo > hi:
            return None
        yaw_gain = float(B[3] @ n)
        s = 0.0 if abs(yaw_gain) < 1e-12 else (w[3] - B[3] @ f0) / yaw_gain
        s = min(max(s, lo), hi)
        return np.clip(f0 + s * n, 0.0, self.f_max)

    def _weighted(self, B, w) -> np.ndarray:
        """Bounded least squares ``min ||W S (B f - w)||`` s.t. ``0 <= f <= f_max``."""
        W = np.asarray(self.config.weights) * self._scale
        res = lsq_linear(W[:, None] * B, W * w, bounds=(0.0, self.f_max), method="bvls",
                         tol=1e-12)
        return np.clip(res.x, 0.0, self.f_max)
