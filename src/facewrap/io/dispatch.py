"""Pick a mesh reader or writer from the file extension.

OBJ and PLY are read and written by facewrap's own exact readers
(:mod:`facewrap.io.obj`, :mod:`facewrap.io.ply`); STL, OFF and glTF scans
(``.stl``, ``.off``, ``.glb``, ``.gltf``) by :mod:`facewrap.io.trimesh_formats`
(through trimesh, except OFF, read there row by row).  Outputs are OBJ or PLY.
"""

from __future__ import annotations

import os

import numpy as np

from facewrap.errors import InputError
from facewrap.io.files import check_coordinates, not_a_file
from facewrap.io.obj import read_obj, write_obj
from facewrap.io.ply import read_ply, write_ply
from facewrap.io.trimesh_formats import (TRIMESH_EXTENSIONS, read_scene_texture,
                                         read_trimesh_format)
from facewrap.mesh import Mesh, check_positions
from facewrap.params import expect_instance

__all__ = ["read_mesh", "write_mesh", "read_mesh_texture", "MESH_READ_EXTENSIONS",
           "MESH_WRITE_EXTENSIONS"]

#: Extensions :func:`write_mesh` writes.
MESH_WRITE_EXTENSIONS = (".obj", ".ply")
#: Extensions :func:`read_mesh` reads.
MESH_READ_EXTENSIONS = (*MESH_WRITE_EXTENSIONS, *TRIMESH_EXTENSIONS)


def _ext(path) -> str:
    if not isinstance(path, (str, os.PathLike)):   # else os's "expected str, bytes..."
        raise TypeError(f"path must be a str or os.PathLike, got {type(path).__name__}")
    return os.path.splitext(os.fspath(path))[1].lower()


def _unknown(ext: str, known, path) -> InputError:
    return InputError(f"unknown mesh format {ext or '(no extension)'!r}; use "
                      + ", ".join(known), path)


def read_mesh(path) -> Mesh:
    """Read a mesh, the reader chosen by extension (:data:`MESH_READ_EXTENSIONS`).

    Raises
    ------
    InputError
        For a missing file, an unknown extension, malformed content or
        coordinates beyond :data:`~facewrap.units.COORDINATE_LIMIT`, naming
        the file.
    """
    ext = _ext(path)
    if os.path.exists(path) and not os.path.isfile(path):
        raise not_a_file(path)          # a folder, fifo, device: say which
    if ext not in MESH_READ_EXTENSIONS:
        raise _unknown(ext, MESH_READ_EXTENSIONS, path)
    if not os.path.isfile(path):
        raise not_a_file(path)
    if ext == ".obj":
        mesh = read_obj(path)
    elif ext == ".ply":
        mesh = read_ply(path)
    else:
        mesh = read_trimesh_format(path)
    if mesh.n_vertices == 0:   # a PLY may declare "element vertex 0"; nothing has no size
        raise InputError("holds no vertices", path)
    # the readers are exact; no head is 1e30 across, and its squares would overflow
    check_coordinates(mesh.vertices, path)
    return mesh


def read_mesh_texture(path):
    """The texture image a mesh file carries inside it (glTF), or None.

    OBJ and PLY files only name their images (:attr:`Mesh.texture`, ``.mtl``);
    a ``.glb`` holds its base-colour image itself
    (:func:`~facewrap.io.trimesh_formats.read_scene_texture`).

    Returns
    -------
    (H, W, 3) uint8 or None
    """
    if _ext(path) not in (".glb", ".gltf"):
        return None
    if not os.path.isfile(path):
        raise InputError("no such file", path)
    return read_scene_texture(path)


def write_mesh(path, mesh: Mesh) -> None:
    """Write an OBJ or PLY mesh, chosen by extension (atomic).

    Raises
    ------
    TypeError
        ``mesh`` is no :class:`~facewrap.mesh.Mesh` (an array of vertices, say), or
        ``path`` no path.
    InputError
        An extension it cannot write.
    ValueError
        A vertex that is NaN, infinite or too large
        (:func:`~facewrap.mesh.check_positions`), or a texture coordinate, normal or
        vertex colour that is NaN or infinite: no reader takes it back.
    """
    expect_instance(mesh, Mesh, "mesh")
    ext = _ext(path)
    if ext not in MESH_WRITE_EXTENSIONS:
        raise _unknown(ext, MESH_WRITE_EXTENSIONS, path)
    # what read_mesh refuses is not written: an OBJ took a NaN or a 1e300 silently
    check_positions(mesh.vertices, "mesh")
    _check_finite_attributes(mesh)
    if ext == ".obj":
        write_obj(path, mesh)
    else:
        write_ply(path, mesh)


def _check_finite_attributes(mesh: Mesh) -> None:
    """Refuse a NaN or infinite texture coordinate, normal or vertex colour: an OBJ
    wrote it as ``nan`` (its UVs and normals then refused by the reader, its colours
    dropped without a word), a PLY refused it naming no row."""
    for what, values in (("texture coordinate", mesh.uvs), ("normal", mesh.normals),
                         ("vertex colour", mesh.vertex_colors)):
        if values is None:
            continue
        bad = ~np.isfinite(values).all(axis=1)
        if bad.any():
            row = int(np.argmax(bad))
            raise ValueError(f"mesh: {what} {row} is not finite ({values[row].tolist()})")
