"""Safe file output: atomic writes (temporary file, then rename) and no silent overwrite."""

from __future__ import annotations

import contextlib
import io
import os
import secrets
import signal
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


def _write_temp(path: Path, data: bytes) -> str:
    """``data`` in a synced temporary file beside ``path``; returns its name. The file is
    created with mode 0666 less the user's umask, as ``open()`` would create ``path`` itself
    (``tempfile.mkstemp`` would make it 0600, unreadable to the user's group)."""
    while True:
        tmp = str(path.parent / f".{path.name}.{secrets.token_hex(4)}.tmp")
        try:
            fd = os.open(
                tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666
            )
            break
        except FileExistsError:  # pragma: no cover - a 32-bit name collision
            continue
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    except BaseException:
        _unlink(tmp)
        raise
    return tmp


def _unlink(name) -> None:
    try:
        os.unlink(name)
    except FileNotFoundError:
        pass


@contextlib.contextmanager
def _sigint_deferred():
    """Hold Ctrl-C (SIGINT) back for the duration; it takes effect on exit. (A Python-level
    handler, not a signal mask: the signal may land on any thread of the process.)"""
    caught = []
    try:
        previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    except ValueError:  # not the main thread: signals are not delivered here anyway
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if caught and previous != signal.SIG_IGN:
            if callable(previous):
                previous(signal.SIGINT, None)
            else:
                raise KeyboardInterrupt


def atomic_write_bytes(path, data: bytes, *, force: bool = False) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder and a rename,
    so an interrupted run never leaves a half-written file."""
    return atomic_write_files({path: data}, force=force)[0]


def atomic_write_files(contents: dict, *, force: bool = False) -> list[Path]:
    """Write several files as one unit (e.g. a CSV and its JSON sidecar): every temporary file
    is written first, then the renames run back to back with Ctrl-C held, so an interrupted
    run leaves either all the new files or none of them (never a new sidecar beside an old or
    missing CSV). ``contents`` maps path -> bytes (or str, written as UTF-8)."""
    paths = [Path(p) for p in contents]
    check_writable(paths, force=force)
    temps = []
    try:
        for path, data in zip(paths, contents.values()):
            temps.append(_write_temp(path, data.encode("utf-8") if isinstance(data, str) else data))
        with _sigint_deferred():
            for tmp, path in zip(temps, paths):
                os.replace(tmp, path)
    except BaseException:
        for tmp in temps:
            _unlink(tmp)
        raise
    return paths


def atomic_write_text(path, text: str, *, force: bool = False) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"), force=force)


def atomic_savefig(fig, path, *, force: bool = False, **kwargs) -> Path:
    """Save a matplotlib figure atomically."""
    buf = io.BytesIO()
    fmt = Path(path).suffix.lstrip(".") or "png"
    fig.savefig(buf, format=fmt, **kwargs)
    return atomic_write_bytes(path, buf.getvalue(), force=force)
