"""The task ids QuadFaultTrack-v0 and QuadFaultRotorLoss-v0: checkers, determinism, the
native vector env against single envs, options, and a small vehicle on the track task."""

import gymnasium as gym
import numpy as np
import pytest

import quad_fault_env  # noqa: F401  (registers the ids)
from quad_fault_env.envs.quad_fault import QuadFaultEnv
from quad_fault_env.vector import QuadFaultVectorEnv
from quadfault.errors import ConfigError
from quadfault.model.sensors import SensorNoise
from quadfault.model.task_scenarios import SmoothTrack, size_scale
from quadfault.model.vehicle import Vehicle

TASK_IDS = ("QuadFaultTrack-v0", "QuadFaultRotorLoss-v0")


@pytest.mark.parametrize("env_id", TASK_IDS)
def test_both_checkers_pass(env_id):
    from gymnasium.utils.env_checker import check_env

    env = gym.make(env_id, duration=0.3, estimator="none")
    check_env(env.unwrapped, skip_render_check=True)
    sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
    sb3.check_env(gym.make(env_id, duration=0.3, estimator="none").unwrapped, warn=True)


@pytest.mark.parametrize("env_id", TASK_IDS)
def test_same_seed_same_episode_other_seed_other_scenario(env_id):
    def episode(seed):
        env = gym.make(env_id, duration=0.5)
        obs, info = env.reset(seed=seed)
        sc = env.unwrapped.scenario
        rows = [obs]
        for k in range(20):
            obs, r, *_ = env.step(np.full(4, 0.1 * np.sin(k)))
            rows.append(obs)
        return sc, np.array(rows)

    sc_a, a = episode(3)
    sc_b, b = episode(3)
    sc_c, _ = episode(4)
    assert sc_a == sc_b and np.array_equal(a, b)
    assert sc_a != sc_c


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["track", "rotor_loss"])
def test_vector_env_matches_single_envs(scenario):
    n, seed, kw = (
        3,
        11,
        dict(
            scenario=scenario,
            duration=0.25,
            estimator_rate="control",
            sensor_noise=SensorNoise(0.01, 0.02, 0.005, 0.01),
        ),
    )
    vec = QuadFaultVectorEnv(n, "irls", **kw)
    singles = [QuadFaultEnv("irls", **kw) for _ in range(n)]
    obs, _ = vec.reset(seed=seed)
    ref = np.array([e.reset(seed=seed + i)[0] for i, e in enumerate(singles)])
    np.testing.assert_allclose(obs, ref, rtol=0, atol=1e-9)
    assert len({repr(s) for s in vec.scenarios}) == n  # a scenario per row
    rng, done, episodes = np.random.default_rng(seed), np.zeros(n, bool), 0
    for k in range(60):
        a = rng.uniform(-1, 1, (n, 4)).astype(np.float32)
        obs, rew, term, trunc, _ = vec.step(a)
        for i, env in enumerate(singles):
            o, r, te, tr = (env.reset()[0], 0.0, False, False) if done[i] else env.step(a[i])[:4]
            np.testing.assert_allclose(obs[i], o, rtol=0, atol=1e-9, err_msg=f"{k} {i}")
            assert abs(rew[i] - r) <= 1e-9 and (term[i], trunc[i]) == (te, tr)
        done = term | trunc
        episodes += int(done.sum())
    assert episodes >= 2 * n


def test_rotor_loss_draws_from_its_options_and_bad_options_are_refused():
    env = QuadFaultEnv(
        "none",
        "rotor_loss",
        duration=2.0,
        scenario_options={"level": (0.2, 0.3), "onset": (0.5, 0.5)},
    )
    for seed in range(5):
        env.reset(seed=seed)
        (fault,) = env.scenario.efficiency.faults
        assert 0.2 <= fault.level <= 0.3 and fault.onset == 1.0
    with pytest.raises(ConfigError, match="unknown keys"):
        QuadFaultEnv("none", "rotor_loss", scenario_options={"speed": (1, 2)})
    with pytest.raises(ConfigError, match="level"):
        QuadFaultEnv("none", "rotor_loss", scenario_options={"level": (0.5, 2.0)})
    with pytest.raises(ConfigError, match="applies to scenario"):
        QuadFaultEnv("none", "hover", scenario_options={"level": (0.1, 0.2)})


