"""The environments on the paths an RL user takes: ``gym.make``, ``gym.make_vec`` (sync, async,
the native vector env), the SB3 adapter and ``quadfault train``; the ``-v1`` reward and episode
rule; numba threads by batch size."""

from __future__ import annotations

import os

import gymnasium as gym
import numpy as np
import pytest

import quad_fault_env  # noqa: F401  (registers the ids)
from quad_fault_env.envs.config import RewardConfig
from quad_fault_env.tasks import REWARD_V0, TASKS
from quad_fault_env.vector import (
    THREADS_MIN_BATCH,
    QuadFaultVectorEnv,
    default_threads,
    usable_cores,
)
from quadfault import jit
from quadfault.errors import ConfigError

ESTIMATORS = ("irls", "ekf", "truth", "none")


def _structure(info: dict) -> dict:
    """key -> (type, shape, dtype) of a single env's info (dict values: their structure; a
    string and None are one kind: ``termination_reason`` is None until the episode ends)."""
    out = {}
    for k, v in info.items():
        if v is None or isinstance(v, str):
            out[k] = "str or None"
        elif isinstance(v, dict):
            out[k] = _structure(v)
        else:
            a = np.asarray(v) if isinstance(v, (np.ndarray, float, int, bool)) else None
            out[k] = (type(v).__name__, None if a is None else (a.shape, a.dtype.kind))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("info", ["light", "full"])
@pytest.mark.parametrize("estimator", ESTIMATORS)
def test_single_env_info_keeps_one_structure_across_reset_step_and_termination(estimator, info):
    env = gym.make(
        "QuadFaultHover-v1", estimator=estimator, action_mode="motor", duration=1.0, info=info
    )
    _, info = env.reset(seed=0)
    first = _structure(info)
    for _ in range(100):  # zero thrust: free fall, crash after ~0.45 s
        _, _, term, trunc, info = env.step(-np.ones(4, np.float32))
        assert _structure(info) == first
        if term or trunc:
            break
    assert term and info["termination_reason"] == "crash"


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["sync", "async"])
def test_make_vec_with_staggered_episode_ends(mode):
    """Sub-env 0 falls (terminates every ~46 steps), sub-env 1 flies to its 100-step end:
    gymnasium's vector envs batch every info value through the episodes, for every
    estimator."""
    for estimator in ESTIMATORS:
        env = gym.make_vec(
            "QuadFaultHover-v1",
            num_envs=2,
            vectorization_mode=mode,
            estimator=estimator,
            duration=1.0,
            action_mode="motor",
            info="full",
        )
        try:
            env.reset(seed=0)
            ends = []
            a = np.zeros((2, 4), np.float32)
            a[0] = -1.0
            for k in range(150):
                _, _, term, trunc, info = env.step(a)
                ends += [(k, i, bool(term[i])) for i in np.flatnonzero(term | trunc)]
            assert {i for _, i, _ in ends} == {0, 1}, estimator
            assert (99, 1, False) in ends  # truncation at 1 s
            assert all(crash for _, i, crash in ends if i == 0)
            assert info["eta_true_samples"].shape == (2, 10, 4)
            assert info["eta_hat"].shape == (2, 4) and np.isfinite(info["eta_hat"]).all()
        finally:
            env.close()


def _episode_steps_single(env) -> int:
    env.reset(seed=0)
    for n in range(1, 100_000):
        _, _, term, trunc, _ = env.step(np.zeros(4, np.float32))
        if term or trunc:
            assert trunc and not term
            return n
    raise AssertionError("no episode end")


def _episode_steps_vector(env, reset=True) -> int:
    if reset:
        env.reset(seed=0)
    for n in range(1, 100_000):
        out = env.step(np.zeros((env.num_envs, 4), np.float32))
        done = out[2] if len(out) == 4 else out[2] | out[3]
        if np.any(done):
            return n
    raise AssertionError("no episode end")


