"""The search trees behind :class:`~facewrap.geometry.closest.ClosestPointTree`.

A search tree answers two questions about a triangle mesh: which triangle is
nearest to each query point, and which triangle each ray hits first.  Two engines
answer them, and answer alike:

- :class:`LibiglSearch`: libigl's AABB tree, exact closest points in float64.
- :class:`FcpwSearch`: the bounding volume hierarchy of FCPW (Sawhney, *Fast
  Closest Points, Normals and Distances*): built 3.5x faster (a 951k-triangle
  scan in 0.23 s against 0.79 s) and queried faster in C++, but in float32 and
  through one Python object per answer.  It only *names* the triangle
  (:meth:`FcpwSearch.nearest_triangles`); the point is found again in float64 on
  it (:func:`closest_on_triangles`).

A point FCPW's answer lands on an edge or a corner of is settled among the
triangles around it (:meth:`VertexFans.walk_to_nearest`): the nearest (a float32
tree can name a neighbour of it), and of equals the one facing the point most
squarely.  Both engines give the same distances and points; where several
triangles are nearest they may name different ones (libigl's own pick is kept:
applying the rule to it too moved fold counts of the real-scan benchmarks both
ways, from tie to tie, and cost a rig's bake 0.2 s).

Which engine (:func:`search_tree`): FCPW from :data:`FCPW_FROM` triangles on,
libigl below.  Per triangle, FCPW's build saves about 0.6 µs; per query point
its answers cost about 0.25 µs more (the objects, the float64 measure): a wrap
asks some 200k points and a rig's texture bake two million, so FCPW pays off on
scans of a million triangles (a whole wrap of 951k triangles: 4.36 -> 3.19 s) and not on the rig's
200k-triangle scans (their bake 0.3-0.5 s slower).  ``FACEWRAP_SEARCH_TREE``
(``fcpw`` or ``libigl``) forces one; libigl is used wherever FCPW has no wheel
(Linux on ARM).

Both take float64 ``V`` (n, 3) and int64 ``T`` (t, 3) that the caller has checked.
"""

from __future__ import annotations

import os

import igl
import numpy as np

from facewrap.geometry.edge_runs import counting_sort_order
from facewrap.geometry.arrays import column_bounds, cross_rows, normalize_rows

__all__ = ["FcpwSearch", "LibiglSearch", "search_tree", "closest_on_triangles",
           "VertexFans", "load_fcpw", "ENGINES", "FCPW_FROM"]

#: the engines :func:`search_tree` knows
ENGINES = ("fcpw", "libigl")
#: meshes of at least this many triangles are searched by FCPW (where installed)
FCPW_FROM = 500_000
# Steps at most of the walk from a tree's answer across the edges it lands on
# (each step strictly better; a vertex's fan is met whole in one step)
_WALK_STEPS = 16
# Relative difference of squared distances below which two triangles are tied
_TIE = 1e-12
# FCPW stores float32 coordinates about the mesh's centre: meshes (or query
# points) beyond this from it are searched by libigl (or clipped) instead
_FLOAT32_SAFE = 1e30


def load_fcpw():
    """The fcpw module, or None where it is not installed."""
    try:
        import fcpw        # a compiled extension: loaded on first use
    except ImportError:
        return None
    return fcpw


def search_tree(V: np.ndarray, T: np.ndarray, engine: str | None = None):
    """A search tree over the mesh ``(V, T)``.

    Parameters
    ----------
    V : (n, 3) float64
    T : (t, 3) int64
    engine : {"fcpw", "libigl"}, optional
        By default the environment's ``FACEWRAP_SEARCH_TREE``, else "fcpw" for a
        mesh of :data:`FCPW_FROM` triangles or more, else "libigl".  "fcpw" falls
        back to libigl where FCPW is not installed or the mesh does not fit
        float32.

    Returns
    -------
    FcpwSearch or LibiglSearch

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> search_tree(V, np.array([[0, 1, 2]]), "libigl").engine
    'libigl'
    """
    engine = engine or os.environ.get("FACEWRAP_SEARCH_TREE") \
        or ("fcpw" if len(T) >= FCPW_FROM else "libigl")
    if engine not in ENGINES:
        raise ValueError(f"FACEWRAP_SEARCH_TREE must be one of {', '.join(ENGINES)}, "
                         f"got {engine!r}")
    if engine == "fcpw" and load_fcpw() is not None and len(V) \
            and np.ptp(column_bounds(V), axis=0).max() < _FLOAT32_SAFE:
        return FcpwSearch(V, T)
    return LibiglSearch(V, T)


