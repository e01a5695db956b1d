"""Sweep backends: local processes and Ray give the serial sweep's table."""

from __future__ import annotations

import pytest

from agents.evaluate import AgentSpec, aggregate, evaluate, markdown_table
from agents.sweep import run_sweep
from quadfault.cli import main
from quadfault.errors import ConfigError

AGENTS = [AgentSpec.parse("geometric"), AgentSpec.parse("estimate-aware:none")]


def _square(x):
    return x * x


def _table(backend, workers=2):
    flights = evaluate(
        AGENTS,
        "quick",
        [0, 1],
        scenarios=["abrupt_20s"],
        duration=0.3,
        backend=backend,
        workers=workers,
    )
    return markdown_table(aggregate(flights)), [f.metrics.rmse for f in flights]


@pytest.fixture(scope="module")
def serial_table():
    return _table("serial")


def test_run_sweep_keeps_task_order():
    tasks = list(range(7))
    assert run_sweep(_square, tasks, backend="local", workers=2) == [t * t for t in tasks]
    assert run_sweep(_square, [], backend="local") == []


def test_local_backend_gives_the_serial_table(serial_table):
    table, rmse = _table("local")
    assert table == serial_table[0]
    assert rmse == serial_table[1]
    assert "geometric" in table


@pytest.mark.slow  # compiles / starts a framework on the first run
def test_ray_backend_gives_the_same_table(serial_table):
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        table, rmse = _table("ray")
    finally:
        ray.shutdown()
    assert table == serial_table[0]
    assert rmse == serial_table[1]


def test_bad_backend_and_workers_are_config_errors(capsys):
    with pytest.raises(ConfigError, match="backend"):
        run_sweep(_square, [1], backend="slurm")
    with pytest.raises(ConfigError, match="workers"):
        run_sweep(_square, [1], workers=0)
    assert main(["evaluate", "--out", "unused", "--workers", "0", "--quiet"]) == 2
    assert "error:" in capsys.readouterr().err


def test_evaluate_cli_hands_backend_and_workers_to_evaluate(tmp_path, monkeypatch):
    """``quadfault evaluate --backend --workers`` reaches agents.evaluate.evaluate and gives
    the serial run's results file."""
    import json

    import agents.evaluate as ev

    seen = []
    original = ev.evaluate

    def spy(*args, **kwargs):
        seen.append((kwargs.get("backend"), kwargs.get("workers")))
        return original(*args, **kwargs)

    monkeypatch.setattr(ev, "evaluate", spy)
    common = [
        "--agents",
        "geometric",
        "--suite",
        "quick",
        "--scenarios",
        "abrupt_20s",
        "--seeds",
        "0",
        "--duration",
        "0.3",
        "--no-plots",
        "--quiet",
    ]
    assert (
        main(
            [
                "evaluate",
                *common,
                "--out",
                str(tmp_path / "a"),
                "--backend",
                "local",
                "--workers",
                "1",
            ]
        )
        == 0
    )
    assert main(["evaluate", *common, "--out", str(tmp_path / "b")]) == 0
    assert seen == [("local", 1), ("serial", None)]
    runs = [json.loads((tmp_path / d / "results.json").read_text())["runs"] for d in "ab"]
    assert runs[0] == runs[1] and len(runs[0]) == 1
