"""Normals and areas of triangle meshes.

This module owns per-triangle normals and areas and per-vertex normals.  All results
are finite: a degenerate (zero-area) triangle has a zero normal and contributes
nothing to its vertices, and a vertex with no non-degenerate triangle around it has a
zero normal.  Orientation follows the triangle winding (counter-clockwise seen from
the side the normal points to).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from facewrap.geometry.edge_runs import EdgeRuns, edge_runs
from facewrap.geometry.arrays import (column_norms, cross_columns, edge_vectors, normalize_rows,
                                      safe_inverse)
from facewrap.geometry.checks import as_mesh_arrays

__all__ = ["face_normals", "face_areas", "vertex_normals", "trusted_face_normals",
           "trusted_face_areas", "trusted_vertex_normals", "TriangleMeasures",
           "trusted_normals_and_measures", "coherent_orientation", "disagreeing_edges",
           "spike_vertices", "SPIKE_LIMIT", "SPIKE_NOISE", "outwardness"]


def trusted_face_normals(V: np.ndarray, T: np.ndarray) -> np.ndarray:
    """:func:`face_normals` (t, 3) of clean ``V`` (n, 3) float64, ``T`` (t, 3) int64 in range."""
    cross = cross_columns(*edge_vectors(V, T))
    return (cross * safe_inverse(column_norms(cross))).T.copy()


def trusted_face_areas(V: np.ndarray, T: np.ndarray) -> np.ndarray:
    """:func:`face_areas` (t,) of clean ``V`` (n, 3) float64, ``T`` (t, 3) int64 in range."""
    return 0.5 * column_norms(cross_columns(*edge_vectors(V, T)))


def _corner_angles(l01_sq: np.ndarray, l02_sq: np.ndarray, d0: np.ndarray,
                   double_area: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t, 3) interior angles at the corners of each triangle, and (t,) the squared
    length of each triangle's longest edge (a by-product), from (t,) the squared
    lengths of the edges ``V1 - V0`` and ``V2 - V0``, their dot product ``d0`` and
    the doubled areas.

    Uses ``angle = 2 atan(|a x b| / (|a| |b| + a . b))`` (accurate for all angles and
    faster than ``arctan2``) at corners 0 and 1, and ``pi`` minus both at corner 2.
    Always finite; meaningless only for degenerate triangles, whose normals are 0.
    Each angle is written into the result as it is found (a million-triangle scan's
    normals peaked 100 MB higher with every temporary held to the end).
    """
    d1 = l01_sq - d0                               # (V0 - V1) . (V2 - V1)
    l12_sq = np.maximum(l01_sq + l02_sq - 2.0 * d0, 0.0)
    l01, l02, l12 = np.sqrt(l01_sq), np.sqrt(l02_sq), np.sqrt(l12_sq)
    angles = np.empty((len(double_area), 3))
    for k, (x, y, d) in enumerate(((l01, l02, d0), (l01, l12, d1))):
        den = x * y + d
        # den <= 0 only for a straight corner (angle pi): atan(inf) = pi / 2
        half = np.arctan(np.divide(double_area, den, out=np.full_like(den, np.inf),
                                   where=den > 0))
        del den
        angles[:, k] = 2.0 * half
    angles[:, 2] = np.pi - angles[:, 0] - angles[:, 1]
    longest_sq = np.maximum(np.maximum(l01_sq, l02_sq), l12_sq)
    return angles, longest_sq


def _sum_at_vertices(T: np.ndarray, weights: np.ndarray | None, values: np.ndarray,
                     n: int) -> np.ndarray:
    """(n, 3): sum over corners of ``weights[f, c] * values[f]`` at vertex ``T[f, c]``.

    A (n, t) sparse matrix built directly in CSC form (three entries per triangle, no
    sorting) times ``values``; faster than ``np.add.at`` or ``bincount`` here.
    """
    t = len(T)
    data = np.ones(3 * t) if weights is None else weights.reshape(-1)
    incidence = sp.csc_matrix((data, T.reshape(-1), np.arange(0, 3 * t + 1, 3)),
                              shape=(n, t))
    return incidence @ values


class TriangleMeasures(NamedTuple):
    """Angle-weighted vertex normals and the triangle measures found on the way.

    Attributes
    ----------
    vertex_normals : (n, 3) float64
        As :func:`vertex_normals` with ``weighting="angle"``.
    doubled_areas : (t,) float64
        Twice each triangle's area (the length of its edges' cross product).
    longest_edges_sq : (t,) float64
        Squared length of each triangle's longest edge.
    """

    vertex_normals: np.ndarray
    doubled_areas: np.ndarray
    longest_edges_sq: np.ndarray


