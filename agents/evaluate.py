"""Evaluate agents over a scenario suite and several seeds.

``python -m agents.evaluate`` or ``quadfault evaluate``::

    quadfault evaluate --agents geometric estimate-aware:irls estimate-aware:truth \\
        --suite quick --seeds 0 1 2 --out results/eval

Agents (``--agents``):

========================================  =================================================
spec                                      agent
========================================  =================================================
``geometric``                             plain geometric controller (1 kHz, nominal
                                          allocation)
``estimate-aware:<irls|ekf|truth|none>``  estimate-aware controller with eta_hat from that
                                          source (the built-in ablation; ``truth`` is the
                                          labelled oracle, ``none`` = nominal belief)
``policy:geometric``                      the geometric controller inside the environment
                                          (100 Hz, zero residual) -- the baseline of residual
                                          policies
``sb3:<run folder or model.zip>``         a trained stable-baselines3 model, with its
                                          ``VecNormalize`` statistics, in the environment it
                                          was trained on (``train_config.json``)
========================================  =================================================

Writes ``OUT/results.json`` (every flight's metrics and the per-agent, per-scenario
aggregates), ``OUT/results.md`` (the table) and ``OUT/fault_<scenario>.png`` (position error,
tilt error and eta_hat of every agent through the first fault, first seed). Results are
deterministic under the seeds; nothing is overwritten without ``--force``.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from agents.rollout import ESTIMATOR_SOURCES, Flight, FlightConfig, fly
from agents.suite import SUITES, get_suite
from agents.sweep import BACKENDS, run_sweep
from quadfault.errors import ConfigError, QuadfaultError
from quadfault.fileio import atomic_write_text, check_writable

RESULT_FILES = ("results.json", "results.md")


@dataclass(frozen=True)
class AgentSpec:
    """A parsed ``--agents`` entry."""

    label: str
    kind: str  # "controller" | "policy" | "sb3"
    controller: str = ""
    estimator: str = "none"
    path: str = ""

    @classmethod
    def parse(cls, text: str) -> AgentSpec:
        if text == "geometric":
            return cls(text, "controller", "geometric", "none")
        if text.startswith("estimate-aware"):
            source = text.partition(":")[2] or "irls"
            if source not in ESTIMATOR_SOURCES:
                raise ConfigError(
                    f"agent {text!r}: estimator must be one of {', '.join(ESTIMATOR_SOURCES)}"
                )
            return cls(f"estimate-aware:{source}", "controller", "estimate-aware", source)
        if text == "policy:geometric":
            return cls(text, "policy", estimator="none")
        if text.startswith("sb3:") and len(text) > 4:
            path = text[4:]
            if not Path(path).exists():
                raise ConfigError(f"agent {text!r}: {path} does not exist")
            return cls(text, "sb3", path=path)
        raise ConfigError(
            f"unknown agent {text!r}; use geometric, estimate-aware:<irls|ekf|"
            "truth|none>, policy:geometric or sb3:<run folder>"
        )


def _sb3_setup(spec: AgentSpec):
    from agents.train import CONFIG_FILE

    path = Path(spec.path)
    folder = path if path.is_dir() else path.parent
    cfg_path = next(
        (p for p in (folder / CONFIG_FILE, folder.parent / CONFIG_FILE) if p.exists()), None
    )
    if cfg_path is None:
        raise QuadfaultError(f"{spec.path}: no {CONFIG_FILE} next to the model")
    saved = json.loads(cfg_path.read_text())
    return saved["env_id"], dict(saved["env_kwargs"])


def fly_agent(
    spec: AgentSpec, scenario, seed: int, config: FlightConfig, env_id: str = "QuadFault-v1"
) -> Flight:
    """One flight of ``spec`` through ``scenario`` seeded with ``seed``."""
    if spec.kind == "controller":
        flight = fly(scenario, spec.controller, spec.estimator, seed, config=config)
        return replace(flight, controller=spec.label)
    from agents.env_rollout import fly_env, make_scenario_env

    if spec.kind == "policy":
        from agents.policies import GeometricPolicy

        env = make_scenario_env(env_id, {"estimator": "none", "action_mode": "residual"}, scenario)
        try:
            return fly_env(
                GeometricPolicy.from_env(env),
                env,
                scenario,
                seed,
                label=spec.label,
                estimator="none",
                config=config,
            )
        finally:
            env.close()
    from agents.train import load_agent

    sb3_env_id, env_kwargs = _sb3_setup(spec)
    env = make_scenario_env(sb3_env_id, env_kwargs, scenario)
    try:
        model, venv = load_agent(spec.path, env)
        from stable_baselines3.common.vec_env import VecNormalize

        norm = venv if isinstance(venv, VecNormalize) else None
        return fly_env(
            model,
            env,
            scenario,
            seed,
            label=spec.label,
            estimator=str(env_kwargs.get("estimator", "irls")),
            normalizer=norm,
            config=config,
        )
    finally:
        env.close()


def _finite_mean(values) -> float | None:
    v = [x for x in values if x is not None and math.isfinite(x)]
    return float(np.mean(v)) if v else None


def aggregate(flights: list[Flight]) -> list[dict]:
    """Per (agent, scenario) summary rows, in first-seen order."""
    groups: dict[tuple, list[Flight]] = {}
    for f in flights:
        groups.setdefault((f.controller, f.scenario), []).append(f)
    rows = []
    for (agent, scenario), fs in groups.items():
        ok = [f for f in fs if not f.metrics.crashed]
        rec = [r for f in fs for r in f.metrics.recovery_times]
        rmse = [f.metrics.rmse for f in ok]
        rows.append(
            {
                "agent": agent,
                "scenario": scenario,
                "runs": len(fs),
                "crash_rate": sum(f.metrics.crashed for f in fs) / len(fs),
                "rmse_mean": _finite_mean(rmse),
                "rmse_std": float(np.std(rmse, ddof=1)) if len(rmse) > 1 else None,
                "rmse_all_mean": _finite_mean([f.metrics.rmse for f in fs]),
                "peak_attitude_error_deg": _finite_mean(
                    [f.metrics.peak_attitude_error for f in fs]
                ),
                "energy": _finite_mean([f.metrics.energy / f.metrics.duration for f in fs]),
                "recovery_mean": _finite_mean(rec),
                "recovery_never": int(sum(1 for r in rec if not math.isfinite(r))),
                "faults": len(rec),
            }
        )
    return rows


def _fmt(x, spec=".3f") -> str:
    return "n/a" if x is None else format(x, spec)


def markdown_table(rows: list[dict]) -> str:
    lines = [
        "| scenario | agent | runs | crash rate | RMSE [m] | RMSE incl. crashed [m] | "
        "peak tilt err [deg] | energy [N] | recovery [s] (never/faults) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        rmse = _fmt(r["rmse_mean"], ".4f")
        if r["rmse_std"] is not None:
            rmse += f" ± {r['rmse_std']:.4f}"
        lines.append(
            f"| {r['scenario']} | {r['agent']} | {r['runs']} | {r['crash_rate']:.2f} | "
            f"{rmse} | {_fmt(r['rmse_all_mean'], '.4f')} | "
            f"{_fmt(r['peak_attitude_error_deg'], '.2f')} | "
            f"{_fmt(r['energy'], '.2f')} | {_fmt(r['recovery_mean'], '.2f')} "
            f"({r['recovery_never']}/{r['faults']}) |"
        )
    notes = [
        "",
        "RMSE: mean over the runs that did not crash (± sample std); RMSE incl. "
        "crashed: mean over all runs, a crashed run scored up to its crash. Energy: "
        "commanded thrust integrated over time, per second of flight [N s / s]. "
        "Recovery: mean time until the position error is back below 1.5x its "
        "pre-fault level (floor 5 cm) for 0.5 s, over the faults that recovered. "
        "`estimate-aware:truth` is the oracle ablation.",
    ]
    return "\n".join(lines + notes) + "\n"


def flight_jobs(
    agents: list[AgentSpec],
    suite: str,
    seeds: list[int],
    *,
    scenarios: list[str] | None = None,
    config: FlightConfig | None = None,
    duration: float | None = None,
) -> list[tuple]:
    """Every flight of an evaluation as a picklable ``(agent, scenario, seed, config)`` task,
    in the table's order (scenario, then seed, then agent)."""
    cfg = config or FlightConfig()
    jobs = []
    for entry in get_suite(suite, scenarios):
        for seed in seeds:
            scenario = entry.scenario(seed)
            if duration is not None:
                scenario = scenario.replace(duration=float(duration))
            jobs.extend((agent, scenario, seed, cfg) for agent in agents)
    return jobs


