"""Import layering: the core model imports neither the estimators, the environment nor the agents;
the estimators do not import the environment or the agents; the environment does not import the agents."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: package (or core module glob) -> top-level packages it must not import
FORBIDDEN = {
    "core": {"estimators", "quad_fault_env", "agents"},
    "estimators": {"quad_fault_env", "agents"},
    "quad_fault_env": {"agents"},
}
#: modules of the quadfault package that sit above the core (they may import estimators)
NON_CORE = {"cli.py", "diagnosis", "importers"}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def _files(layer: str):
    if layer == "core":
        for p in sorted((ROOT / "quadfault").rglob("*.py")):
            rel = p.relative_to(ROOT / "quadfault")
            if rel.parts[0] in NON_CORE or rel.name.startswith("cli"):
                continue
            yield p
    else:
        yield from sorted((ROOT / layer).rglob("*.py"))


@pytest.mark.parametrize("layer", sorted(FORBIDDEN))
def test_layering(layer):
    bad = []
    for path in _files(layer):
        hit = _imports(path) & FORBIDDEN[layer]
        if hit:
            bad.append(f"{path.relative_to(ROOT)} imports {sorted(hit)}")
    assert not bad, "\n".join(bad)


def test_cli_help_does_not_import_numpy():
    import subprocess
    import sys

    code = ("import sys, contextlib, io\n"
            "from quadfault import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
            "    cli.main(['--help'])\n"
            "print('numpy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.stdout.strip() == "False", out.stderr


def _module_graph(packages):
    """Module -> the modules of ``packages`` it imports (anywhere in its source)."""
    mods = {}
    for pkg in packages:
        for p in (ROOT / pkg).rglob("*.py"):
            name = ".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
            mods[name] = p
    graph = {}
    for name, path in mods.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                deps.add(node.module)
                deps.update(f"{node.module}.{a.name}" for a in node.names)
            elif isinstance(node, ast.Import):
                deps.update(a.name for a in node.names)
        graph[name] = deps & set(mods) - {name}
    return graph


def test_no_import_cycles_in_the_model_the_environments_and_the_agents():
    """Modules import each other one way (lazy imports inside functions included)."""
    graph = _module_graph(("quadfault", "quad_fault_env", "agents"))
    state, cycles = {}, []

    def visit(node, path):
        state[node] = "open"
        for dep in sorted(graph[node]):
            if state.get(dep) == "open":
                cycles.append(path[path.index(dep):] + [dep])
            elif dep not in state:
                visit(dep, path + [dep])
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    assert not cycles, "\n".join(" -> ".join(c) for c in cycles)

