"""One numba cache directory per version of the compiled modules' sources (quadfault.jit)."""

import os
import shutil
import sys
from pathlib import Path

import pytest

from quadfault import jit

ROOT = Path(__file__).resolve().parent.parent


def test_every_module_with_a_cached_kernel_is_in_the_digest():
    cached = {
        p
        for d in jit.PACKAGES
        for p in (ROOT / d).rglob("*.py")
        if "cache=True" in p.read_text() or "@jit" in p.read_text()
    }
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


@pytest.fixture
def clean_env(monkeypatch):
    """No cache variables of the user's or of a parent's configure_cache."""
    for name in ("NUMBA_CACHE_DIR", jit._CONFIGURED, jit._USERS):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.delitem(sys.modules, "numba.core.config", raising=False)
    return monkeypatch


def test_configure_sets_a_per_version_directory(tmp_path, clean_env):
    clean_env.setenv("XDG_CACHE_HOME", str(tmp_path))
    got = jit.configure_cache()
    assert got == str(tmp_path / "quadfault-numba" / jit.sources_digest())
    assert os.environ["NUMBA_CACHE_DIR"] == got and Path(got).is_dir()


def test_a_users_numba_cache_dir_is_honoured(tmp_path, clean_env):
    """The cache goes inside the user's NUMBA_CACHE_DIR, one folder per source version; a
    child process (which inherits the variable) uses the same folder, and one of other
    sources (another checkout) gets its own folder inside the user's, not the parent's."""
    mine = tmp_path / "mine"
    clean_env.setenv("NUMBA_CACHE_DIR", str(mine))
    got = jit.configure_cache()
    assert got == str(mine / f"quadfault-{jit.sources_digest()}")
    assert os.environ["NUMBA_CACHE_DIR"] == got
    assert jit.configure_cache() == got  # a child of the same sources: not nested again
    clean_env.setattr(jit, "sources_digest", lambda root=None: "0123456789abcdef")
    assert jit.configure_cache() == str(mine / "quadfault-0123456789abcdef")


@pytest.mark.skipif(os.name != "posix", reason="POSIX user id in the folder name")
def test_an_unwritable_cache_falls_back_to_the_temporary_directory(tmp_path, clean_env):
    blocked = tmp_path / "a-file"  # no folder can be made below a file (not even by root)
    blocked.write_text("")
    clean_env.setenv("XDG_CACHE_HOME", str(blocked))
    clean_env.setattr(jit.tempfile, "tempdir", str(tmp_path / "tmp"))
    got = jit.configure_cache()
    assert got == str(tmp_path / "tmp" / f"quadfault-numba-{os.getuid()}" / jit.sources_digest())
    # nothing writable at all: numba's own choice stands
    clean_env.setattr(jit.tempfile, "tempdir", str(blocked))
    clean_env.delenv("NUMBA_CACHE_DIR")
    assert jit.configure_cache() is None and "NUMBA_CACHE_DIR" not in os.environ


