"""The PPO residual study's fault distribution, scores and confidence intervals
(``benchmarks/studies/ppo_residual_study.py``, loaded from there; no training here)."""

import argparse
import importlib.util
import json
import types
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

_SPEC = importlib.util.spec_from_file_location(
    "ppo_residual_study",
    Path(__file__).resolve().parents[1] / "benchmarks" / "studies" / "ppo_residual_study.py",
)
study = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(study)


def _args(**changes):
    base = {
        "residual_scale": study.RESIDUAL_SCALE,
        "duration": 2.0,
        "random_faults": study.RANDOM_FAULTS,
    }
    return types.SimpleNamespace(**dict(base, **changes))


def test_t_interval_matches_scipy():
    x = np.random.default_rng(0).normal(0.03, 0.01, size=7)
    mean, half = study.t_interval(x)
    low, high = stats.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=stats.sem(x))
    assert mean == pytest.approx(x.mean())
    assert (mean - half, mean + half) == pytest.approx((low, high))
    assert np.isnan(study.t_interval([1.0])[1])


def test_random_faults_flag_parses_json_and_default():
    assert study._random_faults("default") is None
    assert study._random_faults('{"n_faults": [1, 1]}') == {"n_faults": [1, 1]}
    for bad in ("{oops", "[1, 2]"):
        with pytest.raises(argparse.ArgumentTypeError):
            study._random_faults(bad)


def test_episodes_draw_one_fault_of_the_study_severity():
    """The study's environment draws exactly one motor fault within the severity range,
    and both arms' keywords differ only in the estimator."""
    import gymnasium as gym

    import quad_fault_env  # noqa: F401

    args = _args()
    with_kw, without_kw = study.env_kwargs(args, "irls"), study.env_kwargs(args, "none")
    assert {k: v for k, v in with_kw.items() if k != "estimator"} == {
        k: v for k, v in without_kw.items() if k != "estimator"
    }
    seeds = study.episode_seeds(5, without_kw)
    assert seeds == sorted(set(seeds)) and seeds[0] >= 10_000
    env = gym.make(study.ENV_ID, **without_kw)
    try:
        for seed in seeds:
            env.reset(seed=seed)
            faults = env.unwrapped.scenario.efficiency.faults
            assert len(faults) == 1
            assert 0.5 <= faults[0].level <= 0.85
    finally:
        env.close()
    assert "random_faults" not in study.env_kwargs(_args(random_faults=None), "none")


def _results(base, ref, runs):
    out = {"baseline": base, "estimate_aware_reference": ref}
    out.update(runs)
    return out


def _entry(rmse, crashed=None):
    return {"rmse": list(rmse), "crashed": list(crashed or [False] * len(rmse))}


def test_summary_pairs_by_seed_and_scores_crashes_separately():
    base = _entry([0.10, 0.20, 0.30], [False, False, True])
    runs = {
        "with_estimate/0": _entry([0.05, 0.10, 0.10], [False, False, True]),
        "with_estimate/1": _entry([0.07, 0.12, 0.10], [False, False, False]),
        "without_estimate/0": _entry([0.09, 0.19, 0.30], [False, False, True]),
        "without_estimate/1": _entry([0.08, 0.20, 0.28], [False, False, True]),
    }
    seeds = {"with_estimate": [0, 1], "without_estimate": [0, 1]}
    s = study._summary(_results(base, _entry([0.05, 0.05, 0.05]), runs), seeds)
    # primary score: flown RMSE; per-seed mean paired gains, CI over the two seeds
    g0 = np.mean([0.05, 0.10, 0.20])
    g1 = np.mean([0.03, 0.08, 0.20])
    assert s["with_estimate"]["rmse"]["per_seed_gain"] == pytest.approx([g0, g1])
    assert s["with_estimate"]["rmse"]["gain"] == pytest.approx((g0 + g1) / 2)
    assert s["with_estimate"]["rmse"]["ci95"] == pytest.approx(study.t_interval([g0, g1])[1])
    assert s["with_estimate"]["ci_over"] == "seeds"
    assert s["with_estimate"]["crash_rate"] == pytest.approx(1 / 6)
    # secondary score: a crash counts CRASH_RMSE
    g1_crash5 = np.mean([0.03, 0.08, study.CRASH_RMSE - 0.10])
    assert s["with_estimate"]["rmse_crash5"]["per_seed_gain"][1] == pytest.approx(g1_crash5)
    # with vs without: RMSE_without - RMSE_with, positive when the estimate helps
    w = s["with_minus_without"]
    d0 = np.mean([0.04, 0.09, 0.20])
    d1 = np.mean([0.01, 0.08, 0.18])
    assert w["rmse"]["gain"] == pytest.approx((d0 + d1) / 2) and w["seeds"] == [0, 1]
    assert s["baseline"]["rmse"]["gain"] == 0.0
    assert s["estimate_aware_reference"]["crash_rate"] == 0.0
    md = study._markdown(
        s,
        {
            "env_id": study.ENV_ID,
            "random_faults": study.RANDOM_FAULTS,
            "timesteps": 10,
            "evaluated_seeds": seeds,
            "episodes": 3,
            "duration": 10.0,
            "residual_scale": 2.45,
            "missing_runs": [],
            "train_times": {},
        },
    )
    assert "| PPO with estimate |" in md and "With vs without the estimate" in md


