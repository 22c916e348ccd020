"""The images a UV layout is baked into: one per used UDIM tile, more where materials overlap.

A layout that uses tile 1001 only is written as one image ``OUT.png``; any other
layout as one image per used tile, ``OUT.1001.png``, ``OUT.1002.png``, ... (the
Mari/UDIM convention).  Materials whose UVs overlap inside one tile (ICT-FaceKit's
eyeballs, eye blend and occlusion share the face's tile, each with a texture of its
own) cannot share an image: each such group gets ``OUT.<material>.<tile>.png``.
:func:`bake_tiles` bakes every image (:func:`facewrap.texture.bake.bake_texture` per
texture set) with the trees built once.
"""

from __future__ import annotations

import functools
import os
import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facewrap.errors import InputError
from facewrap.geometry import ClosestPointTree
from facewrap.io.dispatch import read_mesh
from facewrap.io.files import read_file_head
from facewrap.io.images import load_image
from facewrap.io.mtl import read_libraries
from facewrap.mesh import Mesh
from facewrap.progress import progress
from facewrap.texture.bake import bake_texture, rasterize_uv, scan_visibility
from facewrap.texture.udim import (FIRST_TILE, triangle_materials, triangle_tiles,
                                   used_tiles)

__all__ = ["PROBE_SIZE", "BAKED_MATERIAL", "TextureSet", "texture_sets", "tile_image_paths",
           "file_layout", "TiledBake", "bake_memory", "bake_tiles", "material_images",
           "file_textures"]

#: Resolution at which :func:`texture_sets` looks for overlapping materials (the
#: split must not depend on the output size, so outputs can be named before baking).
PROBE_SIZE = 256


@dataclass(frozen=True)
class TextureSet:
    """Triangles baked into one image: one tile, one or more materials.

    Attributes
    ----------
    tile : int
        UDIM tile.
    materials : tuple of int
        Material ids (into ``mesh.materials``; -1 for faces without one) whose
        triangles of this tile the image holds.
    label : str or None
        None for the tile's main image; otherwise the name of the largest material
        in it, for an image of materials whose UVs overlap the main one's (ICT's
        eyes share the face's tile, each with a texture of its own).
    """

    tile: int
    materials: tuple
    label: str | None = None


def texture_sets(mesh: Mesh, overlap: float = 0.02) -> tuple[TextureSet, ...]:
    """Split a mesh's UV layout into images: one per used tile, more where materials
    overlap.

    Within a tile, materials are taken largest first (by laid-out texels at
    :data:`PROBE_SIZE`); each joins the first image of the tile whose texels it
    overlaps by at most ``overlap`` of its own, or starts an image of its own.  A
    layout whose materials do not overlap gives one image per tile.

    Parameters
    ----------
    mesh : Mesh
        With texture coordinates.
    overlap : float
        Share of a material's texels that may fall on an image's texels (shared
        edges, rounding) and still join it.

    Returns
    -------
    tuple of TextureSet
        By tile, the tile's main image first.
    """
    mat = triangle_materials(mesh)
    tiles = triangle_tiles(mesh)
    sets = []
    for tile in used_tiles(mesh):
        masks = {}
        for m in np.unique(mat[tiles == tile]).tolist():
            masks[m] = rasterize_uv(mesh, PROBE_SIZE, tile, only=mat == m).mask
        order = sorted(masks, key=lambda m: (-int(masks[m].sum()), m))
        groups: list[tuple[list, np.ndarray]] = []
        for m in order:
            own = max(int(masks[m].sum()), 1)
            for members, union in groups:
                if (masks[m] & union).sum() <= overlap * own:
                    members.append(m)
                    union |= masks[m]
                    break
            else:
                groups.append(([m], masks[m].copy()))
        for k, (members, _) in enumerate(groups):
            label = None if k == 0 else _label(mesh, members[0])
            sets.append(TextureSet(int(tile), tuple(sorted(members)), label))
    return tuple(sets)


