"""``quadfault train`` as a user runs it: the step budget in whole rollouts, the policy for
Dict observations, best-model selection on fixed seeded episodes, the learning curve."""

import json

import numpy as np
import pytest

from agents.train_eval import planned_timesteps
from quadfault.errors import ConfigError

TINY_ENV = {"estimator": "none", "action_mode": "residual", "duration": 0.3}
TINY_PPO = '{"n_steps": 32, "batch_size": 32, "n_epochs": 1}'


def test_budget_rounds_to_the_nearest_whole_rollout():
    assert planned_timesteps(50_000, 8 * 2048) == 49_152  # 3.05 rollouts, not 65,536
    assert planned_timesteps(58_000, 8 * 2048) == 65_536  # 3.54 rollouts
    assert planned_timesteps(100, 8 * 2048) == 16_384  # at least one rollout
    assert planned_timesteps(4096, 2048) == 4096  # a whole number stays
    assert planned_timesteps(3072, 2048) == 4096  # halves round up
    assert planned_timesteps(777, 1) == 777  # SAC, one env: exactly what was asked


def _train(tmp_path, capsys, *extra, env=None, out="run"):
    from quadfault.cli import main

    code = main(
        [
            "train",
            "--env-kwargs",
            json.dumps(env or TINY_ENV),
            "--algo-kwargs",
            TINY_PPO,
            "--vector-env",
            "--n-envs",
            "2",
            "--out",
            str(tmp_path / out),
            *extra,
        ]
    )
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.rl
def test_cli_runs_whole_rollouts_and_says_so(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    code, out, err = _train(
        tmp_path, capsys, "--timesteps", "200", "--eval-freq", "64", "--eval-episodes", "2"
    )
    assert code == 0, err
    lines = out.splitlines()
    assert lines[0] == (
        "ppo seed 0: training 192 steps = 3 rollouts of 2 envs x 32 steps "
        "(n_steps), the nearest whole rollout to the 200 asked"
    )
    assert "ppo seed 0: 192 steps" in lines[1]
    saved = json.loads((tmp_path / "run" / "seed_0" / "train_config.json").read_text())
    assert (saved["timesteps"], saved["timesteps_run"], saved["steps_per_rollout"]) == (
        200,
        192,
        64,
    )
    # evaluations after each rollout at or past a multiple of eval_freq, and at the end
    data = np.load(tmp_path / "run" / "seed_0" / "evaluations.npz")
    assert data["timesteps"].tolist() == [64, 128, 192]
    # a request that is a whole number of rollouts runs as asked, without the line
    code, out, err = _train(
        tmp_path,
        capsys,
        "--timesteps",
        "128",
        "--eval-freq",
        "64",
        "--eval-episodes",
        "2",
        out="exact",
    )
    assert code == 0, err
    assert "rollouts of" not in out and "ppo seed 0: 128 steps" in out


@pytest.mark.rl
def test_sac_budget_in_steps_and_episode_train_freq_refused(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    from quadfault.cli import main

    sac = [
        "train",
        "--algo",
        "sac",
        "--env-kwargs",
        json.dumps(TINY_ENV),
        "--eval-freq",
        "64",
        "--eval-episodes",
        "1",
    ]
    code = main(
        [
            *sac,
            "--timesteps",
            "50",
            "--out",
            str(tmp_path / "sac"),
            "--algo-kwargs",
            '{"learning_starts": 16, "batch_size": 16, "buffer_size": 500}',
        ]
    )
    out, err = capsys.readouterr()
    assert code == 0 and "sac seed 0: 50 steps" in out and "rollouts of" not in out, err
    code = main(
        [
            *sac,
            "--timesteps",
            "50",
            "--out",
            str(tmp_path / "episodes"),
            "--algo-kwargs",
            '{"train_freq": [1, "episode"]}',
        ]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "train_freq" in err[0]
    # a value SB3 itself rejects is one line too, not its traceback
    code = main(
        [*sac, "--out", str(tmp_path / "bad"), "--algo-kwargs", '{"train_freq": ["many", "step"]}']
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "algo_kwargs rejected by SAC" in err[0]


@pytest.mark.rl
def test_dict_observation_picks_multi_input_policy(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    from agents.train import load_agent

    env = dict(TINY_ENV, observation="dict")
    code, out, err = _train(
        tmp_path, capsys, "--timesteps", "64", "--eval-freq", "64", "--eval-episodes", "2", env=env
    )
    assert code == 0, err
    model, venv = load_agent(tmp_path / "run" / "seed_0")
    assert type(model.policy).__name__ == "MultiInputActorCriticPolicy"
    obs = venv.reset()
    assert isinstance(obs, dict) and "eta_hat" in obs
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (1, 4)
    saved = json.loads((tmp_path / "run" / "seed_0" / "train_config.json").read_text())
    assert saved["policy"] == "MultiInputPolicy"
    # an explicit policy that cannot read the observation: one line, exit 2, nothing trained
    for policy, observation in (
        ("MlpPolicy", "dict"),
        ("MultiInputPolicy", "flat"),
        ("CnnPolicy", "flat"),
    ):
        code, _, err = _train(
            tmp_path,
            capsys,
            "--timesteps",
            "64",
            "--policy",
            policy,
            env=dict(TINY_ENV, observation=observation),
            out=policy,
        )
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1 and policy in lines[0], err
        assert not (tmp_path / policy / "seed_0" / "model.zip").exists()


def test_policy_names_are_checked_in_the_config():
    from agents.train import TrainConfig

    with pytest.raises(ConfigError, match="policy"):
        TrainConfig(policy="BigPolicy")
    with pytest.raises(ConfigError, match="eval_seed"):
        TrainConfig(eval_seed=-1)
    assert TrainConfig().eval_episodes >= 10


@pytest.mark.rl
def test_best_model_comes_from_fixed_seeded_episodes(tmp_path, capsys):
    """Every evaluation flies the same seeded episodes (default 10, seeds 10000-10009); the
    geometric controller flies them too; the saved best model reproduces its evaluation."""
    pytest.importorskip("stable_baselines3")
    import gymnasium as gym

    import quad_fault_env  # noqa: F401
    from agents.policies import GeometricPolicy
    from agents.train import load_agent
    from agents.train_eval import evaluate_episodes

    code, _, err = _train(tmp_path, capsys, "--timesteps", "192", "--eval-freq", "64")
    assert code == 0, err
    run = tmp_path / "run" / "seed_0"
    data = np.load(run / "evaluations.npz")
    seeds = list(range(10_000, 10_010))
    assert data["episode_seeds"].tolist() == seeds
    assert data["results"].shape == (3, 10)
    env = gym.make("QuadFaultHover-v1", **TINY_ENV)  # quadfault train's default id
    returns, lengths = evaluate_episodes(GeometricPolicy.from_env(env), env, seeds)
    np.testing.assert_array_equal(data["baseline_results"], returns)
    np.testing.assert_array_equal(data["baseline_ep_lengths"], lengths)
    assert len(set(np.round(returns, 9))) > 1  # ten different episodes, not one repeated
    model, venv = load_agent(run / "best")  # best/best_model.zip with its statistics
    best = data["results"].mean(axis=1).argmax()
    again, _ = evaluate_episodes(model, env, seeds, venv)
    np.testing.assert_allclose(again, data["results"][best], rtol=0, atol=1e-9)


@pytest.mark.slow
@pytest.mark.rl
def test_learning_curve_over_seeds_with_the_baseline(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    from agents.learning_curve import curve_data, matching_runs

    code, out, err = _train(
        tmp_path,
        capsys,
        "--timesteps",
        "128",
        "--eval-freq",
        "64",
        "--eval-episodes",
        "2",
        "--seeds",
        "0",
        "1",
    )
    assert code == 0, err
    png = tmp_path / "run" / "learning_curve.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"learning curve over 2 seed(s) -> {png}" in out
    # a seed trained later into the same folder joins; other settings are left out and named
    code, out, err = _train(
        tmp_path,
        capsys,
        "--timesteps",
        "128",
        "--eval-freq",
        "64",
        "--eval-episodes",
        "2",
        "--seeds",
        "2",
    )
    assert code == 0 and "learning curve over 3 seed(s)" in out, err
    code, out, err = _train(
        tmp_path,
        capsys,
        "--timesteps",
        "64",
        "--eval-freq",
        "64",
        "--eval-episodes",
        "2",
        "--seeds",
        "3",
    )
    assert code == 0 and "over 1 seed(s)" in out and "left out 3 run(s)" in out, err
    saved = json.loads((tmp_path / "run" / "seed_0" / "train_config.json").read_text())
    runs, other = matching_runs(tmp_path / "run", saved)
    assert [r.name for r in runs] == ["seed_0", "seed_1", "seed_2"]
    assert [r.name for r in other] == ["seed_3"]
    data = curve_data(runs)
    assert data["returns"].shape == (3, 2) and data["timesteps"].tolist() == [64, 128]
    assert data["baseline"] is not None and np.isfinite(data["baseline"])
    # seeds differ (the band has a width), the baseline is the same for all of them
    assert np.ptp(data["returns"], axis=0).max() > 0
