"""SB3 training: smoke runs with tiny budgets, save/load round trip with VecNormalize."""

import json

import numpy as np
import pytest

from agents.train import TrainConfig
from quadfault.errors import ConfigError

TINY_ENV = {"estimator": "none", "action_mode": "residual", "duration": 0.5}


def test_config_validation_and_file(tmp_path):
    with pytest.raises(ConfigError, match="algo"):
        TrainConfig(algo="dqn")
    with pytest.raises(ConfigError, match="timesteps"):
        TrainConfig(timesteps=0)
    for bad in (0, True, 1.5):
        with pytest.raises(ConfigError, match="numba_threads"):
            TrainConfig(numba_threads=bad)
    assert TrainConfig(numba_threads=None).numba_threads is None
    path = tmp_path / "cfg.json"
    path.write_text(json.dumps({"algo": "sac", "seeds": [1, 2], "bogus": 1}))
    with pytest.raises(ConfigError, match="unknown key"):
        TrainConfig.from_file(path)
    path.write_text(json.dumps({"algo": "sac", "seeds": [1, 2]}))
    cfg = TrainConfig.from_file(path)
    assert cfg.algo == "sac" and cfg.seeds == (1, 2)
    path.write_text("{not json")
    with pytest.raises(ConfigError, match="not valid JSON"):
        TrainConfig.from_file(path)


def _tiny(algo):
    kwargs = (
        {"n_steps": 32, "batch_size": 32, "n_epochs": 1}
        if algo == "ppo"
        else {"learning_starts": 16, "batch_size": 16, "buffer_size": 1000}
    )
    return TrainConfig(
        algo=algo,
        env_kwargs=TINY_ENV,
        timesteps=64,
        eval_freq=32,
        eval_episodes=1,
        checkpoint_freq=32,
        algo_kwargs=kwargs,
    )


@pytest.mark.slow
@pytest.mark.rl
@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_smoke_training_and_round_trip(algo, tmp_path):
    pytest.importorskip("torch")
    pytest.importorskip("stable_baselines3")
    import tempfile

    from stable_baselines3.common.vec_env import VecNormalize

    from agents.train import load_agent, train_one

    monkey_tmp = tmp_path / "system_tmp"  # SB3's default logger makes tempdir/SB3-* folders
    monkey_tmp.mkdir()
    saved, tempfile.tempdir = tempfile.tempdir, str(monkey_tmp)
    try:
        model = train_one(_tiny(algo), 0, tmp_path / "run", quiet=True)
    finally:
        tempfile.tempdir = saved
    assert not list(monkey_tmp.glob("SB3-*"))  # training leaves no empty logger folder
    assert model.num_timesteps == 64  # whole rollouts: exactly the budget
    for name in (
        "model.zip",
        "vecnormalize.pkl",
        "train_config.json",
        "evaluations.npz",
        "best/best_model.zip",
        "best/vecnormalize.pkl",
    ):
        assert (tmp_path / "run" / name).exists(), name
    assert list((tmp_path / "run" / "checkpoints").glob("*vecnormalize*"))
    loaded, venv = load_agent(tmp_path / "run")
    assert isinstance(venv, VecNormalize) and not venv.training
    trained_vn = model.get_vec_normalize_env()
    np.testing.assert_allclose(venv.obs_rms.mean, trained_vn.obs_rms.mean)
    np.testing.assert_allclose(venv.obs_rms.var, trained_vn.obs_rms.var)
    obs = trained_vn.normalize_obs(
        np.linspace(-1, 1, venv.observation_space.shape[0], dtype=np.float32)
    )
    a1, _ = model.predict(obs, deterministic=True)
    a2, _ = loaded.predict(obs, deterministic=True)
    np.testing.assert_allclose(a1, a2, atol=1e-6)
    # a saved model flies an evaluation scenario deterministically, with its statistics
    if algo == "ppo":
        from agents.evaluate import AgentSpec, fly_agent
        from agents.rollout import FlightConfig
        from agents.suite import get_suite

        spec = AgentSpec.parse(f"sb3:{tmp_path / 'run'}")
        sc = get_suite("smoke")[0].scenario(0).replace(duration=0.3)
        a, b = (fly_agent(spec, sc, 3, FlightConfig()) for _ in range(2))
        assert a.metrics == b.metrics and len(a.t) == 30
    # no silent overwrite
    from quadfault.errors import QuadfaultError

    with pytest.raises(QuadfaultError, match="already exists"):
        train_one(_tiny(algo), 0, tmp_path / "run", quiet=True)