def _label(mesh: Mesh, material: int) -> str:
    """A file-name-safe name for an image of ``material``."""
    name = mesh.materials[material] if material >= 0 else "nomaterial"
    return re.sub(r"[^A-Za-z0-9_-]+", "_", name) or "material"


def tile_image_paths(output, sets) -> dict[TextureSet, str]:
    """Image file of each texture set of a layout, named after the mesh ``output``.

    ``OUT.png`` when the layout is one image of tile 1001 (as before UDIM),
    otherwise ``OUT.<tile>.png`` for the main image of every tile (the Mari/UDIM
    convention) and ``OUT.<label>.<tile>.png`` for images of overlapping materials.

    Parameters
    ----------
    output : path
        The mesh the texture belongs to; its extension is replaced.
    sets : sequence of TextureSet, or of int (tiles)

    Returns
    -------
    dict of TextureSet to str
        In the order of ``sets``.

    Examples
    --------
    >>> tile_image_paths("out/head.obj", [1001])
    {TextureSet(tile=1001, materials=(), label=None): 'out/head.png'}
    >>> list(tile_image_paths("head.obj", [1001, 1002]).values())
    ['head.1001.png', 'head.1002.png']
    """
    sets = [s if isinstance(s, TextureSet) else TextureSet(int(s), ()) for s in sets]
    base = str(Path(os.fspath(output)).with_suffix(""))
    if len(sets) == 1 and sets[0].tile == FIRST_TILE:
        return {sets[0]: base + ".png"}
    return {s: (f"{base}.{s.tile}.png" if s.label is None
                else f"{base}.{s.label}.{s.tile}.png") for s in sets}


@functools.lru_cache(maxsize=2)
def _mesh_of(path: str, stamp: tuple) -> Mesh:
    return read_mesh(path)


@functools.lru_cache(maxsize=8)
def _sets_of(path: str, stamp: tuple) -> tuple:
    mesh = _mesh_of(path, stamp)
    return texture_sets(mesh) if mesh.triangle_uvs is not None else ()


def file_layout(path, sets: bool = True) -> tuple[tuple[TextureSet, ...], tuple[str, ...]]:
    """Texture sets and material names of a mesh file, read once per version.

    What a job needs to name its outputs before any work (one image per texture
    set, a material library when there are materials); cached on the file's path,
    size and modification time, so checking and running a job read the template
    once for this.

    Parameters
    ----------
    path : path
        A mesh file :func:`facewrap.io.read_mesh` reads.
    sets : bool
        False: leave the texture sets out (empty), when only the materials matter.

    Returns
    -------
    (sets, materials)
        :func:`texture_sets` of the mesh (empty without UVs), and its material names
        (``mesh.materials``).

    Raises
    ------
    InputError
        When the file cannot be read.
    """
    real = os.path.realpath(os.fspath(path))
    try:
        st = os.stat(real)
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path) from None
    stamp = (st.st_size, st.st_mtime_ns)
    return (_sets_of(real, stamp) if sets else ()), _mesh_of(real, stamp).materials


@dataclass(frozen=True, eq=False)
class TiledBake:
    """A texture baked one image per texture set (:func:`bake_tiles`).

    Attributes
    ----------
    images : dict of TextureSet to BakeResult
        In the order of :func:`texture_sets`.
    seconds : dict of TextureSet to float
        Time spent baking each image.
    """

    images: dict
    seconds: dict

    @property
    def filled_fraction(self) -> float:
        """Covered over laid-out texels, summed over all images (0.0 when empty)."""
        laid = sum(int(r.layout.sum()) for r in self.images.values())
        covered = sum(int(r.coverage.sum()) for r in self.images.values())
        return covered / laid if laid else 0.0


