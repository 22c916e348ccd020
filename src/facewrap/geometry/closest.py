"""Closest points and ray hits on a triangle mesh, through one search tree.

This module owns point-to-surface queries, the hot path of registration: a
:class:`ClosestPointTree` builds a search tree once per mesh (libigl's AABB tree, or
FCPW's bounding volume hierarchy for a large mesh:
:mod:`~facewrap.geometry.search_trees`) and answers any number of
:meth:`~ClosestPointTree.query` (closest points) and
:meth:`~ClosestPointTree.ray_hits` (line intersections) calls;
:func:`closest_points` is the one-shot form.

Every answer names the triangle and the barycentric coordinates of the point in it,
so callers can move the point with the mesh.  Barycentric coordinates are
``(b0, b1, b2)`` with ``point = b0 * V[T[i, 0]] + b1 * V[T[i, 1]] + b2 * V[T[i, 2]]``,
non-negative and summing to 1, and are never NaN, even for degenerate triangles.

Both engines find ray hits in float32 (libigl's ``intersect_ray_first`` also leaves
``uv`` uninitialised for rays that miss), and FCPW closest points too.  Of those
the trees are asked only which triangle; points, ``t`` and barycentric
coordinates are computed again here in float64 (libigl's closest points, exact in
float64, are kept).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable, NamedTuple

import igl
import numpy as np

from facewrap.geometry.checks import as_mesh_arrays, as_points, as_vertices
from facewrap.geometry.adjacency import triangle_adjacency
from facewrap.geometry.edge_runs import EdgeRuns, edge_runs
from facewrap.geometry.arrays import cross_rows, normalize_rows, spatial_order
from facewrap.geometry.normals import trusted_normals_and_measures
from facewrap.geometry.search_trees import VertexFans, closest_on_triangles, search_tree

__all__ = ["ClosestPoints", "RayHits", "ClosestPointTree", "closest_points"]

# A triangle is treated as a segment when |cross| < _FLAT * (longest edge)^2, i.e.
# when its smallest height is below ~1e-12 of its longest edge.
_FLAT = 1e-12
# Barycentric coordinates below this are rounding noise of a point on an edge or a
# vertex and are set to exactly 0 (moving the point by at most ~1e-12 edge lengths).
_SNAP = 1e-12
# From this many query points on, the tree is asked in spatial order (each answer
# is the same in any order; the tree walks stay in cache).
_ORDERED_FROM = 512


@dataclass(frozen=True, eq=False)
class ClosestPoints:
    """Closest points on a mesh for k query points.

    Attributes
    ----------
    points : (k, 3) float64
        Closest point on the surface.
    triangles : (k,) int64
        Triangle containing it.
    barycentric : (k, 3) float64
        Its coordinates in that triangle: non-negative, summing to 1 (one or two are
        exactly 0 when the point lies on an edge or a vertex).
    normals : (k, 3) float64
        Unit surface normal there, interpolated from the vertex normals with
        ``barycentric`` and renormalised; the triangle's normal where the
        interpolation cancels out, and zero only where neither is defined.
        Found when first asked for (the million texels of a texture bake never
        ask: 0.2 s saved there).
    distances : (k,) float64
        Euclidean distance from each query point to its closest point.
    """

    points: np.ndarray
    triangles: np.ndarray
    barycentric: np.ndarray
    distances: np.ndarray
    #: ``(triangles, barycentric) -> (k, 3)`` normals of the surface queried
    #: (:meth:`ClosestPointTree.normals_at`)
    surface_normals: Callable[[np.ndarray, np.ndarray], np.ndarray] = field(repr=False)

    def __len__(self) -> int:
        return len(self.triangles)

    @cached_property
    def normals(self) -> np.ndarray:
        return self.surface_normals(self.triangles, self.barycentric)


class RayHits(NamedTuple):
    """First hits of k lines with a mesh; unpacks as ``hit, triangles, ...``.

    Attributes
    ----------
    hit : (k,) bool
        Whether the line hits the mesh within the allowed distance.
    triangles : (k,) int64
        Triangle hit, -1 for a miss.
    barycentric : (k, 3) float64
        Coordinates of the hit in that triangle (non-negative, summing to 1); zeros for
        a miss.
    points : (k, 3) float64
        ``origin + t * unit_direction``; NaN for a miss.
    t : (k,) float64
        Signed distance along the unit direction (negative for hits behind the
        origin); NaN for a miss.
    """

    hit: np.ndarray
    triangles: np.ndarray
    barycentric: np.ndarray
    points: np.ndarray
    t: np.ndarray


def _barycentric(X: np.ndarray, corners: np.ndarray, flat=None) -> np.ndarray:
    """(k, 3) barycentric coordinates of points ``X`` (k, 3) on triangles ``corners``.

    ``corners`` is (k, 3, 3) (triangle, corner, coordinate).  Points are assumed to
    lie on (or within rounding of) their triangle; coordinates below ``_SNAP`` are
    set to 0 (so points on edges and vertices get exact zeros) and the rest
    renormalised.  Near-degenerate triangles (see ``_FLAT``) are
    treated as their longest edge, and a triangle shrunk to a point as its first
    corner, so the result is always finite.  ``flat`` (k,) bool says which
    triangles are near-degenerate when the caller knows it already.
    """
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    e0, e1, p = b - a, c - a, X - a
    n = cross_rows(e0, e1)
    nn = np.einsum("ij,ij->i", n, n)
    # lambda_1 = ((p x e1) . n) / |n|^2, lambda_2 = ((e0 x p) . n) / |n|^2: exact for
    # points in the plane, and well conditioned (no Gram-determinant cancellation)
    l1 = np.einsum("ij,ij->i", cross_rows(p, e1), n)
    l2 = np.einsum("ij,ij->i", cross_rows(e0, p), n)
    if flat is None:
        flat = _is_flat(nn, _edge_lengths_sq(corners))
    inv = np.divide(1.0, nn, out=np.zeros_like(nn), where=~flat)
    bary = np.stack([nn - l1 - l2, l1, l2], axis=1) * inv[:, None]
    if np.any(flat):
        bary[flat] = _barycentric_on_longest_edge(X[flat], corners[flat],
                                                  _edge_lengths_sq(corners[flat]))
    bary[bary < _SNAP] = 0.0
    bary /= bary.sum(axis=1, keepdims=True)
    return bary


def _edge_lengths_sq(corners: np.ndarray) -> np.ndarray:
    """(k, 3) squared lengths of edge ``j`` (corner ``j`` to ``(j + 1) % 3``) of the
    triangles ``corners`` (k, 3, 3)."""
    e = corners[:, [1, 2, 0]] - corners
    return np.einsum("kjd,kjd->kj", e, e)


def _is_flat(cross_sq: np.ndarray, edge_sq: np.ndarray) -> np.ndarray:
    """(k,) bool: triangles that are segments (see ``_FLAT``), from their squared
    cross products and squared edge lengths."""
    return cross_sq <= (_FLAT * edge_sq.max(axis=1)) ** 2


def _barycentric_on_longest_edge(X: np.ndarray, corners: np.ndarray,
                                 edge_sq: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of points projected on each triangle's longest edge.

    Edge ``j`` runs from corner ``j`` to corner ``(j + 1) % 3``.
    """
    k = len(X)
    rows = np.arange(k)
    j = edge_sq.argmax(axis=1)
    j1 = (j + 1) % 3
    start, end = corners[rows, j], corners[rows, j1]
    length_sq = edge_sq[rows, j]
    s = np.einsum("ij,ij->i", X - start, end - start)
    s = np.clip(np.divide(s, length_sq, out=np.zeros_like(s), where=length_sq > 0),
                0.0, 1.0)
    bary = np.zeros((k, 3))
    bary[rows, j] = 1.0 - s
    bary[rows, j1] += s
    return bary


