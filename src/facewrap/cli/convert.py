"""``facewrap convert IN OUT``: convert a mesh between OBJ and PLY."""

from __future__ import annotations

from facewrap.io import read_mesh, write_mesh
from facewrap.io.paths import check_output_paths

__all__ = ["register", "cmd_convert"]


def cmd_convert(args) -> int:
    """Convert between OBJ and PLY, keeping vertex order, polygons and UVs."""
    check_output_paths(files=[args.output], inputs=[args.input])
    write_mesh(args.output, read_mesh(args.input))
    print(args.output)
    return 0


def register(subparsers, summary: str) -> None:
    """Add ``convert`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser("convert", help=summary)
    p.add_argument("input")
    p.add_argument("output")
    p.set_defaults(func=cmd_convert)