def trusted_normals_and_measures(V: np.ndarray, T: np.ndarray) -> TriangleMeasures:
    """Angle-weighted vertex normals of clean ``V`` (n, 3) float64, ``T`` (t, 3)
    int64 in range, with each triangle's doubled area and longest squared edge.

    The normals need the areas and the edge lengths anyway: a caller that also
    checks areas or slivers (a scan's tree, its input checks) gets them for free
    instead of a second pass over a million triangles.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0.]])
    >>> m = trusted_normals_and_measures(V, np.array([[0, 1, 2]]))
    >>> m.vertex_normals[0].tolist(), m.doubled_areas.tolist(), m.longest_edges_sq.tolist()
    ([0.0, 0.0, 1.0], [2.0], [5.0])
    """
    n = len(V)
    if len(T) == 0:
        return TriangleMeasures(np.zeros((n, 3)), np.zeros(0), np.zeros(0))
    e01, e02 = edge_vectors(V, T)
    cross = cross_columns(e01, e02)               # 2 * area * unit normal
    double_area = column_norms(cross)
    inverse = safe_inverse(double_area)
    unit = np.empty((len(T), 3))
    for k in range(3):
        np.multiply(cross[k], inverse, out=unit[:, k])
    del cross, inverse   # (the peak memory of a scan's checks is here: free early)
    lengths = (np.einsum("ij,ij->j", e01, e01), np.einsum("ij,ij->j", e02, e02),
               np.einsum("ij,ij->j", e01, e02))
    del e01, e02
    angles, longest_sq = _corner_angles(*lengths, double_area)
    del lengths
    summed = _sum_at_vertices(T, angles, unit, n)
    return TriangleMeasures(normalize_rows(summed)[0], double_area, longest_sq)


def trusted_vertex_normals(V: np.ndarray, T: np.ndarray, weighting: str = "angle"
                           ) -> np.ndarray:
    """:func:`vertex_normals` (n, 3) of clean ``V`` (n, 3) float64, ``T`` (t, 3) int64 in range.

    ``weighting`` is "angle" or "area" (not checked).
    """
    if weighting != "area":
        return trusted_normals_and_measures(V, T).vertex_normals
    if len(T) == 0:
        return np.zeros((len(V), 3))
    summed = _sum_at_vertices(T, None, cross_columns(*edge_vectors(V, T)).T, len(V))
    return normalize_rows(summed)[0]


def face_normals(V, T) -> np.ndarray:
    """Unit normal of each triangle.

    Parameters
    ----------
    V : (n, 3) float64
    T : (t, 3) int64
        Triangles, counter-clockwise around their normal.

    Returns
    -------
    N : (t, 3) float64
        Unit normals; the zero vector for degenerate (zero-area) triangles.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0.]])
    >>> face_normals(V, [[0, 1, 2], [0, 1, 3]]).tolist()
    [[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]
    """
    V, T = as_mesh_arrays(V, T)
    return trusted_face_normals(V, T)


def face_areas(V, T) -> np.ndarray:
    """Area of each triangle.

    Parameters
    ----------
    V : (n, 3) float64
        Vertex positions.
    T : (t, 3) int64
        Triangles (either winding: areas are unsigned).

    Returns
    -------
    A : (t,) float64
        Non-negative areas.

    Examples
    --------
    >>> face_areas([[0, 0, 0], [2, 0, 0], [0, 1, 0]], [[0, 1, 2]]).tolist()
    [1.0]
    """
    V, T = as_mesh_arrays(V, T)
    return trusted_face_areas(V, T)


def vertex_normals(V, T, weighting: str = "angle") -> np.ndarray:
    """Unit normal of each vertex, a weighted mean of its triangles' normals.

    Parameters
    ----------
    V : (n, 3) float64
        Vertex positions; isolated vertices get a zero normal.
    T : (t, 3) int64
    weighting : {"angle", "area"}
        ``"angle"`` weights each triangle by its corner angle at the vertex (stable
        under re-triangulation, the usual choice); ``"area"`` by its area.

    Returns
    -------
    N : (n, 3) float64
        Unit normals; the zero vector for vertices used by no triangle of non-zero
        area, or whose weighted normals cancel out.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [5, 5, 5.]])
    >>> vertex_normals(V, [[0, 1, 2], [0, 2, 3]]).tolist()
    [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]
    """
    V, T = as_mesh_arrays(V, T)
    if weighting not in ("angle", "area"):
        raise ValueError(f'weighting must be "angle" or "area", got {weighting!r}')
    return trusted_vertex_normals(V, T, weighting)


