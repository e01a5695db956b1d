"""One numba cache directory per version of the compiled modules' sources (quadfault.jit)."""

import os
import shutil
import sys
from pathlib import Path

import pytest

from quadfault import jit

ROOT = Path(__file__).resolve().parent.parent


def test_every_module_with_a_cached_kernel_is_in_the_digest():
    cached = {p for d in jit.PACKAGES for p in (ROOT / d).rglob("*.py")
              if "cache=True" in p.read_text() or "@jit" in p.read_text()}
    assert cached <= set(jit.compiled_sources(ROOT)), cached - set(jit.compiled_sources(ROOT))


def test_digest_changes_with_any_compiled_source(tmp_path):
    for path in jit.compiled_sources(ROOT):
        rel = path.relative_to(ROOT)
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(path, tmp_path / rel)
    d0 = jit.sources_digest(tmp_path)
    assert d0 == jit.sources_digest(ROOT)
    callee = tmp_path / jit.compiled_sources(tmp_path)[-1].relative_to(tmp_path)
    callee.write_text(callee.read_text() + "\n# changed\n")
    assert jit.sources_digest(tmp_path) != d0


def test_configure_sets_a_per_version_directory_and_respects_the_user(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delitem(sys.modules, "numba.core.config", raising=False)
    got = jit.configure_cache()
    assert got == str(tmp_path / "quadfault-numba" / jit.sources_digest())
    assert os.environ["NUMBA_CACHE_DIR"] == got and Path(got).is_dir()
    monkeypatch.setenv("NUMBA_CACHE_DIR", "/somewhere/of/mine")
    assert jit.configure_cache() is None
    assert os.environ["NUMBA_CACHE_DIR"] == "/somewhere/of/mine"


def test_configure_leaves_numba_alone_without_a_writable_cache(tmp_path, monkeypatch):
    if os.geteuid() == 0:
        pytest.skip("root can write anywhere")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(ro))
    assert jit.configure_cache() is None
    assert "NUMBA_CACHE_DIR" not in os.environ


def test_jit_compiles_and_falls_back_to_python(monkeypatch):
    @jit.jit
    def add(a, b):
        return a + b

    assert add(2.0, 3.5) == 5.5
    assert hasattr(add, "py_func")  # compiled by numba
    monkeypatch.setattr(jit, "_numba_module", None)
    monkeypatch.setattr(jit, "_warned", False)
    with pytest.warns(RuntimeWarning, match="numba is not importable"):
        plain = jit.jit(lambda a: 2 * a)
    assert plain(4) == 8 and not hasattr(plain, "py_func")


def test_import_quadfault_does_not_import_numba():
    import subprocess

    out = subprocess.run([sys.executable, "-c", "import sys, quadfault; print('numba' in sys.modules)"],
                         capture_output=True, text=True, cwd=ROOT)
    assert out.stdout.strip() == "False", out.stderr