# Peak memory of a texture bake: the image and its masks, the padding's distance
# transform and the PNG's encoding grow with the texels (48 bytes each, measured
# from the peaks of whole wraps of ICT's face region at 2048 and 4096); the texels
# in flight do not (the bake goes band by band: ~250 MB at any size).
BAKE_BYTES_PER_TEXEL = 64
BAKE_BAND_BYTES = 300 * 2 ** 20


def bake_memory(texture_size: int) -> int:
    """Bytes a bake of one ``texture_size`` square image may need at its peak.

    Examples
    --------
    >>> round(bake_memory(8192) / 2 ** 30, 1)
    4.3
    """
    return texture_size ** 2 * BAKE_BYTES_PER_TEXEL + BAKE_BAND_BYTES


def bake_tiles(template: Mesh, scan: Mesh, scan_image, size=1024, padding: int = 8,
               tree=None, max_distance: float | None = None,
               sets=None) -> TiledBake:
    """Bake a scan's texture into every image of a template's layout.

    One image per texture set (:func:`texture_sets`: per used tile, more where
    materials overlap), each baked as :func:`~facewrap.texture.bake.bake_texture`
    does from that set's triangles only; a 0–1 layout gives the one tile 1001.  The
    trees of the scan and of the template are built once for all images.

    Parameters
    ----------
    template, scan, scan_image, size, padding, tree, max_distance
        As for :func:`~facewrap.texture.bake.bake_texture`; ``size`` is the size of
        every image.
    sets : sequence of TextureSet, optional
        Default ``texture_sets(template)``.

    Returns
    -------
    TiledBake
        Per image its :class:`~facewrap.texture.bake.BakeResult` and the seconds it
        took; the overall coverage over the laid-out texels of all images.

    Examples
    --------
    >>> quads = Mesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.]], [[0, 1, 2, 3]] * 2,
    ...              uvs=[[0, 0], [1, 0], [1, 1], [0, 1.], [1, 0], [2, 0], [2, 1],
    ...                   [1, 1]], face_uvs=[[0, 1, 2, 3], [4, 5, 6, 7]])
    >>> baked = bake_tiles(quads, quads, np.zeros((4, 4, 3), np.uint8), size=4)
    >>> [s.tile for s in baked.images], baked.filled_fraction
    ([1001, 1002], 1.0)
    """
    if not isinstance(template, Mesh) or template.triangle_uvs is None:
        raise ValueError("template must be a facewrap Mesh with texture coordinates")
    sets = texture_sets(template) if sets is None else tuple(sets)
    if not isinstance(scan, Mesh):
        raise ValueError(f"scan must be a facewrap Mesh, got {type(scan).__name__}")
    if tree is None:
        tree = ClosestPointTree(scan.vertices, scan.triangles)
    elif not isinstance(tree, ClosestPointTree):
        raise ValueError(f"tree must be a ClosestPointTree, got {type(tree).__name__}")
    visibility = scan_visibility(template, tree)
    materials, tiles = triangle_materials(template), triangle_tiles(template)
    images, seconds = {}, {}
    with progress(len(sets), "baking the texture") as bar:   # on a terminal only
        for s in sets:
            t = time.perf_counter()
            only = (tiles == s.tile) & np.isin(materials, s.materials)
            images[s] = bake_texture(template, scan, scan_image, size, padding, tree,
                                     max_distance, tile=s.tile, only=only,
                                     visibility=visibility, advance=bar.advance)
            seconds[s] = time.perf_counter() - t
    return TiledBake(images=images, seconds=seconds)


#: Material given to baked faces that have none (one per tile, suffixed with the
#: tile, when such faces lie in several tiles).
BAKED_MATERIAL = "facewrap_texture"