def _manifold_pairs(T: np.ndarray, runs: EdgeRuns | None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The two triangles (p,), (p,) of each manifold edge (two half-edges, two
    triangles), and (p,) bool whether they run along it the same way."""
    runs = edge_runs(T) if runs is None else runs
    order, starts = runs.order, runs.starts
    if not len(order):
        empty = np.zeros(0, np.int64)
        return empty, empty, np.zeros(0, bool)
    first = np.flatnonzero(starts)[runs.sizes() == 2]
    h1, h2 = order[first], order[first + 1]
    f1, f2 = h1 // 3, h2 // 3
    tail = T.reshape(-1)                               # half-edge h starts at tail[h]
    keep = f1 != f2
    return f1[keep], f2[keep], tail[h1[keep]] == tail[h2[keep]]


def outwardness(V, T) -> float:
    """How much the triangles face away from the middle of the surface, in [-1, 1].

    The area-weighted mean cosine between each triangle's normal and the direction
    from the centroid of the used vertices to the triangle: a head, a face mask or
    a scan of one wound outward gives about 0.3 to 0.8, the same wound inward
    (every face flipped) the negative, a flat or mixed surface about 0.

    Parameters
    ----------
    V : (n, 3) float
    T : (t, 3) int

    Returns
    -------
    float
        0.0 for a surface of no area.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.]])
    >>> T = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    >>> outwardness(V, T) > 0.5, outwardness(V, T[:, ::-1]) < -0.5
    (True, True)
    """
    V, T = as_mesh_arrays(V, T)
    a, b, c = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
    normal = np.cross(b - a, c - a)                  # twice the area along the normal
    arm = (a + b + c) / 3.0 - V[np.unique(T)].mean(axis=0)
    weight = np.linalg.norm(normal, axis=1) * np.linalg.norm(arm, axis=1)
    total = weight.sum()
    return float(np.einsum("ij,ij->", normal, arm) / total) if total > 0 else 0.0


def disagreeing_edges(T, runs: EdgeRuns | None = None) -> int:
    """Manifold edges whose two triangles run along them the same way (wound
    against each other): 0 for a mesh wound consistently.

    >>> disagreeing_edges([[0, 1, 2], [0, 2, 3]]), disagreeing_edges([[0, 1, 2], [0, 3, 2]])
    (0, 1)
    """
    return int(_manifold_pairs(np.asarray(T, dtype=np.int64), runs)[2].sum())


def coherent_orientation(T, runs: EdgeRuns | None = None
                         ) -> tuple[np.ndarray, np.ndarray, int]:
    """Triangles to reverse so that every piece is wound one way.

    Two triangles on a manifold edge agree when they run along it in opposite
    directions.  Each triangle is two nodes of a graph (as it is, reversed),
    joined to its neighbours' nodes so that agreeing states are connected; the
    connected components then give, for each orientable patch, two consistent
    windings, and the one holding the lower label is chosen.  Non-manifold edges
    (three or more triangles) join nothing; a patch that cannot be oriented (a
    Moebius strip, or windings that contradict each other around a fan) is left
    as it is.

    Parameters
    ----------
    T : (t, 3) int64
    runs : EdgeRuns, optional
        :func:`~facewrap.geometry.edge_runs.edge_runs` of ``T``, when the caller
        has them.

    Returns
    -------
    flip : (t,) bool
        Triangles whose winding to reverse.
    patch : (t,) int64
        The orientable patch of each triangle (edge-connected through manifold
        edges), labels in ``[0, t)`` not necessarily consecutive.
    disagreeing : int
        Manifold edges whose two triangles ran the same way before.

    Examples
    --------
    >>> flip, patch, bad = coherent_orientation([[0, 1, 2], [0, 2, 3], [2, 3, 4]])
    >>> flip.tolist(), bool(patch[0] == patch[2]), bad
    ([False, False, True], True, 1)
    """
    T = np.asarray(T, dtype=np.int64)
    t = len(T)
    if t == 0:
        return np.zeros(0, bool), np.zeros(0, np.int64), 0
    f1, f2, same = _manifold_pairs(T, runs)
    if not same.any():   # wound one way already: the patches alone
        graph = sp.csr_matrix((np.ones(len(f1), np.int8), (f1, f2)), shape=(t, t))
        return (np.zeros(t, bool), csgraph.connected_components(graph, directed=False)[1],
                0)
    rows = np.concatenate([f1, f1 + t])
    cols = np.concatenate([f2 + t * same, f2 + t * ~same])
    graph = sp.csr_matrix((np.ones(len(rows), np.int8), (rows, cols)), shape=(2 * t, 2 * t))
    labels = csgraph.connected_components(graph, directed=False)[1]
    kept, turned = labels[:t], labels[t:]
    return kept > turned, np.minimum(kept, turned), int(same.sum())


def _neighbour_sums(X: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, 3): at each vertex, the sum of ``X`` (n, 3) over its neighbours across
    the edges ``a - b`` (e,), (e,) int64 (each edge once).

    The columns are gathered from a coordinate-major copy of ``X``: contiguous
    reads, twice as fast as ``X[b, k]`` on a million-triangle scan, with the same
    values summed in the same order.
    """
    n = len(X)
    Xt = np.ascontiguousarray(X.T)
    return np.stack([np.bincount(a, x[b], n) + np.bincount(b, x[a], n) for x in Xt],
                    axis=1)


