"""Sweep backends: local processes and Ray give the serial sweep's table."""

from __future__ import annotations

import pytest

from agents.evaluate import AgentSpec, aggregate, markdown_table
from agents.sweep import evaluate_sweep, main, run_sweep
from quadfault.errors import ConfigError

AGENTS = [AgentSpec.parse("geometric"), AgentSpec.parse("estimate-aware:none")]


def _square(x):
    return x * x


def _table(backend, workers=2):
    flights = evaluate_sweep(AGENTS, "quick", [0, 1], scenarios=["abrupt_20s"], duration=0.3,
                             backend=backend, workers=workers)
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
    assert main(["evaluate", "--out", "unused", "--workers", "0"]) == 2
    assert "error:" in capsys.readouterr().err


def test_sweep_cli_evaluates_through_the_backend_parameter(tmp_path, monkeypatch):
    """``python -m agents.sweep evaluate`` hands --backend/--workers to agents.evaluate.evaluate
    (no patching of the module): the same results file as ``quadfault evaluate``."""
    import json

    import agents.evaluate as ev
    import agents.sweep as sweep

    seen = []
    original = ev.evaluate

    def spy(*args, **kwargs):
        seen.append((kwargs.get("backend"), kwargs.get("workers")))
        return original(*args, **kwargs)

    monkeypatch.setattr(ev, "evaluate", spy)
    common = ["--agents", "geometric", "--suite", "quick", "--scenarios", "abrupt_20s",
              "--seeds", "0", "--duration", "0.3", "--no-plots", "--quiet"]
    assert sweep.main(["evaluate", *common, "--out", str(tmp_path / "a"), "--backend", "serial",
                       "--workers", "1"]) == 0
    assert seen == [("serial", 1)]
    from quadfault.cli import main as cli_main

    assert cli_main(["evaluate", *common, "--out", str(tmp_path / "b")]) == 0
    runs = [json.loads((tmp_path / d / "results.json").read_text())["runs"] for d in "ab"]
    assert runs[0] == runs[1] and len(runs[0]) == 1
