"""The one closed loop (quadfault.model.closed_loop): the readable loop's results and random
numbers, one vehicle or N in parallel, the effects hook, and bad input."""

from dataclasses import replace

import numpy as np
import pytest
from support import oracles

from quadfault import jit
from quadfault.errors import ConfigError
from quadfault.model import closed_loop
from quadfault.model.controller import ControllerConfig, GeometricController
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.motors import MotorModel
from quadfault.model.plant import Plant
from quadfault.model.rotation import rot_to_quat
from quadfault.model.scenarios import named_scenario
from quadfault.model.trajectory import Hover
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import SensorNoise, SimConfig, initial_state, simulate

NOISY = SensorNoise(position=0.01, velocity=0.02, attitude=0.003, gyro=0.01, accel=0.05)
FIELDS = (
    ("position", "p"),
    ("velocity", "v"),
    ("quaternion", "q"),
    ("omega", "w"),
    ("thrust_cmd", "f"),
)


def _readable(sc, cfg, seed, vehicle=None, nominal=None, thrust_noise=None):
    vehicle = vehicle or Vehicle()
    nominal = nominal or vehicle
    if not cfg.saturate:
        vehicle = vehicle.replace(max_thrust=np.inf)
    sigma = sc.thrust_noise if thrust_noise is None else thrust_noise
    reference = cfg.integrator == "reference"
    t0 = cfg.dt if reference else 0.0
    ctrl = None if reference else GeometricController(nominal, sc.trajectory, cfg.controller)
    return oracles.closed_loop_flight(
        sc, cfg, seed, vehicle, nominal, sigma, initial_state(sc, t0, ctrl)
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    "case",
    [
        "sensor-noise",
        "decimation",
        "no-saturation",
        "nominal-mismatch",
        "no-accel-record",
        "reference",
        "no-thrust-noise",
    ],
)
def test_simulate_is_the_readable_loop_with_the_same_draws(case):
    """simulate() equals the loop written out with numpy (tests/support/oracles.py) drawing
    from the same generator in the documented order: sensors, motors, accelerometer."""
    sc, kw = named_scenario("combined", duration=0.6), {"seed": 2}
    cfg = SimConfig(sensor_noise=NOISY)
    if case == "decimation":
        cfg = replace(cfg, control_period=0.004)
    elif case == "no-saturation":
        cfg = replace(cfg, saturate=False, controller=ControllerConfig(normalize_b2d=False))
    elif case == "nominal-mismatch":
        sc = named_scenario("clipping", duration=8.0).replace(duration=0.6)
        kw.update(
            vehicle=Vehicle(mass=1.1, inertia=(0.016, 0.014, 0.03), max_thrust=3.2),
            nominal=Vehicle(),
        )
    elif case == "no-accel-record":
        cfg = replace(cfg, record_accel=False)
    elif case == "reference":
        cfg = SimConfig.reference(sensor_noise=replace(NOISY, attitude=0.0))
    else:
        sc, kw["thrust_noise"] = named_scenario("hover_fault", duration=0.6), 0.0
    rec = simulate(sc, config=cfg, **kw)
    want = _readable(sc, cfg, **kw)
    want["q"] = rot_to_quat(want["R"])
    for name, key in FIELDS:
        np.testing.assert_allclose(getattr(rec, name), want[key], rtol=0, atol=1e-9, err_msg=name)
    if cfg.record_accel:
        np.testing.assert_allclose(rec.accel, want["acc"], rtol=0, atol=1e-9)
    else:
        assert rec.accel is None
    if case == "nominal-mismatch":  # the saturation was exercised
        assert rec.thrust_cmd.max() > 3.2


def test_kernel_draws_are_the_generators_own_stream():
    """numba's Generator.standard_normal continues the numpy generator's stream, so draws
    inside a kernel are the numbers (and leave the generator where) numpy would."""
    gen, twin = np.random.default_rng(11), np.random.default_rng(11)
    named_scenario("hover", duration=0.01).replace(thrust_noise=0.1)
    plant = Plant(Vehicle(), MotorModel(0.1), dt=1e-3)
    consts = closed_loop.constants(plant, SensorNoise(gyro=0.1))
    tables = closed_loop.Tables(np.zeros(1, np.int64), np.ones((1, 5, 4)), np.zeros((1, 0, 6, 3)))
    closed_loop.fly(
        closed_loop.generators([gen]),
        0,
        5,
        True,
        consts,
        plant.vehicles,
        tables,
        closed_loop.Records.none(1, 4),
    )
    twin.standard_normal(5 * (9 + 4))  # per step: p, v, w (sensors), 4 motors (no accel)
    assert gen.standard_normal() == twin.standard_normal()


