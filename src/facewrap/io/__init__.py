"""Readers and writers: meshes (OBJ, PLY), landmarks and markers.

:func:`read_mesh` / :func:`write_mesh` pick the format from the file extension.
"""

from facewrap.io.obj import read_obj, read_obj_vertices, write_obj
from facewrap.io.dispatch import read_mesh, write_mesh

__all__ = ["read_obj", "write_obj", "read_obj_vertices", "read_mesh", "write_mesh"]
