"""QuadFaultEnv: registration, check_env, determinism, spaces, physics sanity, terminations,
truth isolation and action validation. Episodes are kept short (each step = 10 substeps)."""

from __future__ import annotations

import copy
import importlib.util
import math
import re

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from support import oracles

import quad_fault_env
from estimators.base import Estimate
from quad_fault_env.envs.config import InitialStateSpread, TerminationLimits
from quad_fault_env.envs.quad_fault import QuadFaultEnv
from quad_fault_env.estimation import NOMINAL_PRIOR_SD, make_estimator
from quadfault.errors import ConfigError
from quadfault.model.scenarios import Scenario, named_scenario
from quadfault.model.trajectory import Hover
from quadfault.sim.simulator import SensorNoise

IDS = list(quad_fault_env.ENVIRONMENTS)


def _have(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


class CountingEstimator:
    """Test double of the online-estimator protocol: constant eta, counts its updates."""

    name = "counting"

    def __init__(self, eta=(0.9, 0.8, 0.7, 0.6)):
        self.eta = np.asarray(eta, dtype=float)
        self.n_updates = 0
        self.times = []

    def reset(self, eta0=None):
        self.n_updates = 0
        self.times = []

    def update(self, sample):
        self.n_updates += 1
        self.times.append(sample.t)
        return Estimate(sample.t, self.eta.copy(), np.full(4, 0.05), "ok", {"n": self.n_updates})


def run(env, actions, seed=0, options=None):
    obs, info = env.reset(seed=seed, options=options)
    out = [(obs, 0.0, False, False, info)]
    for a in actions:
        step = env.step(a)
        out.append(step)
        if step[2] or step[3]:
            break
    return out


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("estimator", ["default", "truth"])
def test_check_env_every_registered_id(env_id, estimator):
    if estimator == "default" and not _have("estimators.irls"):
        pytest.skip("estimators.irls not available")
    if estimator == "default":
        from estimators.irls import IRLSConfig

        kw = {"estimator_kwargs": {"config": IRLSConfig()}}  # the registered estimator
    else:
        kw = {"estimator": estimator}
    env = gym.make(env_id, duration=0.5, **kw)
    assert env.unwrapped.estimator.name == ("irls" if estimator == "default" else estimator)
    check_env(env.unwrapped, skip_render_check=True)


def test_check_env_dict_and_other_action_modes():
    check_env(
        QuadFaultEnv("none", "hover", observation="dict", duration=0.5), skip_render_check=True
    )
    check_env(
        QuadFaultEnv("none", "hover", action_mode="wrench", duration=0.5), skip_render_check=True
    )


@pytest.mark.parametrize("env_id", IDS)
def test_make_with_namespace_prefix_and_default_estimator(env_id):
    if not _have("estimators.irls"):
        pytest.skip("estimators.irls not available yet")
    from estimators.irls import IRLSConfig

    env = gym.make(
        f"quad_fault_env:{env_id}", duration=0.2, estimator_kwargs={"config": IRLSConfig()}
    )
    obs, info = env.reset(seed=0)
    assert env.unwrapped.estimator.name == "irls"
    assert env.spec.max_episode_steps == quad_fault_env.ENVIRONMENTS[env_id][0]
    obs, *_ = env.step(np.zeros(4, dtype=np.float32))
    assert env.observation_space.contains(obs)


def test_observation_names_match_layout():
    env = QuadFaultEnv("none", "hover")
    names = env.observation_names
    assert len(names) == env.observation_space.shape[0] == 26
    assert names[:3] == ["pos_err_x", "pos_err_y", "pos_err_z"]
    assert names[env.layout.slice("eta_hat")] == [
        "eta_hat_1",
        "eta_hat_2",
        "eta_hat_3",
        "eta_hat_4",
    ]
    env2 = QuadFaultEnv("none", "hover", reference_acceleration=False)
    assert len(env2.observation_names) == 23


def test_seeded_determinism_and_obs_in_box():
    kw = dict(
        estimator="none",
        scenario="random",
        duration=0.3,
        sensor_noise=SensorNoise(position=0.01, velocity=0.02, attitude=0.01, gyro=0.02),
        initial_spread=InitialStateSpread(0.2, 0.1, 0.05, 0.1),
    )
    actions = np.random.default_rng(5).uniform(-0.3, 0.3, (30, 4)).astype(np.float32)
    a = run(QuadFaultEnv(**kw), actions, seed=123)
    b = run(QuadFaultEnv(**kw), actions, seed=123)
    c = run(QuadFaultEnv(**kw), actions, seed=124)
    assert len(a) == len(b) == 31
    space = QuadFaultEnv(**kw).observation_space
    for sa, sb in zip(a, b):
        np.testing.assert_array_equal(sa[0], sb[0])
        assert sa[1] == sb[1]
        assert space.contains(sa[0])
    assert not np.array_equal(a[5][0], c[5][0])


def test_reset_options_fix_the_scenario_and_random_scenarios_vary():
    env = QuadFaultEnv("none", "random", duration=1.0, info="full")
    seen = {repr(env.reset(seed=s)[1]["faults"]) for s in range(6)}
    assert len(seen) > 1
    _, info = env.reset(seed=0, options={"scenario": "hover_fault"})
    assert info["scenario"] == "hover_fault"
    assert info["faults"] == [
        {"motor": 1, "onset": 0.3, "end": math.inf, "level": 0.5, "ramp": 0.0}
    ]
    custom = named_scenario("abrupt", 2.0).replace(name="mine", thrust_noise=0.0)
    _, info = env.reset(seed=0, options={"scenario": custom})
    assert info["scenario"] == "mine" and info["thrust_noise"] == 0.0
    with pytest.raises(ConfigError, match="options\\['scenario'\\]"):
        env.reset(options={"scenario": 42})
    with pytest.raises(ConfigError, match="unknown reset option"):
        env.reset(options={"senario": "hover"})


def test_hover_residual_zero_action_stays_up_for_5_s_through_a_fault():
    # motor 1 drops to 50 % at 1.5 s; the nominal geometric controller must hold the hover
    env = gym.make(
        "QuadFaultHover-v0",
        estimator="none",
        scenario="hover_fault",
        duration=5.0,
        thrust_noise=0.07,
        info="full",
    )
    obs, info = env.reset(seed=3)
    z_ref = -1.0
    worst = 0.0
    for k in range(500):  # noqa: B007  (k is read after the loop)
        obs, r, terminated, truncated, info = env.step(np.zeros(4, dtype=np.float32))
        assert not terminated, info["termination_reason"]
        worst = max(worst, info["tracking_error"])
        if truncated:
            break
    assert truncated and k == 499 and info["t"] == pytest.approx(5.0)
    assert info["eta_true"][0] == pytest.approx(0.5)
    assert worst < 0.5
    # without an estimate the nominal controller (no integral action) sags under the fault
    assert 0.6 < -env.unwrapped.plant.state.p[2] < -z_ref
    assert 0.0 < r <= 1.0


def test_fault_compensated_through_the_estimate_removes_the_sag():
    # same fault; the controller divides its commands by eta_hat (here the oracle's)
    env = QuadFaultEnv(
        "truth", "hover_fault", duration=3.0, thrust_noise=0.07, compensate=True, info="full"
    )
    out = run(env, [np.zeros(4)] * 300, seed=3)
    assert len(out) == 301 and out[-1][3]
    assert out[-1][4]["eta_true"][0] == 0.5
    assert out[-1][4]["tracking_error"] < 0.1  # ~0.4 m uncompensated


def test_physics_substeps_per_control_step_and_estimator_rates():
    est = CountingEstimator()
    env = QuadFaultEnv(est, "hover", estimator_rate="physics", duration=1.0, info="full")
    _, _, _, _, info = run(env, [np.zeros(4)] * 3)[-1]
    assert len(info["samples"]) == 10 and est.n_updates == 30
    np.testing.assert_allclose(est.times[:11], np.arange(11) * 1e-3)
    # the command is held over the substeps of one step
    f = np.array([s.f for s in info["samples"]])
    np.testing.assert_array_equal(f, np.broadcast_to(info["motor_command"], f.shape))
    est2 = CountingEstimator()
    env2 = QuadFaultEnv(
        est2, "hover", estimator_rate="control", control_rate=50, duration=1.0, info="full"
    )
    _, _, _, _, info = run(env2, [np.zeros(4)] * 3)[-1]
    assert len(info["samples"]) == 20 and est2.n_updates == 3
    assert est2.times == pytest.approx([0.0, 0.02, 0.04])
    assert info["t"] == pytest.approx(0.06)


def _terminate(env, action, n=300):
    for step in run(env, [np.asarray(action, dtype=np.float32)] * n)[1:]:
        if step[2]:
            return step
    raise AssertionError("no termination")


def test_tilt_termination_is_the_angle_against_the_limit():
    """The tilt check skips its acos well inside the limit: the decision is still
    ``acos(R[8]) > max_tilt`` exactly, at and around the limit and over every angle."""
    from quad_fault_env.envs.config import termination_code

    for max_tilt in (0.05, math.radians(30), math.radians(80), 2.5, 3.1, math.pi):
        c_lim = math.cos(max_tilt)
        cs = list(np.cos(np.linspace(0.0, math.pi, 2001))) + [1.0, -1.0, 1.0 + 1e-12]
        cs += [float(x) for x in np.nextafter(c_lim, [-2.0, 2.0])] + [c_lim]
        for c in cs:
            R = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, c)
            code = termination_code((0.0, 0.0, -1.0), R, (0.0, 0.0, -1.0), (0.0, 10.0, max_tilt))
            want = 1 if math.acos(min(max(c, -1.0), 1.0)) > max_tilt else 0
            assert code == want, (max_tilt, c)