def fly_job(job: tuple) -> Flight:
    """One task of :func:`flight_jobs` (module level, so process pools can pickle it)."""
    agent, scenario, seed, config = job
    return fly_agent(agent, scenario, seed, config)


def evaluate(
    agents: list[AgentSpec],
    suite: str,
    seeds: list[int],
    *,
    scenarios: list[str] | None = None,
    config: FlightConfig | None = None,
    duration: float | None = None,
    progress: bool = False,
    backend: str = "serial",
    workers: int | None = None,
) -> list[Flight]:
    """Fly every agent over every scenario of ``suite`` and every seed.

    ``backend``: ``"serial"`` (this process), ``"local"`` (``workers`` processes) or ``"ray"``
    (:func:`agents.sweep.run_sweep`); every backend returns the same flights in the same order.
    """
    jobs = flight_jobs(agents, suite, seeds, scenarios=scenarios, config=config, duration=duration)
    return run_sweep(
        fly_job, jobs, backend=backend, workers=workers, progress=progress, desc=f"evaluate {suite}"
    )


def results_json(flights: list[Flight], rows: list[dict], meta: dict) -> str:
    runs = [
        {
            "agent": f.controller,
            "estimator": f.estimator,
            "scenario": f.scenario,
            "seed": f.seed,
            **f.metrics.to_dict(),
        }
        for f in flights
    ]
    return json.dumps({"meta": meta, "summary": rows, "runs": runs}, indent=2) + "\n"


