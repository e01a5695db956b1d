"""The accelerometer in the measurement stream: a Sample carries it where the source has
one (recordings with ax..az, the single and vector envs, the agents' rollout), and None
where it has not; every estimator takes samples with and without it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agents.rollout import fly
from estimators.base import Sample, samples
from estimators.registry import make_estimator
from quad_fault_env.envs.quad_fault import QuadFaultEnv
from quad_fault_env.vector import QuadFaultVectorEnv
from quadfault.model.scenarios import named_scenario
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate

NOISE = SensorNoise(position=0.001, velocity=0.005, attitude=0.002, gyro=0.005, accel=0.05)


@pytest.fixture(scope="module")
def recording():
    return simulate(
        named_scenario("abrupt", 0.3), config=SimConfig(sensor_noise=NOISE), seed=2
    ).without_truth()


def test_a_sample_without_accelerometer_is_none_and_old_callers_keep_working():
    s = Sample(0.0, np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3), np.ones(4))
    assert s.accel is None
    assert len(s) == 7 and s._fields[-1] == "accel"


def test_samples_carry_the_recordings_accelerometer(recording):
    rows = list(samples(recording))
    assert recording.accel is not None
    got = np.array([s.accel for s in rows])
    np.testing.assert_array_equal(got, recording.accel)
    # hovering: the specific force is about -g along body z
    assert abs(np.median(got[:, 2]) + recording.vehicle.gravity) < 1.0
    bare = list(samples(dataclasses.replace(recording, accel=None)))
    assert all(s.accel is None for s in bare)


@pytest.mark.parametrize("name", ["irls", "ekf", "rls", "ukf"])
def test_every_estimator_takes_samples_with_and_without_accelerometer(recording, name):
    est = make_estimator(name, recording.vehicle)
    for s in samples(recording):
        out = est.update(s)
    assert np.all(np.isfinite(out.eta))
    plain = [s._replace(accel=None) for s in samples(recording)]
    est.reset()
    for s in plain:
        out = est.update(s)
    assert np.all(np.isfinite(out.eta))


def test_the_single_env_feeds_the_estimator_its_accelerometer():
    env = QuadFaultEnv("irls", info="full", sensor_noise=NOISE)
    env.reset(seed=4)
    _, _, _, _, info = env.step(np.zeros(4, dtype=np.float32))
    acc = np.array([s.accel for s in info["samples"]])
    np.testing.assert_array_equal(acc, info["specific_force_samples"][: len(acc)])
    assert np.all(np.isfinite(acc)) and np.all(acc[:, 2] < -5.0)


def test_the_vector_env_records_the_accelerometer_of_its_single_envs():
    vec = QuadFaultVectorEnv(2, "irls", info="full", sensor_noise=NOISE)
    single = QuadFaultEnv("irls", info="full", sensor_noise=NOISE)
    vec.reset(seed=7)
    single.reset(seed=8)  # sub-env 1 of the vector env
    a = np.zeros((2, 4), dtype=np.float32)
    for _ in range(3):
        vec.step(a)
        info = single.step(a[1])[4]
        fed = np.array([s.accel for s in info["samples"]])[:: single.estimator_stride]
        np.testing.assert_allclose(vec._records.accel[1], fed, rtol=0, atol=1e-12)


def test_the_rollout_measures_the_accelerometer_for_its_estimator():
    seen = []

    class Spy:  # a real estimator, wrapped to see what it is fed
        name = "irls"

        def __init__(self, vehicle):
            self.inner = make_estimator("irls", vehicle)

        def reset(self, eta0=None):
            self.inner.reset()

        def update(self, sample):
            seen.append(sample.accel)
            return self.inner.update(sample)

    fly(named_scenario("abrupt", 0.2), "estimate-aware", Spy(Vehicle()), seed=1)
    acc = np.array(seen)
    assert acc.shape == (len(seen), 3) and np.all(np.isfinite(acc))
    assert abs(np.median(acc[:, 2]) + Vehicle().gravity) < 1.0


def test_the_vector_envs_improved_irls_reads_the_accelerometer_as_the_single_envs_does():
    from estimators.irls import IRLSConfig

    kw = {"config": IRLSConfig.improved()}  # accelerometer "auto"
    vec = QuadFaultVectorEnv(2, "irls", estimator_kwargs=kw, info="full", sensor_noise=NOISE)
    singles = [
        QuadFaultEnv("irls", estimator_kwargs=kw, info="full", sensor_noise=NOISE) for _ in range(2)
    ]
    vec.reset(seed=3)
    for i, env in enumerate(singles):
        env.reset(seed=3 + i)
    a = np.zeros((2, 4), dtype=np.float32)
    for _ in range(20):
        info = vec.step(a)[4]
        for i, env in enumerate(singles):
            one = env.step(a[i])[4]
            np.testing.assert_allclose(info["eta_hat"][i], one["eta_hat"], rtol=0, atol=1e-12)
    assert info["estimator_status"][0] == "ok"
