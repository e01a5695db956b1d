"""The learning curve of ``quadfault train``: ``OUT/learning_curve.png``.

After every run, ``quadfault train --out OUT`` draws the evaluation return against
environment steps from every ``OUT/seed_<k>/`` trained with the same settings (all keys of
``train_config.json`` but the seed): the mean over those seeds, the band between the lowest
and the highest seed, and the geometric controller on the same evaluation episodes (see
:mod:`agents.train_eval`). Seeds trained by separate commands into the same ``OUT`` (in
parallel, say) join the curve; a seed trained with other settings is left out and named.
The figure is derived from the runs' ``evaluations.npz`` and is redrawn after every run.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from agents.plots import plot_learning_curve
from agents.train_eval import EVALUATIONS_FILE

CURVE_FILE = "learning_curve.png"
CONFIG_FILE = "train_config.json"
#: keys of ``train_config.json`` that may differ between the seeds of one curve
PER_RUN_KEYS = ("seed", "seeds", "progress_bar", "tensorboard")


def _settings(run_dir: Path) -> dict | None:
    path = run_dir / CONFIG_FILE
    if not path.exists() or not (run_dir / EVALUATIONS_FILE).exists():
        return None
    data = json.loads(path.read_text())
    return {k: v for k, v in data.items() if k not in PER_RUN_KEYS}


def matching_runs(out, settings: dict) -> tuple[list[Path], list[Path]]:
    """``(matching, other)``: the ``seed_*`` folders of ``out`` with evaluations, trained with
    ``settings`` (a ``train_config.json`` object) or with other settings."""
    want = {k: v for k, v in settings.items() if k not in PER_RUN_KEYS}
    matching, other = [], []
    for run in sorted(Path(out).glob("seed_*"), key=lambda p: (len(p.name), p.name)):
        got = _settings(run)
        if got is not None:
            (matching if got == want else other).append(run)
    return matching, other


def curve_data(runs) -> dict:
    """``timesteps``, ``returns`` (seeds x evaluations: mean over the episodes), ``runs``,
    ``baseline`` (the geometric controller's mean return, or None) and ``episode_seeds`` of
    the runs evaluated at the same steps as the first one (the others are dropped)."""
    rows, used, ts, baseline, seeds = [], [], None, None, []
    for run in runs:
        data = np.load(Path(run) / EVALUATIONS_FILE)
        if ts is None:
            ts = data["timesteps"]
            seeds = [int(s) for s in data["episode_seeds"]] if "episode_seeds" in data else []
            if "baseline_results" in data:
                baseline = float(data["baseline_results"].mean())
        if not np.array_equal(data["timesteps"], ts):
            continue
        rows.append(data["results"].mean(axis=1))
        used.append(Path(run))
    return {
        "timesteps": ts,
        "returns": np.asarray(rows),
        "runs": used,
        "baseline": baseline,
        "episode_seeds": seeds,
    }


def write_learning_curve(runs, path, *, label: str = "policy", title: str | None = None):
    """Draw the learning curve of ``runs`` (run folders) to ``path``; returns the data used."""
    data = curve_data(runs)
    if not data["runs"]:
        return data
    if title is None:
        seeds = data["episode_seeds"]
        title = (
            f"mean return on {len(seeds)} fixed evaluation episodes (reset seeds "
            f"{seeds[0]}-{seeds[-1]})"
            if len(seeds)
            else "mean evaluation return"
        )
    plot_learning_curve(
        data["timesteps"],
        data["returns"],
        path,
        baseline=data["baseline"],
        label=label,
        title=title,
        force=True,
    )
    return data