# -- command line -----------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--agents",
        nargs="+",
        default=[
            "geometric",
            "estimate-aware:irls",
            "estimate-aware:ekf",
            "estimate-aware:truth",
            "estimate-aware:none",
        ],
        help="agent specs (see the module help); default: the controller ablation",
    )
    parser.add_argument(
        "--suite", default="quick", choices=sorted(SUITES), help="scenario suite (default quick)"
    )
    parser.add_argument("--scenarios", nargs="+", help="only these scenarios of the suite")
    parser.add_argument(
        "--seeds", type=int, nargs="+", default=[0, 1, 2], help="evaluation seeds (default 0 1 2)"
    )
    parser.add_argument("--duration", type=float, help="override every scenario's duration [s]")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    parser.add_argument("--force", action="store_true", help="overwrite existing results")
    parser.add_argument(
        "--backend",
        choices=BACKENDS,
        default="serial",
        help="where the flights run: this process (default), local processes "
        "or Ray (agents.sweep.run_sweep)",
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=None,
        help="processes / Ray CPUs of --backend local / ray (default: all cores)",
    )


def run(args) -> int:
    from quadfault.progress import enabled

    agents = [AgentSpec.parse(a) for a in args.agents]
    labels = [a.label for a in agents]
    if len(set(labels)) != len(labels):
        raise ConfigError(f"--agents lists an agent twice: {' '.join(labels)}")
    if any(s < 0 for s in args.seeds):
        raise ConfigError(f"--seeds must be non-negative integers, got {args.seeds}")
    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        raise ConfigError(f"--duration must be positive [s], got {args.duration}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise QuadfaultError(f"{out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    check_writable([out / n for n in RESULT_FILES], force=args.force)
    quiet = getattr(args, "quiet", False)
    flights = evaluate(
        agents,
        args.suite,
        list(args.seeds),
        scenarios=args.scenarios,
        duration=args.duration,
        progress=not quiet and enabled(),
        backend=args.backend,
        workers=args.workers,
    )
    rows = aggregate(flights)
    meta = {
        "suite": args.suite,
        "seeds": list(args.seeds),
        "agents": labels,
        "duration_override": args.duration,
    }
    table = markdown_table(rows)
    if not args.no_plots:
        from agents.plots import plot_through_fault

        for scenario in dict.fromkeys(f.scenario for f in flights):
            first = [f for f in flights if f.scenario == scenario and f.seed == args.seeds[0]]
            plot_through_fault(first, out / f"fault_{scenario}.png", force=args.force)
    atomic_write_text(out / "results.json", results_json(flights, rows, meta), force=args.force)
    atomic_write_text(
        out / "results.md",
        f"# Evaluation: suite {args.suite}, seeds {' '.join(map(str, args.seeds))}\n\n" + table,
        force=args.force,
    )
    if not quiet:
        print(table, end="")
        print(f"wrote {out / 'results.md'}, {out / 'results.json'}")
    return 0


def main(argv=None) -> int:
    import sys

    from quadfault.cli import main as cli_main

    return cli_main(["evaluate", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
