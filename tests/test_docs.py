"""The README and docs/results.md as a user reads them: the quick-start commands are the ones CI
runs, every command named next to a number exists, and the docs cite no internal files."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
import tomllib

from quadfault.cli import SUBCOMMANDS

ROOT = Path(__file__).resolve().parents[1]
USER_DOCS = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))


def _code_spans(text: str) -> list[str]:
    """Inline code and the lines of fenced blocks."""
    spans = re.findall(r"`([^`\n]+)`", re.sub(r"```.*?```", "", text, flags=re.S))
    for block in re.findall(r"```[a-z]*\n(.*?)```", text, flags=re.S):
        spans += block.splitlines()
    return spans


def test_ci_runs_the_readme_test_command_and_it_installs_existing_extras():
    out = subprocess.run(
        ["bash", "-c", "source <(sed -n '/^cmd=/p' .ci/run); echo \"$cmd\""],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    command = out.stdout.strip()
    assert command.startswith("python3 -m venv") and command.endswith("python -m pytest -n 2")
    extras = set(
        tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    )
    (asked,) = re.findall(r'pip install -e "\.\[([a-z0-9_,-]+)\]"', command)
    assert set(asked.split(",")) <= extras
    # command 1 installs the core alone (its job needs no extra)
    first = re.findall(r"```bash\n(.*?)\n```", (ROOT / "README.md").read_text())[0]
    assert "pip install -e . &&" in first and "quadfault reproduce" in first


@pytest.mark.parametrize(
    "doc", [ROOT / "README.md", ROOT / "docs" / "results.md"], ids=lambda p: p.name
)
def test_every_command_named_exists(doc):
    text = doc.read_text(encoding="utf-8")
    for span in _code_spans(text):
        for sub in re.findall(r"(?:^|[\s(])quadfault ([a-z_]+)", span):
            assert sub in SUBCOMMANDS, f"{doc.name}: unknown subcommand in {span!r}"
        for script in re.findall(r"python (benchmarks/[\w/]+\.py|examples/[\w/]+\.py)", span):
            assert (ROOT / script).is_file(), f"{doc.name}: no {script} ({span!r})"


@pytest.mark.parametrize("doc", USER_DOCS, ids=lambda p: p.name)
def test_user_docs_cite_no_internal_files(doc):
    assert "CONTRACT" not in doc.read_text(encoding="utf-8")


@pytest.mark.parametrize(
    "doc",
    [ROOT / "README.md", ROOT / "docs" / "results.md", ROOT / "docs" / "formats.md"],
    ids=lambda p: p.name,
)
def test_front_docs_name_no_machine_paths_or_commits(doc):
    text = doc.read_text(encoding="utf-8")
    assert not re.search(r"\.\./shared|/work/|/tmp/", text), "a path of one machine"
    assert not re.search(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b", text), (
        "a commit hash"
    )


@pytest.mark.slow
def test_product_code_cites_the_user_docs():
    offenders = [
        str(p.relative_to(ROOT))
        for pkg in ("quadfault", "estimators", "quad_fault_env", "agents")
        for p in (ROOT / pkg).rglob("*.py")
        if "CONTRACT" in p.read_text()
    ]
    assert offenders == []
    help_text = subprocess.run(
        [sys.executable, "-m", "quadfault.cli", "diagnose", "--help"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    ).stdout
    assert "docs/formats.md" in help_text


def test_every_benchmark_the_docs_name_exists():
    """Every ``benchmarks/...py`` a doc names is a file (speed scripts in benchmarks/, the
    studies behind the docs' results in benchmarks/studies/)."""
    docs = [ROOT / "README.md", ROOT / "CONTRIBUTING.md", *sorted((ROOT / "docs").glob("*.md"))]
    for doc in docs:
        if not doc.is_file():
            continue
        for script in re.findall(r"benchmarks/[\w/]+\.py", doc.read_text(encoding="utf-8")):
            assert (ROOT / script).is_file(), f"{doc.name}: no {script}"
