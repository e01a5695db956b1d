"""Physics invariants of the rigid-body model and its integrators."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from support import oracles

from quadfault.model.dynamics import (
    RigidBodyState,
    angular_acceleration,
    reference_euler_step,
    reference_euler_store,
    rigid_body,
    specific_force_body,
    step_rk4,
    translational_acceleration,
)
from quadfault.model.rotation import expm_so3, hat
from quadfault.model.vehicle import Vehicle


class ReferenceEuler:
    """The reference-integrator kernels with their memory, stepped on RigidBodyStates."""

    def __init__(self, vehicle, dt):
        self.rigid, self.dt, self.memory = rigid_body(vehicle), dt, np.zeros((4, 3))

    @property
    def a(self):
        return self.memory[0]

    def step(self, s):
        p, v, R, w = reference_euler_step(
            tuple(s.p), tuple(s.v), tuple(s.R.ravel()), tuple(s.w), self.memory, self.rigid, self.dt
        )
        return RigidBodyState(np.array(p), np.array(v), np.array(R).reshape(3, 3), np.array(w))

    def apply(self, thrust, moment, R):
        reference_euler_store(self.memory, thrust, tuple(moment), tuple(R.ravel()))


@pytest.fixture
def vehicle():
    return Vehicle()


def test_hover_equilibrium_has_zero_acceleration(vehicle):
    R = np.eye(3)
    f = np.full(4, vehicle.hover_thrust)
    T, *M = vehicle.wrench(f)
    acc = translational_acceleration(R, T, vehicle)
    alpha = angular_acceleration(np.zeros(3), np.array(M), vehicle)
    np.testing.assert_allclose(acc, 0.0, atol=1e-12)
    np.testing.assert_allclose(alpha, 0.0, atol=1e-12)
    # the accelerometer at hover reads the specific force (0, 0, -g) in FRD
    np.testing.assert_allclose(
        specific_force_body(R, acc, vehicle.gravity), [0, 0, -vehicle.gravity]
    )


def test_free_fall_matches_g_t2_over_2(vehicle):
    s = RigidBodyState.at_rest()
    dt, n = 1e-3, 2000
    for _ in range(n):
        s = step_rk4(s, 0.0, np.zeros(3), vehicle, dt)
    t = n * dt
    np.testing.assert_allclose(s.p, [0, 0, 0.5 * vehicle.gravity * t * t], rtol=1e-12)
    np.testing.assert_allclose(s.v, [0, 0, vehicle.gravity * t], rtol=1e-12)


def _full_ode(vehicle, thrust, moment):
    def f(_, y):
        _p, v, R, w = y[:3], y[3:6], y[6:15].reshape(3, 3), y[15:]
        acc = translational_acceleration(R, thrust, vehicle)
        Rdot = R @ hat(w)
        wdot = angular_acceleration(w, moment, vehicle)
        return np.concatenate((v, acc, Rdot.ravel(), wdot))

    return f


def test_rk4_matches_scipy_on_a_tumbling_thrusting_body(vehicle):
    """RKMK4 agrees with a tight-tolerance solve_ivp of the full 18-dim ODE."""
    R0 = expm_so3(np.array([0.3, -0.2, 0.5]))
    s = RigidBodyState(np.zeros(3), np.array([1.0, 0.0, -0.5]), R0, np.array([2.0, -1.0, 3.0]))
    thrust, moment = 12.0, np.array([0.01, -0.02, 0.005])
    dt, n = 1e-3, 500
    y0 = np.concatenate((s.p, s.v, s.R.ravel(), s.w))
    sol = solve_ivp(
        _full_ode(vehicle, thrust, moment), (0, n * dt), y0, rtol=1e-12, atol=1e-12, method="DOP853"
    )
    for _ in range(n):
        s = step_rk4(s, thrust, moment, vehicle, dt)
    yT = sol.y[:, -1]
    np.testing.assert_allclose(s.p, yT[:3], atol=1e-9)
    np.testing.assert_allclose(s.v, yT[3:6], atol=1e-9)
    np.testing.assert_allclose(s.R, yT[6:15].reshape(3, 3), atol=1e-9)
    np.testing.assert_allclose(s.w, yT[15:], atol=1e-9)


def test_rk4_is_fourth_order(vehicle):
    s0 = RigidBodyState(np.zeros(3), np.zeros(3), np.eye(3), np.array([3.0, -2.0, 4.0]))
    thrust, moment = 10.0, np.array([0.05, 0.02, -0.01])

    def final(dt, T=0.2):
        s = s0
        for _ in range(int(round(T / dt))):
            s = step_rk4(s, thrust, moment, vehicle, dt)
        return s

    exact = final(1e-4)
    e1 = np.abs(final(0.02).R - exact.R).max()
    e2 = np.abs(final(0.01).R - exact.R).max()
    assert 12 < e1 / e2 < 20  # ~2^4


def test_rk4_keeps_rotation_orthonormal_and_batches(vehicle):
    rng = np.random.default_rng(3)
    B = 5
    R0 = expm_so3(rng.normal(size=(B, 3)))
    s = RigidBodyState(np.zeros((B, 3)), np.zeros((B, 3)), R0, rng.normal(scale=5.0, size=(B, 3)))
    thrust = np.full(B, 9.8)
    moment = rng.normal(scale=0.01, size=(B, 3))
    single = [RigidBodyState(s.p[i], s.v[i], s.R[i], s.w[i]) for i in range(B)]
    for _ in range(3000):
        s = step_rk4(s, thrust, moment, vehicle, 1e-3)
    for i in range(B):
        si = single[i]
        for _ in range(3000):
            si = step_rk4(si, thrust[i], moment[i], vehicle, 1e-3)
        np.testing.assert_allclose(s.R[i], si.R, atol=1e-13)
        np.testing.assert_allclose(s.p[i], si.p, atol=1e-13)
    err = np.abs(s.R @ np.swapaxes(s.R, -1, -2) - np.eye(3)).max()
    assert err < 1e-12
    np.testing.assert_allclose(np.linalg.det(s.R), 1.0, atol=1e-12)


def test_torque_free_rotation_conserves_energy_and_momentum(vehicle):
    s = RigidBodyState(np.zeros(3), np.zeros(3), np.eye(3), np.array([1.0, 2.0, 5.0]))
    J = vehicle.inertia

    def invariants(st):
        L_world = st.R @ (J @ st.w)
        return 0.5 * st.w @ J @ st.w, L_world

    E0, L0 = invariants(s)
    for _ in range(5000):
        s = step_rk4(s, vehicle.weight, np.zeros(3), vehicle, 1e-3)
    E1, L1 = invariants(s)
    assert abs(E1 - E0) / E0 < 1e-9
    np.testing.assert_allclose(L1, L0, rtol=1e-9, atol=1e-12)


def test_reference_euler_reproduces_hand_computed_steps(vehicle):
    """The authors' step order: W, v, R, x, then a and W' from the stored command."""
    dt = 1e-3
    ref = ReferenceEuler(vehicle, dt)
    s = RigidBodyState(
        np.array([3.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]), np.eye(3), np.zeros(3)
    )
    # step 1: a = 0 and W' = 0 initially, so only x moves; then a = g e3 (no force stored yet)
    s1 = ref.step(s)
    np.testing.assert_allclose(s1.p, s.p + s.v * dt)
    np.testing.assert_allclose(s1.v, s.v)
    np.testing.assert_allclose(ref.a, [0, 0, vehicle.gravity])
    # the controller stores a wrench; it acts only from the step after next
    T, M = 12.0, np.array([0.01, 0.0, 0.0])
    ref.apply(T, M, s1.R)
    s2 = ref.step(s1)
    np.testing.assert_allclose(s2.v, s1.v + np.array([0, 0, vehicle.gravity]) * dt)
    np.testing.assert_allclose(s2.p, s1.p + s2.v * dt)  # x += v_new dt  -> a dt^2
    np.testing.assert_allclose(s2.w, 0.0)
    a2 = vehicle.gravity * np.array([0, 0, 1.0]) - T * s1.R[:, 2] / vehicle.mass
    np.testing.assert_allclose(ref.a, a2)
    s3 = ref.step(s2)
    np.testing.assert_allclose(s3.v, s2.v + a2 * dt)
    wdot = vehicle.inertia_inverse @ M
    np.testing.assert_allclose(s3.w, wdot * dt)
    R3 = s2.R @ (np.eye(3) + hat(s3.w * dt))
    np.testing.assert_allclose(s3.R, R3, atol=1e-12)  # orthonormalisation is second order here


def test_reference_euler_kernels_equal_the_readable_form(vehicle):
    rng = np.random.default_rng(4)
    dt = 1e-3
    kernel, oracle = ReferenceEuler(vehicle, dt), oracles.ReferenceEuler(vehicle, dt)
    s = RigidBodyState(
        rng.normal(size=3), rng.normal(size=3), expm_so3(rng.normal(size=3)), rng.normal(size=3)
    )
    x = (s.p, s.v, s.R, s.w)
    for _ in range(50):
        s = kernel.step(s)
        x = oracle.step(*x)
        for got, want in zip(s, x):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)
        T, M = 9.0 + rng.normal(), 0.01 * rng.normal(size=3)
        kernel.apply(T, M, s.R)
        oracle.apply(T, M, x[2])


def test_rk4_kernel_equals_the_readable_form_with_and_without_a_wrench(vehicle):
    rng = np.random.default_rng(5)
    for _ in range(5):
        s = RigidBodyState(
            rng.normal(size=3),
            rng.normal(size=3),
            expm_so3(rng.normal(size=3)),
            rng.normal(scale=3.0, size=3),
        )
        T, M, dt = 5 + 5 * rng.random(), 0.05 * rng.normal(size=3), 10 ** rng.uniform(-4, -2)
        want = oracles.step_rk4(*s, T, M, vehicle, dt)
        for got, ref in zip(step_rk4(s, T, M, vehicle, dt), want):
            np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)

        def drag(p, v, R, w):
            return -0.3 * v + 0.01 * p, 0.002 * w

        want = oracles.step_rk4(*s, T, M, vehicle, dt, drag)
        got = step_rk4(s, T, M, vehicle, dt, lambda st: drag(st.p, st.v, st.R, st.w))
        for a, b in zip(got, want):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_rk4_with_a_python_wrench_batches_and_calls_it_once_per_stage(vehicle):
    rng = np.random.default_rng(6)
    B = 7
    s = RigidBodyState(
        rng.normal(size=(B, 3)),
        rng.normal(size=(B, 3)),
        expm_so3(rng.normal(size=(B, 3))),
        rng.normal(size=(B, 3)),
    )
    T, M = 9 + rng.random(B), 0.01 * rng.normal(size=(B, 3))
    dt = np.full((B, 1), 2e-3)  # one step per row, as a column
    calls = []

    def wind(st):
        calls.append(st.p.shape)
        return np.broadcast_to([0.2, -0.1, 0.0], st.p.shape), 0.001 * st.w

    out = step_rk4(s, T, M, vehicle, dt, wind)
    assert calls == [(B, 3)] * 4
    for i in range(B):
        one = step_rk4(
            RigidBodyState(*(x[i] for x in s)),
            T[i],
            M[i],
            vehicle,
            2e-3,
            lambda st: (np.array([0.2, -0.1, 0.0]), 0.001 * st.w),
        )
        for a, b in zip(out, one):
            np.testing.assert_allclose(a[i], b, rtol=0, atol=1e-15)


def test_accelerations_equal_the_readable_forms(vehicle):
    rng = np.random.default_rng(7)
    R, w = expm_so3(rng.normal(size=(6, 3))), rng.normal(size=(6, 3))
    T, M, F, Mx = (
        rng.random(6) * 10,
        rng.normal(size=(6, 3)),
        rng.normal(size=(6, 3)),
        rng.normal(size=(6, 3)),
    )
    np.testing.assert_allclose(
        translational_acceleration(R, T, vehicle, F),
        oracles.translational_acceleration(R, T, vehicle, F),
        atol=1e-13,
    )
    np.testing.assert_allclose(
        angular_acceleration(w, M, vehicle, Mx),
        oracles.angular_acceleration(w, M, vehicle, Mx),
        atol=1e-10,
    )
