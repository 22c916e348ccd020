"""``facewrap sample OUT``: write the built-in synthetic template and scan."""

from __future__ import annotations

from pathlib import Path

from facewrap.errors import InputError
from facewrap.io.paths import check_writable, staged_outputs

__all__ = ["register", "cmd_sample"]


def cmd_sample(args) -> int:
    """Write the built-in synthetic template and scan to a folder; print the files."""
    # deferred: the other commands (and `facewrap --help`) do not pay for this import
    from facewrap.sample import make_scan, make_template, write_sample
    if not args.out.strip():   # Path("") is the current folder: never what was meant
        raise InputError("the output folder name is empty", "OUT")
    out = Path(args.out)
    check_writable(folders=[out])   # before any work
    template = make_template()
    scan = make_scan(template)
    with staged_outputs() as stage:   # every file of the sample appears, or none
        staged = stage.folder(out)
        paths = write_sample(staged, template, scan)
    for name, p in paths.items():
        print(f"{name:>20}: {out / p.relative_to(staged)}")
    return 0


def register(subparsers, summary: str) -> None:
    """Add ``sample`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser("sample", help=summary)
    p.add_argument("out", help="output folder")
    p.set_defaults(func=cmd_sample)
