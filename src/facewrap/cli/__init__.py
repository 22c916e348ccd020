"""The ``facewrap`` command: builds the parser and dispatches to one subcommand.

Each subcommand lives in its own module here (``info``, ``convert``, ``sample``,
``wrap``, ``animate``, ``track``, ``transfer``, ``evaluate``, ``report``, ``run``,
``batch``, ``demo``) with ``register(subparsers)`` and a ``cmd_<name>(args)``
that parses and calls the library.  Errors in user input
(:class:`~facewrap.errors.InputError`, missing files, values the settings refuse)
print one line ``facewrap: error: <file>:<line>: <problem>`` and exit with status
2; nothing is written in that case.
"""

from __future__ import annotations

import argparse
import sys

from facewrap.cli import (animate, batch, convert, demo, evaluate, info, report, run,
                          sample, track, transfer, wrap)
from facewrap.errors import InputError
from facewrap.progress import configure_logging
from facewrap.version import __version__

__all__ = ["main", "build_parser", "COMMANDS"]

#: The subcommand modules, in the order ``facewrap --help`` lists them.
COMMANDS = (info, convert, sample, wrap, animate, track, transfer, evaluate, report, run,
            batch, demo)


def build_parser() -> argparse.ArgumentParser:
    """The ``facewrap`` argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="facewrap",
        description="Wrap a template head onto face scans, transfer deformations, "
                    "make avatar blendshapes.")
    parser.add_argument("--version", action="version", version=f"facewrap {__version__}")
    parser.add_argument("-v", "--verbose", dest="log_verbose", action="count", default=0,
                        help="more log lines (-v info, -vv debug) on standard error")
    parser.add_argument("--silent", dest="log_quiet", action="count", default=0,
                        help="only errors in the log, no progress bars")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for command in COMMANDS:
        command.register(sub)
    return parser


def main(argv=None) -> int:
    """Entry point of the ``facewrap`` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    # progress bars draw only on a terminal; logs go to standard error
    configure_logging(args.log_verbose - args.log_quiet
                      - (1 if getattr(args, "quiet", False) else 0))
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"facewrap: error: {exc}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"facewrap: error: {exc.filename}: no such file", file=sys.stderr)
        return 2
    except ValueError as exc:  # inconsistent inputs found past the readers
        print(f"facewrap: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
