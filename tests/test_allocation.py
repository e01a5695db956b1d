"""Estimate-aware allocation: exact when feasible, bounds respected, yaw given up first."""

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from quadfault.errors import ConfigError
from quadfault.model.allocation import (
    EXACT,
    WEIGHTED,
    YAW_RELEASED,
    AllocationConfig,
    EstimateAwareAllocator,
    guard_eta,
)
from quadfault.model.vehicle import Vehicle

VEH = Vehicle()
FMAX = VEH.rotor_max_thrust
HOVER = np.array([VEH.weight, 0.0, 0.0, 0.0])


def test_nominal_equals_allocation_inverse():
    alloc = EstimateAwareAllocator(VEH)
    w = np.array([10.5, 0.1, -0.05, 0.01])
    res = alloc.allocate(w, np.ones(4))
    assert res.mode == EXACT
    np.testing.assert_allclose(res.f, VEH.rotor_thrust(w), atol=1e-12)


def test_feasible_wrench_is_exact_with_degraded_motor():
    alloc = EstimateAwareAllocator(VEH)
    eta = np.array([0.6, 1.0, 0.9, 1.0])
    w = np.array([9.8, 0.05, 0.05, 0.0])
    res = alloc.allocate(w, eta)
    assert res.mode == EXACT
    # the degraded rotors, scaled by their efficiency, produce exactly the wanted wrench
    np.testing.assert_allclose(VEH.allocation @ (eta * res.f), w, atol=1e-10)
    assert np.all(res.f >= 0) and np.all(res.f <= FMAX)


@pytest.mark.parametrize("seed", range(20))
def test_bounds_always_respected(seed):
    rng = np.random.default_rng(seed)
    alloc = EstimateAwareAllocator(VEH)
    eta = rng.uniform(0.05, 1.2, 4)
    w = np.array([rng.uniform(0, 25), *rng.normal(0, 1.0, 2), rng.normal(0, 0.1)])
    res = alloc.allocate(w, eta)
    assert np.all(res.f >= 0.0) and np.all(res.f <= FMAX)
    np.testing.assert_allclose(res.wrench, VEH.allocation @ (guard_eta(eta) * res.f), atol=1e-9)


def test_yaw_given_up_first_at_eta_03():
    """A single motor at 0.3 cannot hover with zero yaw moment: thrust, roll and pitch stay
    exact, only yaw is lost, and the yaw moment left is the smallest possible."""
    alloc = EstimateAwareAllocator(VEH)
    eta = np.array([0.3, 1.0, 1.0, 1.0])
    res = alloc.allocate(HOVER, eta)
    assert res.mode == YAW_RELEASED
    produced = VEH.allocation @ (eta * res.f)
    np.testing.assert_allclose(produced[:3], HOVER[:3], atol=1e-9)
    assert abs(produced[3]) > 1e-3
    # closed form (paper layout): f1 = f3 = 0.3 f_max produced, f2 = f4 = mg/2 - that
    weak = 0.3 * FMAX
    c = VEH.allocation[3, 1]
    assert abs(produced[3]) == pytest.approx(2 * c * (VEH.weight / 2 - 2 * weak), rel=1e-9)
    assert res.f[0] == pytest.approx(FMAX)


def test_yaw_release_matches_prioritised_scipy_solution():
    """Cross-check: among all bounded commands with T, Mx, My exact, SciPy's bounded least
    squares on a heavily weighted problem finds the same smallest yaw error."""
    alloc = EstimateAwareAllocator(VEH)
    eta = np.array([0.3, 1.0, 0.8, 1.0])
    w = np.array([10.0, 0.1, -0.1, 0.0])
    res = alloc.allocate(w, eta)
    assert res.mode == YAW_RELEASED
    B = VEH.allocation * eta
    W = np.array([1e4, 1e4 / 0.225, 1e4 / 0.225, 1.0 / 0.009012])
    ref = lsq_linear(W[:, None] * B, W * w, bounds=(0, FMAX), method="bvls", tol=1e-14).x
    assert abs((B @ res.f)[3] - w[3]) <= abs((B @ ref)[3] - w[3]) + 1e-6
    np.testing.assert_allclose(B @ res.f, B @ ref, atol=1e-4)


def test_infeasible_thrust_falls_back_to_weighted_least_squares():
    alloc = EstimateAwareAllocator(VEH)
    eta = np.array([0.2, 0.2, 1.0, 1.0])
    w = np.array([18.0, 0.0, 0.0, 0.0])  # more thrust than the weak pair allows, level
    res = alloc.allocate(w, eta)
    assert res.mode == WEIGHTED
    assert np.all(res.f >= 0) and np.all(res.f <= FMAX)
    W = np.asarray(alloc.config.weights) * alloc._scale
    ref = lsq_linear(W[:, None] * (VEH.allocation * eta), W * w, bounds=(0, FMAX)).x
    np.testing.assert_allclose(res.f, ref, atol=1e-6)


def test_eta_guard_floor_and_nan():
    np.testing.assert_allclose(guard_eta([0.0, np.nan, 0.5, 3.0]), [0.1, 1.0, 0.5, 1.5])
    alloc = EstimateAwareAllocator(VEH)
    res = alloc.allocate(HOVER, [np.nan, np.inf, 1.0, 1.0])
    np.testing.assert_allclose(res.f, VEH.hover_thrust)


def test_bad_config_raises():
    with pytest.raises(ConfigError, match="eta_floor"):
        AllocationConfig(eta_floor=0.0)
    with pytest.raises(ConfigError, match="weights"):
        AllocationConfig(weights=(1, 1, 1))
