"""Environment soak, CI subset: random actions (and corner actions) over randomised fault
scenarios with every action mode, estimator and observation kind; finite observations and
rewards, a reason for every termination, seeded bit-for-bit repeatability. The full soak is
``benchmarks/soak_env.py`` (same code, loaded from there)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import quad_fault_env  # noqa: F401
from quad_fault_env.envs.config import TERMINATION_REASONS

_spec = importlib.util.spec_from_file_location(
    "soak_env", Path(__file__).resolve().parents[1] / "benchmarks" / "soak_env.py"
)
soak_env = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(soak_env)

#: A cheaper plant rate for the CI subset (2 physics substeps per 100 Hz control step).
QUICK = {"physics_rate": 200.0}
CLEAN = (
    "nonfinite_obs",
    "nonfinite_reward",
    "outside_space",
    "missing_reason",
    "spurious_reason",
    "nonfinite_truth",
)


def test_soak_subset_is_clean():
    stats = soak_env.soak(
        1000, seed=11, max_episode_steps=100, progress=False, env_kwargs=QUICK, corner_actions=0.2
    )
    assert stats["steps"] == 1000
    assert {k: stats[k] for k in CLEAN} == dict.fromkeys(CLEAN, 0)
    assert stats["episodes"] >= 10 and stats["combos"] >= 6
    assert set(stats["terminations"]) <= set(TERMINATION_REASONS)
    assert sum(stats["terminations"].values()) + stats["truncations"] >= stats["episodes"] - 1


def test_seeded_soak_is_bit_for_bit_repeatable():
    def run(seed):
        return soak_env.soak(
            200,
            seed=seed,
            max_episode_steps=50,  # noqa: E731
            progress=False,
            digest=True,
            env_kwargs=QUICK,
            corner_actions=0.2,
        )

    a, b, c = run(5), run(5), run(6)
    assert a["sha256"] == b["sha256"]
    assert a["sha256"] != c["sha256"]


@pytest.mark.parametrize("mode", soak_env.ACTION_MODES)
def test_extreme_actions_terminate_with_a_reason(mode):
    """Full throttle, zero throttle and alternating corners: every episode ends with a reason
    or by truncation, never NaN."""
    env = gym.make(
        "QuadFault-v0",
        action_mode=mode,
        estimator="none",
        scenario="random",
        max_episode_steps=150,
        **QUICK,
    )
    rng = np.random.default_rng(0)
    for pattern in ([1, 1, 1, 1], [-1, -1, -1, -1], [1, -1, 1, -1], [1, -1, -1, 1]):
        obs, info = env.reset(seed=int(rng.integers(1000)))
        for k in range(150):
            a = np.array(pattern, dtype=np.float32) * (1 if k % 2 == 0 or mode != "motor" else -1)
            obs, reward, terminated, truncated, info = env.step(a)
            assert np.all(np.isfinite(obs)) and np.isfinite(reward)
            if terminated:
                assert info["termination_reason"] in TERMINATION_REASONS
            if terminated or truncated:
                break
        assert terminated or truncated
    env.close()


def test_step_after_termination_needs_reset():
    env = gym.make("QuadFaultHover-v0", action_mode="motor", estimator="none", **QUICK)
    env.reset(seed=1)
    terminated = truncated = False
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(np.full(4, -1.0, dtype=np.float32))
    assert terminated and info["termination_reason"] == "crash"
    with pytest.raises(gym.error.ResetNeeded):
        env.unwrapped.step(np.zeros(4, dtype=np.float32))


@pytest.mark.slow
def test_soak_at_the_registered_physics_rate():
    stats = soak_env.soak(4000, seed=3, max_episode_steps=300, progress=False, corner_actions=0.1)
    assert {k: stats[k] for k in CLEAN} == dict.fromkeys(CLEAN, 0)
    assert stats["combos"] >= 10


def test_vector_env_with_autoreset_stays_finite_and_repeatable():
    """Gymnasium's synchronous vector env over QuadFaultHover-v0 (autoreset across episode
    ends): finite, and the same seed gives the same stream."""

    def run():
        envs = gym.make_vec(
            "QuadFaultHover-v0",
            num_envs=2,
            vectorization_mode="sync",
            action_mode="motor",
            estimator="none",
            max_episode_steps=40,
            **QUICK,
        )
        envs.action_space.seed(3)
        obs, _ = envs.reset(seed=7)
        out, ends = [obs], 0
        for _ in range(120):
            obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
            assert np.all(np.isfinite(obs)) and np.all(np.isfinite(reward))
            ends += int(np.sum(terminated | truncated))
            out.append(obs)
        envs.close()
        return np.array(out), ends

    a, ends = run()
    b, _ = run()
    assert ends >= 2
    assert np.array_equal(a, b)