class LibiglSearch:
    """libigl's AABB tree: closest points in float64, ray hits in float32.

    libigl notes (``igl`` 2.6 nanobind bindings): ``AABB.intersect_ray_first``
    computes ``t`` in float32 and its ``min_t`` argument is really an upper bound
    on ``t``; its build and queries hold the GIL (the queries spread over the
    cores themselves).
    """

    engine = "libigl"

    def __init__(self, V, T):
        self._V, self._T = V, T
        self._tree = igl.AABB()
        self._tree.init(V, T)

    def closest(self, P: np.ndarray):
        """Squared distances (k,), triangles (k,) int64 and closest points (k, 3)
        of points ``P`` (k, 3) float64, in float64."""
        sq, tri, points = self._tree.squared_distance(self._V, self._T, P)
        return (np.array(sq, dtype=np.float64), np.array(tri, dtype=np.int64),
                np.array(points))

    def first_hits(self, O: np.ndarray, D: np.ndarray, bound: float):
        """Triangle (k,) int64, -1 for a miss, and float32-accurate ``t`` (k,) of
        each ray ``O + t D`` (``0 <= t <= bound``; ``D`` unit rows)."""
        tri, t, _ = self._tree.intersect_ray_first(self._V, self._T, O, D, bound)
        return np.asarray(tri, dtype=np.int64), np.asarray(t, dtype=np.float64)


class FcpwSearch:
    """FCPW's bounding volume hierarchy (float32, about the mesh's centre).

    Its queries run on all cores in one call (they hold the GIL meanwhile).
    """

    engine = "fcpw"

    def __init__(self, V, T):
        fcpw = load_fcpw()
        self._V, self._T = V, T
        lo, hi = column_bounds(V)
        self.centre = (lo + hi) / 2
        self._interactions = fcpw.interaction_3D_list
        scene = fcpw.scene_3D()
        scene.set_object_count(1)
        scene.set_object_vertices(np.asfortranarray(V - self.centre, dtype=np.float32), 0)
        scene.set_object_triangles(np.asfortranarray(T, dtype=np.int32), 0)
        # centre splits along the longest axis: built 2.5x faster than the
        # surface-area heuristic's tree, queried as fast on scans (measured)
        scene.build(fcpw.aggregate_type.bvh_longest_axis_center, True)
        self._scene = scene

    def _local(self, P: np.ndarray) -> np.ndarray:
        """Points as FCPW's float32 coordinates (far ones clipped: they still find
        the triangles nearest their direction, measured again in float64)."""
        return np.asfortranarray(np.clip(P - self.centre, -_FLOAT32_SAFE, _FLOAT32_SAFE),
                                 dtype=np.float32)

    def nearest_triangles(self, P: np.ndarray) -> np.ndarray:
        """(k,) int64: the triangle nearest each point of ``P`` (k, 3), to float32
        accuracy (a near tie may name a neighbour of the nearest)."""
        found = self._interactions()
        self._scene.find_closest_points(self._local(P),
                                        np.full(len(P), np.inf, dtype=np.float32), found)
        return np.fromiter((i.primitive_index for i in found), np.int64, len(P))

    def first_hits(self, O: np.ndarray, D: np.ndarray, bound: float):
        """As :meth:`LibiglSearch.first_hits`."""
        found = self._interactions()
        bound = np.float32(min(bound, np.finfo(np.float32).max))
        self._scene.intersect(self._local(O), np.asfortranarray(D, dtype=np.float32),
                              np.full(len(O), bound, dtype=np.float32), found, False)
        tri = np.fromiter((i.primitive_index for i in found), np.int64, len(O))
        t = np.fromiter((i.d for i in found), np.float64, len(O))
        return tri, t


def closest_on_triangles(P: np.ndarray, corners: np.ndarray):
    """Closest point of triangle ``i`` to point ``i``, in float64.

    The region test of Ericson (*Real-Time Collision Detection*, 5.1.5): the
    closest point is a corner, on an edge or inside, decided from dot products of
    the edges with the point, so corners and edges get exact zero weights.

    Parameters
    ----------
    P : (k, 3) float64
    corners : (k, 3, 3) float64
        Triangle, corner, coordinate.

    Returns
    -------
    points : (k, 3) float64
    sq_dist : (k,) float64
        Squared distances; ``inf`` where the triangle has no area to decide by (a
        segment or a point: the caller measures those to their longest edge).
    barycentric : (k, 3) float64
        Weights of the corners (exact zeros on edges and corners).

    Examples
    --------
    >>> tri = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0.]]] * 3)
    >>> pts, sq, bary = closest_on_triangles(
    ...     np.array([[0.25, 0.25, 1.0], [2.0, -1.0, 0.0], [1.0, 1.0, 0.0]]), tri)
    >>> pts.tolist(), sq.tolist()
    ([[0.25, 0.25, 0.0], [1.0, 0.0, 0.0], [0.5, 0.5, 0.0]], [1.0, 2.0, 0.5])
    >>> bary.tolist()
    [[0.5, 0.25, 0.25], [0.0, 1.0, 0.0], [0.0, 0.5, 0.5]]
    """
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    ab, ac = b - a, c - a

    def dot(x, y):
        return np.einsum("ij,ij->i", x, y)

    ap, bp, cp = P - a, P - b, P - c
    d1, d2 = dot(ab, ap), dot(ac, ap)
    d3, d4 = dot(ab, bp), dot(ac, bp)
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    total = va + vb + vc
    # most points fall over their triangle: the weights of their projection, in
    # one pass (a zero weight there is an edge or a corner, as in the cascade)
    bary = np.stack([va, vb, vc], axis=1)
    inside = (va >= 0) & (vb >= 0) & (vc >= 0) & (total > 0)
    bary[inside] /= total[inside, None]
    out = np.flatnonzero(~inside)
    if len(out):
        bary[out] = _outside(d1[out], d2[out], d3[out], d4[out], d5[out], d6[out],
                             va[out], vb[out], vc[out])
    points = np.einsum("kc,kcd->kd", bary, corners)
    sq = dot(points - P, points - P)
    bad = ~np.isfinite(sq)
    if np.any(bad):               # no area (0/0 above): left to the caller
        sq[bad] = np.inf
        points[bad] = a[bad]
        bary[bad] = (1.0, 0.0, 0.0)
    return points, sq, bary


