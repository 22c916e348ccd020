"""Sampling points on surfaces and subsets of vertices.

This module owns random surface samples (area-weighted, reproducible from a seed)
and vertex subsets spread evenly over a shape: greedy farthest-point sampling and
Poisson-disk subsets, used to place deformation-graph nodes.
"""

from __future__ import annotations

import itertools

import numpy as np

from facewrap.geometry.checks import as_count, as_mesh_arrays, as_vertices
from facewrap.geometry.normals import trusted_face_areas

__all__ = ["sample_surface", "farthest_point_sampling", "poisson_disk_vertices"]

# candidates examined per round of poisson_disk_vertices
_BATCH = 1024


def sample_surface(V, T, count, seed=0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Uniform random points on a triangle mesh (area-weighted).

    Parameters
    ----------
    V : (n, 3) float64
    T : (t, 3) int64
        Must have non-zero total area.
    count : int
        Number of samples.
    seed : int or numpy.random.Generator
        Passed to :func:`numpy.random.default_rng`; the same seed gives the same
        samples.

    Returns
    -------
    points : (count, 3) float64
    triangles : (count,) int64
        Triangle of each sample (zero-area triangles are never chosen).
    barycentric : (count, 3) float64
        ``points[i] = barycentric[i] @ V[T[triangles[i]]]``.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.]])
    >>> T = np.array([[0, 1, 2], [1, 3, 2]])
    >>> P, tri, bary = sample_surface(V, T, 1000, seed=1)
    >>> P.shape, bool(np.all((P >= 0) & (P <= 1))), sorted(set(tri.tolist()))
    ((1000, 3), True, [0, 1])
    >>> np.allclose(P, np.einsum("kc,kcd->kd", bary, V[T[tri]]))
    True
    >>> np.array_equal(P, sample_surface(V, T, 1000, seed=1)[0])
    True
    """
    V, T = as_mesh_arrays(V, T)
    count = as_count(count, "count")
    areas = trusted_face_areas(V, T) if len(T) else np.zeros(0)
    cdf = np.cumsum(areas)
    if len(cdf) == 0 or not cdf[-1] > 0:
        raise ValueError("T must have non-zero total area to sample from")
    rng = np.random.default_rng(seed)
    # side="right" never lands on a zero-area triangle (empty cdf interval)
    triangles = np.searchsorted(cdf, rng.random(count) * cdf[-1], side="right")
    triangles = np.minimum(triangles, len(T) - 1).astype(np.int64)
    u, v = rng.random((2, count))
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    barycentric = np.stack([1.0 - u - v, u, v], axis=1)
    points = np.einsum("kc,kcd->kd", barycentric, V[T[triangles]])
    return points, triangles, barycentric


def farthest_point_sampling(V, count, start=0) -> np.ndarray:
    """Greedy farthest-point subset of vertices.

    Starting from ``start``, repeatedly adds the vertex farthest (Euclidean) from
    those chosen so far.  Each step is one vectorised pass over all vertices, so the
    cost is O(count * n): fine for a few thousand samples of 10k vertices.

    Parameters
    ----------
    V : (n, 3) float64
    count : int
        Number of vertices to pick, ``0 <= count <= n``.
    start : int
        First vertex.

    Returns
    -------
    indices : (count,) int64
        Distinct vertex indices in the order picked (``indices[0] == start``).
        Ties go to the lowest index; coincident vertices are picked only after all
        distinct positions.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [10, 0, 0], [5, 0, 0.]])
    >>> farthest_point_sampling(V, 3).tolist()
    [0, 2, 3]
    """
    V = as_vertices(V)
    count = as_count(count, "count")
    n = len(V)
    if count > n:
        raise ValueError(f"count must be at most the number of vertices ({n}), "
                         f"got {count}")
    if isinstance(start, (bool, np.bool_)) or not isinstance(start, (int, np.integer)) \
            or not 0 <= start < max(n, 1):
        raise ValueError(f"start must be a vertex index in [0, {n}), got {start!r}")
    indices = np.empty(count, dtype=np.int64)
    if count == 0:
        return indices
    Vt = np.ascontiguousarray(V.T)
    nearest = np.full(n, np.inf)
    current = int(start)
    for k in range(count):
        indices[k] = current
        d = (Vt[0] - Vt[0, current]) ** 2
        d += (Vt[1] - Vt[1, current]) ** 2
        d += (Vt[2] - Vt[2, current]) ** 2
        np.minimum(nearest, d, out=nearest)
        nearest[current] = -1.0       # never pick a vertex twice
        current = int(np.argmax(nearest))
    return indices


def poisson_disk_vertices(V, radius, seed=0) -> np.ndarray:
    """A random subset of vertices that is ``radius``-separated and ``radius``-dense.

    The greedy "dart throwing" subset: vertices are visited in a random order and
    kept when no kept vertex lies within ``radius``.  Done in batches of candidates
    (each resolved with a vectorised maximal-independent-set pass, giving exactly the
    sequential result) and one :meth:`scipy.spatial.cKDTree.query_ball_point` call
    per batch, so its cost grows with the batches, not with Python-level loops over
    vertices.

    Parameters
    ----------
    V : (n, 3) float64
    radius : float
        Positive spacing.
    seed : int or numpy.random.Generator
        Order of the visit, through :func:`numpy.random.default_rng`.

    Returns
    -------
    indices : (k,) int64
        Sorted vertex indices; any two kept vertices are more than ``radius`` apart
        and every vertex is within ``radius`` of a kept one.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [0.1, 0, 0], [5, 0, 0], [5, 0.1, 0.]])
    >>> len(poisson_disk_vertices(V, 1.0))
    2
    """
    V = as_vertices(V)
    radius = float(radius)
    if not (radius > 0 and np.isfinite(radius)):
        raise ValueError(f"radius must be positive and finite, got {radius}")
    n = len(V)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    from scipy.spatial import cKDTree   # a graph build only (a cached graph skips it)
    tree = cKDTree(V)
    order = np.random.default_rng(seed).permutation(n)
    covered = np.zeros(n, dtype=bool)
    kept = []
    for begin in range(0, n, _BATCH):
        candidates = order[begin:begin + _BATCH]
        candidates = candidates[~covered[candidates]]
        if len(candidates) == 0:
            continue
        pairs = cKDTree(V[candidates]).query_pairs(radius, output_type="ndarray")
        chosen = candidates[_first_independent_set(len(candidates), pairs)]
        kept.append(chosen)
        near = tree.query_ball_point(V[chosen], radius, return_sorted=False)
        covered[np.fromiter(itertools.chain.from_iterable(near), dtype=np.int64)] = True
    return np.sort(np.concatenate(kept))


def _first_independent_set(m: int, pairs: np.ndarray) -> np.ndarray:
    """(m,) bool: the greedy independent set of nodes ``0..m-1`` taken in order.

    ``pairs`` (p, 2) are the graph's edges with ``i < j``.  Each round keeps the
    undecided nodes with no undecided lower neighbour and drops their neighbours,
    which reproduces the sequential greedy choice exactly.
    """
    selected = np.zeros(m, dtype=bool)
    undecided = np.ones(m, dtype=bool)
    i, j = pairs[:, 0], pairs[:, 1]
    while np.any(undecided):
        live = undecided[i] & undecided[j]
        i, j = i[live], j[live]
        new = undecided.copy()
        new[j] = False                  # j has an undecided lower neighbour i
        selected |= new
        undecided &= ~new
        undecided[j[new[i]]] = False    # neighbours of the new picks are out
        undecided[i[new[j]]] = False
    return selected
