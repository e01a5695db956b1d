"""QuadFaultVectorEnv: N sub-envs stepped as arrays equal N single QuadFaultEnv step for step."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import quad_fault_env  # noqa: F401  (registers the ids)
from estimators.ekf import EKFConfig
from estimators.irls import IRLSConfig
from quad_fault_env.envs.config import InitialStateSpread
from quad_fault_env.envs.quad_fault import QuadFaultEnv
from quad_fault_env.vector import QuadFaultVectorEnv
from quadfault.errors import ConfigError
from quadfault.model.controller import ControllerConfig
from quadfault.sim.simulator import SensorNoise

NOISE = SensorNoise(position=0.01, velocity=0.02, attitude=0.002, gyro=0.01, accel=0.1)


def _estimator_kwargs(name):
    if name == "irls":
        return {"config": IRLSConfig()}
    if name == "ekf":
        return {"config": EKFConfig()}
    return None


def _run_side_by_side(n_envs, steps, seed, estimator, action_scale=1.0, **kw):
    """Step a vector env and ``n_envs`` single envs with the same actions; compare all."""
    ekw = _estimator_kwargs(estimator)
    vec = QuadFaultVectorEnv(n_envs, estimator, estimator_kwargs=ekw, info="full", **kw)
    singles = [
        QuadFaultEnv(estimator, estimator_kwargs=ekw, info="full", **kw) for _ in range(n_envs)
    ]
    obs, info = vec.reset(seed=seed)
    single_obs = [e.reset(seed=seed + i)[0] for i, e in enumerate(singles)]
    np.testing.assert_allclose(obs, np.array(single_obs), rtol=0, atol=1e-9)
    rng = np.random.default_rng(seed)
    done = np.zeros(n_envs, dtype=bool)
    n_done = 0
    for k in range(steps):
        a = (action_scale * rng.uniform(-1, 1, (n_envs, 4))).astype(np.float32)
        obs, rew, term, trunc, info = vec.step(a)
        for i, env in enumerate(singles):
            if done[i]:  # next-step autoreset: the vector env returned the reset observation
                o, r, te, tr, inf = env.reset()[0], 0.0, False, False, None
            else:
                o, r, te, tr, inf = env.step(a[i])
            np.testing.assert_allclose(obs[i], o, rtol=0, atol=1e-9, err_msg=f"step {k} env {i}")
            assert abs(rew[i] - r) <= 1e-9, (k, i)
            assert (term[i], trunc[i]) == (te, tr), (k, i)
            if inf is not None:
                assert info["termination_reason"][i] == inf["termination_reason"]
                assert info["estimator_status"][i] == inf["estimator_status"]
                np.testing.assert_allclose(info["eta_true"][i], inf["eta_true"], atol=1e-12)
        done = term | trunc
        n_done += int(done.sum())
    return n_done


def test_matches_single_envs_with_noise_random_scenarios_and_autoreset():
    """Random scenarios (per-env trajectories, schedules, thrust noise), every sensor noise,
    the IRLS estimate in the loop, truncation after 0.3 s and the autoreset after it."""
    n_done = _run_side_by_side(
        3,
        70,
        seed=7,
        estimator="irls",
        scenario="random",
        duration=0.3,
        sensor_noise=NOISE,
        estimator_rate="control",
    )
    assert n_done >= 6  # every sub-env went through at least two episodes


@pytest.mark.parametrize("preset", ["crazyflie", "indiflight"])
def test_matches_single_envs_under_a_sensor_preset_through_autoresets(preset):
    """A measured preset (rates, coloured noise, per-flight bias, latency): each row's sensors
    start again at its reset and draw what the single env draws."""
    n_done = _run_side_by_side(
        2, 70, seed=3, estimator="ekf", scenario="random", duration=0.3, sensor_noise=preset
    )
    assert n_done >= 4


def test_matches_single_envs_with_one_scenario_through_scattered_autoresets():
    """One named scenario for every row (the compiled reset: each row's spread drawn from its
    generator in the kernel, its time tables refilled with the other rows'): motor actions
    crash the vehicles at scattered steps, so rows restart and refill at different steps."""
    n_done = _run_side_by_side(
        4,
        100,
        seed=11,
        estimator="ekf",
        scenario="combined",
        duration=0.8,
        sensor_noise=NOISE,
        initial_spread=InitialStateSpread(0.3, 0.2, 0.1, 0.2),
        action_mode="motor",
    )
    assert n_done >= 5


def test_rows_sharing_a_scenario_do_not_leak_it_to_other_rows():
    """Rows that repeat a reset seed share one interned schedule; the other rows must keep
    their own (a grouping bug once gave row 1 the schedule of rows 0 and 2)."""
    kw = dict(scenario="random", random_trajectory="hover", duration=0.2, estimator_rate="control")
    seeds = [10001, 10002, 10001]
    vec = QuadFaultVectorEnv(len(seeds), "truth", info="full", **kw)
    singles = [QuadFaultEnv("truth", **kw, info="full") for _ in seeds]
    obs, info = vec.reset(seed=seeds)
    assert [e.reset(seed=s)[0] for e, s in zip(singles, seeds)]  # same seeds, same scenarios
    for k in range(15):
        obs, _, _, _, info = vec.step(np.zeros((len(seeds), 4), np.float32))
        for i, env in enumerate(singles):
            o, _, _, _, inf = env.step(np.zeros(4, np.float32))
            np.testing.assert_allclose(obs[i], o, rtol=0, atol=1e-9, err_msg=f"step {k} row {i}")
            np.testing.assert_allclose(info["eta_true"][i], inf["eta_true"], atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("estimator", ["ekf", "rls", "ukf", "truth", "none"])
def test_matches_single_envs_in_motor_mode_until_crashes(estimator):
    """Full-range random motor commands crash or tilt the vehicles: termination reasons,
    penalties and resets must agree too (the estimator at every substep or none)."""
    n_done = _run_side_by_side(
        2,
        60,
        seed=3,
        estimator=estimator,
        scenario="abrupt",
        duration=2.0,
        action_mode="motor",
        estimator_rate="physics",
        reward=gym.make("QuadFault-v0").unwrapped.reward_config,
    )
    assert n_done >= 1


def test_wrench_mode_and_compensation_match():
    _run_side_by_side(
        2,
        15,
        seed=11,
        estimator="truth",
        scenario="combined",
        duration=1.0,
        action_mode="wrench",
        action_scale=0.3,
    )
    _run_side_by_side(
        2,
        15,
        seed=12,
        estimator="truth",
        scenario="combined",
        duration=1.0,
        compensate=True,
        action_scale=0.3,
    )


def test_same_step_autoreset_reports_the_final_observation():
    kw = dict(scenario="combined", duration=0.05, estimator_rate="control")
    nxt = QuadFaultVectorEnv(2, "none", **kw)
    same = QuadFaultVectorEnv(2, "none", autoreset_mode="same_step", **kw)
    nxt.reset(seed=1)
    same.reset(seed=1)
    a = np.zeros((2, 4), dtype=np.float32)
    for _ in range(5):
        o1, _, te1, tr1, _ = nxt.step(a)
        o2, _, te2, tr2, info2 = same.step(a)
        np.testing.assert_array_equal(te1, te2)
        np.testing.assert_array_equal(tr1, tr2)
    assert tr2.all()  # 5 steps of 10 ms
    np.testing.assert_allclose(info2["final_obs"], o1, atol=1e-12)
    o1, r1, _, _, _ = nxt.step(a)  # next-step mode resets only now
    np.testing.assert_allclose(o2, o1, atol=1e-12)
    assert np.all(r1 == 0.0)


def test_make_vec_vector_entry_point_and_dict_observations():
    env = gym.make_vec(
        "QuadFault-v0",
        num_envs=3,
        vectorization_mode="vector_entry_point",
        estimator="none",
        observation="dict",
        info="full",
    )
    assert isinstance(env.unwrapped, QuadFaultVectorEnv)
    assert env.unwrapped.max_episode_steps == 2000  # the registration's limit
    obs, info = env.reset(seed=0)
    assert obs["eta_hat"].shape == (3, 4) and obs["eta_hat"].dtype == np.float32
    assert env.observation_space.contains(obs)
    obs, rew, term, trunc, info = env.step(env.action_space.sample() * 0)
    assert rew.shape == (3,) and np.all(rew > 0.5)  # hovering on the circle's start
    assert set(info) >= {"t", "eta_true", "eta_hat", "tracking_error", "_t"}
    env.close()


def test_light_info_holds_the_termination_reasons_of_the_same_flight():
    """The default info is the termination reasons alone; ``info="full"`` adds the
    diagnostics; the observations, rewards and reasons are the same either way."""
    kw = dict(scenario="abrupt", duration=2.0, action_mode="motor")
    light = QuadFaultVectorEnv(3, "none", **kw)
    full = QuadFaultVectorEnv(3, "none", info="full", **kw)
    (o1, i1), (o2, i2) = light.reset(seed=5), full.reset(seed=5)
    assert set(i1) == {"termination_reason", "_termination_reason"}
    assert set(i2) >= {"t", "eta_true", "eta_hat", "tracking_error", "motor_command"}
    rng, ended = np.random.default_rng(5), 0
    for _ in range(60):
        a = rng.uniform(-1, 1, (3, 4)).astype(np.float32)
        o1, r1, te1, tr1, i1 = light.step(a)
        o2, r2, te2, tr2, i2 = full.step(a)
        np.testing.assert_array_equal(o1, o2)
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_array_equal(te1, te2)
        assert list(i1["termination_reason"]) == list(i2["termination_reason"])
        assert all((r is not None) == t for r, t in zip(i1["termination_reason"], te1))
        ended += int(te1.sum())
    assert ended >= 1  # full-range motor commands crash
    with pytest.raises(ConfigError, match="info must be one of"):
        QuadFaultVectorEnv(2, "none", info="rich")


def test_the_configuration_env_passes_check_env():
    vec = QuadFaultVectorEnv(2, "none", scenario="combined", duration=1.0)
    check_env(vec.single_env, skip_render_check=True)


def test_bad_input_raises_clear_errors():
    with pytest.raises(ConfigError, match="num_envs"):
        QuadFaultVectorEnv(0)
    with pytest.raises(ConfigError, match="estimator"):
        QuadFaultVectorEnv(2, "kalman")
    with pytest.raises(ConfigError, match="autoreset_mode"):
        QuadFaultVectorEnv(2, "none", autoreset_mode="later")
    with pytest.raises(ConfigError, match="scenario"):
        QuadFaultVectorEnv(2, "none", scenario="nope")
    env = QuadFaultVectorEnv(2, "none", duration=1.0)
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros((2, 4)))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(4))
    with pytest.raises(ValueError, match="outside"):
        env.step(np.full((2, 4), 2.0))


def test_unknown_keywords_name_the_closest_of_either_env():
    import gymnasium as gym

    kw = dict(scenario="combined", duration=1.0)
    with pytest.raises(
        ConfigError,
        match="QuadFaultVectorEnv: unknown keyword 'autoreset_mod'; did you mean 'autoreset_mode'",
    ):
        QuadFaultVectorEnv(2, "none", autoreset_mod="same_step", **kw)
    with pytest.raises(ConfigError, match="'estimator_rat'; did you mean 'estimator_rate'"):
        gym.make_vec(
            "QuadFault-v1",
            num_envs=2,
            vectorization_mode="vector_entry_point",
            estimator_rat="control",
        )
    for removed in ("physics", "noise_streams"):  # no-op keywords, removed
        with pytest.raises(ConfigError, match=f"unknown keyword '{removed}'"):
            QuadFaultVectorEnv(2, "none", **{removed: "numpy"}, **kw)


@pytest.mark.slow  # compiles / starts a framework on the first run
def test_sb3_adapter_trains_ppo():
    pytest.importorskip("torch")
    sb3 = pytest.importorskip("stable_baselines3")
    from quad_fault_env.sb3_vec import make_sb3_vec_env

    env = make_sb3_vec_env(4, seed=0, estimator="none", scenario="combined", duration=0.1)
    model = sb3.PPO("MlpPolicy", env, n_steps=16, batch_size=32, n_epochs=1, seed=0, device="cpu")
    from stable_baselines3.common.logger import Logger

    model.set_logger(Logger(folder=None, output_formats=[]))  # no SB3-* temp folder
    model.learn(64)
    obs = env.reset()
    assert obs.shape == (4, env.observation_space.shape[0])
    done_seen = False
    for _ in range(12):  # 10 steps per episode: the adapter reports the terminal observation
        obs, rew, done, infos = env.step(model.predict(obs, deterministic=True)[0])
        for i in np.flatnonzero(done):
            done_seen = True
            assert infos[i]["terminal_observation"].shape == obs[i].shape
            assert infos[i]["TimeLimit.truncated"]
    assert done_seen
    env.close()


def test_sub_envs_of_one_configuration_share_no_episode_state():
    """The sub-envs share one configuration; after a reset each row owns its generator and
    scenario (nothing mutable is shared)."""
    vec = QuadFaultVectorEnv(3, "none", scenario="random", duration=0.5)
    vec.reset(seed=5)
    gens = [vec.flight.generator(i) for i in range(3)]
    assert len({id(g) for g in gens}) == 3 and len({id(s) for s in vec.scenarios}) == 3
    a = gens[0].bit_generator.state["state"]["state"]
    b = gens[1].bit_generator.state["state"]["state"]
    assert a != b


@pytest.mark.parametrize(
    "kw",
    [
        dict(
            scenario="random",
            initial_spread=InitialStateSpread(0.3, 0.2, 0.1, 0.2),
            sensor_noise=NOISE,
        ),
        dict(
            scenario="combined",
            thrust_noise=0.05,
            initial_spread=InitialStateSpread(0.3, 0.2, 0.1, 0.2),
        ),
        dict(scenario="random", random_trajectory="hover", controller=ControllerConfig.reference()),
    ],
)
def test_batched_reset_equals_single_env_resets(kw):
    """The batched reset gives every row the single env's episode start for seed s + i:
    scenario, true and measured initial state, the generator's position after the draws."""
    n = 12
    vec = QuadFaultVectorEnv(n, "none", **kw)
    obs, _ = vec.reset(seed=40)
    for i in range(n):
        env = QuadFaultEnv("none", **kw, info="full")
        o, info = env.reset(seed=40 + i)
        np.testing.assert_allclose(obs[i], o, rtol=0, atol=1e-12, err_msg=f"row {i}")
        assert vec.scenarios[i] == env.scenario
        for got, want in zip(vec.state, env.plant.state):
            np.testing.assert_allclose(got[i], want, rtol=0, atol=1e-12)
        for got, want in zip(vec.meas, env._meas):
            np.testing.assert_allclose(got[i], want, rtol=0, atol=1e-12)
        assert vec.max_steps[i] == env.max_steps
        np.testing.assert_array_equal(vec.eta_true[i], info["eta_true"])
        assert vec.flight.generator(i).bit_generator.state == env.np_random.bit_generator.state


def test_reset_options_and_seed_lists():
    """options['scenario'] for every row (validated like the single env); a list of seeds."""
    vec = QuadFaultVectorEnv(3, "none", scenario="random", duration=0.5, info="full")
    _, info = vec.reset(seed=[7, 7, 9], options={"scenario": "hover"})
    assert list(info["scenario"]) == ["hover"] * 3
    obs, _ = vec.reset(seed=[7, 7, 9])
    np.testing.assert_array_equal(obs[0], obs[1])
    assert not np.array_equal(obs[0], obs[2])
    with pytest.raises(ConfigError, match="unknown reset option"):
        vec.reset(seed=0, options={"wind": 3})
    with pytest.raises(ConfigError, match="options\\['scenario'\\]"):
        vec.reset(seed=0, options={"scenario": 42})


@pytest.mark.parametrize("feedforward", [True, False])
def test_time_tables_equal_the_functions_of_time(feedforward):
    """RowTimeTables: the reference, the feed-forward rates and the efficiency of each row at
    its window's step boundaries / substeps, for rows with their own trajectories, shared ones
    and different window starts; refilled when a row leaves its window or is invalidated.
    Without ``feedforward`` (no controller in the step) only p, v, a are tabulated."""
    from quad_fault_env.time_tables import WINDOW, RowTimeTables
    from quadfault.model.controller import GeometricController
    from quadfault.model.scenarios import random_scenario
    from quadfault.model.vehicle import Vehicle

    rng = np.random.default_rng(3)
    scs = [random_scenario(rng, 5.0, trajectory=t) for t in ("circle", "lissajous", "hover")]
    traj_key = np.array([0, 1, 2, 0])
    sched_key = np.array([0, 1, 2, 2])
    trajs, scheds = [s.trajectory for s in scs], [s.efficiency for s in scs]
    vehicle, cfg, S, dt = Vehicle(), ControllerConfig(), 10, 1e-3
    tables = RowTimeTables(4, S, dt, vehicle, cfg, feedforward=feedforward)
    # (the last refills every row from one step: the trajectories grouped by step)
    for k in (np.array([0, 0, 7, 3]), np.array([5, 15, 7, 20]), np.array([40, 40, 40, 40])):
        tables.ensure(k, traj_key, sched_key, trajs, scheds, WINDOW - 1)
        assert np.all((k - tables.k0 >= 0) & (k - tables.k0 < WINDOW))
        for step in (k, k + 1):
            refs, eta = tables.references(step), tables.efficiency(np.minimum(step, k))
            for i in range(4):
                t = float(step[i] * S * dt)
                want = trajs[traj_key[i]](t)
                ff = GeometricController(vehicle, trajs[traj_key[i]], cfg).feedforward_rates(t)
                rows = tuple(want) + tuple(ff)
                for r, x in enumerate(rows if feedforward else rows[:3]):
                    np.testing.assert_allclose(refs[i, r], x, rtol=0, atol=1e-9)
                if not feedforward:
                    assert np.all(refs[i, 3:] == 0.0)
                ts = (min(step[i], k[i]) * S + np.arange(S + 1)) * dt
                np.testing.assert_allclose(eta[i], scheds[sched_key[i]](ts), rtol=0, atol=1e-12)
    tables.invalidate([1])
    assert tables.k0[1] < 0


def test_time_tables_refilled_rows_join_the_others_column():
    """A row refilled mid-window (a reset) takes the column the other rows are at (one
    further when it idles at the coming step), so a step reads one column for every row;
    its values at its own steps are the functions of time's."""
    from quad_fault_env.time_tables import WINDOW, RowTimeTables
    from quadfault.model.scenarios import random_scenario
    from quadfault.model.vehicle import Vehicle

    rng = np.random.default_rng(5)
    scs = [random_scenario(rng, 5.0, trajectory=t) for t in ("circle", "lissajous")]
    trajs, scheds = [s.trajectory for s in scs], [s.efficiency for s in scs]
    key = np.array([0, 0, 1, 1])
    S, dt = 2, 1e-3
    tables = RowTimeTables(4, S, dt, Vehicle(), ControllerConfig())
    tables.ensure(np.full(4, 30), key, key, trajs, scheds, WINDOW - 1)
    k = np.array([37, 0, 37, 0])  # rows 1 and 3 start new episodes; row 3 idles a step
    tables.invalidate([1, 3])
    tables.ensure(k, key, key, trajs, scheds, WINDOW - 1, np.array([0, 0, 0, 1], bool))
    np.testing.assert_array_equal(k - tables.k0, [7, 7, 7, 8])
    for step in (k, k + 1):
        refs, eta = tables.references(step), tables.efficiency(step)
        for i in range(4):
            t = float(step[i] * S * dt)
            for r, x in enumerate(tuple(trajs[key[i]](t))[:3]):
                np.testing.assert_allclose(refs[i, r], x, rtol=0, atol=1e-12)
            ts = (step[i] * S + np.arange(S + 1)) * dt
            np.testing.assert_allclose(eta[i], scheds[key[i]](ts), rtol=0, atol=1e-12)


@pytest.mark.parametrize("estimator", ["irls", "ekf"])
def test_numba_thread_count_does_not_change_the_flight(estimator):
    """The parallel loop splits rows across threads; each row is computed alone, so
    one thread (training's default, ``TrainConfig.numba_threads``) and several give the
    same observations bit for bit."""
    import numba

    before = numba.get_num_threads()
    traces = []
    try:
        for threads in (1, numba.config.NUMBA_NUM_THREADS):
            numba.set_num_threads(threads)
            venv = QuadFaultVectorEnv(
                6,
                scenario="random",
                random_trajectory="random",
                estimator=estimator,
                estimator_rate="physics",
                duration=1.0,
            )
            obs, _ = venv.reset(seed=11)
            trace = [obs]
            for k in range(40):
                obs, *_ = venv.step(np.full((6, 4), 0.2 * np.cos(0.3 * k)))
                trace.append(obs)
            venv.close()
            traces.append(np.array(trace))
    finally:
        numba.set_num_threads(before)
    np.testing.assert_array_equal(traces[0], traces[1])