def _outside(d1, d2, d3, d4, d5, d6, va, vb, vc) -> np.ndarray:
    """(m, 3) weights of the closest points of points not over their triangle:
    Ericson's cascade of corner and edge regions (the first that holds wins)."""
    m = len(d1)
    bary = np.zeros((m, 3))
    left = np.ones(m, dtype=bool)

    def take(where, weights):
        rows = np.flatnonzero(where & left)
        bary[rows] = np.stack([w[rows] if isinstance(w, np.ndarray) else np.full(
            len(rows), w) for w in weights], axis=1)
        left[rows] = False

    with np.errstate(divide="ignore", invalid="ignore"):
        take((d1 <= 0) & (d2 <= 0), (1.0, 0.0, 0.0))                       # corner a
        take((d3 >= 0) & (d4 <= d3), (0.0, 1.0, 0.0))                      # corner b
        take((d6 >= 0) & (d5 <= d6), (0.0, 0.0, 1.0))                      # corner c
        v = d1 / (d1 - d3)
        take((vc <= 0) & (d1 >= 0) & (d3 <= 0), (1 - v, v, 0.0))           # edge ab
        w = d2 / (d2 - d6)
        take((vb <= 0) & (d2 >= 0) & (d6 <= 0), (1 - w, 0.0, w))           # edge ac
        u = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        take((va <= 0) & (d4 >= d3) & (d5 >= d6), (0.0, 1 - u, u))         # edge bc
        total = va + vb + vc                                # no area: 0/0, NaN
        take(np.ones(m, dtype=bool), (va / total, vb / total, vc / total))
    return bary


