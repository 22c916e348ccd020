"""The texture image a mesh file shows: embedded (glTF), or named by its material
library (OBJ ``map_Kd``) or its header (PLY ``TextureFile``)."""

from __future__ import annotations

import os
import warnings

from facewrap.errors import InputWarning
from facewrap.io.dispatch import read_mesh_texture
from facewrap.io.files import not_a_file
from facewrap.io.images import load_image
from facewrap.io.mtl import read_libraries

__all__ = ["mesh_texture"]


def mesh_texture(path, mesh):
    """The image a mesh read from ``path`` refers to, or None.

    The first material whose library names a ``map_Kd`` image that exists gives it;
    a mesh without texture coordinates has none (it is drawn shaded).  A mesh that
    names images none of which is there (moved, a folder, a fifo) has none either,
    said in an :class:`~facewrap.errors.InputWarning` naming the first.

    Parameters
    ----------
    path : path
        The mesh's file.
    mesh : Mesh
        As read from it.

    Returns
    -------
    (H, W, 3) uint8 or None

    Examples
    --------
    >>> from facewrap.mesh import Mesh
    >>> mesh_texture("a.obj", Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]])) is None
    True
    """
    if mesh.uvs is None:
        return None
    embedded = read_mesh_texture(path)
    if embedded is not None:
        return embedded
    candidates = []
    if mesh.mtllib:
        libraries = read_libraries(path, mesh.mtllib)
        for material in mesh.materials:
            for statement in libraries.get(material, []):
                words = statement.split()
                if len(words) >= 2 and words[0].lower() == "map_kd":
                    candidates.append(words[-1])
    if mesh.texture:
        candidates.append(os.path.join(os.path.dirname(os.path.abspath(os.fspath(path))),
                                       mesh.texture))
    for image in candidates:
        if os.path.isfile(image):
            return load_image(image)
    if candidates:   # named but not there: drawn shaded all the same, but not silently
        warnings.warn(f"{path}: its texture {candidates[0]}: "
                      f"{not_a_file(candidates[0]).problem}; the mesh is drawn shaded to "
                      "find its landmarks", InputWarning, stacklevel=2)
    return None
