"""The ``quadfault`` command line.

Subcommands are listed in :data:`SUBCOMMANDS`; each lives in its own module with
``add_arguments(parser)`` and ``run(args) -> int``, imported only when that subcommand runs,
so ``quadfault --help`` is instant. Errors caused by the user's input print one line and exit
with status 2; an interrupted run exits with 130.
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: name -> (module, one-line help)
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "reproduce": (
        "estimators.paper.reproduce",
        "the paper's evaluation: IRLS vs EKF on the paper's "
        "scenarios; writes metrics.json, report.md and figures",
    ),
    "simulate": ("quadfault.sim.cli", "fly the quadrotor through a scenario and write a recording"),
    "estimate": ("estimators.cli", "run a motor-efficiency estimator over a recording"),
    "diagnose": ("estimators.diagnose_cli", "model-mismatch diagnosis of a recording"),
    "import": ("quadfault.io.importers.cli", "convert a real flight log into a recording"),
    "train": ("agents.train", "train a stable-baselines3 agent (needs the rl extra)"),
    "evaluate": ("agents.evaluate", "evaluate agents over a scenario suite"),
}


class OneLineErrorParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line (``prog: error: ...``), exit 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def _top_parser() -> argparse.ArgumentParser:
    from quadfault import __version__

    p = OneLineErrorParser(
        prog="quadfault",
        description="Fault-tolerant quadrotor research toolkit.",
        epilog="Run 'quadfault <command> --help' for the options of a command.",
    )
    p.add_argument("--version", action="version", version=f"quadfault {__version__}")
    sub = p.add_subparsers(dest="command", metavar="<command>")
    for name, (_, help_text) in SUBCOMMANDS.items():
        sub.add_parser(name, help=help_text, add_help=False)
    return p


def add_common_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags every subcommand shares."""
    parser.add_argument("--quiet", action="store_true", help="no progress bars or chatter")


def _error(prog: str, message: str, code: int = 2) -> int:
    print(f"{prog}: error: {message}", file=sys.stderr)
    return code


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in SUBCOMMANDS:
        parser = _top_parser()
        if not argv:
            parser.print_help()
            return 0
        parser.parse_args(argv)  # prints help/version or a one-line usage error and exits
        return 0
    name, rest = argv[0], argv[1:]
    module_name, help_text = SUBCOMMANDS[name]
    prog = f"quadfault {name}"
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        missing = getattr(exc, "name", None) or str(exc)
        return _error(
            prog,
            f"this command needs a package that is not installed ({missing}); "
            "see the README's install extras",
        )
    parser = OneLineErrorParser(prog=prog, description=help_text)
    module.add_arguments(parser)
    add_common_arguments(parser)
    args = parser.parse_args(rest)
    from quadfault.errors import QuadfaultError
    from quadfault.progress import set_quiet

    set_quiet(args.quiet)
    try:
        return int(module.run(args) or 0)
    except QuadfaultError as exc:
        return _error(prog, str(exc))
    except (FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        return _error(prog, f"{exc.filename}: {exc.strerror}")
    except MemoryError:
        return _error(prog, "out of memory: the input or the requested run is too large")
    except KeyboardInterrupt:
        return _error(prog, "interrupted", 130)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