def test_termination_reasons():
    free_fall = _terminate(
        QuadFaultEnv("none", "hover", action_mode="motor", duration=3.0, info="full"),
        [-1, -1, -1, -1],
    )
    assert free_fall[4]["termination_reason"] == "crash"
    # 1 m of free fall takes ~0.45 s
    assert 0.4 <= free_fall[4]["t"] <= 0.55
    roll = _terminate(
        QuadFaultEnv("none", "hover", action_mode="motor", duration=3.0), [1, -1, -1, 1]
    )
    assert roll[4]["termination_reason"] == "excessive_tilt"
    up = _terminate(
        QuadFaultEnv(
            "none",
            "hover",
            action_mode="motor",
            duration=3.0,
            limits=TerminationLimits(max_position_error=0.2),
            info="full",
        ),
        [1, 1, 1, 1],
    )
    assert up[4]["termination_reason"] == "out_of_bounds"
    assert up[4]["tracking_error"] > 0.2

    class BrokenReference(Hover):
        def __call__(self, t):
            ref = super().__call__(t)
            bad = np.asarray(t) > 0.05
            return ref._replace(position=np.where(bad, np.nan, ref.position))

    broken = named_scenario("hover", 1.0).replace(trajectory=BrokenReference())
    nan = _terminate(QuadFaultEnv("none", broken), [0, 0, 0, 0])
    assert nan[4]["termination_reason"] == "non_finite"
    assert np.all(np.isfinite(nan[0]))
    env = QuadFaultEnv("none", "hover", action_mode="motor", duration=3.0)
    _terminate(env, [-1, -1, -1, -1])
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(4))


