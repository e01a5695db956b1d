"""The sensor model (quadfault.model.sensors) inside the compiled loop: seeded flights give the
white noise, the coloured noise's variance and correlation time, the per-flight bias, the
latency and the rate that were asked for; presets by name and clear one-line errors."""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest

from quadfault.errors import ConfigError
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.flight import Flight
from quadfault.model.motors import MotorModel
from quadfault.model.plant import Plant
from quadfault.model.sensor_presets import PRESETS, as_sensor_noise
from quadfault.model.sensors import COLOURED_SHAPE, STREAMS, SensorNoise
from quadfault.model.vehicle import Vehicle

DT = 1e-3


def _start(N):
    p = np.zeros((N, 3))
    p[:, 2] = -1.0
    eye = np.broadcast_to(np.eye(3), (N, 3, 3)).copy()
    return RigidBodyState(p, np.zeros((N, 3)), eye, np.zeros((N, 3)))


def _fly(sensors, steps, N=1, seed=0, eta=1.0):
    """Hover commands on a noise-free plant (at rest for eta = 1; falling at g (1 - eta)
    otherwise): the records and the flight."""
    veh = Vehicle()
    flight = Flight(Plant(veh, MotorModel(0.0), dt=DT, n_vehicles=N), sensors)
    flight.reset([seed + i for i in range(N)], state=_start(N))
    if eta != 1.0:
        flight.use_efficiency(np.full((N, steps + 1, 4), eta), np.zeros(N, dtype=np.int64))
    rec = flight.step(
        np.full(4, veh.mass * veh.gravity / 4),
        steps,
        record=flight.records(steps),
        measure_first=False,
    )
    return rec, flight


def _per_stream(**numbers) -> SensorNoise:
    """One stream's numbers, e.g. ``_per_stream(stream="velocity", markov=0.02, tau=0.05)``."""
    s = STREAMS.index(numbers.pop("stream"))
    white = numbers.pop("white", 0.0)
    fields = {}
    for k, v in numbers.items():
        five = [0.0] * 5 if k != "tau" else [1.0] * 5
        five[s] = v
        fields[k] = tuple(five)
    return SensorNoise(**{STREAMS[s]: white}, **fields)


def test_white_noise_at_a_rate_is_held_between_samples():
    noise = _per_stream(stream="position", white=0.01, rate=100.0)
    rec, _ = _fly(noise, 20_000)
    err = rec.p[0] - np.array([0.0, 0.0, -1.0])
    changes = np.flatnonzero(np.any(np.diff(err, axis=0) != 0, axis=1))
    assert np.all(np.diff(changes) == 10)  # a new sample every 10 physics steps (100 Hz)
    samples = err[changes + 1]
    assert samples.std() == pytest.approx(0.01, rel=0.05)
    assert abs(samples.mean()) < 0.001
    # the other streams stay the truth
    np.testing.assert_array_equal(rec.v[0], 0.0)
    np.testing.assert_array_equal(rec.w[0], 0.0)


def test_coloured_noise_has_its_variance_and_correlation_time():
    noise = _per_stream(stream="velocity", markov=0.02, tau=0.05)
    rec, _ = _fly(noise, 30_000)
    e = rec.v[0]
    assert e.std() == pytest.approx(0.02, rel=0.1)
    lag = 50  # tau / dt
    r = np.mean([np.corrcoef(e[:-lag, a], e[lag:, a])[0, 1] for a in range(3)])
    assert r == pytest.approx(np.exp(-1.0), abs=0.08)
    # second order (smooth): one step's correlation is (1 + x) exp(-x), x = dt / T,
    # T = tau / COLOURED_SHAPE, not a first-order process's exp(-dt / tau)
    x = DT * COLOURED_SHAPE / 0.05
    r1 = np.mean([np.corrcoef(e[:-1, a], e[1:, a])[0, 1] for a in range(3)])
    assert r1 == pytest.approx((1 + x) * np.exp(-x), abs=2e-4)
    assert abs(r1 - np.exp(-DT / 0.05)) > 0.01


