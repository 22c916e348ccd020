"""Wavefront material libraries (``.mtl``): read a template's, write an output's.

An OBJ names its material library with ``mtllib`` and its materials with
``usemtl``; each ``newmtl`` block of the library holds the material's statements
(``Kd``, ``Ks``, ``Ns``, ``illum``, ``map_Kd`` ...).  :func:`read_mtl` reads the
blocks as they are written; :func:`output_library` builds the library of an output
OBJ: the template's materials kept by name, their texture paths rewritten to be
relative to the output's folder, and ``map_Kd`` of each baked material pointing at
its baked image.  :func:`with_library` gives the mesh to write with it, so an OBJ
never names a library that is not written beside it; :func:`library_beside` does
both for an OBJ written from a mesh read elsewhere (``convert``, ``transfer``).
"""

from __future__ import annotations

import os
import re

import numpy as np

from facewrap.errors import InputError
from facewrap.io.atomic import atomic_write
from facewrap.io.files import read_file_bytes
from facewrap.mesh import Mesh

__all__ = ["DEFAULT_MATERIAL", "read_mtl", "read_libraries", "mtl_text", "write_mtl",
           "output_library", "with_library", "TEXTURE_MATERIAL", "library_beside"]

#: Statements of a material the template's library does not describe.
DEFAULT_MATERIAL = ("Ka 1 1 1", "Kd 0.8 0.8 0.8", "Ks 0 0 0", "d 1", "illum 1")
# statements whose last word is a file (texture maps, bump and reflection maps)
_MAP = re.compile(r"^(map_\w+|bump|disp|decal|refl|norm)$", re.IGNORECASE)


def read_mtl(path) -> dict[str, list[str]]:
    """Read a material library: each material's statements, as written.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    dict of str to list of str
        Material name → its statements (``"Kd 0.6 0.6 0.6"``, ...), white space
        trimmed, comments and blank lines left out, in file order.

    Raises
    ------
    InputError
        Naming the file: missing, unreadable, or a statement before any ``newmtl``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.mtl"
    >>> _ = p.write_text("# skin\\nnewmtl skin\\nKd 1 0.5 0.5\\n  map_Kd tex/skin.png\\n")
    >>> read_mtl(p)
    {'skin': ['Kd 1 0.5 0.5', 'map_Kd tex/skin.png']}
    """
    text = read_file_bytes(path, text=True).decode("utf-8", "replace")
    materials: dict[str, list[str]] = {}
    current = None
    for number, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        key, _, rest = line.partition(" ")
        if key == "newmtl":
            current = materials.setdefault(rest.strip(), [])
        elif current is None:
            raise InputError(f"statement {key!r} before any 'newmtl'", path, number)
        else:
            current.append(" ".join(line.split()))
    return materials


def read_libraries(obj_path, names) -> dict[str, list[str]]:
    """The materials of an OBJ's libraries, read where they can be.

    Parameters
    ----------
    obj_path : path
        The OBJ the libraries belong to (``names`` are relative to its folder).
    names : iterable of str
        Its ``mtllib`` names.

    Returns
    -------
    dict of str to list of str
        Material name → statements, texture paths made absolute; the first library
        that defines a material wins.  A library that is missing or unreadable adds
        nothing (its materials then get :data:`DEFAULT_MATERIAL`).
    """
    folder = os.path.dirname(os.path.abspath(os.fspath(obj_path)))
    out: dict[str, list[str]] = {}
    for name in names:
        for lib in name.split():
            path = os.path.join(folder, lib)
            try:
                found = read_mtl(path)
            except InputError:
                continue
            base = os.path.dirname(path)
            for material, lines in found.items():
                out.setdefault(material, [_rebased(s, base, None) for s in lines])
    return out


def _rebased(statement: str, source: str, target: str | None) -> str:
    """A texture statement's file made absolute (``target`` None) or relative to
    ``target``; other statements as they are."""
    words = statement.split()
    if len(words) < 2 or not _MAP.match(words[0]):
        return statement
    file = os.path.normpath(os.path.join(source, words[-1]))
    if target is not None:
        file = os.path.relpath(file, target).replace(os.sep, "/")
    return " ".join(words[:-1] + [file])


def mtl_text(materials: dict, header: str | None = "written by facewrap") -> str:
    """A material library as text: one ``newmtl`` block per material, in order.

    Examples
    --------
    >>> print(mtl_text({"skin": ["Kd 1 1 1", "map_Kd head.png"]}, header=None), end="")
    newmtl skin
    Kd 1 1 1
    map_Kd head.png
    """
    parts = [f"# {header}\n"] if header else []
    for name, lines in materials.items():
        parts.append(f"newmtl {name}\n" + "".join(f"{s}\n" for s in lines))
    return "\n".join(parts)