def test_seeded_runs_repeat_and_seeds_differ():
    sc = named_scenario("abrupt", duration=0.3)
    a, b, c = (simulate(sc, config=SimConfig(sensor_noise=NOISY), seed=s) for s in (3, 3, 4))
    np.testing.assert_array_equal(a.position, b.position)
    assert not np.array_equal(a.position, c.position)


def _fleet(N, seed=0, sigma=0.07):
    rng = np.random.default_rng(seed)
    veh = Vehicle()
    plant = Plant(veh, MotorModel(sigma), dt=1e-3, n_vehicles=N)
    V = plant.vehicles
    V.p[:] = rng.normal(size=(N, 3))
    V.v[:] = rng.normal(size=(N, 3))
    V.w[:] = rng.normal(size=(N, 3))
    V.f_cmd[:] = veh.hover_thrust + 0.1 * rng.normal(size=(N, 4))
    V.sigma[:] = sigma * rng.random(N)
    consts = closed_loop.constants(plant, NOISY)
    closed_loop.sense_rows(
        closed_loop.generators([np.random.default_rng(1)] * N), np.arange(0), consts, V
    )
    tables = closed_loop.Tables(
        np.zeros(N, np.int64), 0.5 + 0.5 * rng.random((N, 40, 4)), np.zeros((N, 0, 6, 3))
    )
    return plant, consts, tables


@pytest.mark.slow
def test_the_batch_is_the_single_vehicle_loop_in_any_thread_count():
    """fly_batch (parallel over vehicles, each with its generator) equals one fly per
    vehicle bit for bit, whatever the number of threads; idle rows do not move."""
    N = closed_loop.PARALLEL_MIN_VEHICLES + 3
    runs = []
    threads = jit.set_threads(None)
    for n_threads in sorted({1, threads}):
        jit.set_threads(n_threads)
        plant, consts, tables = _fleet(N)
        active = np.ones(N, bool)
        active[5] = False
        out = closed_loop.Records.empty(N, 5, 4, stride=2)
        done = closed_loop.fly_batch(
            closed_loop.generators([np.random.default_rng(s) for s in range(N)]),
            active,
            np.arange(N) % 3,
            10,
            True,
            consts,
            plant.vehicles,
            tables,
            out,
        )
        runs.append((plant.vehicles, out, done))
    jit.set_threads(threads)
    for a, b in zip(runs[0][0] + runs[0][1][1:], runs[-1][0] + runs[-1][1][1:]):
        np.testing.assert_array_equal(np.delete(a, 5, 0), np.delete(b, 5, 0))  # 5: no records
    plant, consts, tables = _fleet(N)
    assert runs[0][2][5] == 0 and np.array_equal(runs[0][0].p[5], plant.vehicles.p[5])
    for i in (0, 1, N - 1):
        one = _fleet(N)
        out = closed_loop.Records.empty(N, 5, 4, stride=2)
        gens = closed_loop.generators([np.random.default_rng(i)] * N)
        closed_loop.fly(gens, i % 3, i % 3 + 10, True, one[1], one[0].vehicles, one[2], out, i=i)
        np.testing.assert_array_equal(one[0].vehicles.p[i], runs[0][0].p[i])
        np.testing.assert_array_equal(one[0].vehicles.R[i], runs[0][0].R[i])
        np.testing.assert_array_equal(out.p[i], runs[0][1].p[i])


def test_a_diverging_vehicle_stops_alone_without_raising():
    N = closed_loop.PARALLEL_MIN_VEHICLES
    plant, consts, tables = _fleet(N)
    plant.vehicles.w[7] = (1e80, -2e80, 3e80)  # finite; the gyroscopic term overflows
    with np.errstate(over="ignore", invalid="ignore"):
        done = closed_loop.fly_batch(
            closed_loop.generators([np.random.default_rng(s) for s in range(N)]),
            np.ones(N, bool),
            np.zeros(N, np.int64),
            10,
            True,
            consts,
            plant.vehicles,
            tables,
            closed_loop.Records.none(N, 4),
        )
    assert done[7] == 1 and np.all(np.delete(done, 7) == 10)
    finite = RigidBodyState(
        *(x for x in (plant.vehicles.p, plant.vehicles.v, plant.vehicles.R, plant.vehicles.w))
    ).is_finite()
    assert not finite[7] and finite.sum() == N - 1


