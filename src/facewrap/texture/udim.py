"""UDIM tiles: which UV tile each triangle lies in, and the image file of each tile.

Studios lay a head's textures out over several unit squares of UV space ("tiles"),
numbered the Mari/UDIM way: the tile ``[i, i + 1) x [j, j + 1)`` is
``1001 + i + 10 j`` for ``0 <= i < 10`` and ``j >= 0`` (1001 is the usual 0–1
square, 1002 the one to its right, 1011 the one above it).  A triangle belongs to
the tile of its UV centroid; the parts of it that cross into a neighbour are
clipped away when its tile is baked.

Which images a layout is baked into, and their file names, is
:mod:`facewrap.texture.tiles`.
"""

from __future__ import annotations

import numpy as np

from facewrap.mesh import Mesh

__all__ = ["FIRST_TILE", "MAX_TILE_ROWS", "triangle_tiles", "used_tiles", "tile_origin",
           "triangle_materials"]

#: The tile of the unit square [0, 1) x [0, 1).
FIRST_TILE = 1001
#: Tile rows (v = 0 ... MAX_TILE_ROWS) a layout may use; UDIM has ten tiles a row.
MAX_TILE_ROWS = 100


def triangle_tiles(mesh: Mesh) -> np.ndarray:
    """UDIM tile of every triangle's UV centroid.

    Parameters
    ----------
    mesh : Mesh
        With texture coordinates (``mesh.triangle_uvs`` is not None).

    Returns
    -------
    (t,) int64
        ``1001 + floor(u) + 10 floor(v)`` of the centroid of each triangle of
        ``mesh.triangles``; -1 where the centroid lies outside the UDIM range
        (``u < 0``, ``u >= 10``, ``v < 0`` or ``v >= 100``), which no tile holds.

    Examples
    --------
    >>> m = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2], [0, 2, 1]],
    ...          uvs=[[0.1, 0.1], [0.2, 0.1], [0.1, 0.2], [1.5, 0.5], [1.6, 0.5],
    ...               [1.5, 1.4]], face_uvs=[[0, 1, 2], [3, 4, 5]])
    >>> triangle_tiles(m).tolist()
    [1001, 1002]
    """
    if mesh.triangle_uvs is None:
        raise ValueError("mesh has no texture coordinates")
    centroid = mesh.uvs[mesh.triangle_uvs].mean(axis=1)            # (t, 2)
    with np.errstate(invalid="ignore"):
        cell = np.floor(centroid)
    ok = ((cell[:, 0] >= 0) & (cell[:, 0] < 10) & (cell[:, 1] >= 0)
          & (cell[:, 1] < MAX_TILE_ROWS))
    tiles = np.full(len(centroid), -1, dtype=np.int64)
    tiles[ok] = FIRST_TILE + cell[ok, 0].astype(np.int64) + 10 * cell[ok, 1].astype(np.int64)
    return tiles


def used_tiles(mesh: Mesh) -> tuple[int, ...]:
    """The tiles that hold at least one triangle, ascending (empty without UVs).

    Examples
    --------
    >>> quad = Mesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.]], [[0, 1, 2, 3]],
    ...             uvs=[[0, 0], [1, 0], [1, 1], [0, 1.]], face_uvs=[[0, 1, 2, 3]])
    >>> used_tiles(quad)
    (1001,)
    """
    if mesh.triangle_uvs is None:
        return ()
    tiles = np.unique(triangle_tiles(mesh))
    return tuple(int(t) for t in tiles if t >= 0)


def tile_origin(tile: int) -> tuple[int, int]:
    """``(u0, v0)``: the lower-left corner of a tile in UV space.

    Examples
    --------
    >>> tile_origin(1001), tile_origin(1007), tile_origin(1012)
    ((0, 0), (6, 0), (1, 1))
    """
    k = int(tile) - FIRST_TILE
    if not 0 <= k < 10 * MAX_TILE_ROWS:
        raise ValueError(f"tile must lie in [{FIRST_TILE}, "
                         f"{FIRST_TILE + 10 * MAX_TILE_ROWS}), got {tile!r}")
    return k % 10, k // 10


def triangle_materials(mesh: Mesh) -> np.ndarray:
    """(t,) int64 material id of every triangle, -1 where its face has none."""
    if mesh.face_materials is None:
        return np.full(len(mesh.triangles), -1, dtype=np.int64)
    return np.asarray(mesh.face_materials)[mesh.triangle_faces]