def test_truncation_at_duration_without_time_limit():
    out = run(QuadFaultEnv("none", "hover", duration=0.05), [np.zeros(4)] * 10)
    assert len(out) == 6 and out[-1][3] and not out[-1][2]
    assert all(not s[3] for s in out[:-1])


def test_truth_only_in_the_observation_of_the_oracle():
    scenario = named_scenario("hover_fault", 1.0)  # motor 1 at 0.5 from 0.3 s
    actions = [np.zeros(4)] * 50
    for est, expect_truth in (("none", False), ("truth", True), (CountingEstimator(), False)):
        env = QuadFaultEnv(est, scenario, info="full")
        sl = env.layout.slice("eta_hat")
        sd = env.layout.slice("eta_sd")
        for obs, _, _, _, info in run(env, actions)[40:]:
            truth = info["eta_true_samples"][-1]
            assert truth[0] == 0.5
            if expect_truth:
                np.testing.assert_allclose(obs[sl], truth, atol=1e-7)
                np.testing.assert_array_equal(obs[sd], 0.0)
            else:
                assert abs(obs[sl][0] - 0.5) > 0.05
        if est == "none":
            np.testing.assert_array_equal(obs[sl], 1.0)
            np.testing.assert_allclose(obs[sd], NOMINAL_PRIOR_SD)


