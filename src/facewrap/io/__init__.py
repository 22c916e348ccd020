"""Readers and writers: meshes (OBJ, PLY, glTF morphs), landmarks and markers, images.

:func:`read_mesh` / :func:`write_mesh` pick the format from the file extension.
Format modules: :mod:`.obj`, :mod:`.ply`, :mod:`.gltf`, :mod:`.landmarks`,
:mod:`.images` (PNG and any image Pillow reads); :mod:`.files` and :mod:`.atomic`
read and write files with one clear error.
"""

from facewrap.io.obj import read_obj, read_obj_vertices, write_obj, write_obj_series
from facewrap.io.dispatch import read_mesh, write_mesh

__all__ = ["read_obj", "write_obj", "write_obj_series", "read_obj_vertices", "read_mesh",
           "write_mesh"]