def test_coloured_noise_is_stepped_exactly_at_a_low_rate():
    """At 20 Hz (a step of 0.43 time constants) the samples keep the stationary variance and
    the second-order process's correlation between samples: the step is exact, not Euler."""
    noise = _per_stream(stream="position", markov=0.01, tau=0.1, rate=20.0)
    rec, _ = _fly(noise, 40_000)
    e = rec.p[0] - np.array([0.0, 0.0, -1.0])
    samples = e[::50]  # one per sample period
    assert samples.std() == pytest.approx(0.01, rel=0.1)
    x = 0.05 * COLOURED_SHAPE / 0.1
    r = np.mean([np.corrcoef(samples[:-1, a], samples[1:, a])[0, 1] for a in range(3)])
    assert r == pytest.approx((1 + x) * np.exp(-x), abs=0.04)


def test_a_bias_is_constant_over_a_flight_and_drawn_per_flight():
    noise = _per_stream(stream="gyro", bias=0.05)
    rec, flight = _fly(noise, 20, N=400)
    per_flight = rec.w[:, :, :]
    np.testing.assert_array_equal(per_flight, np.repeat(per_flight[:, :1], 20, axis=1))  # constant
    assert per_flight[:, 0].std() == pytest.approx(0.05, rel=0.1)  # spread over flights
    # a new flight of the same vehicle draws a new bias; the same seed the same one
    first = per_flight[0, 0].copy()
    flight.reset(list(range(400)), state=_start(400))
    again = flight.step(None, 5, record=flight.records(5), measure_first=False).w[0, 0]
    np.testing.assert_array_equal(again, first)
    flight.reset(list(range(1000, 1400)), state=_start(400))
    other = flight.step(None, 5, record=flight.records(5), measure_first=False).w[0, 0]
    assert not np.array_equal(other, first)


def test_latency_delays_the_truth_by_whole_steps():
    """A vehicle falling at half efficiency: the delayed velocity and accelerometer are the
    noise-free flight's, 20 steps late."""
    steps, d = 400, 20
    truth, _ = _fly(SensorNoise(), steps, eta=0.5)
    late, _ = _fly(SensorNoise(latency=(0.0, d * DT, 0.0, 0.0, d * DT)), steps, eta=0.5)
    np.testing.assert_allclose(late.v[0, d:], truth.v[0, :-d], rtol=0, atol=1e-12)
    np.testing.assert_allclose(late.v[0, :d], truth.v[0, :1].repeat(d, 0), atol=1e-12)
    np.testing.assert_allclose(late.accel[0, d + 1 :], truth.accel[0, 1:-d], atol=1e-9)
    np.testing.assert_allclose(late.p[0], truth.p[0], atol=1e-12)  # no latency on p
    assert truth.v[0, -1, 2] > 0.5  # (it does fall: the test can fail)


def test_attitude_noise_is_a_rotation():
    noise = _per_stream(stream="attitude", white=0.01, markov=0.01, tau=0.1, bias=0.01)
    rec, _ = _fly(noise, 2000)
    R = rec.R[0]
    np.testing.assert_allclose(
        np.einsum("nji,njk->nik", R, R), np.eye(3)[None].repeat(2000, 0), atol=1e-9
    )
    assert 0.005 < np.abs(R - np.eye(3)).max() < 0.2


def test_the_batch_and_single_flights_draw_the_same_numbers():
    noise = PRESETS["crazyflie"]
    batch, _ = _fly(noise, 300, N=3, seed=7)
    for i in range(3):
        one, _ = _fly(noise, 300, N=1, seed=7 + i)
        np.testing.assert_array_equal(batch.p[i], one.p[0])
        np.testing.assert_array_equal(batch.accel[i], one.accel[0])


def test_white_noise_alone_keeps_the_white_kernels():
    assert not SensorNoise(0.01, 0.02, 0.003, 0.01, 0.1).model
    assert SensorNoise(0.01, rate=100).model
    assert not SensorNoise().any and SensorNoise(latency=0.01).any