def test_compensate_divides_controller_commands_by_the_estimate():
    a = QuadFaultEnv(CountingEstimator(), "hover", duration=1.0, info="full")
    b = QuadFaultEnv(CountingEstimator(), "hover", duration=1.0, compensate=True, info="full")
    fa = run(a, [np.zeros(4)] * 2)[-1][4]["motor_command"]
    fb = run(b, [np.zeros(4)] * 2)[-1][4]["motor_command"]
    eta = np.array([0.9, 0.8, 0.7, 0.6])
    # same state after one step with different commands is not guaranteed; compare ratios
    assert np.all(fb > fa) and np.argmax(fb / fa) == 3
    assert np.all(fb * eta < 1.2 * fa)


@pytest.mark.parametrize("mode", ["motor", "residual", "wrench"])
def test_action_modes_map_to_commands_within_limits(mode):
    env = QuadFaultEnv("none", "hover", action_mode=mode, duration=1.0)
    env.reset(seed=0)
    f_max = env.f_max
    for a in ([-1, -1, -1, -1], [1, 1, 1, 1], [0.3, -0.2, 0.1, 0.0]):
        f = env.motor_commands(np.asarray(a, float), 0.0, env.plant.state)
        assert f.shape == (4,) and np.all(f >= 0) and np.all(f <= f_max)
    if mode == "motor":
        np.testing.assert_allclose(env.motor_commands(np.zeros(4), 0.0, env.plant.state), f_max / 2)
    if mode == "wrench":
        f = env.motor_commands(np.array([0.0, 0.0, 0.0, 0.0]), 0.0, env.plant.state)
        np.testing.assert_allclose(env.vehicle.wrench(f), [2 * f_max, 0, 0, 0], atol=1e-12)
    if mode == "residual":
        f0 = env.motor_commands(np.zeros(4), 0.0, env.plant.state)
        np.testing.assert_allclose(f0, env.vehicle.weight / 4, rtol=1e-6)
        f1 = env.motor_commands(np.array([0.5, 0, 0, 0]), 0.0, env.plant.state)
        assert f1[0] - f0[0] == pytest.approx(0.5 * env.action_config.residual_scale)


@pytest.mark.parametrize(
    "action, message",
    [
        (np.zeros(3), "shape"),
        (np.array([0.0, np.nan, 0.0, 0.0]), "NaN"),
        (np.array([0.0, 1.5, 0.0, 0.0]), r"outside \[-1, 1\]"),
        ("fly", "numeric"),
    ],
)
def test_bad_actions_raise(action, message):
    env = QuadFaultEnv("none", "hover", duration=1.0)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        env.step(action)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"estimator": "kalman"}, "unknown estimator"),
        ({"scenario": "loop"}, "unknown scenario"),
        ({"action_mode": "thrust"}, "action_mode"),
        ({"physics_rate": 1000, "control_rate": 300}, "whole multiple"),
        ({"estimator_rate": "fast"}, "estimator_rate"),
        ({"observation": "image"}, "observation"),
        ({"thrust_noise": -0.1}, "thrust_noise"),
        ({"thrust_noise": "high"}, "thrust_noise"),
        ({"duration": 0.0}, "duration"),
        ({"duration": "long"}, "duration"),
        ({"control_rate": None}, "control_rate"),
        ({"random_trajectory": "spiral"}, "random_trajectory"),
        ({"sensor_noise": 0.1}, "sensor_noise"),
        ({"render_mode": "ascii"}, "render_mode"),
        ({"residual_scale": -1.0}, "residual_scale"),
        ({"moment_scale": (1.0, 0.0, 1.0)}, "moment_scale"),
    ],
)
def test_bad_configuration_raises_config_error(kwargs, message):
    kw = {"estimator": "none", "scenario": "hover"}
    kw.update(kwargs)
    with pytest.raises(ConfigError, match=message):
        QuadFaultEnv(**kw)