def test_summary_with_one_seed_gives_episode_intervals():
    base = _entry([0.1, 0.2, 0.3, 0.4])
    runs = {
        "with_estimate/0": _entry([0.1, 0.1, 0.2, 0.3]),
        "without_estimate/0": _entry([0.1, 0.2, 0.3, 0.3]),
    }
    s = study._summary(_results(base, base, runs), {"with_estimate": [0], "without_estimate": [0]})
    assert s["with_estimate"]["ci_over"] == "episodes"
    assert s["with_estimate"]["rmse"]["ci95"] == pytest.approx(
        study.t_interval([0.0, 0.1, 0.1, 0.1])[1]
    )


@pytest.mark.slow
def test_check_distribution_flies_baseline_and_reference(tmp_path):
    """``--check-distribution`` trains nothing and writes the headroom table."""
    out = tmp_path / "dist"
    assert (
        study.main(
            ["--check-distribution", "--episodes", "2", "--duration", "0.5", "--out", str(out)]
        )
        == 0
    )
    md = (out / "distribution.md").read_text()
    assert "| geometric (zero residual) |" in md and "estimate-aware allocation" in md
    assert not (out / "with_estimate").exists()
    # the per-agent episode file is reused while its key (seeds, env keywords) matches
    cache = out / "eval" / "baseline.json"
    data = json.loads(cache.read_text())
    data["episodes"]["rmse"] = [9.0, 9.0]
    cache.write_text(json.dumps(data))
    argv = ["--check-distribution", "--episodes", "2", "--duration", "0.5", "--out", str(out)]
    assert study.main(argv) == 0
    assert "| geometric (zero residual) | 9.0000 |" in (out / "distribution.md").read_text()
    assert study.main(argv[:4] + ["0.4"] + argv[5:]) == 0  # other duration: flown again
    assert "| geometric (zero residual) | 9.0000 |" not in (out / "distribution.md").read_text()


def test_ppo_kwargs_override_merges_policy_kwargs():
    assert study.ppo_kwargs(_args()) == study.PPO_KWARGS
    merged = study.ppo_kwargs(
        _args(ppo_kwargs={"n_epochs": 5, "policy_kwargs": {"log_std_init": -1.0}})
    )
    assert merged["n_epochs"] == 5 and merged["learning_rate"] == study.PPO_KWARGS["learning_rate"]
    assert merged["policy_kwargs"] == {"log_std_init": -1.0, "net_arch": [128, 128]}
    assert study.PPO_KWARGS["policy_kwargs"]["log_std_init"] == -2.3  # not mutated
    with pytest.raises(argparse.ArgumentTypeError):
        study._json_object("[1]")
    with pytest.raises(SystemExit, match="policy_kwargs must be a JSON object"):
        study.ppo_kwargs(_args(ppo_kwargs={"policy_kwargs": [1]}))


def test_trajectory_and_compensate_reach_both_arms_alike():
    args = _args(trajectory="circle", compensate=True)
    with_kw, without_kw = study.env_kwargs(args, "irls"), study.env_kwargs(args, "none")
    assert with_kw["random_trajectory"] == without_kw["random_trajectory"] == "circle"
    assert with_kw["compensate"] is without_kw["compensate"] is True
    assert "compensate" not in study.env_kwargs(_args(), "irls")
    assert study.env_kwargs(_args(), "irls")["random_trajectory"] == "hover"


def test_compensate_is_a_no_op_without_the_estimate():
    """The study's ``--compensate`` changes only the arm with the estimate: with
    ``estimator="none"`` (eta_hat = 1) the environment flies exactly as without it, so the
    arm without the estimate can share its runs."""
    import gymnasium as gym

    from quad_fault_env.vector import QuadFaultVectorEnv

    spec = gym.spec(study.ENV_ID)
    flights = []
    for compensate in (False, True):
        kwargs = study.env_kwargs(_args(compensate=compensate), "none")
        venv = QuadFaultVectorEnv(2, **dict(spec.kwargs, **kwargs))
        obs, _ = venv.reset(seed=[3, 4])
        trace = [obs]
        for k in range(30):
            obs, *_ = venv.step(np.full((2, 4), 0.1 * np.sin(k)))
            trace.append(obs)
        venv.close()
        flights.append(np.array(trace))
    np.testing.assert_array_equal(flights[0], flights[1])
