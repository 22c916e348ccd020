"""In-between frames for meshes in one topology (SPEC §1.5).

Every fitted mesh shares the template's topology, so the frames between a neutral
``S_0`` and an expression ``S_N`` are plain linear interpolation of vertex positions,
``S_k = S_0 + (k / N)(S_N - S_0)``, and likewise for textures.
:func:`write_obj_sequence` writes the frames as OBJ files in the template's exact
topology (faces, UVs, groups, materials), each with its own texture when given.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np

from facewrap.io.atomic import atomic_write
from facewrap.io.files import memory_budget
from facewrap.io.obj import write_obj
from facewrap.io.paths import staged_outputs
from facewrap.geometry.checks import as_positions
from facewrap.mesh import Mesh
from facewrap.texture import interpolate_images, save_png

__all__ = ["interpolate_vertices", "interpolate_textures", "write_obj_sequence",
           "obj_sequence_files", "check_sequence_budget", "MAX_FRAMES"]

# More frames than this is a slip of the keyboard (1e9), not an animation: every
# frame is one file and all of them are held in memory before the first is written.
MAX_FRAMES = 100_000

# Material given to every face when textured frames are written for a mesh that has
# no per-face materials.
FRAME_MATERIAL = "facewrap_texture"


def _frame_count(frames) -> int:
    if (isinstance(frames, (bool, np.bool_)) or not isinstance(frames, (int, np.integer))
            or not 2 <= frames <= MAX_FRAMES):
        raise ValueError(f"frames must be an int in [2, {MAX_FRAMES}] (both ends are "
                         f"included), got {frames!r}")
    return int(frames)


def _gib(n: float) -> str:
    return f"{n / 2 ** 30:.1f} GiB"


def _free_disk(folder) -> int | None:
    """Free bytes where ``folder`` would be created (None when unknown)."""
    here = os.path.abspath(os.fspath(folder))
    while not os.path.isdir(here) and os.path.dirname(here) != here:
        here = os.path.dirname(here)
    try:
        return shutil.disk_usage(here).free
    except OSError:
        return None


def check_sequence_budget(folder, frames: int, n_vertices: int, frame_bytes: int,
                          image_shape=None, memory_limit: int | None = None) -> None:
    """Refuse a sequence that cannot be held in memory or written to disk.

    Checked before any work: :func:`interpolate_vertices` and
    :func:`interpolate_textures` hold every frame at once (8 bytes per coordinate,
    1 per texel), and :func:`write_obj_sequence` writes one OBJ (and image) each.

    Parameters
    ----------
    folder : path
        Where the frames go (free space is looked up on its nearest existing folder).
    frames : int
    n_vertices : int
    frame_bytes : int
        Estimated size of one frame's OBJ file.
    image_shape : tuple, optional
        ``(H, W, C)`` of the textures, when frames are textured (a PNG is counted at
        its raw size: an upper bound).
    memory_limit : int, optional
        Bytes; default half the machine's memory.

    Raises
    ------
    ValueError
        Saying what is needed and what is available.

    Examples
    --------
    >>> check_sequence_budget(".", 10, 100, 5000)
    >>> check_sequence_budget(".", 10, 10 ** 6, 5000, memory_limit=2 ** 28)
    Traceback (most recent call last):
    ValueError: 10 frames of 1000000 vertices need about 0.4 GiB of memory, more than the 0.2 GiB allowed
    """
    frames = _frame_count(frames)
    texels = int(np.prod(image_shape)) if image_shape is not None else 0
    memory = frames * (2 * n_vertices * 3 * 8 + texels)   # frames + one temporary
    limit = memory_budget() if memory_limit is None else memory_limit
    if memory > limit:
        raise ValueError(f"{frames} frames of {n_vertices} vertices need about "
                         f"{_gib(memory)} of memory, more than the {_gib(limit)} allowed")
    disk, free = frames * (frame_bytes + texels), _free_disk(folder)
    if free is not None and disk > free:
        raise ValueError(f"{frames} frames need about {_gib(disk)} of disk, and "
                         f"{folder} has {_gib(free)} free")


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
    start, end = as_positions(start, "start"), as_positions(end, "end")
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
    for name in _frame_names(pattern, _frame_count(frames)):
        path = Path(folder) / name
        out += [path] + ([path.with_suffix(".png"), path.with_suffix(".mtl")]
                         if textures else [])
    return out