def write_mtl(path, materials: dict, header: str | None = "written by facewrap") -> None:
    """Write a material library (:func:`mtl_text`), atomically; its folder is created
    when missing."""
    os.makedirs(os.path.dirname(os.path.abspath(os.fspath(path))), exist_ok=True)
    with atomic_write(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(mtl_text(materials, header))


def output_library(materials, template_path, template_libraries, output_path,
                   images: dict) -> dict[str, list[str]]:
    """The material library of an output OBJ.

    Parameters
    ----------
    materials : sequence of str
        The output mesh's material names (all of them, in order).
    template_path : path
        The OBJ whose libraries describe the materials.
    template_libraries : sequence of str
        Its ``mtllib`` names.
    output_path : path
        The output OBJ (texture paths become relative to its folder).
    images : dict of str to path
        Material name → its baked image.  Such a material's ``map_Kd`` points at
        the image (relative to the output's folder) and its ``Kd`` is white, so the
        viewer shows the baked colours as they are.

    Returns
    -------
    dict of str to list of str
        Material name → statements, ready for :func:`write_mtl`.

    Examples
    --------
    >>> lib = output_library(["skin"], "in/t.obj", [], "out/o.obj", {"skin": "out/o.png"})
    >>> lib["skin"][-2:]
    ['Kd 1 1 1', 'map_Kd o.png']
    """
    target = os.path.dirname(os.path.abspath(os.fspath(output_path)))
    known = read_libraries(template_path, template_libraries)
    out = {}
    for name in materials:
        # texture files were made absolute by read_libraries; now relative to target
        lines = [_rebased(s, target, target) for s in known.get(name, DEFAULT_MATERIAL)]
        if name in images:
            lines = [s for s in lines if s.split()[0].lower() not in ("map_kd", "kd")]
            image = os.path.relpath(os.path.abspath(os.fspath(images[name])), target)
            lines += ["Kd 1 1 1", "map_Kd " + image.replace(os.sep, "/")]
        out[name] = lines
    return out


def with_library(mesh: Mesh, library: str | None, face_materials=None,
                 materials=None) -> Mesh:
    """``mesh`` naming one material library (or none), materials optionally replaced.

    Parameters
    ----------
    mesh : Mesh
    library : str or None
        The ``mtllib`` name to write (a file beside the OBJ); None for none.
    face_materials : (m,) int, optional
        New material id per face (-1 for none), with ``materials``.
    materials : sequence of str, optional

    Returns
    -------
    Mesh
        Same vertices, faces, UVs, normals, groups and colours.
    """
    if face_materials is None:
        face_materials, materials = mesh.face_materials, mesh.materials
    return Mesh(mesh.vertices, (mesh.face_offsets, mesh.face_indices),
                face_materials=None if face_materials is None
                else np.asarray(face_materials, dtype=np.int64),
                materials=tuple(materials or ()), face_groups=mesh.face_groups,
                groups=mesh.groups, mtllib=(library,) if library else (),
                vertex_colors=mesh.vertex_colors, texture=mesh.texture,
                **mesh.corner_attributes())


#: Material given to a mesh read with one texture image and no materials (a PLY's
#: ``TextureFile``), so the OBJ written from it shows the image.
TEXTURE_MATERIAL = "texture"


def library_beside(mesh: Mesh, source_path, output_path, library: str | None = None):
    """The mesh to write as the OBJ ``output_path`` and the library to write beside it.

    The materials of ``mesh`` (read from ``source_path``) are kept by name with their
    libraries' statements, texture paths rebased onto the output's folder
    (:func:`output_library`); a mesh with texture coordinates, no materials and one
    texture image (:attr:`Mesh.texture`, relative to ``source_path``) gets one
    material :data:`TEXTURE_MATERIAL` showing it.  Otherwise there is no library
    and the OBJ names none.

    Parameters
    ----------
    mesh : Mesh
    source_path : path
        The file ``mesh`` was read from (its ``mtllib`` names are relative to it).
    output_path : path
        The OBJ to be written.
    library : str, optional
        The library's file name, in the output's folder; default the output's stem
        with ``.mtl``.

    Returns
    -------
    mesh : Mesh
        Naming ``library`` when there is one, else no library.
    materials : dict of str to list of str, or None
        The library's materials, for :func:`write_mtl` at
        ``os.path.join(os.path.dirname(output_path), library)``; None when none is
        written.

    Examples
    --------
    >>> tri = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]], mtllib=["gone.mtl"])
    >>> written, lib = library_beside(tri, "in/a.obj", "out/b.obj")
    >>> written.mtllib, lib
    ((), None)
    """
    name = library or os.path.splitext(os.path.basename(os.fspath(output_path)))[0] + ".mtl"
    if mesh.materials:
        return with_library(mesh, name), output_library(
            mesh.materials, source_path, mesh.mtllib, output_path, {})
    if mesh.texture and mesh.face_uvs is not None:
        folder = os.path.dirname(os.path.abspath(os.fspath(source_path)))
        image = os.path.join(folder, mesh.texture)
        return (with_library(mesh, name, np.zeros(mesh.n_faces, np.int64),
                             (TEXTURE_MATERIAL,)),
                output_library([TEXTURE_MATERIAL], source_path, (), output_path,
                               {TEXTURE_MATERIAL: image}))
    return with_library(mesh, None), None
