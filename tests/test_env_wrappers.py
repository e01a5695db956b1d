"""Wrappers of quad_fault_env: estimate observation, estimator comparison, flight recording."""

from __future__ import annotations

import importlib.util
import json
import math

import numpy as np
import pytest

from estimators.base import Estimate
from quad_fault_env.envs.quad_fault import QuadFaultEnv
from quad_fault_env.wrappers import EfficiencyEstimateObservation, EstimatorComparison, RecordFlight
from quadfault.errors import ConfigError
from quadfault.io.recording import read_recording
from quadfault.model.rotation import quat_to_rot
from quadfault.model.scenarios import named_scenario


class FrozenEstimator:
    """Test double: reports a fixed eta; counts updates."""

    def __init__(self, eta=(1.0, 1.0, 1.0, 1.0), name="frozen"):
        self.name = name
        self.eta = np.asarray(eta, dtype=float)
        self.n = 0

    def reset(self, eta0=None):
        self.n = 0

    def update(self, sample):
        self.n += 1
        return Estimate(sample.t, self.eta.copy(), np.full(4, 0.2))


def _episode(env, n_steps, seed=0):
    obs, info = env.reset(seed=seed)
    steps = [(obs, info)]
    for _ in range(n_steps):
        obs, r, terminated, truncated, info = env.step(np.zeros(4, dtype=np.float32))
        steps.append((obs, info))
        if terminated or truncated:
            break
    return steps


def _abrupt(duration=1.2):
    # the reference schedule scaled to `duration`: motor k at 50 % from m_k T / 12 for T / 24,
    # m = 1, 4, 7, 10 (for 1.2 s: motor 1 on [0.1, 0.15] s, motor 2 on [0.4, 0.45] s, ...)
    return named_scenario("abrupt", duration).replace(thrust_noise=0.0)


def test_estimate_observation_replaces_slots_from_any_estimator():
    base = QuadFaultEnv("none", "hover_fault", duration=1.0, info="full")
    frozen = FrozenEstimator((0.7, 0.8, 0.9, 1.0))
    env = EfficiencyEstimateObservation(base, frozen)
    steps = _episode(env, 5)
    sl, sd = base.layout.slice("eta_hat"), base.layout.slice("eta_sd")
    np.testing.assert_array_equal(steps[0][0][sl], 1.0)  # before any update
    np.testing.assert_array_equal(steps[0][0][sd], 10.0)
    for obs, info in steps[1:]:
        np.testing.assert_allclose(obs[sl], [0.7, 0.8, 0.9, 1.0], rtol=1e-6)
        np.testing.assert_allclose(obs[sd], 0.2, rtol=1e-6)
        assert info["estimator"] == "frozen"
        assert base.observation_space.contains(obs)
    assert frozen.n == 5 * 10 // base.estimator_stride
    # the rest of the observation is the env's
    raw = _episode(QuadFaultEnv("none", "hover_fault", duration=1.0, info="full"), 5)
    other = np.ones(base.observation_space.shape, bool)
    other[sl] = other[sd] = False
    np.testing.assert_array_equal(steps[-1][0][other], raw[-1][0][other])


def test_estimate_observation_with_the_oracle_and_dict_observations():
    base = QuadFaultEnv("none", "hover_fault", duration=1.0, observation="dict", info="full")
    env = EfficiencyEstimateObservation(base, "truth", stride=1)
    for obs, info in _episode(env, 40)[35:]:
        np.testing.assert_allclose(obs["eta_hat"], info["eta_true_samples"][-1], rtol=1e-6)
        assert info["eta_true_samples"][-1][0] == 0.5


def test_estimator_comparison_summary_keys_and_scores():
    truth_like = FrozenEstimator(name="ones")  # eta = 1: wrong during the fault windows
    env = EstimatorComparison(
        QuadFaultEnv("none", _abrupt(), info="full"), {"oracle": "truth", "ones": truth_like}
    )
    steps = _episode(env, 200)
    last = steps[-1][1]["comparison"]
    assert set(last) == {"oracle", "ones"}
    np.testing.assert_array_equal(last["oracle"]["rmse"], 0.0)
    s = env.summary()
    assert set(s) == {"estimators", "episodes", "current"}
    assert s["estimators"] == ["oracle", "ones"]
    cur = s["current"]
    for name in ("oracle", "ones"):
        assert set(cur[name]) == {"rmse", "spike", "latency", "n_updates"}
        assert cur[name]["n_updates"] == 1200 // env.stride
        assert len(cur[name]["rmse"]) == len(cur[name]["spike"]) == len(cur[name]["latency"]) == 4
    assert cur["oracle"]["rmse"] == [0.0] * 4 and cur["oracle"]["spike"] == [0.0] * 4
    assert cur["oracle"]["latency"] == [0.0] * 4
    # eta = 1 misses each 50 % fault: error 0.5 over 1/24 of the flight -> RMSE 0.5/sqrt(24)
    np.testing.assert_allclose(cur["ones"]["rmse"], 0.5 / math.sqrt(24), rtol=0.03)
    assert cur["ones"]["latency"] == [math.inf] * 4
    # the healthy motors are exact during the other motors' faults
    assert cur["ones"]["spike"] == [0.0] * 4
    np.testing.assert_allclose(last["ones"]["rmse"], cur["ones"]["rmse"])
    env.reset(seed=1)
    assert len(env.summary()["episodes"]) == 1
    json.dumps(env.summary())  # JSON-ready (inf is allowed by the json module)


