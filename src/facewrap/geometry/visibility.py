"""Which vertices of a mesh a camera outside it can see.

A vertex is *seen from direction d* when it faces ``d`` (its normal within about
84 degrees of it) and the line that comes from far away along ``-d`` meets the
surface first at the vertex itself: nothing of the mesh lies in front of it.
Counting the directions, out of a fixed set spread evenly over the sphere, from
which each vertex is seen tells the surface a scanner records (cheeks, nose, the
back of the head) from the surface none can (nostril interiors, the inner lips,
the mouth socket, the skin behind the eyeballs).

Lines are cast with Embree through libigl (``igl.embree.line_mesh_intersection``),
in float32 like every Embree query: a hit counts as the vertex itself when it lies
within ``1e-4`` of the mesh's size of it.  The directions are a Fibonacci sphere, so
the answer is the same on every run.
"""

from __future__ import annotations

import numpy as np

from facewrap.geometry.checks import as_mesh_arrays, as_points
from facewrap.geometry.normals import vertex_normals

__all__ = ["sphere_directions", "outside_views"]

_HIT_TOLERANCE = 1e-4      # of the bounding-box diagonal: a hit at the vertex itself
_FACING_COS = 0.1          # a vertex faces a direction within ~84 degrees of its normal
_RAYS_PER_CALL = 1 << 20   # bounds the memory of one batch of lines


def sphere_directions(k: int) -> np.ndarray:
    """``k`` unit vectors spread evenly over the sphere (a Fibonacci sphere).

    Parameters
    ----------
    k : int
        At least 1.

    Returns
    -------
    (k, 3) float64

    Examples
    --------
    >>> D = sphere_directions(64)
    >>> D.shape, bool(np.allclose(np.linalg.norm(D, axis=1), 1.0))
    ((64, 3), True)
    >>> bool(np.linalg.norm(D.mean(axis=0)) < 0.02)   # no side favoured
    True
    """
    if int(k) < 1:
        raise ValueError(f"k must be at least 1, got {k}")
    i = np.arange(int(k)) + 0.5
    polar = np.arccos(1.0 - 2.0 * i / k)
    azimuth = np.pi * (1.0 + 5.0 ** 0.5) * i
    return np.column_stack([np.cos(azimuth) * np.sin(polar),
                            np.sin(azimuth) * np.sin(polar), np.cos(polar)])


def _sightings(V, T, N, vertices, directions, scale) -> np.ndarray:
    """How many of ``directions`` each of ``vertices`` is seen from."""
    from igl.embree import line_mesh_intersection   # a compiled extension: load on use

    facing = (N[vertices] @ directions.T) > _FACING_COS
    rows, cols = np.nonzero(facing)
    counts = np.zeros(len(vertices), dtype=np.int64)
    far = 2.0 * scale        # origins beyond the bounding sphere: only -d can hit
    for start in range(0, len(rows), _RAYS_PER_CALL):
        r = rows[start:start + _RAYS_PER_CALL]
        d = directions[cols[start:start + _RAYS_PER_CALL]]
        X = V[vertices[r]]
        hits = line_mesh_intersection(X + far * d, np.ascontiguousarray(-d), V, T)
        tri = hits[:, 0].astype(np.int64)
        hit = tri >= 0
        b1, b2 = hits[:, 1], hits[:, 2]
        corners = V[T[np.maximum(tri, 0)]]
        P = (corners[:, 0] * (1.0 - b1 - b2)[:, None] + corners[:, 1] * b1[:, None]
             + corners[:, 2] * b2[:, None])
        seen = hit & (np.linalg.norm(P - X, axis=1) <= _HIT_TOLERANCE * scale)
        counts += np.bincount(r[seen], minlength=len(vertices))
    return counts


def outside_views(V, T, *, vertices=None, occluders=None, normals=None,
                  needed: int = 2, directions: int = 64) -> np.ndarray:
    """Whether a camera outside the mesh sees each vertex, from ``needed`` directions.

    Parameters
    ----------
    V : (n, 3) float64
    T : (t, 3) int64
        Triangles, consistently oriented with normals pointing out.
    vertices : (m,) int, optional
        Vertices to test (default all); the others are reported as not seen.
    occluders : (t,) bool, optional
        Triangles that can hide a vertex (default all).  Thin shells laid over
        the skin (an eye's tear film, lashes) are best left out: a scanner sees
        the skin through them.
    normals : (n, 3) float64, optional
        Vertex normals; default area-weighted from ``T``.
    needed : int
        Directions a vertex must be seen from (2: one grazing line is not enough).
    directions : int
        Size of the direction set over the whole sphere.  A first pass with a
        quarter of them settles most vertices; only the others meet the full set.

    Returns
    -------
    seen : (n,) bool

    Examples
    --------
    A small square under a large one is hidden from every camera above; without
    the large one as an occluder it is seen (and the large one is not tested):

    >>> s = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)
    >>> V = np.vstack([np.c_[10 * s, np.ones(4)], np.c_[0.5 * s, np.zeros(4)]])
    >>> T = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])   # both face +z
    >>> outside_views(V, T).astype(int).tolist()
    [1, 1, 1, 1, 0, 0, 0, 0]
    >>> outside_views(V, T, vertices=[4, 5, 6, 7],
    ...               occluders=[False, False, True, True]).astype(int).tolist()
    [0, 0, 0, 0, 1, 1, 1, 1]
    """
    V, T = as_mesh_arrays(V, T)
    n = len(V)
    vertices = np.arange(n) if vertices is None else np.asarray(vertices, dtype=np.int64)
    N = vertex_normals(V, T) if normals is None else as_points(normals, "normals")
    if N.shape != V.shape:
        raise ValueError(f"normals must have shape {V.shape}, got {N.shape}")
    occluding = T if occluders is None else T[np.asarray(occluders, dtype=bool)]
    seen = np.zeros(n, dtype=bool)
    if len(vertices) == 0 or len(occluding) == 0:
        return seen
    scale = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0))) or 1.0
    counts = _sightings(V, occluding, N, vertices, sphere_directions(max(directions // 4, 1)),
                        scale)
    open_ = vertices[counts < needed]
    if len(open_):
        more = _sightings(V, occluding, N, open_, sphere_directions(directions), scale)
        counts[counts < needed] += more
    seen[vertices[counts >= needed]] = True
    return seen
