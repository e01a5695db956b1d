"""Old import paths of modules that moved into the layer packages.

``import quadfault.rotation`` (and every other path below) keeps working: the finder resolves
the old name to the module at its new place, the same module object, and warns once with a
:class:`DeprecationWarning` naming the new path. A package that moved carries its submodules
with it (``quadfault.effects.drag`` is ``quadfault.model.effects.drag``).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

#: old dotted name -> new dotted name
MOVED = {
    "quadfault.allocation": "quadfault.model.allocation",
    "quadfault.cli_simulate": "quadfault.sim.cli",
    "quadfault.closed_loop": "quadfault.model.closed_loop",
    "quadfault.controller": "quadfault.model.controller",
    "quadfault.dynamics": "quadfault.model.dynamics",
    "quadfault.effects": "quadfault.model.effects",
    "quadfault.flight": "quadfault.model.flight",
    "quadfault.frames": "quadfault.model.frames",
    "quadfault.generator_table": "quadfault.model.generator_table",
    "quadfault.importers": "quadfault.io.importers",
    "quadfault.importers.flight_analysis": "quadfault.diagnosis.flight_analysis",
    "quadfault.motors": "quadfault.model.motors",
    "quadfault.plant": "quadfault.model.plant",
    "quadfault.recording": "quadfault.io.recording",
    "quadfault.rotation": "quadfault.model.rotation",
    "quadfault.sample": "quadfault.io.sample",
    "quadfault.scenarios": "quadfault.model.scenarios",
    "quadfault.sensors": "quadfault.model.sensors",
    "quadfault.sidecar": "quadfault.model.sidecar",
    "quadfault.simulator": "quadfault.sim.simulator",
    "quadfault.task_scenarios": "quadfault.model.task_scenarios",
    "quadfault.trajectory": "quadfault.model.trajectory",
    "quadfault.vehicle": "quadfault.model.vehicle",
}


def new_name(old: str) -> str | None:
    """The new dotted name of an old module path, or None when ``old`` did not move."""
    for prefix in sorted(MOVED, key=len, reverse=True):
        if old == prefix or old.startswith(prefix + "."):
            return MOVED[prefix] + old[len(prefix) :]
    return None


class _Alias(importlib.abc.Loader):
    def __init__(self, new: str):
        self.new = new

    def create_module(self, spec):
        return importlib.import_module(self.new)

    def exec_module(self, module):
        sys.modules[module.__spec__.name] = module  # the same object under the old name


class MovedModuleFinder(importlib.abc.MetaPathFinder):
    """Finds the old paths of :data:`MOVED` (installed once by ``quadfault/__init__.py``)."""

    def find_spec(self, fullname, path=None, target=None):
        new = new_name(fullname)
        if new is None:
            return None
        warnings.warn(
            f"{fullname} moved to {new}; import it from there", DeprecationWarning, stacklevel=2
        )
        return importlib.util.spec_from_loader(fullname, _Alias(new))


def install() -> None:
    if not any(isinstance(f, MovedModuleFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, MovedModuleFinder())  # before the path finder: no second copy