# -- presets and errors -----------------------------------------------------------------------
def test_presets_by_name_and_forms():
    assert as_sensor_noise("crazyflie") is PRESETS["crazyflie"]
    assert as_sensor_noise(" PX4 ") is PRESETS["px4"]
    assert as_sensor_noise("none") == SensorNoise(name="none")
    assert not as_sensor_noise(None).any
    assert as_sensor_noise("0.1,0.2,0.3,0.4").white == (0.1, 0.2, 0.3, 0.4, 0.0)
    assert as_sensor_noise([0.1, 0.2, 0.3, 0.4, 0.5]).accel == 0.5
    changed = as_sensor_noise({"preset": "crazyflie", "gyro": 0.05})
    assert changed.gyro == 0.05 and changed.rate == PRESETS["crazyflie"].rate
    for name, noise in PRESETS.items():
        assert noise.name == name
        assert SensorNoise(**noise.fields()) == noise


@pytest.mark.parametrize(
    "value, message",
    [
        ("bogus", r"unknown sensor noise preset 'bogus'; presets: none, crazyflie"),
        ("0.1,0.2,0.3", r"4 or 5 numbers .* got 3"),
        ([0.1, 0.2], r"4 or 5 numbers"),
        ("0.1,x,0.3,0.4", r"preset name or 4 or 5 numbers"),
        ("0.1,-1,0.3,0.4", r">= 0"),
        ({"gyro": 0.1, "colour": 1}, r"unknown keys \['colour'\]"),
        ({"markov": (0.1, 0.2, 0.3)}, r"markov must have 5 values .* got shape \(3,\)"),
        ({"rate": [[1, 2, 3, 4, 5]]}, r"rate must have 5 values"),
        ({"tau": (1, 1, 0, 1, 1)}, r"tau of attitude must be > 0"),
        ({"preset": "nope"}, r"presets: none"),
        (0.1, r"sensor_noise must be a preset name"),
    ],
)
def test_bad_sensor_noise_is_a_one_line_error(value, message):
    with pytest.raises(ConfigError, match=message) as err:
        as_sensor_noise(value)
    assert "\n" not in str(err.value)


def test_simulate_takes_a_preset_and_names_an_unknown_one(tmp_path):
    from quadfault.cli import main
    from quadfault.io.recording import read_recording

    def cli(*argv):
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main([str(a) for a in argv])
            except SystemExit as exc:
                code = exc.code
        return code, err.getvalue()

    base = ["simulate", "--scenario", "hover", "--duration", "0.5", "--seed", "1"]
    code, err = cli(*base, "--sensor-noise", "crazyfly", "--out", tmp_path / "a.csv")
    assert code == 2 and err.count("\n") == 1
    assert "unknown sensor noise preset 'crazyfly'; presets: none, crazyflie" in err
    code, err = cli(*base, "--sensor-noise", "1,2,3", "--out", tmp_path / "b.csv")
    assert code == 2 and "4 or 5 numbers" in err and err.count("\n") == 1
    code, _ = cli(*base, "--sensor-noise", "crazyflie", "--out", tmp_path / "c.csv")
    assert code == 0
    rec = read_recording(tmp_path / "c.csv")
    assert rec.meta["sensor_noise"]["name"] == "crazyflie"
    held = np.any(np.diff(rec.position, axis=0) != 0, axis=1)
    assert held.mean() == pytest.approx(0.1, abs=0.01)  # 100 Hz position in a 1 kHz file


def test_every_env_id_and_the_vector_env_take_a_preset_by_name():
    import gymnasium as gym

    import quad_fault_env

    for env_id in quad_fault_env.ENVIRONMENTS:
        env = gym.make(env_id, sensor_noise="px4", estimator="none")
        assert env.unwrapped.sensor_noise is PRESETS["px4"]
        obs, _ = env.reset(seed=0)
        obs, *_ = env.step(env.action_space.sample() * 0)
        assert np.all(np.isfinite(obs))
        env.close()
    vec = gym.make_vec(
        "QuadFaultHover-v1",
        num_envs=2,
        vectorization_mode="vector_entry_point",
        sensor_noise="crazyflie",
        estimator="none",
    )
    assert vec.unwrapped.flight.sensors is PRESETS["crazyflie"]
    vec.close()
    with pytest.raises(ConfigError, match=r"presets: none, crazyflie"):
        gym.make("QuadFaultHover-v1", sensor_noise="crazy")
