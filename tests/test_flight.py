"""The flight interface over the closed loop (quadfault.model.flight): seeding, the one way the
efficiency reaches the motors, batches against single flights, records."""

import numpy as np
import pytest

from quadfault.errors import ConfigError
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.flight import Flight
from quadfault.model.motors import MotorModel
from quadfault.model.plant import Plant
from quadfault.model.sensors import SensorNoise
from quadfault.model.vehicle import Vehicle

NOISY = SensorNoise(0.01, 0.02, 0.003, 0.01)


def _hover_commands(veh: Vehicle) -> np.ndarray:
    return np.full(4, veh.mass * veh.gravity / 4)


def _start(N=1):
    p = np.zeros((N, 3))
    p[:, 2] = -1.0
    return RigidBodyState(
        p, np.zeros((N, 3)), np.broadcast_to(np.eye(3), (N, 3, 3)).copy(), np.zeros((N, 3))
    )


def _flight(N=1, sigma=0.07, sensors=NOISY):
    veh = Vehicle()
    plant = Plant(veh, MotorModel(sigma), dt=1e-3, n_vehicles=N)
    return veh, Flight(plant, sensors)


def test_a_seed_repeats_a_flight_and_seeds_differ():
    runs = []
    for seed in (3, 3, 4):
        veh, flight = _flight()
        flight.reset(seed, state=_start())
        out = flight.step(_hover_commands(veh), 50, record=flight.records(50))
        runs.append(out.p[0].copy())
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0], runs[2])


def test_efficiency_reaches_the_motors_through_the_plan_only():
    """Half efficiency on every rotor: the vehicle falls at g / 2 under hover commands; the
    nominal flight (no plan) holds."""
    veh, weak = _flight(sigma=0.0, sensors=SensorNoise())
    weak.reset(0, state=_start())
    eta = weak.plan(200, lambda t: np.full((np.size(t), 4), 0.5))
    assert eta.shape == (200, 4)
    weak.step(_hover_commands(veh), 200)
    _, nominal = _flight(sigma=0.0, sensors=SensorNoise())
    nominal.reset(0, state=_start())
    nominal.step(_hover_commands(veh), 200)
    t = 0.2
    assert weak.state().v[2] == pytest.approx(0.5 * veh.gravity * t, rel=1e-6)  # NED: down
    assert abs(nominal.state().v[2]) < 1e-9


def test_a_window_refilled_in_place_stays_current():
    veh, flight = _flight(sigma=0.0, sensors=SensorNoise())
    eta, first = np.ones((1, 10, 4)), np.zeros(1, dtype=np.int64)
    flight.use_efficiency(eta, first)
    flight.reset(0, state=_start())
    flight.step(_hover_commands(veh), 10)
    assert abs(flight.state().v[2]) < 1e-9
    eta[:] = 0.5  # the caller's next window, written into the same arrays
    first[:] = 10
    flight.step(_hover_commands(veh), 10)
    assert flight.state().v[2] == pytest.approx(0.5 * veh.gravity * 0.01, rel=1e-6)


def test_a_batch_equals_single_flights_and_idle_rows_keep_still():
    N, n = 5, 30
    veh, batch = _flight(N)
    batch.reset(list(range(10, 10 + N)), state=_start(N))
    active = np.array([True, False, True, True, False])
    before = batch.state(1)
    out = batch.step(
        np.tile(_hover_commands(veh), (N, 1)), n, record=batch.records(n), active=active
    )
    np.testing.assert_array_equal(batch.state(1).p, before.p)
    np.testing.assert_array_equal(out.p[1], np.broadcast_to(batch.measured(1).p, (n, 3)))
    assert batch.k.tolist() == [n, 0, n, n, 0]
    for i in np.flatnonzero(active):
        _, one = _flight()
        one.reset(10 + int(i), state=_start())
        rec = one.step(_hover_commands(veh), n, record=one.records(n))
        np.testing.assert_allclose(out.p[i], rec.p[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(batch.state(int(i)).R, one.state().R, rtol=0, atol=1e-12)


def test_bad_input_gives_clear_errors():
    with pytest.raises(ConfigError, match="MotorModel"):
        Plant(Vehicle(), None, MotorModel(0.1))  # the efficiency is no longer the plant's
    veh, flight = _flight(2)
    with pytest.raises(ConfigError, match="seeds"):
        flight.reset([1, 2, 3])
    with pytest.raises(ConfigError, match="efficiency table"):
        flight.use_efficiency(np.ones((1, 5, 4)), np.zeros(1, dtype=np.int64))
    with pytest.raises(ConfigError, match="reset"):
        flight.step(np.zeros(4), 1)


def test_an_env_whose_generator_is_replaced_flies_on_the_new_one():
    """The single env's flight draws from the env's generator, also after a wrapper or a
    user assigns ``env.np_random``."""
    from quad_fault_env.envs.quad_fault import QuadFaultEnv

    runs = []
    for replace in (True, True, False):
        env = QuadFaultEnv("none", "hover", duration=1.0, thrust_noise=0.1, sensor_noise=NOISY)
        env.reset(seed=1)
        if replace:
            env.np_random = np.random.default_rng(99)
        obs = [env.step(np.zeros(4, dtype=np.float32))[0] for _ in range(5)]
        runs.append(np.array(obs))
        if replace:
            assert env.flight.generator(0) is env.np_random
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0], runs[2])