@pytest.mark.slow
@pytest.mark.parametrize(
    "kw, steps",
    [
        ({"duration": 0.6}, 60),
        ({"duration": 30.0}, 3000),
        ({"duration": 0.6, "control_rate": 50.0}, 30),
    ],
)
def test_duration_and_control_rate_set_the_episode_length_on_every_path(kw, steps):
    pytest.importorskip("stable_baselines3")
    from agents.train import TrainConfig, make_vec_env
    from quad_fault_env.sb3_vec import make_sb3_vec_env

    kw = dict(kw, estimator="none")
    assert _episode_steps_single(gym.make("QuadFault-v1", **kw)) == steps
    for mode in ("sync", "vector_entry_point"):
        assert (
            _episode_steps_vector(gym.make_vec("QuadFault-v1", 2, vectorization_mode=mode, **kw))
            == steps
        ), mode
    sb3 = make_sb3_vec_env(2, seed=0, env_id="QuadFault-v1", **kw)
    sb3.reset()
    assert _episode_steps_vector(sb3, reset=False) == steps
    for vector_env in (True, False):  # quadfault train's two kinds of training env
        venv = make_vec_env(
            TrainConfig(env_id="QuadFault-v1", env_kwargs=kw, vector_env=vector_env), 0, 2
        )
        venv.reset()
        assert _episode_steps_vector(venv, reset=False) == steps, vector_env
        venv.close()


def test_v0_ids_keep_their_step_limit_and_reward():
    for env_id, limit in (("QuadFault-v0", 2000), ("QuadFaultHover-v0", 1000)):
        spec = gym.spec(env_id)
        assert spec.max_episode_steps == limit and spec.kwargs["reward"] == REWARD_V0
        assert gym.spec(env_id.replace("-v0", "-v1")).max_episode_steps is None
    assert REWARD_V0 == RewardConfig(
        position_scale=1.0,
        velocity_weight=0.1,
        effort_weight=0.01,
        action_weight=0.0,
        survival_bonus=0.0,
        termination_penalty=0.0,
    )
    assert {t.id for t in TASKS} == {
        "QuadFault-v0",
        "QuadFaultHover-v0",
        "QuadFault-v1",
        "QuadFaultHover-v1",
        "QuadFaultTrack-v0",
        "QuadFaultRotorLoss-v0",
        "QuadFaultRotorLossComplete-v0",
    }


def _returns(reward: RewardConfig, rng, steps=500, crash_at=None):
    """Return of one episode of ``steps`` steps of random tracking errors, rotor commands
    and actions (worst cases included), and of the same episode ending in a crash at step
    ``crash_at`` instead (the same tracking and effort up to it)."""
    pe = rng.normal(0, 1, (steps, 3)) * rng.choice([0.01, 1.0, 100.0], (steps, 1))
    ve = rng.normal(0, 2, (steps, 3))
    f = rng.choice([0.0, 0.5, 1.0], (steps, 4)) * 4.0
    a = rng.choice([-1.0, 0.0, 1.0], (steps, 4))
    survived = reward(pe, ve, f, 4.0, np.zeros(steps, bool), a).sum()
    term = np.zeros(crash_at, bool)
    term[-1] = True
    crashed = reward(pe[:crash_at], ve[:crash_at], f[:crash_at], 4.0, term, a[:crash_at]).sum()
    return survived, crashed


def test_a_late_crash_scores_below_a_survived_episode_of_the_same_tracking():
    v1 = gym.spec("QuadFault-v1").kwargs["reward"]
    rng = np.random.default_rng(0)
    for crash_at in (500, 499, 450, 10):
        survived, crashed = _returns(v1, rng, crash_at=crash_at)
        assert crashed < survived - v1.termination_penalty + 1.0, crash_at
    # the -v0 reward cannot tell them apart: a crash on the last step scores the same
    survived, crashed = _returns(REWARD_V0, np.random.default_rng(0), crash_at=500)
    assert crashed == pytest.approx(survived)