def material_images(mesh: Mesh, paths: dict) -> tuple[np.ndarray | None, tuple, dict]:
    """Which baked image each material shows, giving baked faces without one a material.

    Parameters
    ----------
    mesh : Mesh
        With texture coordinates.
    paths : dict of TextureSet to path
        The images (:func:`tile_image_paths`).

    Returns
    -------
    face_materials : (m,) int64 or None
        Material per face (None when the mesh has none and nothing is baked).
    materials : tuple of str
        The mesh's materials, then :data:`BAKED_MATERIAL` (``..._<tile>``) for baked
        faces that had none.
    images : dict of str to path
        Material name → the image holding most of its triangles (a material of
        several tiles, such as ICT's lacrimal fluid, shows one; OBJ materials have
        one ``map_Kd``).
    """
    mat = triangle_materials(mesh)
    tiles = (triangle_tiles(mesh) if mesh.triangle_uvs is not None
             else np.full(len(mat), -1, dtype=np.int64))
    materials = list(mesh.materials)
    face_mat = (np.full(mesh.n_faces, -1, dtype=np.int64) if mesh.face_materials is None
                else np.array(mesh.face_materials, dtype=np.int64))
    bare = list({s.tile: s for s in reversed(list(paths)) if -1 in s.materials}.values())
    bare.reverse()                        # faces without a material: by tile, first set
    first = np.full(mesh.n_faces, -1, dtype=np.int64)     # a face's first triangle
    first[mesh.triangle_faces[::-1]] = np.arange(len(mat))[::-1]
    face_tile = np.where(first >= 0, tiles[np.maximum(first, 0)], -1)
    names = {}
    for s in bare:
        name = BAKED_MATERIAL if len(bare) == 1 else f"{BAKED_MATERIAL}_{s.tile}"
        names[name] = s
        face_mat[(face_mat == -1) & (face_tile == s.tile)] = len(materials)
        materials.append(name)
    images = {name: paths[s] for name, s in names.items()}
    for m, name in enumerate(mesh.materials):
        held = [(int(np.sum((mat == m) & (tiles == s.tile))), -k, s)
                for k, s in enumerate(paths) if m in s.materials]
        if held:
            images[name] = paths[max(held, key=lambda h: h[:2])[2]]
    if mesh.face_materials is None and not bare:
        return None, (), images
    return face_mat, tuple(materials), images


_TEXTURE_FILE = re.compile(rb"^comment\s+TextureFile\s+(\S.*?)\s*$", re.M)


def file_textures(path, mesh: Mesh) -> dict:
    """The base-colour image of each UDIM tile of a mesh file, where it can be told.

    An OBJ: per tile, the ``map_Kd`` image of the material that holds most of the
    tile's triangles (of those with one).  A PLY: its one ``TextureFile`` for tile
    1001; none when it names several, since which face shows which image is not
    read.  Images that are missing or unreadable are left out.

    Parameters
    ----------
    path : path
        The file ``mesh`` was read from.
    mesh : Mesh

    Returns
    -------
    dict of int to (H, W, 3) uint8
    """
    if mesh.triangle_uvs is None:
        return {}
    folder = os.path.dirname(os.path.abspath(os.fspath(path)))
    files: dict[int, str] = {}
    if os.fspath(path).lower().endswith(".ply"):
        named = _TEXTURE_FILE.findall(read_file_head(path, 1 << 16))
        if len(named) == 1:
            files[FIRST_TILE] = os.path.join(folder, named[0].decode("utf-8", "replace"))
    else:
        maps = {name: [s.split()[-1] for s in lines if s.split()[0].lower() == "map_kd"]
                for name, lines in read_libraries(path, mesh.mtllib).items()}
        mat, tiles = triangle_materials(mesh), triangle_tiles(mesh)
        for tile in used_tiles(mesh):
            counts = [(int(np.sum((tiles == tile) & (mat == m))), m)
                      for m, name in enumerate(mesh.materials) if maps.get(name)]
            if counts and max(counts)[0] > 0:
                files[tile] = maps[mesh.materials[max(counts)[1]]][0]
    out = {}
    for tile, file in files.items():
        try:
            out[tile] = load_image(file)
        except InputError:
            continue
    return out
