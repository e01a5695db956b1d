"""Import layering. The packages stand in one order, lowest first: ``quadfault`` (the model
and its applications: simulator, diagnosis, importers) < ``estimators`` < ``quad_fault_env``
< ``agents``; every import (lazy ones included) points down or stays in its package, and
inside ``quadfault`` the layers of :data:`LAYERS` do the same. The ``quadfault`` command line
reaches the upper packages' subcommand modules only by name (``quadfault.cli.SUBCOMMANDS``,
imported when the subcommand runs). The import graph is acyclic, and outside the subcommand
modules only optional dependencies are imported inside functions."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_cli_help_does_not_import_numpy():
    code = (
        "import sys, contextlib, io\n"
        "from quadfault import cli\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "    cli.main(['--help'])\n"
        "print('numpy' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.stdout.strip() == "False", out.stderr


#: the packages, lowest first: a module imports only its own package and those below
PACKAGES = ("quadfault", "estimators", "quad_fault_env", "agents")
#: packages whose import graph must be acyclic
ACYCLIC = PACKAGES


def _module_names():
    mods = {}
    for pkg in ACYCLIC:
        for p in sorted((ROOT / pkg).rglob("*.py")):
            parts = p.relative_to(ROOT).with_suffix("").parts
            mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return mods


def _import_graph():
    """module -> the modules of :data:`ACYCLIC` it imports anywhere (lazy imports included)."""
    mods = _module_names()

    def resolve(name):
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    graph = {}
    for name, path in mods.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                deps.update(resolve(a.name) for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                deps.add(resolve(node.module))
                deps.update(resolve(f"{node.module}.{a.name}") for a in node.names)
        graph[name] = deps - {None, name}
    return graph


def _cycles(graph):
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_packages_are_layered():
    """quadfault < estimators < quad_fault_env < agents: no import points up (the CLI entry
    point names the upper packages' subcommand modules as strings, not imports)."""
    graph = _import_graph()
    rank = {pkg: k for k, pkg in enumerate(PACKAGES)}
    bad = sorted(
        f"{name} imports {dep}"
        for name, deps in graph.items()
        for dep in deps
        if rank[dep.split(".")[0]] > rank[name.split(".")[0]]
    )
    assert "quad_fault_env" in graph["agents.env_rollout"]  # the check sees a package's edges
    assert not bad, "\n".join(bad)


def test_the_import_graph_has_no_cycles():
    graph = _import_graph()
    assert "estimators.irls" in graph and "quadfault.io.sample" in graph
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": set()}) == [["a", "b"]]  # the check works
    assert _cycles(graph) == []


@pytest.mark.slow
@pytest.mark.parametrize(
    "module",
    [
        "quadfault.io.sample",
        "estimators.base",
        "estimators.irls",
        "estimators.ekf",
        "estimators.batched",
        "estimators.paper.reproduce",
    ],
)
def test_modules_import_on_their_own(module):
    """Each entry point imports in a fresh interpreter (no order-dependent import)."""
    out = subprocess.run(
        [sys.executable, "-c", f"import {module}"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        check=False,
    )
    assert out.returncode == 0, out.stderr


def test_the_core_does_not_load_the_estimators():
    code = (
        "import sys, quadfault.io.sample, quadfault.io.recording\n"
        "import quadfault.io.importers.px4_ulog\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('estimators', 'quad_fault_env', 'agents')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=False
    )
    assert out.stdout.strip() == "[]", out.stderr


# the layers of the quadfault package ---------------------------------------------------
#: lowest first: a module imports (lazy imports included) only its own layer and those below
LAYERS = (
    (
        "foundation",
        (
            "quadfault",
            "quadfault._moved",
            "quadfault.errors",
            "quadfault.jit",
            "quadfault.progress",
            "quadfault.fileio",
            "quadfault.layout",
        ),
    ),
    (
        "model basics",
        (
            "quadfault.model",
            "quadfault.model.rotation",
            "quadfault.model.vehicle",
            "quadfault.model.frames",
            "quadfault.model.sidecar",
            "quadfault.model.trajectory",
            "quadfault.model.generator_table",
        ),
    ),
    ("effects", ("quadfault.model.effects",)),
    (
        "model",
        (
            "quadfault.model.dynamics",
            "quadfault.model.motors",
            "quadfault.model.sensors",
            "quadfault.model.sensor_presets",
            "quadfault.model.controller",
            "quadfault.model.closed_loop",
            "quadfault.model.plant",
            "quadfault.model.flight",
            "quadfault.model.allocation",
            "quadfault.model.scenarios",
            "quadfault.model.task_scenarios",
            "quadfault.model.relaxed_hover",
            "quadfault.model.relaxed_hover_control",
        ),
    ),
    ("io", ("quadfault.io",)),
    ("diagnosis", ("quadfault.diagnosis",)),
    ("applications", ("quadfault.sim", "quadfault.cli")),
)


def _layer(module: str) -> int:
    """The layer of a module of the quadfault package (a package counts for its modules)."""
    best = None
    for k, (_, members) in enumerate(LAYERS):
        for m in members:
            if (module == m or module.startswith(m + ".")) and (
                best is None or len(m) > len(best[1])
            ):
                best = (k, m)
    assert best is not None, f"{module} is in no layer of LAYERS"
    return best[0]


def test_the_model_sits_below_the_applications():
    """foundation <- effects <- model <- applications: every import points down (or stays in
    its layer), so the effects sit below the physics core and replay, the diagnosis and the
    importers above it."""
    graph = _import_graph()
    bad = []
    for name, deps in graph.items():
        if name.split(".")[0] != "quadfault":
            continue
        for dep in deps:
            if dep.split(".")[0] == "quadfault" and _layer(dep) > _layer(name):
                bad.append(
                    f"{name} ({LAYERS[_layer(name)][0]}) imports {dep} ({LAYERS[_layer(dep)][0]})"
                )
    assert _layer("quadfault.model.effects.motor_lag") < _layer(
        "quadfault.model.dynamics"
    )  # the check
    assert not bad, "\n".join(sorted(bad))


#: third-party modules a product module may import inside a function: optional extras and
#: heavy ones only some commands need (plots, progress bars, the compiler's own loader, the RL
#: stack, video)
OPTIONAL = {
    "matplotlib",
    "pyulog",
    "pymavlink",
    "numba",
    "tqdm",
    "torch",
    "stable_baselines3",
    "sb3_contrib",
    "ray",
    "imageio",
}


def _function_imports(path: Path):
    for fn in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for node in ast.walk(fn):
                if isinstance(node, ast.Import):
                    yield from ((node.lineno, a.name) for a in node.names)
                elif isinstance(node, ast.ImportFrom) and node.level == 0:
                    yield node.lineno, node.module


def _subcommand_modules() -> set[str]:
    """The CLI entry point and the modules of its subcommands (they load what a subcommand
    needs when it runs)."""
    from quadfault.cli import SUBCOMMANDS

    mods = {module for module, _help in SUBCOMMANDS.values()} | {"quadfault.cli"}
    missing = mods - set(_module_names())
    assert not missing, f"SUBCOMMANDS names modules that do not exist: {sorted(missing)}"
    return mods


def test_only_optional_dependencies_are_imported_inside_functions():
    """Outside the CLI's subcommand modules, imports are at the top of the module (a lazy
    import hides a dependency, or a cycle)."""
    exempt = _subcommand_modules()
    assert {"estimators.cli", "agents.train"} <= exempt  # the subcommands of the upper packages
    bad = []
    for name, path in sorted(_module_names().items()):
        if name in exempt:
            continue
        for line, module in _function_imports(path):
            if module.split(".")[0] not in OPTIONAL:
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {module} in a function")
    assert not bad, "\n".join(bad)


def test_each_effect_is_named_in_its_own_module():
    """An effect's quoted name appears in its module, the registry and at most one other
    product module (keys of JSON objects are not names, nor are the vehicle's own quantities:
    a ``mass`` or an ``inertia`` may be the vehicle's)."""
    import dataclasses

    from quadfault.model.effects import registry
    from quadfault.model.vehicle import Vehicle

    def quoted(tree):
        keys = set()
        for n in ast.walk(tree):
            if isinstance(n, ast.Dict):
                keys.update(id(k) for k in n.keys if k is not None)
            elif isinstance(n, ast.Subscript):
                keys.add(id(n.slice))
            elif isinstance(n, ast.Compare) and any(
                isinstance(o, (ast.In, ast.NotIn)) for o in n.ops
            ):
                keys.add(id(n.left))
            elif (
                isinstance(n, ast.Call)
                and isinstance(n.func, ast.Attribute)
                and n.func.attr in ("get", "pop", "setdefault")
                and n.args
            ):
                keys.add(id(n.args[0]))
        return {
            n.value
            for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in keys
        }

    names = {
        p: quoted(ast.parse(p.read_text(encoding="utf-8")))
        for pkg in ACYCLIC
        for p in sorted((ROOT / pkg).rglob("*.py"))
    }
    effects = ROOT / "quadfault" / "model" / "effects"
    bad = {}
    quantities = {f.name for f in dataclasses.fields(Vehicle)}
    for name in set(registry.names()) - quantities:
        own = {effects / f"{name}.py", effects / "registry.py"}
        hits = [str(p.relative_to(ROOT)) for p, s in names.items() if name in s and p not in own]
        if len(hits) > 1:
            bad[name] = hits
    lag = effects / "motor_lag.py"
    assert lag in names and '"motor_lag"' in lag.read_text(encoding="utf-8")  # the check works
    assert not bad, bad


def test_old_import_paths_resolve_to_the_moved_modules():
    """A module that moved into a layer package keeps its old path, as the same module
    object, with a DeprecationWarning naming the new one."""
    code = (
        "import warnings, quadfault\n"
        "warnings.simplefilter('error')\n"
        "import quadfault.model.effects.wind as new\n"
        "try:\n"
        "    import quadfault.effects.wind\n"
        "except DeprecationWarning as e:\n"
        "    print(e)\n"
        "warnings.simplefilter('ignore')\n"
        "import quadfault.effects.wind as old, quadfault.importers.px4_ulog as px4\n"
        "import quadfault.io.importers.px4_ulog as px4_new\n"
        "print(old is new, px4 is px4_new)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=False
    )
    assert out.stdout.splitlines() == [
        "quadfault.effects moved to quadfault.model.effects; import it from there",
        "True True",
    ], out.stderr