def test_divergence_is_a_one_line_error():
    sc = named_scenario("hover", duration=0.1).replace(trajectory=Hover(position=(np.nan, 0, -1)))
    with pytest.raises(ConfigError, match=r"diverged at t = 0\.000 s"):
        simulate(sc)


# --- the effects hook ------------------------------------------------------------------------
class Heavier:
    """A test effect with every hook of the protocol: the plant flies a heavier vehicle
    (``true_vehicle``), pushes it with a constant world force, and keeps the thrust."""

    def __init__(self, extra_mass=0.0, force=(0.0, 0.0, 0.0)):
        self.extra_mass, self.force = extra_mass, np.array(force, dtype=float)
        self.calls = {"reset": 0, "rotor_thrust": 0, "wrench": 0}

    def reset(self, n_rotors):
        self.calls["reset"] += 1

    def rotor_thrust(self, f, t, dt, state):
        self.calls["rotor_thrust"] += 1
        assert isinstance(state, RigidBodyState) and state.R.shape == (3, 3)
        return f

    def wrench(self, state, f, t):
        self.calls["wrench"] += 1
        return self.force, np.zeros(3)

    def true_vehicle(self, vehicle):
        return vehicle.replace(mass=vehicle.mass + self.extra_mass)


def test_a_neutral_effect_runs_the_interpreted_loop_to_the_compiled_numbers():
    sc = named_scenario("combined", duration=0.2)
    cfg = SimConfig(sensor_noise=NOISY)
    fx = Heavier()
    got = simulate(sc, config=cfg, effects=(fx,), seed=1)
    want = simulate(sc, config=cfg, seed=1)
    n = len(got.t)
    assert fx.calls == {"reset": 1, "rotor_thrust": n, "wrench": 4 * n}  # every RK stage
    for name in ("position", "velocity", "quaternion", "omega", "thrust_cmd", "accel"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=0, atol=1e-12)
    assert got.meta["effects"] == [{"name": "Heavier"}]


def test_true_vehicle_and_wrench_act_on_the_plant_only():
    """``true_vehicle``: the plant flies the heavier vehicle, the controller and the
    recording keep the nominal one -- the same flight as ``simulate(vehicle=heavy,
    nominal=light)``. A constant world force acts like a change of gravity."""
    sc = named_scenario("hover_fault", duration=0.5)
    light = Vehicle(max_thrust=Vehicle().rotor_max_thrust)  # the limit must not follow m g
    heavy = light.replace(mass=1.2)
    got = simulate(sc, vehicle=light, effects=(Heavier(extra_mass=0.2),), seed=3)
    want = simulate(sc, vehicle=heavy, nominal=light, seed=3)
    assert got.vehicle == light and want.vehicle == light
    for name in ("position", "quaternion", "thrust_cmd"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), atol=1e-12)
    push = simulate(sc, vehicle=light, effects=(Heavier(force=(0.0, 0.0, 0.5)),), seed=3)
    sink = simulate(sc, vehicle=light.replace(gravity=light.gravity + 0.5), nominal=light, seed=3)
    np.testing.assert_allclose(push.position, sink.position, atol=1e-12)
    assert push.position[-1, 2] > simulate(sc, vehicle=light, seed=3).position[-1, 2]  # sags


def test_effects_with_the_reference_integrator_are_refused():
    with pytest.raises(ConfigError, match="reference integrator does not support"):
        simulate(
            named_scenario("hover", duration=0.1),
            config=SimConfig.reference(),
            effects=(Heavier(),),
        )


def test_true_vehicle_must_keep_the_rotors():
    class Tri(Heavier):
        def true_vehicle(self, vehicle):
            return "not a vehicle"

    with pytest.raises(ConfigError, match="true_vehicle must return a Vehicle"):
        simulate(named_scenario("hover", duration=0.1), effects=(Tri(),))


def test_controller_must_be_geometric():
    with pytest.raises(ConfigError, match="controller must be a GeometricController"):
        simulate(named_scenario("hover", duration=0.1), controller=object())
