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
   one-dimensional null space of their rows, ``f(s) = f_exact + s n`` with
   ``n = n_A / eta_hat`` (``n_A`` spans the null space of the nominal rows ``A[:3]``); the
   bounds give an interval of ``s`` and the yaw error is ``|s (A diag(eta_hat) n)_z|``, so
   the best yaw is the ``s`` of that interval closest to 0;
2. if even ``T, Mx, My`` cannot be met, the bounded weighted least-squares problem on the
   whole wrench, ``min ||W (A diag(eta_hat) f - w)||`` s.t. ``0 <= f <= f_max``, with weights
   that favour roll/pitch and thrust and nearly ignore yaw. It is solved exactly by
   enumerating the 3^4 active sets (each rotor free, at 0 or at f_max) with one batched
   solve of their normal equations; the problem is strictly convex, so the feasible
   candidate of least cost is the optimum (the tests cross-check it against
   :func:`scipy.optimize.lsq_linear`).

``eta_hat`` is guarded: values below ``eta_floor`` (default 0.1) are raised to it, and
non-finite values count as 1 (nominal), so a bad estimate can at most make a rotor ask for
10x its nominal command, which saturation then bounds.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.vehicle import Vehicle

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


#: The 81 active sets of 4 bounded variables: 0 = free, 1 = at the lower, 2 = at the upper bound.
_PATTERNS = np.array(list(itertools.product((0, 1, 2), repeat=4)))
_FREE = (_PATTERNS == 0).astype(float)
_UPPER = (_PATTERNS == 2).astype(float)
_PIN = np.eye(4) * (1.0 - _FREE)[:, None, :]


