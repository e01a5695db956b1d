"""Where numba keeps the compiled kernels: one cache directory per version of their sources.

numba's on-disk cache (``cache=True``) checks only the source file of the function it
compiled. Our kernels call compiled functions of other modules (the IRLS window solver calls
the residual kernels, the batched EKF calls the EKF step, ...), so after an update that
changes only a callee -- a ``git pull`` in an editable install -- numba would load a stale
caller that still has the old callee inlined: wrong numbers or a segmentation fault.

:func:`configure` points ``NUMBA_CACHE_DIR`` at ``<user cache>/quadfault-numba/<hash>``, the
hash being that of every compiled module's source, so any change to any of them starts a
fresh cache. It does nothing when the user set ``NUMBA_CACHE_DIR`` themselves, or when no
writable cache directory exists (numba then keeps its default, next to the sources).
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

#: modules (paths relative to the repository/site root) whose njit functions are cached
COMPILED_MODULES = (
    "quadfault/_numba_kernels.py", "quadfault/_numba_mirrors.py", "quadfault/_sim_numba.py",
    "estimators/_residuals_numba.py", "estimators/_irls_numba.py",
    "estimators/_irls_online_numba.py", "estimators/ekf_numba.py", "estimators/batched.py",
    "quad_fault_env/envs/compiled_substeps.py",
)


def sources_digest(root: Path | None = None) -> str:
    """SHA-256 (hex, 16 characters) over the compiled modules' sources (missing ones skipped)."""
    root = root or Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for rel in COMPILED_MODULES:
        path = root / rel
        h.update(rel.encode())
        if path.is_file():
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


def _user_cache() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "quadfault-numba"


def configure() -> str | None:
    """Set ``NUMBA_CACHE_DIR`` for this process (see the module docstring); return it, or
    None when left alone."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return None
    target = _user_cache() / sources_digest()
    try:
        target.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    if not os.access(target, os.W_OK):
        return None
    os.environ["NUMBA_CACHE_DIR"] = str(target)
    config = sys.modules.get("numba.core.config")
    if config is not None:  # numba was imported first: make it read the variable again
        config.reload_config()
    return str(target)
