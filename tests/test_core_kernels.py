"""The core model's kernels against their readable numpy forms (tests/support/oracles.py),
and how they are compiled."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from support import oracles

from quadfault import jit
from quadfault.model import closed_loop, controller, dynamics, motors, rotation, sensors
from quadfault.model.controller import ControllerConfig, GeometricController
from quadfault.model.motors import MotorModel
from quadfault.model.scenarios import named_scenario
from quadfault.model.sensors import SensorNoise
from quadfault.model.vehicle import Vehicle


def test_rotation_kernels_equal_the_readable_forms_and_scipy():
    rng = np.random.default_rng(1)
    phi = rng.normal(scale=1.5, size=(50, 3))
    R = rotation.expm_so3(phi)
    np.testing.assert_allclose(R, Rotation.from_rotvec(phi).as_matrix(), rtol=0, atol=1e-14)
    np.testing.assert_allclose(R, oracles.expm_so3(phi), rtol=0, atol=1e-14)
    np.testing.assert_array_equal(rotation.hat(phi), oracles.hat(phi))
    np.testing.assert_array_equal(rotation.vee(rotation.hat(phi)), phi)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=3)
    np.testing.assert_allclose(rotation.cross(a, b), np.cross(a, b), rtol=0, atol=1e-15)
    assert rotation.cross(a[0], b).shape == (3,)
    M = rng.normal(size=(3, 3))
    np.testing.assert_allclose(
        np.array(rotation.dcm_renormalize3(tuple(M.ravel()))),
        oracles.dcm_renormalize(M).ravel(),
        rtol=0,
        atol=1e-15,
    )


def test_expm_series_equals_rodrigues_on_both_sides_of_its_bound():
    """Below 0.1 rad expm3 evaluates sin(th)/th and (1 - cos th)/th^2 from their series:
    equal to the closed forms to rounding, up to and across the bound."""
    rng = np.random.default_rng(7)
    bound = np.sqrt(rotation._EXPM_SERIES_MAX_TH2)
    for th in (1e-9, 1e-5, 1e-3, 0.03, 0.0999999, bound, 0.1000001, 0.3):
        for _ in range(5):
            axis = rng.normal(size=3)
            phi = th * axis / np.linalg.norm(axis)
            got = np.array(rotation.expm3(tuple(phi))).reshape(3, 3)
            x, y, z = phi
            a = np.sin(th) / th
            b = 2 * np.sin(th / 2) ** 2 / th**2  # (1 - cos th)/th^2 without cancellation
            hat = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
            np.testing.assert_allclose(got, np.eye(3) + a * hat + b * hat @ hat, rtol=0, atol=2e-16)


@pytest.mark.parametrize("saturate", [True, False])
def test_motor_kernel_draws_in_rotor_order(saturate):
    rng = np.random.default_rng(2)
    f = rng.uniform(-1.0, 6.0, size=(20, 4))
    eta = rng.uniform(0.3, 1.0, size=(20, 4))
    got = MotorModel(0.07, saturate).apply(f, eta, 4.9, np.random.default_rng(9))
    z = np.random.default_rng(9).standard_normal((20, 4))  # row by row, rotor by rotor
    want = oracles.motor_thrust(f, eta, 4.9, saturate, 0.07, z)
    np.testing.assert_allclose(got, want, rtol=1e-15, atol=0)
    np.testing.assert_array_equal(MotorModel(0.0).apply(f, 1.0, 4.9, None), np.clip(f, 0.0, 4.9))


@pytest.mark.parametrize(
    "config",
    [ControllerConfig(), ControllerConfig.reference(), ControllerConfig(angular_feedforward=False)],
)
def test_controller_kernel_equals_the_readable_form(config):
    rng = np.random.default_rng(3)
    veh = Vehicle()
    traj = named_scenario("lissajous").trajectory
    ctrl = GeometricController(veh, traj, config)
    for _ in range(10):
        t = rng.uniform(0, 20)
        p, v, w = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        R = rotation.expm_so3(rng.normal(size=3))
        f, out = ctrl.motor_commands(t, p, v, R, w)
        wd, wdd = oracles.feedforward_rates(traj, t, veh, config)
        if not config.angular_feedforward:
            wd = wdd = np.zeros(3)
        T, M, Rd = oracles.geometric_control(p, v, R, w, traj(t), wd, wdd, veh, config)
        np.testing.assert_allclose(out.thrust, T, rtol=0, atol=1e-12)
        np.testing.assert_allclose(out.moment, M, rtol=0, atol=1e-12)
        np.testing.assert_allclose(out.Rd, Rd, rtol=0, atol=1e-14)
        want = oracles.mix(veh.allocation_inverse, T, M, config.yaw_release)
        np.testing.assert_allclose(f, want, atol=1e-12)
        np.testing.assert_allclose(
            ctrl.feedforward_rates(t)[0],
            oracles.feedforward_rates(traj, t, veh, config)[0],
            atol=1e-11,
        )
    # a batch of states is the same kernel per row
    P = rng.normal(size=(5, 3))
    batch = ctrl.compute(1.0, P, np.zeros(3), np.eye(3), np.zeros(3))
    for i in range(5):
        one = ctrl.compute(1.0, P[i], np.zeros(3), np.eye(3), np.zeros(3))
        np.testing.assert_array_equal(batch.moment[i], one.moment)


@pytest.mark.parametrize(
    "config",
    [
        ControllerConfig(),
        ControllerConfig.reference(),
        ControllerConfig(acceleration_feedforward=False, normalize_b2d=False),
    ],
)
def test_feedforward_over_arrays_equals_the_compiled_kernel(config):
    ctrl = GeometricController(Vehicle(), named_scenario("lissajous").trajectory, config)
    for t in (0.3, np.linspace(0.0, 20.0, 7), np.linspace(0.0, 20.0, 200).reshape(4, 50)):
        compiled, arrays = ctrl.feedforward(t, compiled=True), ctrl.feedforward(t, compiled=False)
        for a, b in zip(compiled, arrays):
            assert a.shape == b.shape == np.shape(t) + a.shape[np.ndim(t) :]
            np.testing.assert_array_equal(a, b)
    # a flight's table (many times) takes the numpy form by default
    t = np.linspace(0.0, 20.0, 500)
    for a, b in zip(ctrl.feedforward(t), ctrl.feedforward(t, compiled=True)):
        np.testing.assert_array_equal(a, b)


def test_sensor_kernel_draws_p_v_attitude_w_then_the_accelerometer():
    rng = np.random.default_rng(4)
    noise = SensorNoise(0.1, 0.2, 0.03, 0.4, 0.5)
    state = dynamics.RigidBodyState(
        rng.normal(size=3),
        rng.normal(size=3),
        rotation.expm_so3(rng.normal(size=3)),
        rng.normal(size=3),
    )
    sf = rng.normal(size=3)
    got, got_sf = noise.measure(state, sf, np.random.default_rng(5))
    twin = np.random.default_rng(5)
    want = oracles.measure(*state, noise, twin)
    for a, b in zip(got, want):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-15)
    np.testing.assert_allclose(got_sf, sf + 0.5 * twin.standard_normal(3), rtol=0, atol=1e-15)
    quiet, _ = SensorNoise().measure(state, None, np.random.default_rng(5))
    for a, b in zip(quiet, state):
        np.testing.assert_array_equal(a, b)


KERNELS = (
    rotation.expm3,
    dynamics.rkmk4_step,
    controller.geometric_control,
    closed_loop.fly_vehicle,
    closed_loop._fly_parallel,
    closed_loop.sense_vehicle,
    sensors.measure3,
    motors._motor_rows,
)


def test_compile_options_float64_nopython_cache_no_fastmath():
    if not jit.AVAILABLE:
        pytest.skip("numba is not importable")
    for d in KERNELS:
        opts = d.targetoptions
        assert opts.get("nopython") and opts.get("error_model") == "numpy", d
        assert type(d._cache).__name__ == "FunctionCache", d  # cache=True
        assert not opts.get("fastmath"), d


def test_per_step_cores_take_no_arrays():
    """The RKMK4, controller and sensor kernels run per vehicle-step; an array argument of a
    call would make every call increment / decrement its reference count (an atomic
    operation the threads of the parallel loop share). They take tuples, or are inlined into
    the caller (no call at all)."""
    if not jit.AVAILABLE:
        pytest.skip("numba is not importable")
    import numba

    from quadfault.model.plant import Plant

    plant = Plant(Vehicle(), MotorModel(0.07))
    C = closed_loop.constants(plant, SensorNoise(0.1, 0.1, 0.1, 0.1, 0.1))
    K = GeometricController(Vehicle(), None).constants

    V = plant.vehicles

    @numba.njit(cache=False)  # types the kernels afresh (a cached caller does not)
    def one_step(C, V, K, gen):
        rigid, noise = closed_loop._tuples(C, V, 0)
        gains, nominal = controller.controller_tuples(K)
        z, R = (0.0, 0.0, -1.0), (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
        x = dynamics.rkmk4_step(z, z, R, z, 9.8, z, rigid, 1e-3)
        u = controller.geometric_control(z, z, R, z, (z, z, z, z, z, z), gains, nominal)
        return x, u, sensors.measure3(z, z, R, z, noise, gen)

    one_step(C, V, K, np.random.default_rng(0))
    # the signatures this caller typed for the cores (not the dispatchers' state: with a
    # warm cache the cores may never have been compiled in this process)
    ta = one_step.overloads[one_step.signatures[0]].type_annotation
    calls = {}
    for expr, sig in ta.calltypes.items():
        disp = (
            getattr(
                ta.typemap.get(getattr(getattr(expr, "func", None), "name", "")), "dispatcher", None
            )
            if getattr(expr, "op", None) == "call"
            else None
        )
        if disp is not None:
            calls[disp.py_func.__name__] = sig
    cores = {
        "rkmk4_step": dynamics.rkmk4_step,
        "geometric_control": controller.geometric_control,
        "measure3": sensors.measure3,
    }
    for name, core in cores.items():
        if core.targetoptions.get("inline") == "always":  # no call: its body is the caller's
            assert name not in calls, (name, calls)
            continue
        flat = [
            t
            for a in calls[name].args
            for t in (a.types if isinstance(a, numba.types.BaseTuple) else (a,))
        ]
        assert not any(isinstance(t, numba.types.Array) for t in flat), (name, calls[name])


@pytest.mark.parametrize("kernel", ["compiled", "interpreted"])
def test_the_mixer_gives_up_yaw_first_at_zero_thrust(kernel):
    """A yaw demand that the plain inverse meets by driving a rotor pair below zero: the
    mixer keeps thrust, roll and pitch exactly and scales the yaw moment down until the
    lowest command is zero; a demand within bounds is the plain inverse's, bit for bit."""
    veh = Vehicle()
    Ai, B = veh.allocation_inverse, veh.allocation
    mix = (
        controller.rotor_commands if kernel == "compiled" else jit.python(controller.rotor_commands)
    )
    T, M = veh.mass * veh.gravity, (0.05, -0.03, 0.4)
    plain, mixed = np.empty(4), np.empty(4)
    mix(T, M, Ai, plain)
    mix(T, M, Ai, mixed, True)
    assert plain.min() < -1.0  # the plain inverse asks a rotor to push
    np.testing.assert_allclose(plain, Ai @ np.array([T, *M]), rtol=0, atol=1e-12)
    assert mixed.min() == pytest.approx(0.0, abs=1e-12)
    wrench = B @ mixed
    np.testing.assert_allclose(wrench[:3], [T, M[0], M[1]], rtol=0, atol=1e-9)
    assert 0.0 < wrench[3] < M[2]  # yaw kept as far as zero thrust allows
    small = (0.05, -0.03, 0.01)
    a, b = np.empty(4), np.empty(4)
    mix(T, small, Ai, a)
    mix(T, small, Ai, b, True)
    assert a.min() > 0 and np.array_equal(a, b)


def test_the_mixer_gives_up_yaw_first_at_the_thrust_limit():
    """A saturating flight's mixer (``f_max``): a yaw demand that pushes a rotor above the
    limit is scaled down until the highest command is the limit; roll, pitch and thrust
    kept."""
    veh = Vehicle()
    Ai, B, f_max = veh.allocation_inverse, veh.allocation, veh.rotor_max_thrust
    T, M = 1.6 * veh.mass * veh.gravity, (0.05, -0.03, -0.1)
    plain, mixed = np.empty(4), np.empty(4)
    controller.rotor_commands(T, M, Ai, plain)
    controller.rotor_commands(T, M, Ai, mixed, True, f_max)
    assert plain.max() > f_max + 1.0 and plain.min() > 0
    assert mixed.max() == pytest.approx(f_max, abs=1e-12)
    wrench = B @ mixed
    np.testing.assert_allclose(wrench[:3], [T, M[0], M[1]], rtol=0, atol=1e-9)
    assert M[2] < wrench[3] < 0.0