def test_estimator_comparison_no_faults_gives_null_spike_and_latency():
    env = EstimatorComparison(
        QuadFaultEnv("none", "hover", duration=0.1, info="full"), {"a": FrozenEstimator()}
    )
    _episode(env, 20)
    cur = env.summary()["current"]["a"]
    assert cur["spike"] is None and cur["latency"] == [None] * 4


@pytest.mark.skipif(
    importlib.util.find_spec("estimators.ekf") is None
    or importlib.util.find_spec("estimators.irls") is None,
    reason="IRLS / EKF not available",
)
def test_estimator_comparison_runs_irls_and_ekf():
    from estimators.ekf import EKFConfig, MotorEfficiencyEKF
    from estimators.irls import IRLSConfig, SlidingWindowIRLS

    base = QuadFaultEnv("none", "hover_fault", duration=0.6, estimator_rate="control", info="full")
    default = EstimatorComparison(base)
    assert {n: e.name for n, e in default.estimators.items()} == {"irls": "irls", "ekf": "ekf"}
    # the numpy backends: same results, and no numba compilation inside this test
    v = base.vehicle
    env = EstimatorComparison(
        base,
        {"irls": SlidingWindowIRLS(v, IRLSConfig()), "ekf": MotorEfficiencyEKF(v, EKFConfig())},
    )
    steps = _episode(env, 60)
    assert set(steps[-1][1]["comparison"]) == {"irls", "ekf"}
    cur = env.summary()["current"]
    for name in ("irls", "ekf"):
        assert cur[name]["n_updates"] == 60
        assert all(np.isfinite(cur[name]["rmse"]))
        # motor 1 drops to 50 % at 0.18 s: both estimators see it
        assert steps[-1][1]["comparison"][name]["eta"][0] < 0.75


@pytest.mark.slow
def test_estimator_comparison_runs_any_set_of_registered_estimators():
    """IRLS, the EKF, RLS and the UKF side by side on one measurement stream, by name."""
    base = QuadFaultEnv("none", "hover_fault", duration=0.6, estimator_rate="control", info="full")
    names = ("irls", "ekf", "rls", "ukf")
    env = EstimatorComparison(base, {n: n for n in names})
    steps = _episode(env, 60)
    assert set(steps[-1][1]["comparison"]) == set(names)
    cur = env.summary()["current"]
    for name in names:
        assert cur[name]["n_updates"] == 60 and all(np.isfinite(cur[name]["rmse"]))
        # motor 1 drops to 50 % at 0.18 s: every estimator sees it
        assert steps[-1][1]["comparison"][name]["eta"][0] < 0.75, name


def test_record_flight_writes_loadable_recordings(tmp_path):
    base = QuadFaultEnv("none", _abrupt(0.3), thrust_noise=0.05, info="full")
    env = RecordFlight(base, tmp_path / "flight")
    steps = _episode(env, 100, seed=4)
    assert len(steps) == 31  # 0.3 s at 100 Hz, truncated
    _episode(env, 7, seed=5)  # cut short: written at close()
    env.close()
    assert [p.name for p in env.paths] == ["flight_000.csv", "flight_001.csv"]
    rec = read_recording(env.paths[0])
    assert len(rec) == 300
    np.testing.assert_allclose(rec.t, np.arange(300) * 1e-3, atol=1e-12)
    samples = [s for _, info in steps[1:] for s in info["samples"]]
    np.testing.assert_allclose(rec.position, [s.p for s in samples], atol=1e-12)
    np.testing.assert_allclose(rec.thrust_cmd, [s.f for s in samples], atol=1e-12)
    np.testing.assert_allclose(quat_to_rot(rec.quaternion), [s.R for s in samples], atol=1e-9)
    # motor 1 is at 50 % on [0.025, 0.0375] s of this 0.3 s schedule
    assert rec.eta_true[30, 0] == 0.5 and rec.eta_true[30, 1] == 1.0
    assert rec.eta_true[150, 0] == 1.0
    assert rec.accel is not None and rec.accel[0, 2] < -5.0  # FRD specific force ~ -g
    assert rec.meta["scenario"] == "abrupt" and rec.meta["seed"] == 4
    assert rec.vehicle == base.vehicle
    assert len(read_recording(env.paths[1])) == 70
    with pytest.raises(ConfigError, match="never overwrites"):
        RecordFlight(QuadFaultEnv("none", "hover", info="full"), tmp_path / "flight.csv")
    with pytest.raises(ConfigError, match="folder does not exist"):
        RecordFlight(QuadFaultEnv("none", "hover", info="full"), tmp_path / "missing" / "flight")


def test_record_flight_enu_round_trip(tmp_path):
    env = RecordFlight(
        QuadFaultEnv("none", "hover", duration=0.05, info="full"), tmp_path / "f", frame="ENU"
    )
    steps = _episode(env, 10)
    rec = read_recording(env.paths[0])
    assert rec.frame == "ENU"
    np.testing.assert_allclose(rec.position[-1], steps[-1][1]["samples"][-1].p, atol=1e-9)


@pytest.mark.parametrize(
    "wrap",
    [
        lambda env: EfficiencyEstimateObservation(env, "irls"),
        EstimatorComparison,
        lambda env: RecordFlight(env, "flight"),
    ],
)
def test_wrappers_of_the_measurement_stream_refuse_a_light_info(wrap):
    """The stream lives in the full info: a light env is a one-line error naming the fix."""
    with pytest.raises(ConfigError, match="info='full'"):
        wrap(QuadFaultEnv("none", "hover"))
