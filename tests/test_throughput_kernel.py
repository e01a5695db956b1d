"""The batched compiled kernel ``quadfault._sim_numba.step_batch`` and its helpers: equal to the
numpy core over a batch (motors, allocation, RKMK4, controller), serial == parallel, the
compiled per-env draws equal numpy's, and the compile options (float64, nopython, cache,
numpy error model, threads within the machine).
"""

import os

import numpy as np
import pytest

from quadfault import _sim_numba as fast
from quadfault.controller import ControllerConfig, GeometricController
from quadfault.dynamics import RigidBodyState, step_rk4
from quadfault.errors import ConfigError
from quadfault.motors import MotorModel
from quadfault.rotation import expm_so3
from quadfault.scenarios import named_scenario
from quadfault.vehicle import Vehicle

pytestmark = pytest.mark.skipif(not fast.AVAILABLE, reason="numba (the 'fast' extra) missing")

DT = 1e-3


class _Draws:
    def __init__(self, z):
        self.z = z

    def standard_normal(self, shape):
        return self.z.reshape(shape)


def _batch(rng, N):
    """N random flying states, commands around hover, per-row efficiencies and noise."""
    p = rng.normal(size=(N, 3))
    v = rng.normal(size=(N, 3))
    R = expm_so3(rng.uniform(-1.0, 1.0, (N, 3)))
    w = rng.normal(scale=2.0, size=(N, 3))
    return RigidBodyState(p, v, R, w)


def _numpy_substeps(state, veh, f_cmd, eta, sigma, z, z_off, saturate=True):
    """The vector env's numpy physics: MotorModel.apply -> Vehicle.wrench -> step_rk4."""
    N, k = eta.shape[:2]
    motor = MotorModel(1.0, saturate)
    rows = np.arange(N)[:, None]
    for j in range(k):
        eps = z[rows, z_off[:, j:j + 1] + np.arange(4)] * sigma[:, None]
        f = motor.apply(f_cmd, eta[:, j], veh.rotor_max_thrust, _Draws(eps))
        wrench = veh.wrench(f)
        state = step_rk4(state, wrench[:, 0], wrench[:, 1:], veh, DT)
    return state


def _inputs(rng, N, k, veh):
    f_cmd = veh.weight / 4 + rng.normal(scale=1.5, size=(N, 4))  # some < 0, some > f_max
    f_cmd[0, 0] = 2 * veh.rotor_max_thrust
    eta = rng.uniform(0.4, 1.0, (N, k, 4))
    sigma = np.where(np.arange(N) % 3 == 0, 0.0, 0.07)
    z = rng.standard_normal((N, 4 * k + 5))
    z_off = np.ascontiguousarray(np.broadcast_to(4 * np.arange(k) + 1, (N, k)))
    return f_cmd, eta, sigma, z, z_off


@pytest.mark.parametrize("N", [3, fast.PARALLEL_MIN_VEHICLES + 5], ids=["serial", "parallel"])
def test_step_batch_equals_numpy_core(N):
    rng = np.random.default_rng(0)
    veh = Vehicle(inertia=(0.02, 0.015, 0.03), mass=1.3)
    s0 = _batch(rng, N)
    f_cmd, eta, sigma, z, z_off = _inputs(rng, N, 7, veh)
    want = _numpy_substeps(s0, veh, f_cmd, eta, sigma, z, z_off)
    got = s0.copy()
    fast.step_batch(got.p, got.v, got.R, got.w, f_cmd.copy(), eta, sigma, z, z_off, True,
                    fast.body_of(veh), DT)
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-12)
    assert np.abs(got.p - s0.p).max() > 1e-4  # the vehicles did move
    np.testing.assert_allclose(got.R @ np.swapaxes(got.R, 1, 2), np.broadcast_to(np.eye(3),
                               (N, 3, 3)), atol=1e-13)  # RKMK4 stays on SO(3)


def test_step_batch_without_saturation_equals_numpy_core():
    rng = np.random.default_rng(5)
    veh = Vehicle()
    s0 = _batch(rng, 4)
    f_cmd, eta, sigma, z, z_off = _inputs(rng, 4, 3, veh)
    want = _numpy_substeps(s0, veh, f_cmd, eta, sigma, z, z_off, saturate=False)
    got = s0.copy()
    fast.step_batch(got.p, got.v, got.R, got.w, f_cmd, eta, sigma, z, z_off, False,
                    fast.body_of(veh), DT)
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-12)


