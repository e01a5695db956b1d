"""Exception types. Every user-facing error says *what* was wrong and *where*."""

from __future__ import annotations


class QuadfaultError(ValueError):
    """Base class of errors caused by bad user input (files, parameters, flags).

    The CLI prints ``str(error)`` on one line and exits non-zero, without a traceback.
    """


class RecordingError(QuadfaultError):
    """A recording (CSV + JSON sidecar) breaks the ``quadfault-recording/1`` format.

    The message names the file and, where relevant, the column or key and the row.
    """

    def __init__(
        self,
        path,
        message: str,
        *,
        column: str | None = None,
        key: str | None = None,
        row: int | None = None,
    ):
        where = [str(path)]
        if column is not None:
            where.append(f"column '{column}'")
        if key is not None:
            where.append(f"key '{key}'")
        if row is not None:
            where.append(f"row {row}")
        self.path = path
        self.column = column
        self.key = key
        self.row = row
        super().__init__(f"{', '.join(where)}: {message}")


class ConfigError(QuadfaultError):
    """A parameter or configuration value is out of range or inconsistent."""