def test_make_estimator_factory():
    from quadfault.model.vehicle import Vehicle

    v = Vehicle()
    est = CountingEstimator()
    assert make_estimator(est, v) is est
    assert make_estimator("none", v).name == "none"
    with pytest.raises(ConfigError, match="reset\\(\\) and update"):
        make_estimator(3.0, v)
    for name, module in (("irls", "estimators.irls"), ("ekf", "estimators.ekf")):
        if _have(module):
            assert make_estimator(name, v).name == name


def test_scenario_object_keeps_its_duration():
    sc = Scenario("short", 0.05, named_scenario("hover").efficiency, Hover(), thrust_noise=0.0)
    out = run(QuadFaultEnv("none", sc), [np.zeros(4)] * 20)
    assert len(out) == 6 and out[-1][3]


_PROPERTY_ENVS = {}


def _property_env(mode="motor"):
    """One env per action mode, reused across hypothesis examples (reset each time)."""
    if mode not in _PROPERTY_ENVS:
        _PROPERTY_ENVS[mode] = QuadFaultEnv(
            "none",
            "hover_fault",
            action_mode=mode,
            duration=100.0,
            sensor_noise=SensorNoise(gyro=0.01),
            info="full",
        )
    return _PROPERTY_ENVS[mode]


@settings(max_examples=25, deadline=None)
@given(
    action=hnp.arrays(np.float64, 4, elements=st.floats(-1.0, 1.0)),
    seed=st.integers(0, 2**16),
    mode=st.sampled_from(["motor", "residual", "wrench"]),
)
def test_any_valid_action_gives_an_observation_in_the_box(action, seed, mode):
    env = _property_env(mode)
    obs, _ = env.reset(seed=seed)
    for _ in range(3):
        obs, r, terminated, truncated, info = env.step(action)
        assert env.observation_space.contains(obs)
        w = env.reward_config
        low = -(w.effort_weight + w.action_weight) + w.survival_bonus
        assert (
            low - 1e-12 <= r <= 1.0 + w.survival_bonus
            if not terminated
            else r <= 1.0 - w.termination_penalty
        )
        assert np.all((info["motor_command"] >= 0) & (info["motor_command"] <= env.f_max))
        if terminated:
            break


@settings(max_examples=25, deadline=None)
@given(
    action=hnp.arrays(
        np.float64, 4, elements=st.floats(allow_nan=True, allow_infinity=True, width=32)
    )
)
def test_out_of_range_actions_always_raise(action):
    assume(not np.all(np.abs(action) <= 1.0 + 1e-6))
    env = _property_env()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN|outside"):
        env.step(action)


def test_fault_events_are_reported_in_the_step_they_happen():
    # abrupt, 1.2 s: motor 1 at 50 % on [0.1, 0.15] s, motor 2 from 0.4 s, ...
    env = QuadFaultEnv("none", named_scenario("abrupt", 1.2).replace(thrust_noise=0.0), info="full")
    out = run(env, [np.zeros(4)] * 20)
    events = [(k, e["motor"], e["kind"]) for k, s in enumerate(out) for e in s[4]["fault_events"]]
    # step k covers [(k - 1) / 100, k / 100) s; out[0] is the reset
    assert events == [(11, 1, "onset"), (16, 1, "end")]
    onset = out[11][4]["fault_events"][0]
    assert onset["t"] == pytest.approx(0.1) and onset["level"] == 0.5
    np.testing.assert_array_equal(out[10][4]["eta_true_samples"][:, 0], 1.0)
    np.testing.assert_array_equal(out[11][4]["eta_true_samples"][:, 0], 0.5)
    assert out[16][4]["eta_true_samples"][-1, 0] == 1.0


