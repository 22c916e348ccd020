"""Triangle matching: which source triangles correspond to which target triangles.

Once one mesh lies on the other (:mod:`.marker_deformation`), each triangle is
paired with the nearest triangle of the other mesh by centroid whose normal is
within 90°, both ways; the union is the many-to-many correspondence (SPEC §3.2).

This is not :func:`facewrap.geometry.matching.closest_compatible_points`, on
purpose: the query and the candidates are both *triangles* (centroid to centroid
among the other mesh's triangle centroids, not to the closest surface point), the
compatibility is between two face normals, and a pair farther than the distance
bound is not even a candidate (the k-d tree's ``distance_upper_bound``), so the
nearest compatible triangle beyond a closer incompatible one is still found.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from facewrap.geometry import face_normals

__all__ = ["triangle_centroids_normals", "nearest_compatible_triangles",
           "match_triangles"]


def triangle_centroids_normals(V: np.ndarray, T: np.ndarray
                               ) -> tuple[np.ndarray, np.ndarray]:
    """Centroids (t, 3) and unit face normals (t, 3) of triangles ``T`` over ``V``.

    The two things triangle matching and the partner ambiguity compare.
    """
    return V[T].mean(axis=1), face_normals(V, T)


def nearest_compatible_triangles(query_c, query_n, tree: cKDTree, normals, k: int,
                                 max_distance: float) -> np.ndarray:
    """Index of the nearest compatible triangle per query (-1 when none).

    Parameters
    ----------
    query_c, query_n : (q, 3) float64
        Centroids and unit normals of the query triangles.
    tree : scipy.spatial.cKDTree
        Over the candidate triangles' centroids.
    normals : (c, 3) float64
        The candidates' unit normals.
    k : int
        Candidates examined per query, nearest first.
    max_distance : float
        Farthest centroid distance of a pair (``np.inf``: none).

    Returns
    -------
    (q,) int64
        The nearest candidate with a positive normal dot product, -1 when none
        of the ``k`` nearest within ``max_distance`` is.

    Notes
    -----
    The nearest triangle is compatible for almost every query, so only the others
    look further (``k`` candidates): a k-nearest query costs several times a
    nearest one.
    """
    k = min(k, tree.n)
    rows = np.arange(len(query_c))
    dist, idx = tree.query(query_c, k=1, distance_upper_bound=max_distance)
    found = np.isfinite(dist)
    safe = np.where(found, idx, 0)
    ok = found & (np.einsum("ij,ij->i", normals[safe], query_n) > 0)
    out = np.where(ok, safe, -1)
    retry = rows[found & ~ok] if k > 1 else rows[:0]
    if len(retry):
        dist, idx = tree.query(query_c[retry], k=k, distance_upper_bound=max_distance)
        dist, idx = dist.reshape(len(retry), k), idx.reshape(len(retry), k)
        found = np.isfinite(dist)
        safe = np.where(found, idx, 0)
        ok = found & (np.einsum("ikj,ij->ik", normals[safe], query_n[retry]) > 0)
        first = ok.argmax(axis=1)
        sub = np.arange(len(retry))
        out[retry] = np.where(ok[sub, first], safe[sub, first], -1)
    return out


def match_triangles(source_V, source_T, target_V, target_T, neighbours: int = 16,
                    max_distance: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """Match triangles by centroid distance and normals within 90°, both ways.

    Parameters
    ----------
    source_V : (n, 3) float64
        Source positions (deformed onto the target, or the target deformed onto it:
        the two meshes must lie on top of each other).
    source_T : (t, 3) int64
    target_V : (q, 3) float64
    target_T : (s, 3) int64
    neighbours : int
        Candidates examined per triangle, nearest first.
    max_distance : float
        Farthest centroid distance of a pair.

    Returns
    -------
    source_triangles, target_triangles : (k,) int64
        Sorted unique pairs: for every source triangle its nearest compatible
        target triangle, and for every target triangle its nearest compatible
        source triangle.
    """
    cs, ns = triangle_centroids_normals(np.asarray(source_V, float), np.asarray(source_T))
    ct, nt = triangle_centroids_normals(np.asarray(target_V, float), np.asarray(target_T))
    ts = nearest_compatible_triangles(cs, ns, cKDTree(ct), nt, neighbours, max_distance)
    st = nearest_compatible_triangles(ct, nt, cKDTree(cs), ns, neighbours, max_distance)
    a = np.flatnonzero(ts >= 0)
    b = np.flatnonzero(st >= 0)
    pairs = np.concatenate([np.stack([a, ts[a]], 1), np.stack([st[b], b], 1)])
    pairs = np.unique(pairs, axis=0) if len(pairs) else np.zeros((0, 2), np.int64)
    return pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