class VertexFans:
    """The triangles around each vertex of a mesh, and the walk that settles a
    tree's answers among them.

    Parameters
    ----------
    V : (n, 3) float64
    T : (t, 3) int64

    Attributes
    ----------
    offsets : (n + 1,) int64
    triangles : (3t,) int
        The triangles around vertex ``v`` are ``triangles[offsets[v]:offsets[v + 1]]``.

    Examples
    --------
    >>> fans = VertexFans(np.zeros((4, 3)), np.array([[0, 1, 2], [0, 2, 3]]))
    >>> fans.offsets.tolist(), fans.triangles.tolist()
    ([0, 2, 3, 5, 6], [0, 1, 0, 0, 1, 1])
    """

    def __init__(self, V: np.ndarray, T: np.ndarray):
        self._V, self._T = V, T
        corners = T.ravel()
        self.triangles = counting_sort_order(corners, len(V)) // 3
        self.offsets = np.r_[0, np.cumsum(np.bincount(corners, minlength=len(V)))]
        # squared distances nearer each other than this (a trillionth of the mesh's
        # squared diagonal, beyond the relative _TIE) are one
        self._tie_floor = (_TIE * float(np.sum(np.ptp(column_bounds(V), axis=0) ** 2))
                           if len(V) else 0.0)

    def _fan_runs(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(counts, triangles)``: the fans of vertices ``v`` (k,), one run each."""
        offsets = self.offsets
        counts = offsets[v + 1] - offsets[v]
        at = np.repeat(offsets[v] - np.r_[0, np.cumsum(counts)[:-1]], counts) \
            + np.arange(counts.sum())
        return counts, self.triangles[at].astype(np.int64)

    def across(self, tri: np.ndarray) -> np.ndarray:
        """(k, 3) int64: the triangle across edge ``j`` (corners ``j``, ``j + 1``)
        of each of ``tri`` (k,), -1 on a border or a self-loop edge; on a
        non-manifold edge one of the others.

        Examples
        --------
        >>> V = np.zeros((4, 3))
        >>> VertexFans(V, np.array([[0, 1, 2], [0, 2, 3]])).across(np.array([0, 1])).tolist()
        [[-1, -1, 1], [0, -1, -1]]
        """
        T = self._T
        ends = T[tri]
        start, end = ends.reshape(-1), ends[:, [1, 2, 0]].reshape(-1)
        counts, other = self._fan_runs(start)
        slot = np.repeat(np.arange(len(start)), counts)
        holds = (T[other] == end[slot][:, None]).any(axis=1) \
            & (other != np.repeat(tri, 3)[slot]) & (start != end)[slot]
        out = np.full(len(start), -1, dtype=np.int64)
        out[slot[holds]] = other[holds]
        return out.reshape(-1, 3)

    def walk_to_nearest(self, P, sq_dist, tri, closest, bary) -> None:
        """Answers moved (in place) to the nearest triangle around where they land,
        and ties broken by a rule of their own.

        A float32 tree can name a neighbour of the nearest triangle when the point
        is all but equidistant from both.  The float64 point then lands on their
        shared edge, or on a corner they share, and the nearer triangle is across
        that edge or in that corner's fan: each step looks there.  Where several
        triangles are nearest (a point over a corner or an edge), the one whose
        plane faces the point most squarely is kept, then the lowest index (not
        the float32 tree's traversal order).  Each step moves to a strictly better
        triangle by
        (distance, facing, index), so the walk ends.

        Parameters
        ----------
        P : (k, 3) float64
            The query points.
        sq_dist, tri, closest, bary : (k,), (k,) int64, (k, 3), (k, 3) float64
            Their answers on a triangle each (:func:`closest_on_triangles`),
            updated in place.
        """
        V, T = self._V, self._T
        rows = np.flatnonzero((bary == 0).any(axis=1))
        for _ in range(_WALK_STEPS):
            if not len(rows):
                return
            asker, other = self._around(rows, tri[rows], bary[rows])
            asker, other = np.r_[rows, asker], np.r_[tri[rows], other]   # stay: a choice
            points, sq, b = closest_on_triangles(P[asker], V[T[other]])
            pick = self._best_of(P[asker], asker, other, points, sq)
            moved = pick[other[pick] != tri[asker[pick]]]
            if not len(moved):
                return
            rows = asker[moved]
            sq_dist[rows], tri[rows] = sq[moved], other[moved]
            closest[rows], bary[rows] = points[moved], b[moved]
            rows = rows[(b[moved] == 0).any(axis=1)]

    def _best_of(self, P, asker, other, points, sq) -> np.ndarray:
        """Index of each asker's best candidate: the nearest (to rounding), then the
        one facing the point most squarely, then the lowest triangle index."""
        corners = self._V[self._T[other]]
        normal = normalize_rows(cross_rows(corners[:, 1] - corners[:, 0],
                                           corners[:, 2] - corners[:, 0]))[0]
        away = normalize_rows(P - points)[0]        # zero on the surface: no facing
        facing = np.abs(np.einsum("ij,ij->i", normal, away))
        by_asker = np.argsort(asker, kind="stable")
        starts = np.flatnonzero(np.r_[True, np.diff(asker[by_asker]) != 0])
        nearest = np.minimum.reduceat(sq[by_asker], starts)
        nearest = np.repeat(nearest, np.diff(np.r_[starts, len(asker)]))
        # equal distances to rounding: one point measured from two triangles
        tied = np.empty(len(asker), dtype=bool)
        tied[by_asker] = sq[by_asker] <= nearest * (1 + _TIE) + self._tie_floor
        order = np.lexsort((other, -facing, ~tied, asker))
        first = np.r_[True, asker[order][1:] != asker[order][:-1]]
        return order[first]

    def _around(self, rows, tri, bary) -> tuple[np.ndarray, np.ndarray]:
        """``(asker, other)``: for points ``rows`` on an edge of their triangle
        ``tri`` (one zero in ``bary``), the triangles around that edge; on a corner
        (two zeros), every triangle of the corner's fan.  (From the corners' fans
        alone: no edge adjacency, which a one-off query of a million-triangle
        scan would pay 0.15 s for.)"""
        on = bary > 0
        T = self._T
        first = np.argmax(on, axis=1)                      # a corner the point is on
        last = 2 - np.argmax(on[:, ::-1], axis=1)          # the other end of its edge
        v, w = T[tri, first], T[tri, last]
        counts, other = self._fan_runs(v)
        asker = np.repeat(rows, counts)
        # on an edge: only the fan's triangles that hold its other end too
        keep = (T[other] == np.repeat(w, counts)[:, None]).any(axis=1)
        return asker[keep], other[keep]