@pytest.mark.parametrize("config", [ControllerConfig(), ControllerConfig.reference()])
def test_step_batch_closed_loop_equals_numpy_controller_and_core(config):
    """Controller every 2 substeps from the true state, the reference held over the call."""
    rng = np.random.default_rng(1)
    veh, nominal = Vehicle(mass=1.1), Vehicle()
    ctrl = GeometricController(nominal, named_scenario("lissajous").trajectory, config)
    N, k, t = 5, 6, 1.7
    state = _batch(rng, N)
    state = RigidBodyState(0.1 * state.p + [0, 0, -1], 0.1 * state.v, state.R, 0.1 * state.w)
    ref = ctrl.trajectory(np.full(N, t))
    w_d, w_dot_d = ctrl.feedforward_rates(np.full(N, t))
    refs = np.stack((ref.position, ref.velocity, ref.acceleration, ref.b1d, w_d, w_dot_d), 1)
    _, eta, sigma, z, z_off = _inputs(rng, N, k, veh)
    want = state
    f_np = np.zeros((N, 4))
    for j in range(k):
        if j % 2 == 0:
            f_np, _ = ctrl.motor_commands(t, *want, ref, (w_d, w_dot_d))
        want = _numpy_substeps(want, veh, f_np, eta[:, j:j + 1], sigma, z, z_off[:, j:j + 1])
    got, f_nb = state.copy(), np.zeros((N, 4))
    fast.step_batch(got.p, got.v, got.R, got.w, f_nb, eta, sigma, z, z_off, True,
                    fast.body_of(veh), DT, 2, np.ascontiguousarray(refs), fast.gains_of(ctrl),
                    fast.body_of(nominal))
    np.testing.assert_allclose(f_nb, f_np, rtol=0, atol=1e-11)
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-12)


def test_controller_batch_equals_numpy_controller():
    rng = np.random.default_rng(2)
    veh = Vehicle(inertia=(0.02, 0.015, 0.03))
    ctrl = GeometricController(veh, named_scenario("combined").trajectory)
    N = fast.PARALLEL_MIN_VEHICLES + 1
    s = _batch(rng, N)
    t = rng.uniform(0, 10, N)
    ref = ctrl.trajectory(t)
    ff = ctrl.feedforward_rates(t)
    want, _ = ctrl.motor_commands(t, *s, ref, ff)
    refs = np.ascontiguousarray(np.stack(tuple(ref) + tuple(ff), 1))
    out = np.empty((N, 4))
    fast.controller_batch(s.p, s.v, s.R, s.w, refs, fast.gains_of(ctrl), fast.body_of(veh), out)
    np.testing.assert_allclose(out, want, rtol=0, atol=1e-11)


def test_serial_and_parallel_kernels_agree_bit_for_bit():
    rng = np.random.default_rng(3)
    veh = Vehicle()
    N, k = 40, 5
    s0 = _batch(rng, N)
    f_cmd, eta, sigma, z, z_off = _inputs(rng, N, k, veh)
    out = []
    for kernel in (fast._step_batch_serial, fast._step_batch_parallel):
        s = s0.copy()
        kernel(s.p, s.v, s.R, s.w, f_cmd.copy(), eta, sigma, z, z_off, True, fast.body_of(veh),
               DT, 0, np.zeros((1, 6, 3)), fast.no_gains(), fast.body_of(veh))
        out.append(s)
    for a, b in zip(*out):
        np.testing.assert_array_equal(a, b)


def test_non_finite_vehicle_does_not_raise_or_spread():
    """A division by zero or NaN in one vehicle gives NaN there (numpy's error model), never
    an exception inside the parallel loop, and leaves the other vehicles alone."""
    rng = np.random.default_rng(4)
    veh = Vehicle()
    N = fast.PARALLEL_MIN_VEHICLES
    s0 = _batch(rng, N)
    f_cmd, eta, sigma, z, z_off = _inputs(rng, N, 2, veh)
    s0.w[7] = np.nan
    s = s0.copy()
    fast.step_batch(s.p, s.v, s.R, s.w, f_cmd, eta, sigma, z, z_off, True, fast.body_of(veh), DT)
    assert not np.isfinite(s.R[7]).all()
    assert np.isfinite(np.delete(s.p, 7, 0)).all() and np.isfinite(np.delete(s.R, 7, 0)).all()


def test_draw_normals_is_the_generators_own_stream():
    from numba.typed import List

    sizes = np.array([5, 0, 12, 3])
    rows = np.array([0, 2, 3])  # row 1 is skipped: its generator must not move
    gens = [np.random.default_rng(s) for s in range(4)]
    twins = [np.random.default_rng(s) for s in range(4)]
    z = np.zeros((4, 12))
    fast.draw_normals(List(gens), rows, sizes, z)
    for i in range(4):
        want = twins[i].standard_normal(sizes[i]) if i in rows else np.zeros(0)
        np.testing.assert_array_equal(z[i, :sizes[i]], want)
        assert gens[i].standard_normal() == twins[i].standard_normal()  # same state after


