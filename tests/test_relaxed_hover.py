"""The relaxed hover after a complete rotor loss: the model's solution, the closed-form
conditions, and the simulator holding it open loop."""

import math

import numpy as np
import pytest

from quadfault.errors import ConfigError
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.effects import parse_effect
from quadfault.model.flight import Flight
from quadfault.model.plant import Plant
from quadfault.model.relaxed_hover import (
    ROTOR_LOSS_EFFECTS,
    SpinPhysics,
    closed_form_hover,
    hover_residual,
    hover_state,
    linearised,
    relaxed_hover,
    rotor_loss_vehicle,
)
from quadfault.model.vehicle import Vehicle

VEHICLE = rotor_loss_vehicle()


@pytest.mark.parametrize("lost", range(4))
@pytest.mark.parametrize("rho", [0.0, 0.3, 0.6])
def test_closed_form_conditions_equal_the_models_solution_under_their_assumptions(lost, rho):
    """Without roll/pitch damping (the closed form's assumption) the two agree to solver
    precision, for any lost rotor; the yaw rate's sign follows the remaining rotors' net
    drag torque."""
    phys = SpinPhysics(linear=(0.0, 0.0, 5e-3))
    a, b = relaxed_hover(VEHICLE, phys, lost, rho), closed_form_hover(VEHICLE, phys, lost, rho)
    np.testing.assert_allclose(a.f, b.f, rtol=1e-9)
    np.testing.assert_allclose(a.w, b.w, rtol=1e-8, atol=1e-9)
    assert a.f[lost] == 0.0
    assert np.sign(a.yaw_rate) == -np.sign(VEHICLE.allocation[3, lost])


def test_solution_balances_moments_and_weight_with_every_term_on():
    phys = SpinPhysics()  # roll/pitch damping, yaw damping, gyroscopic moment
    h = relaxed_hover(VEHICLE, phys, 0, 0.3)
    assert np.max(np.abs(hover_residual(VEHICLE, phys, h.f, h.w))) < 1e-9
    assert np.sum(h.f) * math.cos(h.tilt) == pytest.approx(VEHICLE.weight, rel=1e-9)
    cf = closed_form_hover(VEHICLE, phys, 0, 0.3)  # roll/pitch damping ignored there
    assert abs(math.degrees(h.tilt - cf.tilt)) < 0.5 and h.yaw_rate == pytest.approx(
        cf.yaw_rate, rel=1e-3
    )
    # the gyroscopic moment matters: without it the spin axis tilts less
    assert relaxed_hover(VEHICLE, SpinPhysics(momentum=0.0), 0, 0.3).tilt < h.tilt - 0.02


def test_spin_rate_scales_inversely_with_yaw_damping_and_none_means_no_hover():
    fast = relaxed_hover(VEHICLE, SpinPhysics(linear=(0, 0, 2.5e-3)), 0, 0.0)
    slow = relaxed_hover(VEHICLE, SpinPhysics(linear=(0, 0, 5e-3)), 0, 0.0)
    assert fast.yaw_rate == pytest.approx(2 * slow.yaw_rate, rel=1e-9)
    with pytest.raises(ConfigError, match="yaw damping"):
        relaxed_hover(VEHICLE, SpinPhysics(linear=(0.0, 0.0, 0.0)), 0)


def test_thrust_to_weight_two_leaves_no_margin_and_the_named_vehicle_does():
    """The default vehicle (thrust-to-weight 2) can hold the two-rotor spin only with both
    neighbours at their limit; the complete-loss vehicle has a third in reserve."""
    phys = SpinPhysics()
    assert relaxed_hover(Vehicle(), phys, 0, 0.0).load == pytest.approx(1.0)
    assert relaxed_hover(Vehicle(), phys, 0, 0.3).load > 0.85
    h = relaxed_hover(VEHICLE, phys, 0, 0.3)
    assert h.feasible and h.load < 0.7


@pytest.mark.parametrize("lost", [0, 3])
def test_simulator_holds_the_relaxed_hover_open_loop(lost):
    """The model's solution flown with constant commands by the simulator (RKMK4, the
    named vehicle's effects, the lost rotor's efficiency 0) for 3 s: the body rate stays
    and the centre of mass stays on its circle about the hover point."""
    phys = SpinPhysics.of(ROTOR_LOSS_EFFECTS)
    h = relaxed_hover(VEHICLE, phys, lost)
    p, v, R, w = hover_state(VEHICLE, h)
    plant = Plant(VEHICLE, effects=tuple(parse_effect(s) for s in ROTOR_LOSS_EFFECTS))
    plant.reset(RigidBodyState(p, v, R, w))
    flight = Flight(plant, record_accel=False)
    flight.reset(np.random.default_rng(0))
    eta = np.ones(4)
    eta[lost] = 0.0
    flight.plan(3000, lambda t: eta)
    flight.step(h.f, 3000)
    s = flight.state()
    np.testing.assert_allclose(s.w, h.w, atol=1e-5)
    radius = np.linalg.norm(s.p - np.array([0.0, 0.0, -1.0]))
    assert radius == pytest.approx(h.circle_radius(VEHICLE), abs=5e-4)
    assert radius < 0.02


def test_linearisation_is_controllable_from_the_three_rotors():
    h = relaxed_hover(VEHICLE, SpinPhysics(), 2)
    A, B = linearised(VEHICLE, SpinPhysics(), h)
    C = np.hstack([np.linalg.matrix_power(A, k) @ B for k in range(5)])
    assert np.linalg.matrix_rank(C) == 5
    assert np.all(B[:, 2] == 0.0)
