"""The core example runs as a user would run it (subprocess) and writes its figure."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_simulate_and_plot_example(tmp_path):
    out = tmp_path / "flight.png"
    r = subprocess.run(
        [
            sys.executable,
            str(ROOT / "examples" / "simulate_and_plot.py"),
            "--duration",
            "3",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stderr
    assert out.stat().st_size > 10_000 and "position error RMS" in r.stdout
    again = subprocess.run(
        [
            sys.executable,
            str(ROOT / "examples" / "simulate_and_plot.py"),
            "--duration",
            "3",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
    )
    assert again.returncode != 0 and "already exists" in again.stderr
    assert "Traceback" not in again.stderr