def _run_on_a_terminal(code: str, env: dict) -> tuple[int, str]:
    """Run ``python -c code`` with stderr on a pseudo-terminal; its exit code and stderr."""
    import pty
    import subprocess

    master, slave = pty.openpty()
    try:
        proc = subprocess.run(
            [sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, stderr=slave, timeout=300
        )
    finally:
        os.close(slave)
    out = b""
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:  # EIO: the terminal has no more to read
            break
        if not chunk:
            break
        out += chunk
    os.close(master)
    return proc.returncode, out.decode(errors="replace")


@pytest.mark.slow
@pytest.mark.skipif(os.name != "posix", reason="needs a POSIX pseudo-terminal")
def test_read_only_install_caches_in_the_user_folder_and_notices_the_first_compile(tmp_path):
    """A read-only copy of the package (a system-wide install): the kernels are cached in the
    user's cache folder, never beside the sources; the first run, which compiles, says so in
    one line on the terminal, the second, which loads them, says nothing."""
    install = tmp_path / "site"
    shutil.copytree(
        ROOT / "quadfault", install / "quadfault", ignore=shutil.ignore_patterns("__pycache__")
    )
    for path in sorted(install.rglob("*"), reverse=True) + [install]:
        path.chmod(0o555 if path.is_dir() else 0o444)
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("NUMBA_CACHE_DIR", jit._CONFIGURED, jit._USERS)
    }
    env.update(PYTHONPATH=str(install), XDG_CACHE_HOME=str(tmp_path / "cache"))
    code = (
        "import numpy as np; from quadfault.model.rotation import dot3; "
        "assert dot3(np.ones(3), np.ones(3)) == 3.0"
    )
    try:
        first, second = _run_on_a_terminal(code, env), _run_on_a_terminal(code, env)
    finally:
        for path in [install] + sorted(install.rglob("*")):
            path.chmod(0o755 if path.is_dir() else 0o644)
    assert first[0] == 0 and second[0] == 0, (first, second)
    notices = [line for line in first[1].splitlines() if "compiling kernels" in line]
    assert len(notices) == 1 and "once per install" in notices[0], first[1]
    assert "compiling kernels" not in second[1], second[1]
    assert list((tmp_path / "cache" / "quadfault-numba").rglob("*.nbi"))
    assert not list(install.rglob("*.nbi"))


_INNER = """
from quadfault.jit import jit


@jit(inner=True)
def scaled(x, a):
    return (a * x[0], a * x[1])


@jit
def outer(x):
    y = scaled(x, 2.0)
    return y[0] + y[1]
"""


@pytest.mark.slow
def test_an_inner_kernel_runs_from_kernels_and_from_python_and_is_cached(tmp_path):
    """``jit(inner=True)``: no CPython wrapper in the form kernels call; a call from Python
    runs a form with one; both are cached, so a second process compiles nothing."""
    if not jit.AVAILABLE:
        pytest.skip("numba is not importable")
    import subprocess

    (tmp_path / "inner_mod.py").write_text(_INNER)
    env = {k: v for k, v in os.environ.items() if k not in (jit._CONFIGURED, jit._USERS)}
    env.update(
        PYTHONPATH=os.pathsep.join([str(ROOT), str(tmp_path)]),
        NUMBA_CACHE_DIR=str(tmp_path / "cache"),
    )
    code = (
        "import inner_mod as m\n"
        "assert m.scaled.targetoptions['no_cpython_wrapper']\n"
        "assert m.outer((1.0, 2.0)) == 6.0 and m.scaled((1.0, 2.0), 3.0) == (3.0, 6.0)\n"
        "print(sum(m.outer.stats.cache_misses.values()),"
        " sum(m.scaled._python_form.stats.cache_misses.values()))\n"
    )
    runs = [
        subprocess.run(
            [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300
        )
        for _ in range(2)
    ]
    assert [r.returncode for r in runs] == [0, 0], runs[0].stderr[-2000:]
    assert runs[0].stdout.split() == ["1", "1"] and runs[1].stdout.split() == ["0", "0"]


def test_no_notice_when_stderr_is_not_a_terminal(monkeypatch):
    import io

    monkeypatch.setattr(jit, "_noticed", False)
    quiet = io.StringIO()
    assert jit._compile_notice(quiet) is False and quiet.getvalue() == ""


def test_notice_gets_its_own_line_under_a_progress_bar(monkeypatch):
    import io

    from tqdm.auto import tqdm

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    monkeypatch.setattr(jit, "_noticed", False)
    term = Terminal()
    bar = tqdm(total=10, file=term, disable=False)
    bar.update(3)
    assert jit._compile_notice(term) is True
    bar.update(3)
    bar.close()
    lines = term.getvalue().replace("\r", "\n").split("\n")
    notice = [ln for ln in lines if "compiling kernels" in ln]
    assert notice and all(ln.startswith("quadfault: compiling") for ln in notice)
    assert not any("%|" in ln for ln in notice)


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

    out = subprocess.run(
        [sys.executable, "-c", "import sys, quadfault; print('numba' in sys.modules)"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert out.stdout.strip() == "False", out.stderr
