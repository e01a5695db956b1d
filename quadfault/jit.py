"""The one compile decorator of the project, and where numba keeps what it compiled.

Every algorithm is written once, as plain allocation-free Python, and decorated with
:func:`jit`. With numba importable (a core dependency) the function is compiled
(``nopython``, ``cache=True``, ``error_model="numpy"``: a division by zero gives inf / NaN as
in numpy, never an exception inside a parallel loop; no ``fastmath``, so results do not
depend on the compiler's reassociation; ``no_cfunc_wrapper``: no kernel is called through a C
function pointer, and the wrapper would cost every compiled kernel a few hundredths of a
CPU-second on a first run). A kernel that only other kernels call is declared
``@jit(inner=True)``: compiled without numba's CPython wrapper too (boxing and unboxing its
arguments: LLVM code of its own, again a few hundredths of a CPU-second per kernel on a
first run); a call from Python still works, through a form with the wrapper compiled on the
first such call (:class:`InnerKernel`). Without numba the decorator leaves the function as
Python -- slow but correct -- and warns once. Batched paths run the same kernel under
:data:`prange`. :func:`python` gives a kernel's interpreted form (the same code, with every
kernel it calls interpreted too): the closed loop runs that way when it must call Python
objects (the effects of ``quadfault.model.effects``), and a kernel written with plain arithmetic
runs over whole arrays that way (``quadfault.model.dynamics.step_rk4`` with a Python wrench).

Cache: numba's on-disk cache checks only the source file of the function it compiled. Our
kernels call compiled functions of other modules, so after an update that changes only a
callee (a ``git pull`` in an editable install) numba would load a stale caller with the old
callee inlined: wrong numbers or a crash. :func:`configure_cache` points ``NUMBA_CACHE_DIR``
at a folder named after the hash of every module that uses this decorator, so any change to
any of them starts a fresh cache: ``quadfault-<hash>`` inside the user's own
``NUMBA_CACHE_DIR`` when they set one, else ``<user cache>/quadfault-numba/<hash>``
(``$XDG_CACHE_HOME`` or ``~/.cache``), else, when that is not writable either, a folder of the
temporary directory. Never the package's own folder, which may be read-only (a system-wide
install).

The first compile: numba compiles a kernel the first time it runs, unless the cache holds it.
When it does compile one of ours and stderr is a terminal, one line says so, once per process
("compiling kernels, once per install ..."): a first run takes a minute or more, later runs
load the kernels from the cache in a fraction of a second.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import sys
import tempfile
import types
import warnings
from pathlib import Path

from quadfault.errors import ConfigError

#: the packages whose modules may hold compiled kernels
PACKAGES = ("quadfault", "estimators", "quad_fault_env", "agents")
#: a module whose source mentions one of these is hashed into the cache key
_MARKERS = (b"quadfault.jit", b"numba")

#: environment variables of :func:`configure_cache`: the ``NUMBA_CACHE_DIR`` it set and the
#: user's own before it, so that a child process (of these or of other sources) does not take
#: the one for the other
_CONFIGURED, _USERS = "QUADFAULT_NUMBA_CACHE", "QUADFAULT_NUMBA_CACHE_USER"
#: the one-line notice of a first compile (:func:`_compile_notice`)
COMPILE_NOTICE = (
    "quadfault: compiling kernels, once per install (a minute or two; later "
    "runs load them from the cache{where})"
)

_warned = False
_noticed = False
_INTERPRETED: dict = {}  # (kernel id, replacements) -> its interpreted form
_numba_module = False  # not looked up yet


def _numba():
    """numba, imported on first use (``import quadfault`` stays light), or None."""
    global _numba_module
    if _numba_module is False:
        try:
            import numba
        except ImportError:  # pragma: no cover - exercised only without numba
            numba = None
        else:
            _listen_for_compiles(numba)
        _numba_module = numba
    return _numba_module


def _ours(dispatcher) -> bool:
    module = getattr(getattr(dispatcher, "py_func", None), "__module__", None) or ""
    return module.split(".")[0] in PACKAGES


def _compile_notice(stream=None) -> bool:
    """Print :data:`COMPILE_NOTICE` to ``stream`` (stderr) once per process, when it is a
    terminal; return whether it was printed."""
    global _noticed
    stream = stream or sys.stderr
    if _noticed or not getattr(stream, "isatty", lambda: False)():
        return False
    _noticed = True
    cache = os.environ.get("NUMBA_CACHE_DIR")
    line = COMPILE_NOTICE.format(where=f" in {cache}" if cache else "")
    try:  # through tqdm: an active progress bar is cleared, the notice gets its own line
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency
        print(line, file=stream, flush=True)
    else:
        tqdm.write(line, file=stream)
        stream.flush()
    return True


def _listen_for_compiles(numba) -> None:
    """Call :func:`_compile_notice` when numba starts compiling one of our kernels: its
    ``numba:compile`` event fires on a cache miss only, never when a kernel is loaded."""
    try:
        from numba.core import event
    except ImportError:  # pragma: no cover - a numba without the event API
        return

    class _FirstCompile(event.Listener):
        def on_start(self, ev):
            if not _noticed and _ours((ev.data or {}).get("dispatcher")):
                _compile_notice()

        def on_end(self, ev):
            pass

    event.register("numba:compile", _FirstCompile())


def __getattr__(name):
    if name == "InnerKernel":  # numba's pickling of a dispatcher names its class
        return _inner_kernel_class()
    if name == "AVAILABLE":
        return _numba() is not None
    if name == "prange":
        nb = _numba()
        return range if nb is None else nb.prange
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _warn_once() -> None:
    global _warned
    if not _warned:
        _warned = True
        warnings.warn(
            "numba is not importable: quadfault's kernels run as plain Python "
            "(correct but slow); pip install numba",
            RuntimeWarning,
            stacklevel=3,
        )


def jit(*args, **kwargs):
    """Compile a kernel with the project's options (``@jit`` or ``@jit(parallel=True)``).

    Keyword arguments go to ``numba.njit`` (``cache``, ``error_model``, ``nogil`` and
    ``no_cfunc_wrapper`` have the project's defaults). Without numba the function is
    returned unchanged.
    """
    nb = _numba()
    if nb is None:
        _warn_once()
        if len(args) == 1 and callable(args[0]) and not kwargs:
            return args[0]
        return lambda f: f
    inner = kwargs.pop("inner", False)
    kwargs.setdefault("cache", True)
    kwargs.setdefault("error_model", "numpy")
    kwargs.setdefault("nogil", True)
    kwargs.setdefault("no_cfunc_wrapper", True)
    if inner:
        if args and not (len(args) == 1 and callable(args[0])):
            raise TypeError("jit(inner=True) takes no signatures")
        return _inner(args[0], kwargs) if args else lambda f: _inner(f, kwargs)
    if len(args) == 1 and callable(args[0]):
        return nb.njit(**kwargs)(args[0])
    return nb.njit(*args, **kwargs)


def _inner(fn, options: dict):
    """``fn`` compiled as an :class:`InnerKernel` with numba options ``options``."""
    options = dict(options, nopython=True, no_cpython_wrapper=True)
    cache = options.pop("cache")
    kernel = _inner_kernel_class()(
        py_func=fn, locals=options.pop("locals", None) or {}, targetoptions=options
    )
    if cache:
        kernel.enable_caching()
    return kernel


_InnerKernel = None


def _null_cache():
    from numba.core.caching import NullCache

    return NullCache


def _inner_kernel_class():
    """:class:`InnerKernel` (built on first use: it derives from numba's dispatcher)."""
    global _InnerKernel
    if _InnerKernel is None:
        from numba.core.registry import CPUDispatcher

        class InnerKernel(CPUDispatcher):
            """A kernel that other kernels call (``@jit(inner=True)``): numba compiles it
            without the CPython wrapper, so its compiled form cannot be called from Python.
            A call from Python runs the same function compiled with the wrapper (cached
            apart, as ``<name>.python``)."""

            def __call__(self, *args, **kwargs):
                form = self.__dict__.get("_python_form")
                if form is None:
                    form = self.__dict__["_python_form"] = self._with_wrapper()
                return form(*args, **kwargs)

            def _with_wrapper(self):
                f = self.py_func
                copy = types.FunctionType(
                    f.__code__, f.__globals__, f.__name__, f.__defaults__, f.__closure__
                )
                copy.__qualname__ = f.__qualname__ + ".python"  # its own cache entry
                copy.__doc__, copy.__kwdefaults__ = f.__doc__, f.__kwdefaults__
                options = dict(self.targetoptions)
                for name in ("no_cpython_wrapper", "nopython"):
                    options.pop(name, None)
                return _numba().njit(
                    cache=not isinstance(self._cache, _null_cache()), locals=self.locals, **options
                )(copy)

        InnerKernel.__module__, InnerKernel.__qualname__ = __name__, "InnerKernel"
        _InnerKernel = InnerKernel
    return _InnerKernel


def python(fn, replace: dict | None = None):
    """The interpreted form of kernel ``fn``: its own code run by Python, every kernel it
    calls (recursively) interpreted as well, and the globals named in ``replace`` swapped for
    the given objects. Arguments may then be any Python objects the code can handle (an
    effects hook, numpy arrays in place of floats); results equal the compiled kernel's
    (the same IEEE operations in the same order, no ``fastmath``)."""
    return _python(fn, tuple(sorted((replace or {}).items())), _INTERPRETED)


def _python(fn, replace: tuple, memo: dict):
    key = (id(fn), replace)
    if key in memo:
        return memo[key]
    f = getattr(fn, "py_func", fn)
    env = dict(f.__globals__)
    out = types.FunctionType(f.__code__, env, f.__name__, f.__defaults__, f.__closure__)
    out.__doc__ = f.__doc__
    memo[key] = out
    swap = dict(replace)
    for name in f.__code__.co_names:
        if name in swap:
            env[name] = swap[name]
        elif hasattr(env.get(name), "py_func"):  # a compiled callee
            env[name] = _python(env[name], replace, memo)
    return out


def set_threads(n: int | None) -> int:
    """Set numba's worker-thread count for the calling thread (``None``: leave it); return it.

    numba's OpenMP-style workers spin between parallel regions, so a small batch on a busy
    machine runs faster on one thread (docs/throughput.md has the measured crossover).
    :func:`threads` sets it for a block only.
    """
    nb = _numba()
    if nb is None:
        return 1
    if n is not None:
        most = nb.config.NUMBA_NUM_THREADS
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= most:
            raise ConfigError(f"numba threads must be an integer in 1..{most}, got {n!r}")
        nb.set_num_threads(n)
    return int(nb.get_num_threads())


@contextlib.contextmanager
def threads(n: int | None):
    """Run the block with ``n`` numba threads on the calling thread, then restore the caller's
    count (``None``: leave it). numba's thread count belongs to the thread that sets it, so
    this changes nothing for other threads or for code after the block."""
    nb = _numba()
    before = None if (nb is None or n is None) else nb.get_num_threads()
    if before is None or before == n:
        yield
        return
    set_threads(n)
    try:
        yield
    finally:
        nb.set_num_threads(before)


# ----------------------------------------------------------------------------------------
# the per-source-version cache
def compiled_sources(root: Path | None = None) -> list[Path]:
    """The modules of :data:`PACKAGES` that use this decorator (sorted)."""
    root = root or Path(__file__).resolve().parent.parent
    out = []
    for pkg in PACKAGES:
        base = root / pkg
        if not base.is_dir():
            continue
        for path in sorted(base.rglob("*.py")):
            try:
                text = path.read_bytes()
            except OSError:
                continue
            if any(m in text for m in _MARKERS):
                out.append(path)
    return out


def sources_digest(root: Path | None = None) -> str:
    """SHA-256 (hex, 16 characters) over the compiled modules' paths and sources."""
    root = root or Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for path in compiled_sources(root):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def _user_cache() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "quadfault-numba"


def cache_candidates(digest: str) -> list[Path]:
    """Where the cache of sources ``digest`` may go, in order of preference (see the module
    docstring)."""
    user = _users_cache_dir()
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    return ([Path(user) / f"quadfault-{digest}"] if user else []) + [
        _user_cache() / digest,
        Path(tempfile.gettempdir()) / f"quadfault-numba-{uid}" / digest,
    ]


def _users_cache_dir() -> str:
    """The user's own ``NUMBA_CACHE_DIR`` ("" if none), also in a child process of one that
    ran :func:`configure_cache`."""
    value = os.environ.get("NUMBA_CACHE_DIR", "")
    if value and value == os.environ.get(_CONFIGURED):
        return os.environ.get(_USERS, "")
    return value


def _writable(folder: Path) -> bool:
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(folder, os.W_OK | os.X_OK)


def configure_cache() -> str | None:
    """Set ``NUMBA_CACHE_DIR`` for this process (see the module docstring); return it, or
    None when no candidate folder is writable (numba's own choice then stands)."""
    target = next((c for c in cache_candidates(sources_digest()) if _writable(c)), None)
    if target is None:
        return None
    os.environ[_USERS] = _users_cache_dir()
    os.environ["NUMBA_CACHE_DIR"] = os.environ[_CONFIGURED] = str(target)
    config = sys.modules.get("numba.core.config")
    if config is not None:  # numba was imported first: make it read the variable again
        config.reload_config()
    return str(target)


__all__ = [
    "COMPILE_NOTICE",
    "jit",
    "python",
    "set_threads",
    "threads",
    "cache_candidates",
    "configure_cache",
    "sources_digest",
]
