"""Progress bars that stay quiet when stdout is not a terminal or ``--quiet`` is given."""

from __future__ import annotations

import os
import sys

_QUIET = False


def set_quiet(quiet: bool) -> None:
    global _QUIET
    _QUIET = bool(quiet)


def enabled() -> bool:
    return not _QUIET and sys.stdout.isatty() and os.environ.get("CI") is None


def progress_bar(total=None, desc: str = "", unit: str = "it", disable: bool | None = None):
    """A tqdm bar (or a no-op stand-in when disabled)."""
    from tqdm.auto import tqdm

    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        disable=(not enabled()) if disable is None else disable,
        dynamic_ncols=True,
        leave=False,
    )
