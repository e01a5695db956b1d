"""The compiled (numba) simulator path: helpers mirror the pure functions, the whole loop gives
the pure loop's results to <= 1e-9, and the backend dispatch falls back or fails clearly.

The helper tests run without numba too (the helpers are then plain Python); the loop tests
skip when numba is missing.
"""

from dataclasses import replace

import numpy as np
import pytest

from quadfault import _sim_numba as fast
from quadfault.controller import ControllerConfig, GeometricController
from quadfault.dynamics import ReferenceEuler, RigidBodyState, step_rk4
from quadfault.dynamics import specific_force_body, translational_acceleration
from quadfault.errors import ConfigError
from quadfault.motors import MotorModel
from quadfault.rotation import cross, dcm_orthonormalize_reference, expm_so3, hat, vee
from quadfault.scenarios import named_scenario
from quadfault.simulator import SensorNoise, SimConfig, simulate
from quadfault.trajectory import Hover
from quadfault.vehicle import Vehicle

needs_numba = pytest.mark.skipif(not fast.AVAILABLE, reason="numba (the 'fast' extra) missing")

NOISY = SensorNoise(position=0.01, velocity=0.02, attitude=0.003, gyro=0.01, accel=0.05)
TOL = 1e-9
FIELDS = ("position", "velocity", "quaternion", "omega", "thrust_cmd", "eta_true", "accel")


def _random_rotation(rng):
    return expm_so3(rng.uniform(-2.0, 2.0, 3))


def _random_state(rng):
    return RigidBodyState(rng.normal(size=3), rng.normal(size=3), _random_rotation(rng),
                          rng.normal(size=3))


# --- random numbers ------------------------------------------------------------------------
def test_one_block_of_draws_is_the_pure_loops_stream():
    """The premise of drawing all noise up front: (n, m) == n * m single draws in row order,
    whatever sizes the loop asks for (3, 3, 3, 3 sensor; 4 motors; 3 accelerometer)."""
    sizes = (3, 3, 3, 3, 4, 3)
    a, b = np.random.default_rng(11), np.random.default_rng(11)
    stream = [np.concatenate([a.standard_normal(s) for s in sizes]) for _ in range(500)]
    np.testing.assert_array_equal(b.standard_normal((500, sum(sizes))), np.array(stream))
    assert a.standard_normal() == b.standard_normal()  # both generators end in the same state


def test_noise_layout_follows_the_pure_draw_order():
    layout, width = fast.noise_layout(NOISY, 4, 0.07, record_accel=True)
    assert list(layout) == [0, 3, 6, 9, 12, 16] and width == 19
    no_att = replace(NOISY, attitude=0.0)
    layout, width = fast.noise_layout(no_att, 4, 0.07, record_accel=False)
    assert list(layout) == [0, 3, -1, 6, 9, -1] and width == 13
    layout, width = fast.noise_layout(SensorNoise(), 4, 0.0, record_accel=True)
    assert list(layout) == [-1] * 6 and width == 0


# --- helpers vs the pure functions ----------------------------------------------------------
def test_rotation_helpers_mirror_rotation_module():
    rng = np.random.default_rng(0)
    for scale in (1e-7, 1e-3, 1.0, 3.0):  # both branches of expm_so3
        phi = scale * rng.normal(size=3)
        np.testing.assert_allclose(fast.expm_so3(phi), expm_so3(phi), rtol=0, atol=1e-15)
        a, b = rng.normal(size=3), rng.normal(size=3)
        np.testing.assert_allclose(fast.cross(a, b), cross(a, b), rtol=0, atol=1e-15)
        np.testing.assert_array_equal(fast.hat(a), hat(a))
        M = rng.normal(size=(3, 3))
        np.testing.assert_array_equal(fast.vee(M), vee(M))
        Rn = _random_rotation(rng) + 1e-4 * rng.normal(size=(3, 3))
        np.testing.assert_allclose(fast.dcm_orthonormalize_reference(Rn),
                                   dcm_orthonormalize_reference(Rn), rtol=0, atol=1e-15)


def test_dynamics_helpers_mirror_dynamics_module():
    rng = np.random.default_rng(1)
    veh = Vehicle(inertia=(0.02, 0.015, 0.03), mass=1.3)
    body = fast.body_of(veh)
    for _ in range(5):
        s = _random_state(rng)
        thrust, moment = float(rng.uniform(5, 20)), rng.normal(scale=0.2, size=3)
        got = fast.step_rk4(s.p, s.v, s.R, s.w, thrust, moment, body, 1e-3)
        want = step_rk4(s, thrust, moment, veh, 1e-3)
        for g, w in zip(got, want):
            np.testing.assert_allclose(g, w, rtol=0, atol=1e-14)
        acc = fast.translational_acceleration(s.R, thrust, body)
        np.testing.assert_allclose(acc, translational_acceleration(s.R, thrust, veh), atol=1e-14)
        np.testing.assert_allclose(fast.specific_force_body(s.R, acc, veh.gravity),
                                   specific_force_body(s.R, acc, veh.gravity), atol=1e-14)


