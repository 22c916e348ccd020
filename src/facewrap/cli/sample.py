"""``facewrap sample OUT``: write the built-in synthetic template and scan.

The folder may exist, but no file of the sample may be in it already (a user's
own ``template.obj`` would be lost) unless ``--overwrite`` is given; the files are
staged and moved in together, so they appear all or not at all.
"""

from __future__ import annotations

import os
from pathlib import Path

from facewrap.errors import InputError
from facewrap.io.paths import check_writable, staged_outputs

__all__ = ["register", "cmd_sample", "check_replaced"]


def check_replaced(paths, overwrite: bool = False) -> None:
    """Refuse to write the sample's files over what is already there.

    Parameters
    ----------
    paths : iterable of path
        The files the sample writes (:func:`facewrap.sample.sample_paths`).
    overwrite : bool
        Replace existing files (``--overwrite``); a folder where a file goes, or
        a file where a folder goes, is refused all the same (it cannot be replaced
        by a file).

    Raises
    ------
    InputError
        Naming the first path in the way.
    """
    for path in paths:
        path = Path(path)
        for parent in reversed(path.parents):   # a file where a sub-folder goes
            if os.path.lexists(parent) and not parent.is_dir():
                raise InputError("is a file where the sample writes a folder: choose "
                                 "an empty or new folder", parent)
        if path.is_dir():
            raise InputError("is a folder where the sample writes a file: choose an "
                             "empty or new folder", path)
        if os.path.lexists(path) and not overwrite:   # lexists: a dangling link too
            raise InputError("already exists and the sample would replace it: choose "
                             "an empty or new folder, or pass --overwrite", path)


def cmd_sample(args) -> int:
    """Write the built-in synthetic template and scan to a folder; print the files."""
    # deferred: the other commands (and `facewrap --help`) do not pay for this import
    from facewrap.sample import make_scan, make_template, sample_paths, write_sample
    if not args.out.strip():   # Path("") is the current folder: never what was meant
        raise InputError("the output folder name is empty", "OUT")
    out = Path(args.out)
    check_writable(folders=[out])   # before any work
    check_replaced(sample_paths(out).values(), args.overwrite)
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
    p = subparsers.add_parser(
        "sample", help=summary,
        description="Write the built-in synthetic template, its landmarks and "
                    "blendshapes, a scan of another face with its landmarks, texture "
                    "and ground truth into a folder (created if missing).")
    p.add_argument("out", help="output folder: new, empty, or holding none of the "
                               "sample's file names")
    p.add_argument("--overwrite", action="store_true",
                   help="replace sample files already in the folder (a re-run)")
    p.set_defaults(func=cmd_sample)
