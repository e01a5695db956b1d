"""The rotor-loss agent study: each arm sees only its own estimate, on the same flights
(:mod:`agents.observed_estimate`), and ``benchmarks/rotor_loss_agents.py`` runs end to end on
a tiny budget."""

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from agents.observed_estimate import ObservedEstimateVectorEnv
from estimators.baselines import NOMINAL_PRIOR_SD
from quad_fault_env.tasks import registered_kwargs
from quadfault.errors import ConfigError

ENV_ID = "QuadFaultRotorLossComplete-v0"
SEEDS = [3, 4]


def _flight(observe, steps, **kw):
    """Observations, final observations and true efficiencies of zero-residual steps."""
    env = ObservedEstimateVectorEnv(
        len(SEEDS),
        autoreset_mode="same_step",
        observe=observe,
        info="full",
        **registered_kwargs(ENV_ID, **kw),
    )
    obs, _ = env.reset(seed=SEEDS)
    out, finals, truth = [obs], [], []
    for _ in range(steps):
        obs, _, term, trunc, info = env.step(np.zeros((len(SEEDS), 4)))
        out.append(obs)
        truth.append(info["eta_true"])
        if "final_obs" in info:
            done = info["_final_obs"]
            finals.append((info["final_obs"][done], info["final_info"]["eta_true"][done]))
    names = env.unwrapped.single_env.observation_names
    env.close()
    return np.array(out), finals, np.array(truth), names


def test_arms_differ_only_in_the_estimate_slots_on_the_same_flight():
    steps = 620  # past the latest onset (6 s): the loss and the switch happen in every row
    irls, _, eta_true, names = _flight("irls", steps)
    est = [i for i, n in enumerate(names) if n.startswith(("eta_hat", "eta_sd"))]
    rest = [i for i in range(len(names)) if i not in est]
    assert (eta_true[-1] == 0).sum() == len(SEEDS)  # one rotor gone in every row
    for observe in ("none", "truth", "ekf"):
        obs, _, _, _ = _flight(observe, steps)
        # the flight (the base flies on the IRLS estimate) is the same to the bit
        np.testing.assert_array_equal(obs[:, :, rest], irls[:, :, rest])
        assert not np.array_equal(obs[:, :, est], irls[:, :, est])
    none, _, _, _ = _flight("none", steps)
    np.testing.assert_array_equal(none[:, :, est[:4]], 1.0)
    np.testing.assert_allclose(none[:, :, est[4:]], NOMINAL_PRIOR_SD)
    truth, _, _, _ = _flight("truth", steps)
    np.testing.assert_allclose(truth[1:, :, est[:4]], eta_true, atol=1e-6)
    np.testing.assert_array_equal(truth[:, :, est[4:]], 0.0)


def test_final_observation_carries_the_observed_estimate():
    # 0.5 s episodes (the rotor stops at 0.15-0.3 s) end in the run: the final observation of
    # the truth arm holds the episode's last true efficiency (a rotor at 0), the first
    # observation of the next episode (same-step reset) the new one's (all 1)
    obs, finals, _, names = _flight("truth", 60, duration=0.5)
    est = [i for i, n in enumerate(names) if n.startswith("eta_hat")]
    assert finals
    for final, eta_true in finals:
        np.testing.assert_array_equal(final[:, est], eta_true)
        assert (eta_true == 0).sum(axis=1).tolist() == [1] * len(eta_true)
    assert np.all(obs[51, :, est] == 1.0)  # the step after the 50-step episodes ended


def test_observe_is_checked():
    kw = registered_kwargs(ENV_ID)
    with pytest.raises(ConfigError, match="observe must be one of"):
        ObservedEstimateVectorEnv(1, observe="oracle", **kw)
    with pytest.raises(ConfigError, match="batched"):
        ObservedEstimateVectorEnv(1, observe="truth", **dict(kw, estimator="none"))


def _study():
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "rotor_loss_agents.py"
    spec = importlib.util.spec_from_file_location("rotor_loss_agents", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)  # its dataclass looks its module up
    spec.loader.exec_module(sys.modules[spec.name])
    return sys.modules[spec.name]


def test_study_runs_end_to_end_on_a_tiny_budget(tmp_path):
    pytest.importorskip("stable_baselines3")
    study = _study()
    figure = tmp_path / "curves.png"
    argv = ["--arms", "irls", "memory", "--seeds", "0", "--timesteps", "512", "--n-envs", "2"]
    argv += ["--eval-every", "256", "--curve-episodes", "2", "--episodes", "2"]
    argv += ["--duration", "6.5", "--out", str(tmp_path / "out"), "--plot", str(figure)]
    assert study.main(argv) == 0
    data = json.loads((tmp_path / "out" / "study.json").read_text())
    runs = data["runs"]
    assert set(runs) == {"irls", "memory"}
    for arm in runs.values():
        (run,) = arm
        assert [c["steps"] for c in run["curve"]] == [0, 512]
        # paired: every arm and the reference fly the same rotors and onsets
        assert run["test"]["rotor"] == data["reference"]["rotor"]
        assert run["test"]["onset"] == data["reference"]["onset"]
        assert all(1 <= r <= 4 for r in run["test"]["rotor"])
        assert all(0.3 * 6.5 <= t <= 0.6 * 6.5 for t in run["test"]["onset"])
    assert figure.stat().st_size > 0
    table = (tmp_path / "out" / "study.md").read_text()
    assert "reference controller alone" in table and "memory" in table
    # a second call reuses the runs and will not overwrite the figure
    with pytest.raises(SystemExit, match="exists"):
        study.main(argv)


def test_steps_to_half():
    study = _study()
    curve = [{"steps": 0, "success": 0.0}, {"steps": 10, "success": 0.5}]
    assert study.steps_to(curve, "success") == 10
    assert study.steps_to(curve[:1], "success") is None
