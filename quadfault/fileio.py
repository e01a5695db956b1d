"""Safe file output: atomic writes (temporary file, then rename) and no silent overwrite."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from quadfault.errors import QuadfaultError


def check_writable(paths, *, force: bool = False) -> None:
    """Raise if any of ``paths`` exists (unless ``force``) or its folder is missing."""
    for p in map(Path, paths):
        if p.exists() and not force:
            raise QuadfaultError(f"{p}: already exists; pass --force (force=True) to overwrite")
        if p.exists() and p.is_dir():
            raise QuadfaultError(f"{p}: is a directory")
        if not p.parent.exists():
            raise QuadfaultError(f"{p.parent}: folder does not exist")


def atomic_write_bytes(path, data: bytes, *, force: bool = False) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder and a rename,
    so an interrupted run never leaves a half-written file."""
    path = Path(path)
    check_writable([path], force=force)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def atomic_write_text(path, text: str, *, force: bool = False) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"), force=force)


def atomic_savefig(fig, path, *, force: bool = False, **kwargs) -> Path:
    """Save a matplotlib figure atomically."""
    import io

    buf = io.BytesIO()
    fmt = Path(path).suffix.lstrip(".") or "png"
    fig.savefig(buf, format=fmt, **kwargs)
    return atomic_write_bytes(path, buf.getvalue(), force=force)
