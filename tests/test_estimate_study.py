"""The estimate study's one command: a tiny run of every arm writes a complete, paired result."""

import json
import sys
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks" / "studies"))

import estimate_study  # noqa: E402


@pytest.mark.slow
def test_every_arm_trains_and_flies_the_same_episodes(tmp_path):
    out = tmp_path / "study"
    assert (
        estimate_study.main(
            [
                "--tasks",
                "rotor_loss",
                "--seeds",
                "0",
                "--timesteps",
                "128",
                "--n-envs",
                "4",
                "--n-steps",
                "32",
                "--episodes",
                "2",
                "--tuning-episodes",
                "1",
                "--curve-points",
                "2",
                "--allocation",
                "nominal",
                "--duration",
                "0.5",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    result = json.loads((out / "study.json").read_text())
    assert (out / "study.png").stat().st_size > 0
    assert set(result["design"]["arms"]) == set(estimate_study.ARMS)
    task = result["tasks"]["rotor_loss"]
    assert set(task["arms"]) == set(estimate_study.ARMS)
    runs = [run for arm in task["arms"].values() for run in arm.values()]
    # paired: every arm flew the same test episodes, whose scenarios drew the same faults
    assert all(r["episode_seeds"] == task["episode_seeds"] for r in runs)
    assert len({tuple(r["episode_scenarios"]) for r in runs}) == 1
    for r in runs:
        assert len(r["crashed"]) == len(r["rmse"]) == len(r["return"]) == 2
        assert r["timesteps_run"] == 128 and r["curve"]["timesteps"][-1] == 128
        assert all(0 <= c <= 1 for c in r["curve"]["crash_rate"])
    for _arm, s in task["summary"].items():
        assert 0 <= s["crashed"][0] <= 1 and s["rmse"][0] > 0
    assert set(task["paired_vs_mlp_none"]) == set(estimate_study.ARMS) - {"mlp_none"}
    # every arm is also paired with its own zero-residual base on the same episodes
    assert set(task["paired_vs_base"]) == set(estimate_study.ARMS)
    base = task["references"]["base_irls"]
    irls = next(iter(task["arms"]["mlp_irls"].values()))
    assert task["paired_vs_base"]["mlp_irls"]["return"][0] == pytest.approx(
        sum(a - b for a, b in zip(irls["return"], base["return"])) / len(base["return"])
    )
    assert result["cpu_s"] > 0
    # --replot redraws from study.json alone, with the bases' returns on the learning curves
    (out / "study.png").unlink()
    assert estimate_study.main(["--replot", "--out", str(out)]) == 0
    assert (out / "study.png").stat().st_size > 0
    replotted = json.loads((out / "study.json").read_text())["tasks"]["rotor_loss"]
    assert replotted["paired_vs_base"] == task["paired_vs_base"]
    # the memory arm saw stacked observations; the oracle arm the true efficiency
    cfg = json.loads(
        (out / "rotor_loss" / "memory_none" / "seed_0" / "train_config.json").read_text()
    )
    assert cfg["frame_stack"] == estimate_study.FRAME_STACK
    assert cfg["env_kwargs"]["estimator"] == "none"


def test_train_only_then_evaluate_reuses_the_runs_and_their_cpu(tmp_path, capsys):
    """Runs trained by a --train-only process (here over a lock a dead process left behind)
    are evaluated, not retrained, by the full command, which counts their training CPU."""
    import subprocess

    out = tmp_path / "study"
    tiny = [
        "--tasks",
        "rotor_loss",
        "--arms",
        "mlp_none",
        "mlp_truth",
        "--seeds",
        "0",
        "--timesteps",
        "64",
        "--n-envs",
        "2",
        "--n-steps",
        "32",
        "--episodes",
        "1",
        "--tuning-episodes",
        "1",
        "--curve-points",
        "1",
        "--allocation",
        "nominal",
        "--duration",
        "0.3",
        "--out",
        str(out),
    ]
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (out / "rotor_loss" / "mlp_none").mkdir(parents=True)
    (out / "rotor_loss" / "mlp_none" / ".seed_0.training").write_text(str(dead.pid))
    assert estimate_study.main(tiny + ["--train-only"]) == 0
    assert not (out / "study.json").exists()
    assert not list(out.rglob(".*.training"))
    models = {p: p.stat().st_mtime_ns for p in out.rglob("seed_0/model.zip")}
    assert len(models) == 2
    capsys.readouterr()
    assert estimate_study.main(tiny + ["--markdown"]) == 0
    printed = capsys.readouterr().out
    assert "| `mlp_truth` |" in printed and "| arm | crash rate |" in printed
    assert {p: p.stat().st_mtime_ns for p in models} == models  # reused, not retrained
    task = json.loads((out / "study.json").read_text())["tasks"]["rotor_loss"]
    assert all(r["train_cpu_s"] > 0 for arm in task["arms"].values() for r in arm.values())
