"""``facewrap convert IN OUT``: convert a mesh between OBJ and PLY.

An OBJ output names a material library only when one is written beside it:
``OUT.mtl`` with the input's materials (texture paths rebased onto the output's
folder) or, for a PLY with one ``TextureFile``, a material showing that image
(:func:`facewrap.io.mtl.library_beside`).  Mesh and library are staged and moved
into place together.  A PLY output keeps no materials or groups (the format has
none): what is left out is said in one warning line naming the output.
"""

from __future__ import annotations

import os
import sys

from facewrap.errors import InputError
from facewrap.io import read_mesh, write_mesh
from facewrap.io.dispatch import MESH_WRITE_EXTENSIONS
from facewrap.io.mtl import library_beside, write_mtl
from facewrap.io.paths import check_output_paths, staged_outputs

__all__ = ["register", "cmd_convert"]


def _library_path(output) -> str:
    return os.path.splitext(os.fspath(output))[0] + ".mtl"


def cmd_convert(args) -> int:
    """Convert between OBJ and PLY, keeping vertex order, polygons and UVs."""
    ext = os.path.splitext(os.fspath(args.output))[1].lower()
    is_obj = ext == ".obj"
    # OUT.mtl is checked whether or not the input turns out to have materials
    check_output_paths(files=[args.output] + ([_library_path(args.output)] if is_obj
                                              else []), inputs=[args.input])
    if ext not in MESH_WRITE_EXTENSIONS:  # before staging, so the error names OUT
        raise InputError(f"unknown mesh format {ext or '(no extension)'!r}; use "
                         + ", ".join(MESH_WRITE_EXTENSIONS), args.output)
    mesh = read_mesh(args.input)
    if is_obj and mesh.n_faces == 0:
        # an OBJ of 'v' lines alone is refused by every reader of ours ("no faces"):
        # written, it would be a file no facewrap command reads back
        raise InputError("has no faces (a point cloud): an OBJ of it would not be read "
                         "back; convert it to .ply", args.input)
    with staged_outputs() as stage:
        if is_obj:
            mesh, library = library_beside(mesh, args.input, args.output)
            if library is not None:
                write_mtl(stage.file(_library_path(args.output)), library)
        write_mesh(stage.file(args.output), mesh)
    if not is_obj:
        dropped = _dropped_by_ply(mesh)
        if dropped:   # written all the same: the geometry and UVs are whole
            print(f"facewrap: warning: {args.output}: PLY keeps no materials or groups: "
                  f"{dropped} left out (convert to .obj to keep them)", file=sys.stderr)
    print(args.output)
    return 0


def _dropped_by_ply(mesh) -> str:
    """What a PLY of ``mesh`` leaves out, as text ("" for nothing): its materials
    and groups, by name (a few, then a count)."""
    parts = []
    for what, names in (("material", list(mesh.materials)), ("group", list(mesh.groups))):
        if names:
            shown = ", ".join(repr(n) for n in names[:3])
            more = f" and {len(names) - 3} more" if len(names) > 3 else ""
            parts.append(f"{len(names)} {what}{'s' if len(names) > 1 else ''} "
                         f"({shown}{more})")
    return " and ".join(parts)


def register(subparsers, summary: str) -> None:
    """Add ``convert`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser("convert", help=summary)
    p.add_argument("input")
    p.add_argument("output")
    p.set_defaults(func=cmd_convert)
