"""One numba cache directory per version of the compiled modules' sources."""

import os
import shutil
import sys
from pathlib import Path

import pytest

from quadfault import _numba_cache as nc

ROOT = Path(__file__).resolve().parent.parent


def test_every_cached_kernel_module_is_in_the_digest():
    cached = {str(p.relative_to(ROOT)) for d in ("quadfault", "estimators", "quad_fault_env")
              for p in (ROOT / d).rglob("*.py")
              if p.name != "_numba_cache.py" and "cache=True" in p.read_text()}
    assert cached <= set(nc.COMPILED_MODULES), cached - set(nc.COMPILED_MODULES)


def test_digest_changes_with_any_compiled_source(tmp_path):
    for rel in nc.COMPILED_MODULES:
        if (ROOT / rel).is_file():
            (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(ROOT / rel, tmp_path / rel)
    d0 = nc.sources_digest(tmp_path)
    assert d0 == nc.sources_digest(ROOT)
    callee = tmp_path / "estimators/_residuals_numba.py"
    callee.write_text(callee.read_text() + "\n# changed\n")
    assert nc.sources_digest(tmp_path) != d0


def test_configure_sets_a_per_version_directory_and_respects_the_user(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delitem(sys.modules, "numba.core.config", raising=False)
    got = nc.configure()
    assert got == str(tmp_path / "quadfault-numba" / nc.sources_digest())
    assert os.environ["NUMBA_CACHE_DIR"] == got and Path(got).is_dir()
    monkeypatch.setenv("NUMBA_CACHE_DIR", "/somewhere/of/mine")
    assert nc.configure() is None
    assert os.environ["NUMBA_CACHE_DIR"] == "/somewhere/of/mine"


def test_configure_leaves_numba_alone_without_a_writable_cache(tmp_path, monkeypatch):
    if os.geteuid() == 0:
        pytest.skip("root can write anywhere")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(ro))
    assert nc.configure() is None
    assert "NUMBA_CACHE_DIR" not in os.environ
