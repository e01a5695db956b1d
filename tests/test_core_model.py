"""Vehicle, rotations, motors, scenarios and controller."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from quadfault.errors import ConfigError
from quadfault.model.motors import MotorModel
from quadfault.model.rotation import (
    ENU_TO_NED,
    FLU_TO_FRD,
    expm_so3,
    hat,
    logm_so3,
    orthonormalize,
    quat_multiply,
    quat_to_rot,
    rot_to_quat,
    vee,
)
from quadfault.model.scenarios import (
    AbruptFault,
    ConstantEfficiency,
    EfficiencySchedule,
    named_scenario,
    random_scenario,
)
from quadfault.model.vehicle import Vehicle, allocation_from_rotors, paper_allocation


def test_paper_vehicle_defaults():
    v = Vehicle()
    assert v.mass == 1.0 and v.gravity == 9.8
    np.testing.assert_allclose(np.diag(v.inertia), [0.01466, 0.01466, 0.02848])
    d, c = 0.225, 0.009012
    Lam = np.array([[1, 1, 1, 1], [-d, d, d, -d], [d, d, -d, -d], [-c, c, -c, c]])
    np.testing.assert_allclose(v.allocation, Lam)
    assert v.rotor_max_thrust == pytest.approx(4.9)  # thrust-to-weight 2
    np.testing.assert_allclose(v.allocation @ v.allocation_inverse, np.eye(4), atol=1e-12)


def test_allocation_from_rotor_positions_matches_paper_layout():
    d, c = 0.1, 0.02
    pos = [(d, d), (d, -d), (-d, -d), (-d, d)]
    np.testing.assert_allclose(
        allocation_from_rotors(pos, [-1, 1, -1, 1], c), paper_allocation(d, c)
    )
    # a rotor on the right (+y in FRD) pushing up (-z) rolls the vehicle left: Mx < 0
    A = allocation_from_rotors(
        [(0.0, 0.2), (0.0, -0.2), (0.2, 0.0), (-0.2, 0.0)], [1, 1, -1, -1], c
    )
    assert A[1, 0] < 0 and A[1, 1] > 0 and A[2, 2] > 0 and A[2, 3] < 0


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"mass": 0.0}, "mass"),
        ({"mass": -1.0}, "mass"),
        ({"mass": float("nan")}, "mass"),
        ({"inertia": [1.0, -1.0, 1.0]}, "positive definite"),
        ({"inertia": [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]}, "symmetric"),
        ({"allocation": np.ones((4, 4))}, "singular"),
        ({"allocation": np.ones((3, 4))}, "shape"),
        ({"max_thrust": -1.0}, "max_thrust"),
    ],
)
def test_vehicle_rejects_bad_parameters(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        Vehicle(**kwargs)


def test_rotation_helpers_agree_with_scipy():
    rng = np.random.default_rng(0)
    phi = rng.normal(size=(20, 3))
    phi *= (np.pi * 0.99 / np.maximum(np.linalg.norm(phi, axis=1), np.pi))[:, None]
    R = expm_so3(phi)
    np.testing.assert_allclose(R, Rotation.from_rotvec(phi).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(logm_so3(R), phi, atol=1e-12)
    q = rot_to_quat(R)
    sq = Rotation.from_matrix(R).as_quat(scalar_first=True)
    sq *= np.sign(sq[:, :1])
    np.testing.assert_allclose(q, sq, atol=1e-14)
    np.testing.assert_allclose(quat_to_rot(q), R, atol=1e-14)
    # Hamilton product composes rotations
    np.testing.assert_allclose(quat_to_rot(quat_multiply(q[0], q[1])), R[0] @ R[1], atol=1e-14)
    w = rng.normal(size=3)
    np.testing.assert_allclose(hat(w) @ phi[0], np.cross(w, phi[0]))
    np.testing.assert_allclose(vee(hat(w)), w)
    noisy = R[0] + 1e-3 * rng.normal(size=(3, 3))
    Rn = orthonormalize(noisy)
    np.testing.assert_allclose(Rn @ Rn.T, np.eye(3), atol=1e-14)


def test_frame_matrices_are_proper_involutions():
    for M in (ENU_TO_NED, FLU_TO_FRD):
        np.testing.assert_allclose(M @ M, np.eye(3))
        assert np.linalg.det(M) == pytest.approx(1.0)


def test_motor_model_saturation_efficiency_and_noise():
    rng = np.random.default_rng(0)
    m = MotorModel(thrust_noise=0.0, saturate=True)
    f = m.apply(np.array([-1.0, 2.0, 6.0, 4.9]), np.array([1.0, 0.5, 0.5, 1.0]), 4.9, rng)
    np.testing.assert_allclose(f, [0.0, 1.0, 2.45, 4.9])
    ref = MotorModel(thrust_noise=0.0, saturate=False)
    np.testing.assert_allclose(
        ref.apply(np.array([-1.0, 6.0, 1, 1]), np.ones(4), 4.9, rng), [0, 6, 1, 1]
    )
    noisy = MotorModel(thrust_noise=0.07)
    samples = np.array([noisy.apply(np.full(4, 2.0), np.ones(4), 4.9, rng) for _ in range(4000)])
    logs = np.log(samples / 2.0)
    assert abs(logs.std() - 0.07) < 0.004 and abs(logs.mean()) < 0.004
    with pytest.raises(ConfigError):
        MotorModel(thrust_noise=-0.1)


def test_combined_scenario_follows_reference_schedule():
    sc = named_scenario("combined")
    assert sc.duration == 80.0 and sc.thrust_noise == 0.07
    eta = sc.efficiency
    # voltage degradation: 1.0 at 0 s, exp(-0.25) at 80 s
    np.testing.assert_allclose(eta(0.0), 1.0)
    np.testing.assert_allclose(eta(80.0), math.exp(-0.25), rtol=1e-12)
    # motor k at 0.5 on samples m*6667 .. m*6667 + 3333 (m = 1, 4, 7, 10)
    for k, m in enumerate((1, 4, 7, 10)):
        on, off = m * 6667 * 1e-3, (m * 6667 + 3333) * 1e-3
        inside = eta(np.array([on, 0.5 * (on + off), off]))
        np.testing.assert_allclose(inside[:, k], 0.5)
        others = [j for j in range(4) if j != k]
        assert np.all(inside[:, others] > 0.75)
        before, after = eta(on - 1e-3), eta(off + 1e-3)
        assert before[k] > 0.75 and after[k] > 0.75
    assert [round(w[1], 3) for w in sc.fault_windows()] == [6.667, 26.668, 46.669, 66.670]


def test_abrupt_scenario_is_one_outside_faults_and_fault_modes():
    sc = named_scenario("abrupt")
    np.testing.assert_allclose(sc.efficiency(np.array([0.0, 20.0, 79.9])), 1.0)
    sched = EfficiencySchedule(
        ConstantEfficiency((0.8, 1, 1, 1)), (AbruptFault(1, 1.0, 1.0, 0.5, mode="multiply"),)
    )
    assert sched(1.5)[0] == pytest.approx(0.4)
    ramp = EfficiencySchedule(faults=(AbruptFault(2, 1.0, level=0.5, ramp=1.0),))
    assert ramp(1.5)[1] == pytest.approx(0.75)
    with pytest.raises(ConfigError):
        AbruptFault(motor=5, onset=1.0)
    with pytest.raises(ConfigError, match="unknown scenario"):
        named_scenario("nope")


def test_random_scenarios_are_seeded():
    a = random_scenario(np.random.default_rng(7))
    b = random_scenario(np.random.default_rng(7))
    assert a == b
    t = np.linspace(0, a.duration, 50)
    eta = a.efficiency(t)
    assert eta.shape == (50, 4) and np.all((eta >= 0) & (eta <= 1.0 + 1e-12))
