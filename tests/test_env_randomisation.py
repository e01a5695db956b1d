"""Domain randomisation in the environments: ``effects`` ranges drawn at reset, a diagnosis'
fitted model (``model=``, ``model_uncertainty=``), the vector env equal to single envs."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import quad_fault_env  # noqa: F401  (registers the ids)
from quad_fault_env.envs.quad_fault import QuadFaultEnv
from quad_fault_env.vector import QuadFaultVectorEnv
from quadfault.errors import ConfigError
from quadfault.io.recording import Recording, recording_sidecar
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import SensorNoise

RANGES = ["mass=0.8:1.2", "drag=0.1:0.5", "motor_lag=0.01:0.05", "wind=-2:2,-2:2,0,gust=0.3"]
NOISE = SensorNoise(position=0.01, velocity=0.02, attitude=0.002, gyro=0.01, accel=0.1)


def _drawn(info) -> dict:
    return {e["name"]: e["params"] for e in info["effects"]}


@pytest.mark.slow
def test_reset_draws_every_range_from_the_env_generator():
    env = QuadFaultEnv("none", "hover", effects=RANGES, info="full")
    seen = []
    for seed in range(6):
        _, info = env.reset(seed=seed)
        d = _drawn(info)
        assert set(d) == {"mass", "drag", "motor_lag", "wind"}
        assert 0.8 <= d["mass"]["scale"] <= 1.2
        k = d["drag"]["k_N_s_per_m"]
        assert k[0] == k[1] == k[2] and 0.1 <= k[0] <= 0.5  # one value: all three axes
        assert 0.01 <= d["motor_lag"]["tau_s"] <= 0.05
        vx, vy, vz = d["wind"]["velocity_m_per_s"]
        assert -2 <= vx <= 2 and -2 <= vy <= 2 and vz == 0.0 and d["wind"]["gust_m_per_s"] == 0.3
        # the plant flies the draw: the true mass, the chain's parameters
        assert env.plant.vehicles.mass[0] == pytest.approx(d["mass"]["scale"] * env.vehicle.mass)
        assert env.vehicle.mass == Vehicle().mass  # the controller keeps the nominal vehicle
        seen.append(d)
    assert len({d["drag"]["k_N_s_per_m"][0] for d in seen}) == 6  # a new draw per episode
    _, again = env.reset(seed=3)
    assert _drawn(again) == seen[3]  # seeded: the same draws
    step_info = env.step(np.zeros(4, dtype=np.float32))[4]
    assert step_info["effects"] == again["effects"]  # every step says what the episode flies


@pytest.mark.slow
def test_the_drawn_physics_acts_on_the_flight():
    """A steady wind along +x (drag through the wind) pushes the hovering vehicle to +x."""
    errs = {}
    for name, effects in (("calm", None), ("wind", ["wind=4:5,0,0"])):
        env = QuadFaultEnv("none", "hover", effects=effects, thrust_noise=0.0, info="full")
        env.reset(seed=0)
        for _ in range(50):
            info = env.step(np.zeros(4, dtype=np.float32))[4]
        errs[name] = info["position_error"][0]
    assert errs["wind"] > errs["calm"] + 0.01


def test_no_effects_keeps_the_info_and_the_physics():
    env = QuadFaultEnv("none", "hover", info="full")
    _, info = env.reset(seed=0)
    assert "effects" not in info and env.plant.hook is None


@pytest.mark.slow
def test_vector_env_equals_single_envs_with_the_same_draws():
    N, seed = 3, 11
    kw = dict(
        scenario="random",
        random_trajectory="hover",
        duration=0.3,
        sensor_noise=NOISE,
        effects=RANGES + ["inertia=0.8:1.2,0.9:1.1,0.8:1.2", "delay=0:0.01"],
    )
    vec = QuadFaultVectorEnv(N, "none", info="full", **kw)
    singles = [QuadFaultEnv("none", **kw, info="full") for _ in range(N)]
    obs, info = vec.reset(seed=seed)
    infos = [e.reset(seed=seed + i)[1] for i, e in enumerate(singles)]
    for i in range(N):
        assert info["effects"][i] == infos[i]["effects"]
    rng = np.random.default_rng(0)
    done = np.zeros(N, dtype=bool)
    resets = 0
    for k in range(60):  # 0.3 s episodes: autoresets draw new physics
        a = rng.uniform(-0.5, 0.5, (N, 4)).astype(np.float32)
        obs, rew, term, trunc, info = vec.step(a)
        for i, env in enumerate(singles):
            if done[i]:
                o, inf = env.reset()
                resets += 1
            else:
                o, _, _, _, inf = env.step(a[i])
            np.testing.assert_allclose(obs[i], o, rtol=0, atol=1e-9, err_msg=f"step {k} env {i}")
            assert info["effects"][i] == inf["effects"], (k, i)
        done = term | trunc
    assert resets >= N


@pytest.mark.parametrize(
    "kw, words",
    [
        ({"effects": ["drag=0.5:0.1"]}, "low <= high"),
        ({"effects": ["vortex=1"]}, "unknown effect 'vortex'"),
        ({"effects": ["motor_lag=-0.1:0.05"]}, "motor_lag"),
        ({"effects": ["drag"]}, "NAME=VALUES"),
        ({"effects": ["drag=a:b"]}, "not a number"),
        ({"effects": 5}, "effects must be a list"),
        ({"effects": ["drag=0.1", "drag=0.1:0.2"]}, "given twice"),
        ({"model_uncertainty": True}, "needs a model"),
        ({"model": {"format": "nope"}}, "format"),
    ],
)
def test_bad_randomisation_is_a_one_line_error(kw, words):
    with pytest.raises(ConfigError) as err:
        QuadFaultEnv("none", "hover", **kw)
    assert words in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(ConfigError):
        QuadFaultVectorEnv(2, "none", scenario="hover", **kw)


VEHICLE = Vehicle.from_arm(
    0.2, 0.01, mass=1.2, inertia=(0.012, 0.012, 0.022), gravity=9.81, max_thrust=8.0
)


def _diagnosis(tmp_path):
    rec = Recording(
        t=np.arange(3.0),
        omega=np.zeros((3, 3)),
        thrust_cmd=np.ones((3, 4)),
        vehicle=VEHICLE,
        position=np.zeros((3, 3)),
        velocity=np.zeros((3, 3)),
        quaternion=np.tile([1.0, 0, 0, 0], (3, 1)),
    )
    side = recording_sidecar(rec, "NED")
    doc = {
        "format": "quadfault-diagnosis/2",
        "verdict": "mismatch",
        "frame": "NED",
        "gravity": side["gravity"],
        "vehicle": side["vehicle"],
        "effects": [
            {
                "name": "drag",
                "params": {"k_N_s_per_m": [0.2, 0.25, 0.1]},
                "uncertainty": {"k_N_s_per_m": [0.02, 0.02, 0.02]},
                "bounds": {"k_N_s_per_m": [[0, 0, 0], [1.5, 1.5, 2.5]]},
            },
            {
                "name": "motor_lag",
                "params": {"tau_s": 0.03},
                "uncertainty": {"tau_s": 0.003},
                "bounds": {"tau_s": [1e-4, 0.3]},
            },
        ],
    }
    path = tmp_path / "d.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.slow
def test_make_with_a_model_flies_its_vehicle_and_fitted_effects(tmp_path):
    path = _diagnosis(tmp_path)
    env = gym.make("QuadFaultHover-v0", model=str(path), estimator="none", info="full")
    _, info = env.reset(seed=0)
    assert env.unwrapped.vehicle == VEHICLE  # the model's nominal vehicle
    d = _drawn(info)
    assert d["drag"]["k_N_s_per_m"] == [0.2, 0.25, 0.1] and d["motor_lag"]["tau_s"] == 0.03
    assert _drawn(env.reset(seed=1)[1]) == d  # fitted values: the same every episode
    for _ in range(20):
        obs, *_ = env.step(np.zeros(4, dtype=np.float32))
    assert np.all(np.isfinite(obs))
    with pytest.raises(ConfigError, match="either vehicle or model"):
        QuadFaultEnv("none", "hover", model=path, vehicle=VEHICLE)


def test_model_uncertainty_draws_the_fitted_parameters_per_reset(tmp_path):
    path = _diagnosis(tmp_path)
    env = QuadFaultEnv(
        "none", "hover", model=path, model_uncertainty=True, effects=["wind=-1:1,0,0"], info="full"
    )
    draws = [_drawn(env.reset(seed=s)[1]) for s in range(40)]
    taus = np.array([d["motor_lag"]["tau_s"] for d in draws])
    k = np.array([d["drag"]["k_N_s_per_m"] for d in draws])
    assert len(set(taus)) == 40 and abs(taus.mean() - 0.03) < 0.002
    assert 0.001 < taus.std() < 0.006  # the reported sigma, 0.003
    np.testing.assert_allclose(k.mean(axis=0), [0.2, 0.25, 0.1], atol=0.015)
    assert all("wind" in d for d in draws)
    assert _drawn(env.reset(seed=7)[1]) == draws[7]


@pytest.mark.slow
def test_a_vehicle_flies_any_number_of_wrench_effects():
    """Seven drags of 0.1 N s/m push as one of 0.7 (every slot of the layout is summed)."""
    from quadfault.model.effects import chain, parse_effect, rows

    state = ((0.0, 0.0, -1.0), (1.0, -0.5, 0.2), tuple(np.eye(3).ravel()), (0.1, 0.2, -0.3))
    f = np.full(4, 2.0)
    out = []
    for effects in ([parse_effect("drag=0.1")] * 7, [parse_effect("drag=0.7")]):
        fx = rows.build([[rows.entry(e, 4, 1e-3) for e in effects]], 4)
        out.append(chain.summed_wrench(chain.wrench_terms(fx, 0, f, 0.0), *state, f, 0.0)[0])
    np.testing.assert_allclose(out[0], out[1], rtol=1e-12)
    assert np.linalg.norm(out[1]) > 0.5
