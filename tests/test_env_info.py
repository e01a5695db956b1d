"""``info="light" | "full"``: the light info is one definition shared by the single and the
vector env, the full one a superset with the same numbers, and the flight is the same."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import quad_fault_env  # noqa: F401  (registers the ids)
from quad_fault_env.envs.config import LIGHT_INFO_KEYS, light_info
from quad_fault_env.envs.quad_fault import QuadFaultEnv
from quad_fault_env.vector import QuadFaultVectorEnv
from quadfault.errors import ConfigError

#: motor commands drawn over the whole range: the hover crashes within a second or two
FLIGHT = dict(scenario="abrupt", duration=2.0, action_mode="motor")


def _episode(env, seed, actions):
    """(obs, reward, terminated, truncated, info) of the reset and every step until the end."""
    obs, info = env.reset(seed=seed)
    out = [(obs, 0.0, False, False, info)]
    for a in actions:
        out.append(env.step(a))
        if out[-1][2] or out[-1][3]:
            break
    return out


def test_the_light_info_is_the_termination_reason_in_both_envs():
    assert LIGHT_INFO_KEYS == ("termination_reason",)
    assert light_info("crash") == {"termination_reason": "crash"}
    env = QuadFaultEnv("none", "hover", duration=0.1)
    _, info = env.reset(seed=0)
    assert tuple(info) == LIGHT_INFO_KEYS and info["termination_reason"] is None
    *_, info = env.step(np.zeros(4, np.float32))
    assert tuple(info) == LIGHT_INFO_KEYS
    vec = QuadFaultVectorEnv(2, "none", scenario="hover", duration=0.1)
    _, info = vec.reset(seed=0)
    assert set(info) == set(LIGHT_INFO_KEYS) | {"_" + k for k in LIGHT_INFO_KEYS}


@pytest.mark.parametrize("estimator", ["none", "irls"])
def test_light_and_full_fly_the_same_flight_and_agree_on_the_shared_keys(estimator):
    """Same seed, same actions: the observations, rewards and episode ends are identical, the
    full info holds every light key with the same value, and the termination reason names
    the crash."""
    actions = list(np.random.default_rng(2).uniform(-1, 1, (300, 4)).astype(np.float32))
    light = _episode(QuadFaultEnv(estimator, **FLIGHT), 7, actions)
    full = _episode(QuadFaultEnv(estimator, info="full", **FLIGHT), 7, actions)
    assert len(light) == len(full) and light[-1][2]  # the episode terminated
    for (o1, r1, te1, tr1, i1), (o2, r2, te2, tr2, i2) in zip(light, full):
        np.testing.assert_array_equal(o1, o2)
        assert (r1, te1, tr1) == (r2, te2, tr2)
        assert tuple(i1) == LIGHT_INFO_KEYS and set(i2) > set(i1)
        assert all(i1[k] == i2[k] for k in LIGHT_INFO_KEYS)
        assert (i1["termination_reason"] is not None) == te1
    assert light[-1][4]["termination_reason"] in ("crash", "excessive_tilt", "out_of_bounds")


@pytest.mark.slow
def test_full_info_of_the_single_env_equals_the_vector_env_where_both_have_a_key():
    """The vector env's full info holds, per sub-env, what the single env's reports."""
    kw = dict(FLIGHT, scenario="hover_fault", thrust_noise=0.0)
    vec = QuadFaultVectorEnv(1, "truth", info="full", **kw)
    env = QuadFaultEnv("truth", info="full", **kw)
    vec.reset(seed=3)
    env.reset(seed=3)
    a = np.full(4, 0.2, np.float32)
    for _ in range(40):
        *_, iv = vec.step(a[None])
        *_, info = env.step(a)
    for key in ("t", "eta_true", "eta_hat", "position_error", "tracking_error", "motor_command"):
        np.testing.assert_allclose(iv[key][0], info[key], rtol=0, atol=1e-9, err_msg=key)
    for key in ("termination_reason", "scenario"):
        assert iv[key][0] == info[key], key


@pytest.mark.parametrize("level", ["light", "full"])
def test_check_env_with_either_info(level):
    check_env(
        gym.make("QuadFaultRotorLoss-v0", duration=0.3, info=level).unwrapped,
        skip_render_check=True,
    )


def test_seeded_determinism_with_the_light_info():
    actions = list(np.random.default_rng(0).uniform(-1, 1, (50, 4)).astype(np.float32))
    a = _episode(QuadFaultEnv("irls", **FLIGHT), 11, actions)
    b = _episode(QuadFaultEnv("irls", **FLIGHT), 11, actions)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x[0], y[0])
        assert x[1:] == y[1:]


@pytest.mark.parametrize(
    "make",
    [
        lambda v: QuadFaultEnv("none", info=v),
        lambda v: gym.make("QuadFault-v1", info=v),
        lambda v: QuadFaultVectorEnv(2, "none", info=v),
    ],
)
def test_an_unknown_info_level_names_the_closest(make):
    with pytest.raises(
        ConfigError, match="info must be one of 'light', 'full', got 'ful'; did you mean 'full'"
    ):
        make("ful")
    with pytest.raises(ConfigError, match="got None$"):
        make(None)


@pytest.mark.slow
@pytest.mark.rl
def test_the_info_benchmark_runs():
    """``benchmarks/bench_info.py`` prints both tables (no timing assertion here)."""
    import subprocess
    import sys
    from pathlib import Path

    pytest.importorskip("stable_baselines3")
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_info.py"
    res = subprocess.run(
        [
            sys.executable,
            str(script),
            "--estimators",
            "none",
            "--rounds",
            "1",
            "--steps",
            "20",
            "--n-steps",
            "16",
            "--rollouts",
            "1",
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stderr
    assert "light/full" in res.stdout and "info copy" in res.stdout