def test_step_batch_controller_needs_refs_and_gains():
    veh = Vehicle()
    s = RigidBodyState.at_rest(batch_shape=(2,))
    with pytest.raises(ConfigError, match="needs refs and gains"):
        fast.step_batch(s.p, s.v, s.R, s.w, np.zeros((2, 4)), np.ones((2, 1, 4)), np.zeros(2),
                        np.zeros((2, 4)), np.zeros((2, 1), np.int64), True, fast.body_of(veh),
                        DT, control_every=1)


def test_compile_options_float64_nopython_cache_and_threads():
    import numba

    kernels = (fast._step_batch_parallel, fast._step_batch_serial, fast.run_steps,
               fast._controller_batch_parallel, fast.plant_step)
    for d in kernels:
        assert d.targetoptions.get("nopython") and d.targetoptions.get("error_model") == "numpy"
        assert type(d._cache).__name__ == "FunctionCache", d  # cache=True
        assert not d.targetoptions.get("fastmath")
    rng = np.random.default_rng(6)
    veh = Vehicle()
    s = _batch(rng, 2)
    fast.step_batch(s.p, s.v, s.R, s.w, *_inputs(rng, 2, 1, veh), True, fast.body_of(veh), DT)
    for sig in fast._step_batch_serial.signatures:  # every array argument is float64 / int64
        arrays = [t for t in sig if isinstance(t, numba.types.Array)]
        assert arrays and all(t.dtype in (numba.float64, numba.int64) for t in arrays), sig
    assert 1 <= numba.get_num_threads() <= (os.cpu_count() or 1)


def test_expm_series_equals_rodrigues_on_both_sides_of_its_bound():
    """Below 0.1 rad ``_expm`` evaluates sin(th)/th and (1 - cos th)/th^2 from their series:
    equal to the closed forms (and to ``expm_so3``) to rounding, up to and across the bound."""
    from quadfault import _numba_kernels as K

    rng = np.random.default_rng(7)
    bound = np.sqrt(K._EXPM_SERIES_MAX_TH2)
    for th in (1e-9, 1e-5, 1e-3, 0.03, 0.0999999, bound, 0.1000001, 0.3):
        for _ in range(5):
            axis = rng.normal(size=3)
            phi = th * axis / np.linalg.norm(axis)
            got = np.array(K._expm(tuple(phi))).reshape(3, 3)
            np.testing.assert_allclose(got, expm_so3(phi), rtol=0, atol=2e-16)
            x, y, z = phi
            a = np.sin(th) / th
            b = 2 * np.sin(th / 2) ** 2 / th**2  # (1 - cos th)/th^2 without cancellation
            hat = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
            np.testing.assert_allclose(got, np.eye(3) + a * hat + b * hat @ hat, rtol=0,
                                       atol=2e-16)


def test_per_step_cores_take_no_arrays():
    """The RKMK4 and controller cores are called per vehicle-step; an array argument would
    make every call increment / decrement its reference count (an atomic operation the
    threads share), which cost more than the physics (~200 ns per vehicle-step). Their array
    wrappers are inlined into the caller instead."""
    import numba

    from quadfault import _numba_kernels as K

    rng = np.random.default_rng(8)
    veh = Vehicle()
    ctrl = GeometricController(veh, named_scenario("lissajous").trajectory)
    s = _batch(rng, 1)
    f_cmd, eta, _, z, _ = _inputs(rng, 1, 1, veh)

    @numba.njit(cache=False)  # types the kernels afresh (a cached caller does not)
    def one_step(p, v, R, w, f_cmd, eta, z, ref, gains, body):
        pi, vi, Ri, wi = K._vec(p[0]), K._vec(v[0]), K._mat(R[0]), K._vec(w[0])
        K._controller(pi, vi, Ri, wi, ref, gains, body, f_cmd[0])
        return K.plant_step(pi, vi, Ri, wi, f_cmd[0], eta[0], 0, True, 0.07, z[0], 0, body,
                            DT)

    one_step(s.p, s.v, s.R, s.w, f_cmd, eta, z, np.zeros((6, 3)), fast.gains_of(ctrl),
             fast.body_of(veh))
    for core in (K._rk4_c, K._controller_c):  # called per step from the inlined wrappers
        assert core.signatures, core
        for sig in core.signatures:
            flat = [t for a in sig for t in (a.types if isinstance(a, numba.types.BaseTuple)
                                             else (a,))]
            nested = [u for t in flat for u in (t.types if isinstance(t, numba.types.BaseTuple)
                                                else (t,))]
            assert not any(isinstance(t, numba.types.Array) for t in nested), (core, sig)
    for wrapper in (K.plant_step, K._rk4, K._controller, K._motor_wrench, K._tacc, K._wacc):
        assert wrapper.targetoptions.get("inline") == "always", wrapper