def test_estimator_rate_physics_by_default_control_on_request():
    env = QuadFaultEnv(estimator="irls")
    assert env.estimator_rate == "physics" and env.estimator_stride == 1
    assert QuadFaultEnv(estimator="irls", estimator_rate="control").estimator_stride == env.substeps


def test_random_faults_bounds_the_random_scenarios_faults():
    env = QuadFaultEnv(
        "none",
        "random",
        random_faults={"n_faults": (1, 1), "severity": (0.6, 0.7), "degradation_prob": 0.0},
    )
    for seed in range(8):
        env.reset(seed=seed)
        faults = env.scenario.efficiency.faults
        assert len(faults) == 1
        assert 0.6 <= faults[0].level <= 0.7


@pytest.mark.parametrize(
    "spec, word",
    [
        ({"n_faults": (0, 1.5)}, "whole numbers"),
        ({"severity": (0.5, 1.2)}, "[0, 1]"),
        ({"severity": (0.8, 0.5)}, "low <= high"),
        ({"ramp_prob": 2}, "probability"),
        ({"bogus": 1}, "unknown key"),
        ({"severity": 0.5}, "pair"),
        ([1, 2], "dict"),
    ],
)
def test_random_faults_rejects_bad_specs(spec, word):
    with pytest.raises(ConfigError, match=re.escape(word)):
        QuadFaultEnv("none", "random", random_faults=spec)


# -- the physics: the model's closed loop, one call per control step --------------------------
FAULT_NOISE = dict(
    scenario="combined",
    duration=1.2,
    thrust_noise=0.07,
    sensor_noise=SensorNoise(position=0.01, velocity=0.02, attitude=0.002, gyro=0.01, accel=0.1),
)


@pytest.mark.parametrize(
    "kw",
    [
        FAULT_NOISE,
        dict(
            scenario="lissajous",
            duration=0.4,
            thrust_noise=0.0,
            sensor_noise=SensorNoise(accel=0.1),
        ),
    ],
)
def test_substeps_are_the_readable_loop_with_the_env_generator(kw):
    """Every substep sample and accelerometer reading equals the loop written out with numpy
    (tests/support/oracles.py: sensors, motors with the step's held command, RKMK4,
    accelerometer) drawing from a twin of the env's generator in the same order, with the
    end-of-step measurement drawn after the step."""
    env = QuadFaultEnv("none", **kw, info="full")
    env.reset(seed=7)
    twin = copy.deepcopy(env.np_random)
    x = tuple(np.array(a) for a in env.plant.state)
    veh, noise, dt = env.vehicle, env.sensor_noise, env.dt
    sigma = env.scenario.thrust_noise
    rng = np.random.default_rng(1)
    x_meas = None  # the reset's measurement (drawn before the twin was made)
    for k in range(40):
        _, _, term, _, info = env.step(rng.uniform(-0.3, 0.3, 4).astype(np.float32))
        f_cmd = info["motor_command"]
        for j, sample in enumerate(info["samples"]):
            if j > 0:
                x_meas = oracles.measure(*x, noise, twin)
            for got, want in zip(sample[1:5], x_meas or sample[1:5]):
                np.testing.assert_allclose(got, want, rtol=0, atol=1e-9, err_msg=f"{k} {j}")
            eta = info["eta_true_samples"][j]
            z = twin.standard_normal(4) if sigma > 0 else 0.0
            f = oracles.motor_thrust(f_cmd, eta, veh.rotor_max_thrust, True, sigma, z)
            T, *M = veh.allocation @ f
            acc = oracles.translational_acceleration(x[2], T, veh)
            sf = x[2].T @ (acc - veh.gravity * oracles.E3)
            x = oracles.step_rk4(*x, T, np.array(M), veh, dt)
            if noise.accel:
                sf = sf + noise.accel * twin.standard_normal(3)
            np.testing.assert_allclose(info["specific_force_samples"][j], sf, atol=1e-9)
        x_meas = oracles.measure(*x, noise, twin)  # the end-of-step measurement
        assert not term
    assert env.np_random.bit_generator.state == twin.bit_generator.state