class ClosestPointTree:
    """An AABB tree over a triangle mesh, built once, queried many times.

    Parameters
    ----------
    V : (n, 3) float64
        Vertex positions (copied).
    T : (t, 3) int64
        Triangles, at least one (copied).
    vertex_normals : (n, 3) float64, optional
        Normals to interpolate in :meth:`query`; by default the angle-weighted
        :func:`~facewrap.geometry.vertex_normals` of the mesh.

    Attributes
    ----------
    vertices : (n, 3) float64, read-only
    triangles : (t, 3) int64, read-only
    vertex_normals : (n, 3) float64, read-only
    own_normals : bool
        Whether ``vertex_normals`` are the mesh's own angle-weighted normals (none
        were given), so that other checks of the mesh may reuse them.
    doubled_areas, flat_triangles, edge_runs, triangle_neighbours, boundary_triangles
        Facts of the mesh found once, on first use (the areas with the normals).

    Notes
    -----
    Building costs about as much as 100k queries (with its normals, 0.5 s for a
    951k-triangle scan), so build once per mesh shape and reuse.  The tree
    belongs to the vertex positions given: after the mesh moves, build a new one.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> tree = ClosestPointTree(V, [[0, 1, 2]])
    >>> cp = tree.query([[0.25, 0.25, 2.0], [2.0, -1.0, 0.0]])
    >>> cp.points.tolist(), cp.distances.tolist()
    ([[0.25, 0.25, 0.0], [1.0, 0.0, 0.0]], [2.0, 1.4142135623730951])
    >>> cp.barycentric.tolist(), cp.normals.tolist()
    ([[0.5, 0.25, 0.25], [0.0, 1.0, 0.0]], [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    >>> hits = tree.ray_hits([[0.5, 0.25, -3.0]], [[0, 0, 1.0]])
    >>> hits.hit.tolist(), hits.t.tolist(), hits.barycentric.tolist()
    ([True], [3.0], [[0.25, 0.5, 0.25]])
    """

    def __init__(self, V, T, vertex_normals=None):
        V, T = as_mesh_arrays(V, T)
        if len(T) == 0:
            raise ValueError("T must hold at least one triangle")
        self.vertices = _readonly(V)
        self.triangles = _readonly(T)
        self._measures = None
        if vertex_normals is None:
            # the areas and edge lengths come with the normals: kept for the flat
            # test and the scan's input checks
            self._measures = trusted_normals_and_measures(self.vertices, self.triangles)
            normals = self._measures.vertex_normals
        else:
            normals = as_vertices(vertex_normals, "vertex_normals")
            if normals.shape != V.shape:
                raise ValueError(f"vertex_normals must have shape {V.shape}, "
                                 f"got {normals.shape}")
        self.vertex_normals = _readonly(normals)
        self.own_normals = vertex_normals is None
        # (both engines' builds hold the GIL: a background thread would gain nothing)
        self._search = search_tree(self.vertices, self.triangles)

    def _triangle_measures(self) -> tuple[np.ndarray, np.ndarray]:
        """(t,) doubled areas and (t,) longest squared edges of the triangles."""
        if self._measures is not None:
            return self._measures.doubled_areas, self._measures.longest_edges_sq
        V, T = self.vertices, self.triangles
        a, b, c = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]      # (three gathers: faster
        n = cross_rows(b - a, c - a)                        # than one (t, 3, 3) one)
        longest_sq = np.max([np.einsum("ij,ij->i", e, e) for e in (b - a, c - b, a - c)],
                            axis=0)
        return np.sqrt(np.einsum("ij,ij->i", n, n)), longest_sq

    @cached_property
    def doubled_areas(self) -> np.ndarray:
        """(t,) float64: twice each triangle's area, found once."""
        return _readonly(self._triangle_measures()[0])

    @cached_property
    def flat_triangles(self) -> np.ndarray:
        """(t,) bool: triangles that are segments (see ``_FLAT``), found once."""
        double_area, longest_sq = self._triangle_measures()
        return _readonly(double_area <= _FLAT * longest_sq)

    @property
    def engine(self) -> str:
        """The search tree's engine: "fcpw" or "libigl"
        (:func:`~facewrap.geometry.search_trees.search_tree`)."""
        return self._search.engine

    @cached_property
    def _flat_segments(self):
        """The segment-like triangles as their longest edges, in a tree of their own:
        ``(rows, edges, tree)``, or None when there are none.  A triangle tree can
        miss the nearest of them (libigl's measured a collinear triangle 0.21 away
        where its edge was 0.15), so :meth:`query` asks this tree as well."""
        rows = np.flatnonzero(self.flat_triangles)
        if not len(rows):
            return None
        T = self.triangles[rows]
        j = _edge_lengths_sq(self.vertices[T]).argmax(axis=1)
        edges = np.ascontiguousarray(np.stack([T[np.arange(len(T)), j],
                                               T[np.arange(len(T)), (j + 1) % 3]], axis=1))
        tree = igl.AABB()
        tree.init(self.vertices, edges)
        return rows, edges, tree

    def _nearer_flat(self, P, sq_dist, tri, closest) -> np.ndarray:
        """Answers moved (in place) to a segment-like triangle where one is nearer
        than the tree's answer; (k,) bool: which moved."""
        moved = np.zeros(len(P), dtype=bool)
        if self._flat_segments is None:
            return moved
        rows, edges, tree = self._flat_segments
        d, k, c = tree.squared_distance(self.vertices, edges, P)
        better = np.flatnonzero(np.asarray(d) < sq_dist)
        sq_dist[better] = np.asarray(d)[better]
        tri[better] = rows[np.asarray(k)[better]]
        closest[better] = np.asarray(c)[better]
        moved[better] = True
        return moved

    def _onto_flat(self, P, sq_dist, closest, corners, flat) -> None:
        """Answers on segment-like triangles measured to their longest edge (in
        place): a closest point on a triangle of zero area can be off by 1e-3 of
        its size (seen from libigl on a collinear triangle).  ``corners`` (k, 3, 3) are
        the triangles met and ``flat`` (k,) which of them are segments."""
        rows = np.flatnonzero(flat)
        if not len(rows):
            return
        bary = _barycentric_on_longest_edge(P[rows], corners[rows],
                                            _edge_lengths_sq(corners[rows]))
        on_edge = np.einsum("kc,kcd->kd", bary, corners[rows])
        d = np.einsum("ij,ij->i", on_edge - P[rows], on_edge - P[rows])
        better = d < sq_dist[rows]
        sq_dist[rows[better]] = d[better]
        closest[rows[better]] = on_edge[better]

    @cached_property
    def edge_runs(self) -> EdgeRuns:
        """The triangles' half-edges grouped by edge (:func:`~facewrap.geometry.edge_runs.edge_runs`):
        one sort for the neighbours here and the scan's non-manifold check."""
        return edge_runs(self.triangles)

    @cached_property
    def triangle_neighbours(self) -> np.ndarray:
        """(t, 3) int64 edge-neighbour triangles (-1 on the border), computed once."""
        return _readonly(triangle_adjacency(self.triangles, self.edge_runs))

    @cached_property
    def boundary_triangles(self) -> np.ndarray:
        """(t,) bool: triangles with a vertex on the mesh boundary (holes, borders)."""
        # border edges are those of one half-edge: runs of one in the edge runs the
        # scan's checks sorted already (no triangle adjacency: 0.18 s on a
        # million-triangle scan)
        runs = self.edge_runs
        border = runs.ends[runs.sizes() == 1]
        border = border[border[:, 0] != border[:, 1]]
        on = np.zeros(len(self.vertices), dtype=bool)
        on[border.ravel()] = True
        return _readonly(on[self.triangles].any(axis=1))

    def neighbours_of(self, triangles) -> np.ndarray:
        """(k, 3) int64: :attr:`triangle_neighbours` rows of some ``triangles``
        (k,), found from the vertex fans (no adjacency of the whole mesh).  On a
        non-manifold edge it names one of the others, maybe not the same one."""
        return self._fans.across(np.asarray(triangles, dtype=np.int64))

    def __repr__(self) -> str:
        return (f"<ClosestPointTree {len(self.vertices)} vertices, "
                f"{len(self.triangles)} triangles>")

    def query(self, points) -> ClosestPoints:
        """Closest surface point to each query point.

        Parameters
        ----------
        points : (k, 3) float64
            Query points, anywhere in space (no distance limit).

        Returns
        -------
        ClosestPoints
            Points, triangles, barycentric coordinates, normals and distances, one
            row per query point (where several triangles are nearest, libigl's
            pick, or on FCPW's tree the one facing the point most squarely:
            :meth:`~facewrap.geometry.search_trees.VertexFans.walk_to_nearest`).
        """
        P = as_points(points, "points")
        if len(P) == 0:
            return ClosestPoints(np.zeros((0, 3)), np.zeros(0, np.int64),
                                 np.zeros((0, 3)), np.zeros(0), self.normals_at)
        # (both engines spread the tree walks over the cores themselves: libigl's
        # 0.62 s of CPU in 0.33 s for 200k points; splitting the rows over threads
        # measured slower)
        sq_dist, tri, closest, bary = self._closest(P)
        moved = self._nearer_flat(P, sq_dist, tri, closest)
        flat = self.flat_triangles[tri]
        again = np.flatnonzero(flat | moved)   # their coordinates are found again
        if len(again):
            corners = self.vertices[self.triangles[tri[again]]]
            pts, d = closest[again], sq_dist[again]
            self._onto_flat(P[again], d, pts, corners, flat[again])
            closest[again], sq_dist[again] = pts, d
            bary[again] = _barycentric(pts, corners, flat[again])
        return ClosestPoints(points=closest, triangles=tri, barycentric=bary,
                             distances=np.sqrt(np.maximum(sq_dist, 0.0)),
                             surface_normals=self.normals_at)

    def _closest(self, P: np.ndarray):
        """Squared distances (k,), triangles (k,) int64, closest points (k, 3) and
        their barycentric coordinates (k, 3) of points ``P`` (k, 3), in the order
        of ``P``: the triangle the tree names
        (asked in :func:`~facewrap.geometry.arrays.spatial_order` when many), the
        point measured on it in float64 (FCPW's: and walked to the nearest triangle
        around)."""
        order = spatial_order(P) if len(P) >= _ORDERED_FROM else None
        asked = P if order is None else np.ascontiguousarray(P[order])
        if self._search.engine == "libigl":    # exact points: their coordinates here
            sq_dist, tri, closest = self._search.closest(asked)
            bary = _barycentric(closest, self.vertices[self.triangles[tri]],
                                self.flat_triangles[tri])
        else:           # float32: measured again here, and settled among neighbours
            tri = self._search.nearest_triangles(asked)
            closest, sq_dist, bary = closest_on_triangles(
                asked, self.vertices[self.triangles[tri]])
            self._fans.walk_to_nearest(asked, sq_dist, tri, closest, bary)
        if order is not None:                  # back to the order of P
            back = np.empty_like(order)
            back[order] = np.arange(len(order))
            sq_dist, tri, closest, bary = sq_dist[back], tri[back], closest[back], bary[back]
        return sq_dist, tri, closest, bary

    @cached_property
    def _fans(self) -> VertexFans:
        """The triangles around each vertex (for the walk of :meth:`_closest`)."""
        return VertexFans(self.vertices, self.triangles)

    def normals_at(self, triangles, barycentric) -> np.ndarray:
        """(k, 3) unit surface normals at the points with these ``barycentric``
        (k, 3) coordinates in ``triangles`` (k,): the vertex normals interpolated
        and renormalised, the triangle's normal where they cancel out, zero only
        where neither is defined."""
        ids = self.triangles[np.asarray(triangles, dtype=np.int64)]
        bary = np.asarray(barycentric, dtype=np.float64)
        summed = np.einsum("kc,kcd->kd", bary, self.vertex_normals[ids])
        normals, norm = normalize_rows(summed)
        bad = norm <= 1e-12
        if np.any(bad):
            corners = self.vertices[ids[bad]]
            normals[bad] = normalize_rows(cross_rows(corners[:, 1] - corners[:, 0],
                                                       corners[:, 2] - corners[:, 0]))[0]
        return normals

    def ray_hits(self, origins, directions, max_distance: float = np.inf,
                 both_directions: bool = True) -> RayHits:
        """First hit of each line ``origin + t * direction`` with the mesh.

        Parameters
        ----------
        origins : (k, 3) float64
        directions : (k, 3) float64
            Normalised internally; rows of zero length never hit.
        max_distance : float
            Hits farther than this from the origin (``|t| > max_distance``) are
            ignored.
        both_directions : bool
            Also look backwards (``t < 0``) and keep the hit nearer the origin
            (the forward one on a tie).  Otherwise only ``t >= 0``.

        Returns
        -------
        RayHits
            ``(hit, triangles, barycentric, points, t)``, one row per line.
        """
        O = as_points(origins, "origins")
        D = as_points(directions, "directions")
        if D.shape != O.shape:
            raise ValueError(f"directions must have shape {O.shape}, got {D.shape}")
        max_distance = float(max_distance)
        if not max_distance >= 0:
            raise ValueError(f"max_distance must be >= 0, got {max_distance}")
        D, length = normalize_rows(D)
        valid = length > 0
        k = len(O)
        best_tri = np.full(k, -1, dtype=np.int64)
        best_t = np.full(k, np.nan)
        if k == 0:
            return self._ray_result(O, D, best_tri, best_t)
        # the trees' bound is float32-accurate: widen it, filter exactly afterwards
        bound = max_distance * (1 + 1e-5) + 1e-30 if np.isfinite(max_distance) \
            else np.inf
        aim = np.where(valid[:, None], D, (0.0, 0.0, 1.0))   # (zero rows never hit)
        for sign in ((1.0, -1.0) if both_directions else (1.0,)):
            tri, t_tree = self._search.first_hits(O, np.ascontiguousarray(sign * aim),
                                                  bound)
            found = (tri >= 0) & valid
            t = np.full(k, np.nan)
            t[found] = self._line_plane_t(O[found], D[found], tri[found],
                                          sign * t_tree[found])
            found &= np.abs(t) <= max_distance
            better = found & ~(np.abs(t) >= np.abs(best_t))   # NaN best_t: better
            best_tri[better] = tri[better]
            best_t[better] = t[better]
        return self._ray_result(O, D, best_tri, best_t)

    def _line_plane_t(self, O, D, tri, t_fallback):
        """Signed t of the line's intersection with each triangle's plane, float64."""
        corners = self.vertices[self.triangles[tri]]
        n = cross_rows(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        n, _ = normalize_rows(n)
        cos = np.einsum("ij,ij->i", n, D)
        grazing = np.abs(cos) < 1e-9   # line (nearly) in the plane: keep the tree's t
        num = np.einsum("ij,ij->i", n, corners[:, 0] - O)
        return np.where(grazing, t_fallback,
                        num / np.where(grazing, 1.0, cos))

    def _ray_result(self, O, D, tri, t) -> RayHits:
        hit = tri >= 0
        points = O + t[:, None] * D
        bary = np.zeros((len(O), 3))
        if np.any(hit):
            bary[hit] = _barycentric(points[hit], self.vertices[self.triangles[tri[hit]]],
                                     self.flat_triangles[tri[hit]])
        return RayHits(hit=hit, triangles=tri, barycentric=bary, points=points, t=t)


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, order="C", copy=True)
    a.setflags(write=False)
    return a


def closest_points(V, T, points) -> ClosestPoints:
    """Closest surface point of a mesh to each query point (one-shot).

    Builds a :class:`ClosestPointTree`; build the tree yourself to query the same
    mesh more than once.

    Parameters
    ----------
    V : (n, 3) float64
    T : (t, 3) int64
    points : (k, 3) float64

    Returns
    -------
    ClosestPoints
        One row per query point (a tree is built and dropped: use
        :class:`ClosestPointTree` for repeated queries).

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> cp = closest_points(V, [[0, 1, 2]], [[1.0, 1.0, 0.5]])
    >>> cp.points.tolist(), cp.triangles.tolist(), cp.barycentric.tolist()
    ([[0.5, 0.5, 0.0]], [0], [[0.0, 0.5, 0.5]])
    """
    return ClosestPointTree(V, T).query(points)