def test_cli_bad_json_is_one_line(capsys):
    from quadfault.cli import main

    assert main(["train", "--env-kwargs", "{oops", "--out", "x"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--env-kwargs" in err[0]


def test_missing_sb3_is_one_clean_error(monkeypatch, tmp_path, capsys):
    import sys

    monkeypatch.setitem(sys.modules, "stable_baselines3", None)  # import now fails
    from quadfault.cli import main

    assert (
        main(["train", "--env-kwargs", '{"estimator": "none"}', "--out", str(tmp_path / "x")]) == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "rl" in err[0] and "stable-baselines3" in err[0]


def test_tensorboard_missing_is_clean(tmp_path, monkeypatch):
    pytest.importorskip("stable_baselines3")
    import importlib.util
    from dataclasses import replace

    from agents.train import train_one
    from quadfault.errors import QuadfaultError

    find_spec = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util,
        "find_spec",  # as without the tensorboard package
        lambda name, *a: None if name == "tensorboard" else find_spec(name, *a),
    )
    cfg = replace(_tiny("ppo"), tensorboard=str(tmp_path / "tb"))
    with pytest.raises(QuadfaultError, match="tensorboard"):
        train_one(cfg, 0, tmp_path / "run", quiet=True)


@pytest.mark.rl
def test_vector_env_training_writes_complete_files(tmp_path):
    """``vector_env``: PPO on the array-stepped env; every file of the run is written through
    a rename (no temporary or scratch file is left) and loads into a single env."""
    pytest.importorskip("torch")
    pytest.importorskip("stable_baselines3")
    import zipfile
    from dataclasses import replace

    from agents.train import load_agent, train_one

    cfg = replace(_tiny("ppo"), vector_env=True, n_envs=2, timesteps=128, eval_freq=64)
    model = train_one(cfg, 0, tmp_path / "run", quiet=True)
    run = tmp_path / "run"
    assert model.num_timesteps == 128
    assert type(model.get_env().venv).__name__ == "VecMonitor"
    checkpoints = sorted(p.name for p in (run / "checkpoints").iterdir())
    assert "model_64_steps.zip" in checkpoints and "model_vecnormalize_64_steps.pkl" in checkpoints
    for path in [
        run / "best" / "best_model.zip",
        run / "model.zip",
        *(run / "checkpoints").glob("*.zip"),
    ]:
        assert zipfile.is_zipfile(path), path
    assert np.load(run / "evaluations.npz")["results"].shape[0] >= 2
    leftovers = [p for p in run.rglob("*") if p.name.startswith(".")]
    assert leftovers == []
    assert (run / "monitor" / "monitor.csv").exists()
    loaded, venv = load_agent(run)  # a single (non-vector) env from train_config.json
    action, _ = loaded.predict(venv.reset(), deterministic=True)
    assert action.shape == (1, 4) and np.all(np.abs(action) <= 1)


def test_vector_env_rejects_other_ids(tmp_path):
    pytest.importorskip("stable_baselines3")
    from agents.train import TrainConfig, make_vec_env

    cfg = TrainConfig(env_id="CartPole-v1", env_kwargs={}, vector_env=True)
    with pytest.raises(ConfigError, match="QuadFault"):
        make_vec_env(cfg, 0, 2)


def test_flags_override_the_config_file(tmp_path):
    """``quadfault train`` flags win over the config file; unset flags keep its values."""
    import argparse

    from agents.train import add_arguments, config_from_args

    path = tmp_path / "cfg.json"
    path.write_text(
        json.dumps(
            {
                "algo": "sac",
                "timesteps": 500,
                "numba_threads": 2,
                "env_kwargs": {"estimator": "ekf", "duration": 2},
            }
        )
    )
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    cfg = config_from_args(
        parser.parse_args(
            ["--config", str(path), "--timesteps", "700", "--estimator", "irls", "--out", "x"]
        )
    )
    assert (cfg.algo, cfg.timesteps, cfg.numba_threads) == ("sac", 700, 2)
    assert cfg.env_kwargs == {"estimator": "irls", "duration": 2}
    cfg = config_from_args(parser.parse_args(["--numba-threads", "1", "--out", "x"]))
    assert cfg.numba_threads == 1 and cfg.algo == "ppo"
    with pytest.raises(ConfigError, match="numba_threads"):
        config_from_args(parser.parse_args(["--numba-threads", "0", "--out", "x"]))


def test_torch_keeps_its_thread_count_through_vector_env_steps():
    # numba's OpenMP layer and torch share the OpenMP runtime: the vector env's per-step
    # numba thread switch must not hand torch the core count back
    torch = pytest.importorskip("torch")
    from agents.train import TrainConfig, make_vec_env, set_threads

    config = TrainConfig(
        env_id="QuadFaultRotorLoss-v0",
        env_kwargs=dict(TINY_ENV),
        n_envs=2,
        vector_env=True,
        torch_threads=1,
    )
    before = torch.get_num_threads()
    try:
        env = make_vec_env(config, 0, 2)
        set_threads(config)
        env.reset()
        env.step(np.zeros((2, 4), dtype=np.float32))
        assert torch.get_num_threads() == 1
        env.close()
    finally:
        torch.set_num_threads(before)
