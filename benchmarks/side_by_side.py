"""Run one measurement of a benchmark script in this checkout and in another, side by side.

``measure(checkout, script, function, **kwargs)`` runs ``function(**kwargs)`` of
``benchmarks/<script>.py`` in a fresh Python process whose ``quadfault`` (and the other
packages) come from ``checkout`` (``PYTHONPATH``), and returns what it returned (JSON).
``compare`` alternates the checkouts for ``rounds`` rounds and keeps each number's best, so a
busy shared machine slows both alike; the benchmark prints the ratio.

The measured function must use the public API both checkouts share (``simulate``,
``gym.make``, ``QuadFaultVectorEnv``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent


def measure(checkout, script: str, function: str, env: dict | None = None, **kwargs) -> dict:
    """``function(**kwargs)`` of ``benchmarks/<script>.py`` run against ``checkout``."""
    code = (
        "import json, sys\n"
        f"sys.path.insert(1, {str(HERE)!r})\n"
        f"import {script}\n"
        f"print('@@' + json.dumps({script}.{function}(**{kwargs!r})))\n"
    )
    environ = dict(os.environ, PYTHONPATH=str(Path(checkout).resolve()), **(env or {}))
    out = subprocess.run(
        [sys.executable, "-c", code], env=environ, capture_output=True, text=True, cwd=str(checkout)
    )
    if out.returncode != 0:
        raise RuntimeError(f"{script}.{function} failed in {checkout}:\n{out.stderr[-3000:]}")
    line = [x for x in out.stdout.splitlines() if x.startswith("@@")][-1]
    return json.loads(line[2:])


def compare(
    baseline,
    script: str,
    function: str,
    rounds: int = 3,
    better=min,
    env: dict | None = None,
    **kwargs,
) -> tuple[dict, dict]:
    """Best of ``rounds`` alternated runs of the measurement in this checkout and in
    ``baseline``: ``(this, baseline)``, each a dict of numbers (``better`` picks the best)."""
    best: list[dict] = [{}, {}]
    for _ in range(rounds):
        for k, checkout in enumerate((ROOT, Path(baseline))):
            got = measure(checkout, script, function, env=env, **kwargs)
            for key, x in got.items():
                best[k][key] = x if key not in best[k] else better(best[k][key], x)
    return best[0], best[1]


def load() -> str:
    return "load average " + ", ".join(f"{x:.2f}" for x in os.getloadavg())