def test_reference_euler_helpers_mirror_the_class():
    rng = np.random.default_rng(2)
    veh = Vehicle()
    ref, lag = ReferenceEuler(veh, 1e-3), np.zeros((4, 3))
    s = _random_state(rng)
    sp = s
    for _ in range(4):  # apply -> step -> apply ...: the stored lag must agree too
        thrust, moment = float(rng.uniform(5, 15)), rng.normal(scale=0.1, size=3)
        ref.apply(thrust, moment, s.R)
        fast.reference_euler_apply(lag, thrust, moment, sp[2])
        s = ref.step(s)
        sp = fast.reference_euler_step(*sp, lag, fast.body_of(veh), 1e-3)
        for g, w in zip(sp, s):
            np.testing.assert_allclose(g, w, rtol=0, atol=1e-14)
        np.testing.assert_allclose(lag[:2], [ref.a, ref.w_dot], rtol=0, atol=1e-12)


@pytest.mark.parametrize("saturate", [True, False])
def test_motor_helper_mirrors_motor_model(saturate):
    f_cmd = np.array([-0.5, 2.0, 4.8, 7.0])
    eta = np.array([1.0, 0.5, 0.9, 0.7])
    for sigma in (0.0, 0.07):
        want = MotorModel(sigma, saturate).apply(f_cmd, eta, 4.9, np.random.default_rng(5))
        eps = np.random.default_rng(5).standard_normal(4)
        got = fast.motor_apply(f_cmd, eta, 4.9 if saturate else np.inf, saturate, sigma, eps)
        np.testing.assert_allclose(got, want, rtol=1e-15, atol=0)
        if sigma == 0.0:  # negative commands give 0; 7 N is clipped to f_max only if saturating
            assert got[0] == 0.0 and got[3] == pytest.approx((4.9 if saturate else 7.0) * 0.7)


@pytest.mark.parametrize("config", [ControllerConfig(), ControllerConfig.reference(),
                                    ControllerConfig(acceleration_feedforward=False)])
def test_controller_helper_mirrors_geometric_controller(config):
    rng = np.random.default_rng(3)
    veh = Vehicle(inertia=(0.02, 0.015, 0.03))
    ctrl = GeometricController(veh, named_scenario("lissajous").trajectory, config)
    for t in (0.3, 2.0, 7.5):
        ref = ctrl.trajectory(t)
        w_d, w_dot_d = ctrl.feedforward_rates(t)
        s = _random_state(rng)
        want, _ = ctrl.motor_commands(t, s.p, s.v, s.R, s.w, ref, (w_d, w_dot_d))
        got = fast.motor_commands(s.p, s.v, s.R, s.w, *(np.asarray(a, float) for a in ref),
                                  w_d, w_dot_d, fast.gains_of(ctrl), fast.body_of(veh))
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_measure_helper_mirrors_sensor_noise():
    rng = np.random.default_rng(4)
    s = _random_state(rng)
    for noise in (NOISY, replace(NOISY, attitude=0.0), SensorNoise()):
        want, _ = noise.measure(s, None, np.random.default_rng(9))
        layout, width = fast.noise_layout(noise, 4, 0.0, record_accel=False)
        row = np.random.default_rng(9).standard_normal(max(width, 1))
        std = np.array([noise.position, noise.velocity, noise.attitude, noise.gyro])
        got = fast.measure(s.p, s.v, s.R, s.w, row, layout, std)
        for g, w in zip(got, want):
            np.testing.assert_allclose(g, w, rtol=0, atol=1e-15)


# --- the whole loop -----------------------------------------------------------------------
def _both(scenario, config, **kwargs):
    pure = simulate(scenario, config=replace(config, backend="numpy"), **kwargs)
    compiled = simulate(scenario, config=replace(config, backend="numba"), **kwargs)
    return pure, compiled


def _assert_same(pure, compiled, tol=TOL):
    np.testing.assert_array_equal(pure.t, compiled.t)
    for name in FIELDS:
        a, b = getattr(pure, name), getattr(compiled, name)
        assert (a is None) == (b is None), name
        if a is not None:
            err = np.max(np.abs(a - b))
            assert err <= tol, f"{name}: compiled differs from numpy by {err:.3g}"
    assert pure.meta == compiled.meta