def test_v1_reward_terms_in_the_env():
    """Tracking, thrust and action effort, the survival bonus on every flown step and the
    penalty on the crash step, the same in the single and the vector env."""
    env = gym.make(
        "QuadFaultHover-v1", estimator="none", action_mode="motor", duration=1.0, info="full"
    )
    vec = gym.make_vec(
        "QuadFaultHover-v1",
        1,
        vectorization_mode="vector_entry_point",
        estimator="none",
        action_mode="motor",
        duration=1.0,
    )
    env.reset(seed=3)
    vec.reset(seed=3)
    rewards = []
    for _ in range(100):
        _, r, term, _, info = env.step(-np.ones(4, np.float32))
        _, rv, _, _, _ = vec.step(-np.ones((1, 4), np.float32))
        assert rv[0] == pytest.approx(r, abs=1e-9)
        rewards.append(r)
        if term:
            break
    assert info["termination_reason"] == "crash"
    cfg = env.unwrapped.reward_config
    assert min(rewards[:-1]) >= 0.0
    assert rewards[-1] <= 1.0 - cfg.termination_penalty
    # zero thrust: no thrust effort, full action effort, so every flown step earns
    # exp(-track / scale) - action_weight + survival_bonus
    assert np.all(info["motor_command"] == 0.0)
    low = cfg.survival_bonus - cfg.action_weight
    high = 1.0 + low
    assert all(low < r <= high for r in rewards[:-1])
    env.close()
    vec.close()


@pytest.mark.parametrize(
    "kwargs, word",
    [
        ({"reward": {"survival_bonus": -1}}, "survival_bonus"),
        ({"reward": {"bonus": 1}}, "unknown keys"),
        ({"reward": 3}, "reward must be"),
    ],
)
def test_bad_reward_keywords_raise_one_clear_error(kwargs, word):
    with pytest.raises(ConfigError, match=word):
        gym.make("QuadFault-v1", **kwargs)


def test_numba_threads_by_batch_size(monkeypatch):
    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    assert default_threads(1) == default_threads(THREADS_MIN_BATCH - 1) == 1
    assert default_threads(THREADS_MIN_BATCH) == usable_cores() >= 1
    monkeypatch.setenv("NUMBA_NUM_THREADS", "2")  # the user's choice is kept
    assert default_threads(4) is None
    monkeypatch.delenv("NUMBA_NUM_THREADS")
    venv = QuadFaultVectorEnv(4, "none", scenario="hover", duration=0.1)
    assert venv.numba_threads == 1
    if hasattr(os, "sched_setaffinity") and len(os.sched_getaffinity(0)) > 1:
        allowed = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {min(allowed)})  # a user's thread limit (taskset -c 0)
        try:
            assert usable_cores() == 1 == default_threads(THREADS_MIN_BATCH)
        finally:
            os.sched_setaffinity(0, allowed)
    with pytest.raises(ConfigError, match="numba_threads"):
        QuadFaultVectorEnv(4, "none", numba_threads=0)
    if jit.AVAILABLE:
        import numba

        before = numba.get_num_threads()
        venv.reset(seed=0)
        venv.step(np.zeros((4, 4), np.float32))
        assert numba.get_num_threads() == before  # the caller's count is left alone


def test_auto_threads_keep_the_callers_thread_limit(monkeypatch):
    """``numba_threads="auto"`` never steps on more threads than the calling thread's
    numba count: ``numba.set_num_threads(1)`` before a step keeps it on one thread."""
    if not jit.AVAILABLE:
        pytest.skip("numba is not installed")
    import numba

    from quad_fault_env import vector_step

    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    venv = QuadFaultVectorEnv(THREADS_MIN_BATCH, "none", scenario="hover", duration=0.1)
    seen = []
    real = vector_step.step
    monkeypatch.setattr(vector_step, "step", lambda *a: (seen.append(a[-1]), real(*a))[1])
    zeros = np.zeros((THREADS_MIN_BATCH, 4), np.float32)
    before = numba.get_num_threads()
    venv.reset(seed=0)
    try:
        numba.set_num_threads(1)
        venv.step(zeros)
        assert numba.get_num_threads() == 1
    finally:
        numba.set_num_threads(before)
    venv.step(zeros)
    assert seen == [1, min(usable_cores(), before)]
