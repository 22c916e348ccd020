"""In-between frames for meshes in one topology (SPEC §1.5).

Every fitted mesh shares the template's topology, so the frames between a neutral
``S_0`` and an expression ``S_N`` are plain linear interpolation of vertex positions,
``S_k = S_0 + (k / N)(S_N - S_0)``, and likewise for textures.
:func:`write_obj_sequence` writes the frames as OBJ files in the template's exact
topology (faces, UVs, groups, materials), each with its own texture when given.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from facewrap.io.atomic import atomic_write
from facewrap.io.obj import write_obj
from facewrap.io.paths import staged_outputs
from facewrap.geometry.checks import as_points
from facewrap.mesh import Mesh
from facewrap.texture import interpolate_images, save_png

__all__ = ["interpolate_vertices", "interpolate_textures", "write_obj_sequence",
           "obj_sequence_files"]

# Material given to every face when textured frames are written for a mesh that has
# no per-face materials.
FRAME_MATERIAL = "facewrap_texture"


def _frame_count(frames) -> int:
    if (isinstance(frames, (bool, np.bool_))
            or not isinstance(frames, (int, np.integer)) or frames < 2):
        raise ValueError(f"frames must be an int >= 2 (both ends are included), "
                         f"got {frames!r}")
    return int(frames)


def interpolate_vertices(start, end, frames: int) -> np.ndarray:
    """Linear in-betweens from one shape to another, both ends included.

    ``S_k = S_0 + (k / (frames - 1)) (S_N - S_0)`` for ``k = 0 .. frames - 1``
    (SPEC §1.5 with ``N = frames - 1``): frame 0 is ``start`` and the last frame is
    ``end``, both exactly.

    Parameters
    ----------
    start, end : (n, 3) float
        Vertex positions of the same mesh topology.
    frames : int
        Number of frames, >= 2.

    Returns
    -------
    (frames, n, 3) float64

    Examples
    --------
    >>> S = interpolate_vertices([[0, 0, 0.]], [[1, 2, 4.]], 5)
    >>> S.shape, S[:, 0, 2].tolist()
    ((5, 1, 3), [0.0, 1.0, 2.0, 3.0, 4.0])
    """
    start, end = as_points(start, "start"), as_points(end, "end")
    if start.shape != end.shape:
        raise ValueError(f"start and end must have the same shape, got {start.shape} "
                         f"and {end.shape}")
    frames = _frame_count(frames)
    t = np.arange(frames, dtype=np.float64) / (frames - 1)
    out = start + t[:, None, None] * (end - start)
    out[-1] = end          # exact, whatever the rounding of start + (end - start)
    return out


def interpolate_textures(a, b, frames: int) -> np.ndarray:
    """Linear in-betweens of two texture images, both ends included.

    Frame ``k`` is :func:`~facewrap.texture.bake.interpolate_images` ``(a, b, k / (frames
    - 1))``.

    Parameters
    ----------
    a, b : (H, W) or (H, W, C) uint8
        Same shape.
    frames : int
        Number of frames, >= 2.

    Returns
    -------
    (frames, H, W[, C]) uint8
        ``frames`` full images: mind the memory for long sequences of large textures.

    Examples
    --------
    >>> a, b = np.zeros((1, 1, 3), np.uint8), np.full((1, 1, 3), 90, np.uint8)
    >>> interpolate_textures(a, b, 4)[:, 0, 0, 0].tolist()
    [0, 30, 60, 90]
    """
    frames = _frame_count(frames)
    return np.stack([interpolate_images(a, b, k / (frames - 1)) for k in range(frames)])


def _frame_names(pattern: str, frames: int) -> list[str]:
    try:
        names = [pattern.format(k) for k in range(frames)]
    except (IndexError, KeyError, ValueError) as exc:
        raise ValueError(f"pattern {pattern!r} must format one frame number, as in "
                         f"'frame_{{:04d}}.obj' ({type(exc).__name__}: {exc})") from None
    if len(set(names)) != frames:
        raise ValueError(f"pattern {pattern!r} gives the same file name to different "
                         "frames; it needs a field for the frame number")
    if not all(n.lower().endswith(".obj") for n in names):
        raise ValueError(f"pattern {pattern!r} must name .obj files")
    return names


def _textured_mesh(mesh: Mesh, vertices: np.ndarray, mtl_name: str) -> Mesh:
    """``mesh`` with new vertices, referring to one material library only."""
    offsets = mesh.face_offsets
    if mesh.face_materials is None:
        face_materials, materials = np.zeros(mesh.n_faces, np.int64), (FRAME_MATERIAL,)
    else:
        face_materials, materials = mesh.face_materials, mesh.materials
    return Mesh(vertices, (offsets, mesh.face_indices),
                uvs=mesh.uvs, face_uvs=(offsets, mesh.face_uvs),
                face_materials=face_materials, materials=materials,
                face_groups=mesh.face_groups, groups=mesh.groups,
                mtllib=[mtl_name], vertex_colors=mesh.vertex_colors)


def _mtl_text(materials, png_name: str) -> str:
    block = ("newmtl {}\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\n"
             "map_Kd " + png_name + "\n")
    return "# written by facewrap\n" + "\n".join(block.format(m) for m in materials)


def write_obj_sequence(folder, mesh: Mesh, vertex_frames,
                       pattern: str = "frame_{:04d}.obj", textures=None) -> list[Path]:
    """Write one OBJ per frame, in the mesh's exact topology.

    Frame ``k`` is ``mesh.with_vertices(vertex_frames[k])`` written to
    ``folder / pattern.format(k)``: faces, UVs, groups and materials as in ``mesh``
    (its ``mtllib`` references are kept as they are); stored normals are dropped, as
    they belong to the mesh's own shape.  With ``textures``, frame ``k`` also gets
    ``<name>.png`` (``textures[k]``) and ``<name>.mtl``, whose materials (those of
    ``mesh``, or one material ``facewrap_texture`` on all faces when the mesh has
    none) all use that PNG as ``map_Kd``; the OBJ then refers to that ``.mtl`` only.
    The files are staged and moved into ``folder`` together (a failure leaves none).

    Parameters
    ----------
    folder : str or os.PathLike
        Created when missing.
    mesh : Mesh
        The topology (typically the fitted template).
    vertex_frames : (f, n, 3) float
        Positions per frame, e.g. from :func:`interpolate_vertices`.
    pattern : str
        File name of frame ``k`` as ``pattern.format(k)``; must end in ``.obj`` and
        differ between frames.
    textures : sequence of f images, optional
        ``(H, W, 3|4)`` uint8 per frame, e.g. from :func:`interpolate_textures`;
        requires ``mesh`` to have UVs.

    Returns
    -------
    list of pathlib.Path
        The OBJ files, in frame order.

    Examples
    --------
    >>> import tempfile
    >>> from facewrap.io.obj import read_obj
    >>> tri = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]])
    >>> frames = interpolate_vertices(tri.vertices, tri.vertices * 3, 3)
    >>> paths = write_obj_sequence(tempfile.mkdtemp(), tri, frames)
    >>> [p.name for p in paths], read_obj(paths[1]).vertices[1].tolist()
    (['frame_0000.obj', 'frame_0001.obj', 'frame_0002.obj'], [2.0, 0.0, 0.0])
    """
    if not isinstance(mesh, Mesh):
        raise ValueError(f"mesh must be a facewrap Mesh, got {type(mesh).__name__}")
    frames = np.asarray(vertex_frames, dtype=np.float64)
    if frames.ndim != 3 or frames.shape[1:] != mesh.vertices.shape:
        raise ValueError(f"vertex_frames must have shape (f, {mesh.n_vertices}, 3), "
                         f"got {frames.shape}")
    if not np.all(np.isfinite(frames)):
        raise ValueError("vertex_frames must be finite (found NaN or inf)")
    names = _frame_names(pattern, len(frames))
    if textures is not None:
        if len(textures) != len(frames):
            raise ValueError(f"textures must hold one image per frame ({len(frames)}), "
                             f"got {len(textures)}")
        if mesh.uvs is None or mesh.face_uvs is None:
            raise ValueError("textures need a mesh with texture coordinates")
    final = Path(folder)
    with staged_outputs() as stage:   # all frames appear together, or none
        staged = stage.folder(final)
        for k, name in enumerate(names):   # one iteration per file written
            path = staged / name
            if textures is None:
                write_obj(path, mesh.with_vertices(frames[k]))
            else:
                png, mtl = path.with_suffix(".png"), path.with_suffix(".mtl")
                framed = _textured_mesh(mesh, frames[k], mtl.name)
                save_png(png, textures[k])
                with atomic_write(mtl, "w", encoding="utf-8", newline="\n") as fh:
                    fh.write(_mtl_text(framed.materials, png.name))
                write_obj(path, framed)
    return [final / name for name in names]


def obj_sequence_files(folder, frames: int, pattern: str = "frame_{:04d}.obj",
                       textures: bool = False) -> list[Path]:
    """Every file :func:`write_obj_sequence` writes for ``frames`` frames.

    Known before any work, so a command can check them against its inputs.

    Examples
    --------
    >>> [p.name for p in obj_sequence_files("out", 2, textures=True)][:3]
    ['frame_0000.obj', 'frame_0000.png', 'frame_0000.mtl']
    """
    out = []
    for name in _frame_names(pattern, frames):
        path = Path(folder) / name
        out += [path] + ([path.with_suffix(".png"), path.with_suffix(".mtl")]
                         if textures else [])
    return out
