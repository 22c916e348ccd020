"""Pick a mesh reader or writer from the file extension."""

from __future__ import annotations

import os

from facewrap.errors import InputError
from facewrap.io.obj import read_obj, write_obj
from facewrap.io.ply import read_ply, write_ply
from facewrap.mesh import Mesh

__all__ = ["read_mesh", "write_mesh"]


def _ext(path) -> str:
    return os.path.splitext(os.fspath(path))[1].lower()


def read_mesh(path) -> Mesh:
    """Read an OBJ or PLY mesh, chosen by extension.

    Raises
    ------
    InputError
        For a missing file, an unknown extension or malformed content.
    """
    ext = _ext(path)
    if ext not in (".obj", ".ply"):
        raise InputError(f"unknown mesh format {ext or '(no extension)'!r}; "
                         "use .obj or .ply", path)
    if not os.path.isfile(path):
        raise InputError("no such file", path)
    if ext == ".obj":
        return read_obj(path)
    return read_ply(path)


def write_mesh(path, mesh: Mesh) -> None:
    """Write an OBJ or PLY mesh, chosen by extension (atomic)."""
    ext = _ext(path)
    if ext not in (".obj", ".ply"):
        raise InputError(f"unknown mesh format {ext or '(no extension)'!r}; "
                         "use .obj or .ply", path)
    if ext == ".obj":
        write_obj(path, mesh)
    else:
        write_ply(path, mesh)