@needs_numba
@pytest.mark.slow
@pytest.mark.parametrize("reference", [False, True], ids=["rk4", "reference"])
@pytest.mark.parametrize("noise", [SensorNoise(), NOISY], ids=["clean", "sensor-noise"])
def test_compiled_equals_pure_over_10s_combined(reference, noise):
    sc = named_scenario("combined", duration=10.0)
    cfg = (SimConfig.reference if reference else SimConfig)(sensor_noise=noise)
    pure, compiled = _both(sc, cfg, seed=7)
    _assert_same(pure, compiled)
    # a real flight: faults and degradation happened, the circle is tracked
    assert pure.eta_true.min() == 0.5 and pure.eta_true[-1, 0] < 1.0
    err = np.linalg.norm(compiled.position - sc.trajectory(compiled.t).position, axis=1)
    assert err[compiled.t > 3.0].max() < 1.0  # faults shake it, but it stays on the circle


@needs_numba
@pytest.mark.parametrize("case", ["decimation", "no-saturation", "clipping-nominal-mismatch",
                                  "no-accel-record", "hover-no-thrust-noise"])
def test_compiled_equals_pure_short_cases(case):
    sc, kwargs = named_scenario("combined", duration=1.5), {"seed": 2}
    cfg = SimConfig(sensor_noise=replace(NOISY, attitude=0.0))
    if case == "decimation":
        cfg = replace(cfg, control_period=0.004)
    elif case == "no-saturation":
        cfg = replace(cfg, saturate=False, controller=ControllerConfig(normalize_b2d=False))
    elif case == "clipping-nominal-mismatch":
        sc = named_scenario("clipping", duration=8.0).replace(duration=1.5)
        kwargs["vehicle"] = Vehicle(mass=1.1, inertia=(0.016, 0.014, 0.03), max_thrust=3.2)
        kwargs["nominal"] = Vehicle()
    elif case == "no-accel-record":
        cfg = replace(cfg, record_accel=False, sensor_noise=NOISY)
    else:
        sc, kwargs["thrust_noise"] = named_scenario("hover_fault", duration=1.5), 0.0
    pure, compiled = _both(sc, cfg, **kwargs)
    _assert_same(pure, compiled)
    if case == "clipping-nominal-mismatch":  # the saturation was really exercised
        assert pure.thrust_cmd.max() > 3.2


@needs_numba
def test_compiled_runs_are_seeded():
    sc = named_scenario("abrupt", duration=0.5)
    cfg = SimConfig(backend="numba", sensor_noise=NOISY)
    a, b, c = (simulate(sc, config=cfg, seed=s) for s in (3, 3, 4))
    np.testing.assert_array_equal(a.position, b.position)
    assert not np.array_equal(a.position, c.position)


@needs_numba
@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_divergence_is_reported_the_same_way(backend):
    sc = named_scenario("hover", duration=0.1).replace(trajectory=Hover(position=(np.nan, 0, -1)))
    with pytest.raises(ConfigError, match=r"diverged at t = 0\.000 s"):
        simulate(sc, config=SimConfig(backend=backend))


# --- backend dispatch ---------------------------------------------------------------------
class _Breeze:
    """A minimal unmodelled effect (constant force): only the numpy path simulates effects."""

    def reset(self, n_rotors):
        pass

    def rotor_thrust(self, f, t, dt, state):
        return f

    def wrench(self, state, f, t):
        return np.array([0.1, 0.0, 0.0]), np.zeros(3)

    def describe(self):
        return {"name": "breeze"}


def test_backend_is_validated():
    with pytest.raises(ConfigError, match="backend must be one of"):
        SimConfig(backend="cuda")


def test_effects_fall_back_on_auto_and_are_refused_on_numba():
    sc = named_scenario("hover", duration=0.05)
    auto = simulate(sc, config=SimConfig(), effects=(_Breeze(),))
    pure = simulate(sc, config=SimConfig(backend="numpy"), effects=(_Breeze(),))
    np.testing.assert_array_equal(auto.position, pure.position)
    why = "unmodelled effects" if fast.AVAILABLE else "numba is not installed"
    with pytest.raises(ConfigError, match=f"backend 'numba' cannot run this simulation: {why}"):
        simulate(sc, config=SimConfig(backend="numba"), effects=(_Breeze(),))


def test_without_numba_auto_uses_numpy_and_numba_is_refused(monkeypatch):
    monkeypatch.setattr(fast, "AVAILABLE", False)
    sc = named_scenario("abrupt", duration=0.05)
    auto = simulate(sc, seed=1)
    pure = simulate(sc, seed=1, config=SimConfig(backend="numpy"))
    np.testing.assert_array_equal(auto.position, pure.position)
    with pytest.raises(ConfigError, match="numba is not installed"):
        simulate(sc, config=SimConfig(backend="numba"))