class AllocationResult(NamedTuple):
    f: np.ndarray  # rotor thrust commands [N] (before the motors' efficiency)
    wrench: np.ndarray  # wrench the commands give if eta_hat is right [N, N m]
    mode: str | np.ndarray  # one of MODES (an array of them, one per row, for rows)


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
            raise ConfigError(
                f"the estimate-aware allocation needs 4 rotors, got {vehicle.n_rotors}"
            )
        self.vehicle = vehicle
        self.config = config or AllocationConfig()
        self.f_max = vehicle.rotor_max_thrust
        A = vehicle.allocation
        # moments expressed in newtons through the mean lever arm of the roll/pitch rows
        arm = float(np.mean(np.abs(A[1:3])))
        yaw = float(np.mean(np.abs(A[3]))) or 1.0
        self._scale = np.array([1.0, 1.0 / arm, 1.0 / arm, 1.0 / yaw])
        self._null3 = np.linalg.svd(A[:3])[2][-1]  # A[:3] n_A = 0

    def effective_allocation(self, eta_hat) -> np.ndarray:
        """``A diag(eta_hat)`` with the guarded estimate (eq. 13)."""
        return self.vehicle.allocation * guard_eta(eta_hat, self.config.eta_floor)

    def _feasible(self, f) -> bool:
        lo, hi = -1e-9, self.f_max + 1e-9
        return all(lo <= x <= hi for x in f.tolist())

    def _guard(self, eta_hat) -> np.ndarray:
        """:func:`guard_eta` for 4 values, in plain floats (cheaper at 1 kHz)."""
        floor = self.config.eta_floor
        return np.array(
            [
                min(max(x, floor), 1.5) if math.isfinite(x) else 1.0
                for x in np.asarray(eta_hat, dtype=float).tolist()
            ]
        )

    def allocate(self, wrench, eta_hat=None) -> AllocationResult:
        """Rotor commands [N] realising ``wrench`` = [T, Mx, My, Mz] with efficiency ``eta_hat``
        (``None``: nominal)."""
        w = np.asarray(wrench, dtype=float)
        eta = np.ones(4) if eta_hat is None else self._guard(eta_hat)
        # eqs. 12-13: A diag(eta) f = w  <=>  f = (A^-1 w) / eta
        f = (self.vehicle.allocation_inverse @ w) / eta
        if not self.config.saturate or self._feasible(f):
            return AllocationResult(f, w, EXACT)
        B = self.vehicle.allocation * eta
        if self.config.yaw_first:
            f_yaw = self._release_yaw(f, eta)
            if f_yaw is not None:
                return AllocationResult(f_yaw, B @ f_yaw, YAW_RELEASED)
        f_ls = self._weighted(B, w)
        return AllocationResult(f_ls, B @ f_ls, WEIGHTED)

    def allocate_rows(self, wrenches, eta_hat) -> AllocationResult:
        """:meth:`allocate` for rows: wrenches ``(N, 4)`` with estimates ``eta_hat`` ``(N, 4)``
        (the environments' base controller, one row or a batch). The exact split is computed
        for every row at once; a row it does not fit goes through :meth:`allocate`. ``mode``
        is an array of the rows' modes."""
        w = np.asarray(wrenches, dtype=float)
        eta = np.asarray(eta_hat, dtype=float)
        floor = self.config.eta_floor
        eta = np.where(np.isfinite(eta), np.clip(eta, floor, 1.5), 1.0)  # _guard, per row
        f = (w @ self.vehicle.allocation_inverse.T) / eta  # eqs. 12-13, every row
        modes = np.full(len(w), EXACT, dtype=object)
        done = w
        if self.config.saturate:
            tol = 1e-9
            for i in np.flatnonzero(~np.all((f >= -tol) & (f <= self.f_max + tol), axis=1)):
                if done is w:
                    done = w.copy()
                f[i], done[i], modes[i] = self.allocate(w[i], eta[i])
        return AllocationResult(f, done, modes)

    def _release_yaw(self, f_exact, eta) -> np.ndarray | None:
        """T, Mx, My exact along ``f_exact + s n``; the ``s`` closest to 0 within the bounds."""
        n = (self._null3 / eta).tolist()  # A[:3] diag(eta) n = 0
        f0 = f_exact.tolist()
        lo, hi, f_max = -math.inf, math.inf, self.f_max
        for fi, ni in zip(f0, n):
            a, b = -fi / ni, (f_max - fi) / ni  # |n_i| > 0 for every rotor
            if a > b:
                a, b = b, a
            lo, hi = max(lo, a), min(hi, b)
        if lo > hi + 1e-12:
            return None
        s = min(max(0.0, lo), hi)
        return np.array([min(max(fi + s * ni, 0.0), f_max) for fi, ni in zip(f0, n)])

    def _weighted(self, B, w) -> np.ndarray:
        """``min ||W (B f - w)||`` s.t. ``0 <= f <= f_max`` by active-set enumeration."""
        W = np.asarray(self.config.weights) * self._scale
        M, r = W[:, None] * B, W * w
        upper = self.f_max if math.isfinite(self.f_max) else 0.0
        fixed = _UPPER * upper  # (81, 4): bound values of the fixed rotors
        Mf = M[None] * _FREE[:, None, :]  # columns of fixed rotors zeroed
        rhs = r[None] - fixed @ M.T
        # normal equations of the free rotors; a unit diagonal pins the fixed ones to 0
        MfT = np.swapaxes(Mf, 1, 2)
        G = MfT @ Mf + _PIN
        f = fixed + np.linalg.solve(G, MfT @ rhs[..., None])[..., 0] * _FREE
        if not math.isfinite(self.f_max):
            f = f[np.all(_PATTERNS != 2, axis=1)]
        tol = 1e-9
        ok = np.all((f >= -tol) & (f <= self.f_max + tol), axis=1)
        cost = np.sum((f[ok] @ M.T - r) ** 2, axis=1)
        return np.clip(f[ok][np.argmin(cost)], 0.0, self.f_max)


__all__ = [
    "EXACT",
    "MODES",
    "WEIGHTED",
    "YAW_RELEASED",
    "AllocationConfig",
    "AllocationResult",
    "EstimateAwareAllocator",
    "guard_eta",
]
