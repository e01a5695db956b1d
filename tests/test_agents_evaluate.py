"""Evaluation: deterministic under a seed, files written safely, clear errors."""

import json

import pytest

from agents.evaluate import AgentSpec, aggregate, evaluate, markdown_table
from agents.suite import SUITES, get_suite, single_motor_failure
from quadfault.cli import main
from quadfault.errors import ConfigError


def test_agent_specs():
    assert AgentSpec.parse("estimate-aware").estimator == "irls"
    assert AgentSpec.parse("estimate-aware:truth").label == "estimate-aware:truth"
    with pytest.raises(ConfigError, match="estimator must be"):
        AgentSpec.parse("estimate-aware:magic")
    with pytest.raises(ConfigError, match="does not exist"):
        AgentSpec.parse("sb3:/no/such/run")
    with pytest.raises(ConfigError, match="unknown agent"):
        AgentSpec.parse("pid")


def test_suites_build_and_restrict():
    for _name, entries in SUITES.items():
        for e in entries:
            sc = e.scenario(0)
            assert sc.name == e.name and sc.duration > 0
    assert [e.name for e in get_suite("quick", ["single_0.3"])] == ["single_0.3"]
    with pytest.raises(ConfigError, match="no scenario"):
        get_suite("quick", ["nope"])
    with pytest.raises(ConfigError, match="unknown suite"):
        get_suite("nope")
    assert single_motor_failure(0.3).fault_windows()[0][0] == 1


def test_evaluation_deterministic_under_seed():
    agents = [AgentSpec.parse("geometric"), AgentSpec.parse("estimate-aware:truth")]
    runs = [evaluate(agents, "smoke", [4], duration=0.4) for _ in range(2)]
    rows = [aggregate(r) for r in runs]
    assert rows[0] == rows[1]
    assert [f.metrics for f in runs[0]] == [f.metrics for f in runs[1]]
    other = aggregate(evaluate(agents[:1], "smoke", [5], duration=0.4))
    assert other[0]["rmse_mean"] != rows[0][0]["rmse_mean"]
    table = markdown_table(rows[0])
    assert "| abrupt_4s | estimate-aware:truth | 1 |" in table


def test_cli_writes_tables_and_plots_and_refuses_overwrite(tmp_path, capsys):
    out = tmp_path / "eval"
    args = [
        "evaluate",
        "--agents",
        "geometric",
        "estimate-aware:none",
        "--suite",
        "smoke",
        "--seeds",
        "0",
        "--duration",
        "0.3",
        "--out",
        str(out),
        "--quiet",
    ]
    assert main(args) == 0
    data = json.loads((out / "results.json").read_text())
    assert {r["agent"] for r in data["summary"]} == {"geometric", "estimate-aware:none"}
    assert len(data["runs"]) == 2 and data["runs"][0]["crashed"] is False
    assert (out / "results.md").read_text().startswith("# Evaluation")
    assert (out / "fault_abrupt_4s.png").stat().st_size > 1000
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--force" in err[0]
    assert main(args + ["--force"]) == 0


def test_cli_duplicate_agent_is_an_error(tmp_path, capsys):
    assert main(["evaluate", "--agents", "geometric", "geometric", "--out", str(tmp_path)]) == 2
    assert "twice" in capsys.readouterr().err


def test_evaluate_flies_env_policies_on_current_ids():
    """``quadfault evaluate`` of an environment policy makes a current id: no deprecation
    warning of the project's own ``-v0`` ids."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        flights = evaluate([AgentSpec.parse("policy:geometric")], "smoke", [0], duration=0.3)
    assert len(flights) == 1 and flights[0].metrics
    assert not [w for w in caught if "out of date" in str(w.message) or "-v0" in str(w.message)], [
        str(w.message) for w in caught
    ]