def test_a_crazyflie_flies_the_track_task_scaled_to_its_size():
    """The track scales with the vehicle (Froude) and the controller's gains with its mass and
    inertia: the geometric controller (zero residual) flies a 30 g vehicle through a whole
    episode: from its initial offset (the task's spread) to within 1 cm after 2 s."""
    cf = Vehicle.from_arm(0.046, 0.006, mass=0.03, inertia=np.diag([1.4e-5, 1.4e-5, 2.2e-5]))
    env = gym.make("QuadFaultTrack-v0", vehicle=cf, estimator="none", duration=5.0, info="full")
    env.reset(seed=0)
    tr = env.unwrapped.scenario.trajectory
    assert isinstance(tr, SmoothTrack)
    assert max(abs(a) for a in tr.amplitude) <= size_scale(cf) / 0.3 + 1e-12
    errors = []
    while True:
        _, _, term, trunc, info = env.step(np.zeros(4))
        errors.append(info["tracking_error"])
        if term or trunc:
            break
    assert not term and len(errors) == 500 and max(errors[200:]) < 0.01


def test_sensor_noise_as_a_dict_equals_the_dataclass_and_bad_keys_are_named():
    """JSON keywords (``quadfault train --env-kwargs``) can switch the sensor noise on."""
    a = QuadFaultEnv(
        "none", "rotor_loss", duration=0.2, sensor_noise={"position": 0.01, "gyro": 0.02}
    )
    b = QuadFaultEnv(
        "none", "rotor_loss", duration=0.2, sensor_noise=SensorNoise(position=0.01, gyro=0.02)
    )
    assert a.sensor_noise == b.sensor_noise
    oa, ob = a.reset(seed=5)[0], b.reset(seed=5)[0]
    for _ in range(5):
        oa, ob = a.step(np.zeros(4))[0], b.step(np.zeros(4))[0]
    np.testing.assert_array_equal(oa, ob)
    with pytest.raises(ConfigError, match="sensor_noise has unknown keys"):
        QuadFaultEnv("none", "hover", sensor_noise={"pos": 0.01})
    with pytest.raises(ConfigError, match="sensor noise gyro"):
        QuadFaultEnv("none", "hover", sensor_noise={"gyro": -1.0})


@pytest.mark.slow
def test_drag_learnt_by_the_diagnosis_flies_in_the_env_and_is_found_again(tmp_path):
    """simulate a drag flight -> diagnose -> gym.make(model=...) + RecordFlight -> diagnose:
    the calibrated env's recording gives back the same drag (within 20 % on every axis)."""
    import json

    from quad_fault_env.wrappers import RecordFlight
    from quadfault.cli import main
    from quadfault.model.scenarios import named_scenario
    from quadfault.model.trajectory import Lissajous

    first, diag1, diag2 = tmp_path / "drag.csv", tmp_path / "d1.json", tmp_path / "d2.json"
    assert (
        main(
            [
                "simulate",
                "--scenario",
                "nominal",
                "--trajectory",
                "lissajous",
                "--effect",
                "drag=0.3",
                "--duration",
                "20",
                "--seed",
                "0",
                "--out",
                str(first),
                "--quiet",
            ]
        )
        == 0
    )
    assert main(["diagnose", str(first), "--json", str(diag1), "--quiet"]) == 0
    sc = named_scenario("nominal", 20.0).replace(trajectory=Lissajous())
    env = RecordFlight(
        gym.make("QuadFault-v1", model=str(diag1), estimator="none", scenario=sc, info="full"),
        tmp_path / "calibrated",
    )
    env.reset(seed=1)
    while True:
        *_, term, trunc, info = env.step(np.zeros(4))
        if term or trunc:
            break
    env.close()
    assert not term and [e["name"] for e in info["effects"]] == ["drag"]
    assert main(["diagnose", str(env.paths[0]), "--json", str(diag2), "--quiet"]) == 0

    def drag(path):
        (fit,) = [e for e in json.loads(path.read_text())["effects"] if e["name"] == "drag"]
        return np.array(fit["params"]["k_N_s_per_m"])

    k1, k2 = drag(diag1), drag(diag2)
    assert np.allclose(k1[:2], 0.3, rtol=0.05)
    assert np.all(np.abs(k2 / k1 - 1.0) < 0.2), (k1, k2)
