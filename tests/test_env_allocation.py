"""The environments' base allocation (``allocation="nominal" | "estimate-aware"``): checked
envs, seeded determinism, the single env equals the vector env, bad combinations, and the
base that survives a partial rotor loss."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import quad_fault_env  # noqa: F401  (registers the ids)
from quad_fault_env.envs.quad_fault import QuadFaultEnv
from quad_fault_env.tasks import registered_kwargs
from quad_fault_env.vector import QuadFaultVectorEnv
from quadfault.errors import ConfigError
from quadfault.model.allocation import EXACT

#: a rotor loss early in a short flight: the allocation saturates within a few steps
EARLY_LOSS = dict(
    scenario="rotor_loss",
    duration=1.0,
    scenario_options={"level": (0.1, 0.2), "onset": (0.05, 0.05)},
)


def _rollout(env, seed, steps, action=None):
    obs, _ = env.reset(seed=seed)
    out = [obs]
    a = np.zeros(4, dtype=np.float32) if action is None else action
    for _ in range(steps):
        obs, r, term, trunc, info = env.step(a)
        out.append(np.append(obs, r))
        if term or trunc:
            break
    return np.array(out[1:]), info


@pytest.mark.parametrize("env_id", ["QuadFaultRotorLoss-v0", "QuadFault-v1"])
def test_check_env_with_the_estimate_aware_base(env_id):
    env = gym.make(env_id, allocation="estimate-aware", estimator="truth")
    check_env(env.unwrapped, skip_render_check=True)


@pytest.mark.parametrize("mode", ["residual", "wrench"])
def test_seeded_episodes_repeat(mode):
    env = QuadFaultEnv("irls", allocation="estimate-aware", action_mode=mode, **EARLY_LOSS)
    a, _ = _rollout(env, 7, 40, np.full(4, 0.1, dtype=np.float32))
    b, _ = _rollout(env, 7, 40, np.full(4, 0.1, dtype=np.float32))
    np.testing.assert_array_equal(a, b)


def test_estimate_aware_base_allocates_with_the_estimate_after_the_loss():
    """With the true efficiency in the observation, after the rotor drops to 0.1-0.2 the
    base's commands are the allocator's (the exact split no longer fits), not the nominal
    split."""
    env = QuadFaultEnv("truth", allocation="estimate-aware", **EARLY_LOSS, info="full")
    env.reset(seed=3)
    for _ in range(20):
        _, _, term, _, info = env.step(np.zeros(4, dtype=np.float32))
        assert not term
    m = env._meas
    f_nominal = env._controller_commands(env.time, m)
    wrench = env.vehicle.allocation @ f_nominal
    res = env.allocator.allocate(wrench, info["eta_hat"])
    assert res.mode != EXACT
    f = env.motor_commands(np.zeros(4), env.time, m)
    np.testing.assert_allclose(f, res.f, rtol=0, atol=1e-12)
    assert not np.allclose(f, np.clip(f_nominal, 0, env.f_max), atol=1e-3)


def test_allocate_rows_equals_allocate_row_by_row():
    env = QuadFaultEnv("none", allocation="estimate-aware")
    rng = np.random.default_rng(0)
    W = np.column_stack(
        (rng.uniform(2, 25, 64), rng.normal(0, 0.5, (64, 2)), rng.normal(0, 0.05, 64))
    )
    eta = rng.uniform(0.05, 1.2, (64, 4))
    eta[3, 2] = np.nan
    rows = env.allocator.allocate_rows(W, eta)
    assert set(rows.mode) > {EXACT}
    for i in range(64):
        one = env.allocator.allocate(W[i], eta[i])
        np.testing.assert_allclose(rows.f[i], one.f, rtol=0, atol=1e-12)
        np.testing.assert_allclose(rows.wrench[i], one.wrench, rtol=0, atol=1e-12)
        assert rows.mode[i] == one.mode


@pytest.mark.slow
@pytest.mark.parametrize("estimator", ["truth", "irls"])
def test_vector_env_equals_single_envs(estimator):
    n, steps = 3, 40
    vec = QuadFaultVectorEnv(n, estimator, allocation="estimate-aware", **EARLY_LOSS)
    obs, _ = vec.reset(seed=20)
    rows = [obs]
    for _ in range(steps):
        obs, *_ = vec.step(np.zeros((n, 4)))
        rows.append(obs)
    for i in range(n):
        env = QuadFaultEnv(estimator, allocation="estimate-aware", **EARLY_LOSS)
        o, _ = env.reset(seed=20 + i)
        np.testing.assert_allclose(rows[0][i], o, rtol=0, atol=1e-9)
        for k in range(steps):
            o, *_ = env.step(np.zeros(4, dtype=np.float32))
            np.testing.assert_allclose(
                rows[k + 1][i], o, rtol=0, atol=1e-9, err_msg=f"row {i} step {k}"
            )


@pytest.mark.parametrize(
    "kw, word",
    [
        (dict(allocation="fancy"), "allocation must be one of"),
        (dict(allocation="estimate-aware", action_mode="motor"), "motor mode"),
        (dict(allocation="estimate-aware", compensate=True), "not both"),
    ],
)
def test_bad_allocation_keywords_raise_one_line_errors(kw, word):
    with pytest.raises(ConfigError, match=word):
        QuadFaultEnv("none", **kw)
    with pytest.raises(ConfigError, match=word):
        QuadFaultVectorEnv(2, "none", **kw)


@pytest.mark.slow
def test_the_estimate_aware_base_survives_partial_rotor_losses():
    """Zero residual, IRLS estimate in the observation: at least 8 of 10 seeded
    QuadFaultRotorLoss-v0 episodes with the rotor dropping to 0.1-0.5 end without a
    termination (the vector env's rows equal single envs seeded 0..9); the nominal base
    crashes in most of them."""

    def survivors(allocation):
        kw = registered_kwargs(
            "QuadFaultRotorLoss-v0", allocation=allocation, scenario_options={"level": (0.1, 0.5)}
        )
        kw.pop("estimator", None)
        vec = QuadFaultVectorEnv(10, "irls", **kw)
        vec.reset(seed=0)
        ended = np.zeros(10, dtype=bool)
        for _ in range(int(vec.max_steps.max())):
            _, _, term, trunc, _ = vec.step(np.zeros((10, 4)))
            ended |= term
            if trunc.all() or ended.all():
                break
        return int((~ended).sum())

    assert survivors("estimate-aware") >= 8
    assert survivors("nominal") <= 5