#: a scan vertex is a spike when it stands farther off the centroid of its
#: neighbours, along their mean normal, than this many times their RMS distance
#: from that centroid (james: at most 1.2 on its interior vertices; 54 of 64
#: vertices pushed 5-20 mm along the normal go past 1.5)
SPIKE_LIMIT = 1.5
#: ... and farther than this many times the median such distance over the interior
#: vertices: a dense scan's noise (the sample's at 0.2 mm spacing: 0.2 mm, up to
#: 7 times that median) keeps the ratio above 1.5 on 2 % of its vertices
SPIKE_NOISE = 10.0


def spike_vertices(V, T, limit: float = SPIKE_LIMIT, *, runs: EdgeRuns | None = None,
                   normals: np.ndarray | None = None) -> np.ndarray:
    """Interior vertices that stand far out of (or into) the surface around them.

    A vertex is compared with the ring of its neighbours: its distance from the
    ring's centroid along the ring's mean normal (the sum of the neighbours'
    normals, whose tilts toward a spike cancel), over the ring's radius (the
    neighbours' RMS distance from that centroid, which the vertex itself does not
    change).  A smooth surface keeps that ratio far below 1, whatever the
    triangulation (a vertex off its ring's centre within the surface does not
    count); a scanner's spike, a vertex shot out along the line of sight, goes
    past it, and past ``SPIKE_NOISE`` times the median of that distance (the
    scan's noise: on a dense, noisy scan the ratio alone calls noise spikes).
    Border vertices (whose ring is one-sided) are never called spikes.

    Parameters
    ----------
    V : (n, 3) float64
    T : (t, 3) int64
    limit : float
        The ratio above which a vertex is a spike.
    runs : EdgeRuns, optional
        :func:`~facewrap.geometry.edge_runs.edge_runs` of ``T``, when the caller
        has them (the edges and borders come from them, no sort).
    normals : (n, 3) float64, optional
        The angle-weighted :func:`vertex_normals` of ``V``, ``T``, when the caller
        has them (a scan's :class:`~facewrap.geometry.ClosestPointTree` does:
        its ``vertex_normals``), instead of a second pass over the triangles.

    Returns
    -------
    (n,) bool

    Examples
    --------
    >>> a, b = np.meshgrid(np.arange(9.0), np.arange(9.0), indexing="ij")
    >>> V = np.stack([a.ravel(), b.ravel(), 0 * a.ravel()], axis=1)
    >>> i = (np.arange(8)[:, None] * 9 + np.arange(8)).ravel()
    >>> T = np.vstack([np.stack([i, i + 9, i + 1], 1), np.stack([i + 1, i + 9, i + 10], 1)])
    >>> bool(spike_vertices(V, T).any())
    False
    >>> V[40, 2] = 3.0
    >>> np.flatnonzero(spike_vertices(V, T)).tolist()
    [40]
    """
    V, T = as_mesh_arrays(V, T)
    n = len(V)
    runs = edge_runs(T) if runs is None else runs
    if not len(runs.order):
        return np.zeros(n, bool)
    # the normals first: their pass over the triangles is the peak memory of the
    # scan's checks, lower while none of the ring sums below are held
    N = trusted_vertex_normals(V, T) if normals is None else np.asarray(normals, np.float64)
    # each undirected edge once, from the runs; runs of one are border edges
    single = runs.sizes() == 1
    a, b = runs.ends[:, 0].astype(np.int64), runs.ends[:, 1].astype(np.int64)
    edge = a != b
    a, b, single = a[edge], b[edge], single[edge]
    # sums over each vertex's neighbours by bincount: no sparse matrix to sort
    degree = np.bincount(a, minlength=n) + np.bincount(b, minlength=n)
    inv = safe_inverse(degree.astype(np.float64))
    total = _neighbour_sums(V, a, b)
    centroid = total * inv[:, None]
    squares = np.einsum("ij,ij->i", V, V)
    spread = ((np.bincount(a, squares[b], n) + np.bincount(b, squares[a], n)) * inv
              - np.einsum("ij,ij->i", centroid, centroid))
    radius = np.sqrt(np.maximum(spread, 0.0))
    ring = _neighbour_sums(N, a, b)
    offset = np.abs(np.einsum("ij,ij->i", V - centroid, ring)) * safe_inverse(
        np.linalg.norm(ring, axis=1))
    interior = degree >= 3
    interior[a[single]] = False
    interior[b[single]] = False
    if not interior.any():
        return interior
    noise = np.median(offset[interior])
    return interior & (offset > limit * radius) & (offset > SPIKE_NOISE * noise)
