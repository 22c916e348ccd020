"""Closest compatible points: the one matcher of wrapping, projection and transfer.

A registration pairs each query point (a template vertex) with the closest point of
a surface (the scan) and then rejects the pairs that are not trustworthy:

* **excluded** — the caller marked the query as not to be matched (eyes, mouth
  interior: they follow the fit, unpulled); it is not even looked up;
* **distance** — the closest point is farther than ``max_distance``;
* **normal** — the surface normal there and the query's normal differ by more than
  ``max_normal_angle`` degrees (the closest point is on the wrong side of a thin
  part, or on a fold);
* **border** — the closest point lies on a triangle touching the surface's border
  (a hole or a crop: the closest point there is only where the scan stops, not
  where the template belongs).

The tests run in this order and every rejected query is counted once, under the
first test it fails.  :func:`closest_compatible_points` queries the surface's
:class:`~facewrap.geometry.ClosestPointTree` and applies them;
:func:`compatible` applies them to surface points found otherwise (the
projection's prism and ray hits).  Each caller sets the rules it needs: the ICP
all of them, the rigid alignment distance and normal, the transfer the normal
test with a nearest-vertex fallback.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from facewrap.geometry.closest import ClosestPointTree
from facewrap.geometry.frames import NormalisedFrame

__all__ = ["Matches", "closest_compatible_points", "compatible"]


@dataclass(frozen=True, eq=False)
class Matches:
    """Accepted closest points of m query points (k of them kept).

    Attributes
    ----------
    index : (k,) int64
        Rows of the accepted queries, increasing.
    points : (k, 3) float64
        Their closest surface points (in the frame, when one was given).
    normals : (k, 3) float64
        The surface's unit normals there.
    distances : (k,) float64
        Query-to-point distances (in the frame's units, when one was given).
    triangles : (k,) int64
        Surface triangle of each point; -1 for a nearest-vertex fallback.
    accepted : (m,) bool
        True for the rows in ``index``.
    rejected : dict
        How many queries each test removed: "excluded", "distance", "normal",
        "border" (and "fallback": how many the nearest-vertex fallback rescued).
    """

    index: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    distances: np.ndarray
    triangles: np.ndarray
    accepted: np.ndarray
    rejected: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.index)


def compatible(tree: ClosestPointTree, distances, triangles, surface_normals=None,
               query_normals=None, *, max_distance: float | None = None,
               max_normal_angle: float | None = None,
               reject_border: bool = False) -> tuple[np.ndarray, dict]:
    """Which query/surface-point pairs pass the distance, normal and border tests.

    Parameters
    ----------
    tree : ClosestPointTree
        The surface (for its border triangles).
    distances : (k,) float64
        Query-to-point distances.
    triangles : (k,) int64
        Surface triangle of each point.
    surface_normals, query_normals : (k, 3) float64, optional
        Unit normals of the surface at the points and of the queries; the normal
        test runs when both are given and ``max_normal_angle`` is not None.
    max_distance : float, optional
        Longest accepted distance (same units as ``distances``); None: no test.
    max_normal_angle : float, optional
        Degrees; None: no test.
    reject_border : bool
        Reject points on triangles that touch the surface's border.

    Returns
    -------
    ok : (k,) bool
    rejected : dict
        Counts per test ("distance", "normal", "border"), each among the pairs
        that passed the tests before it.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> tree = ClosestPointTree(V, [[0, 1, 2]])
    >>> up = np.array([[0, 0, 1.]] * 3)
    >>> ok, rejected = compatible(tree, [0.1, 0.5, 0.1], [0, 0, 0], up,
    ...                           [[0, 0, 1.], [0, 0, 1.], [0, 0, -1.]],
    ...                           max_distance=0.2, max_normal_angle=60.0)
    >>> ok.tolist(), rejected
    ([True, False, False], {'distance': 1, 'normal': 1, 'border': 0})
    """
    d = np.asarray(distances, dtype=np.float64)
    ok_d = d <= max_distance if max_distance is not None else np.ones(len(d), bool)
    ok_n = np.ones(len(d), bool)
    if max_normal_angle is not None and surface_normals is not None \
            and query_normals is not None:
        cos = np.einsum("ka,ka->k", np.asarray(query_normals, dtype=np.float64),
                        np.asarray(surface_normals, dtype=np.float64))
        ok_n = cos >= np.cos(np.radians(max_normal_angle))
    ok_b = (~tree.boundary_triangles[np.asarray(triangles, dtype=np.int64)]
            if reject_border else np.ones(len(d), bool))
    rejected = {"distance": int((~ok_d).sum()), "normal": int((ok_d & ~ok_n).sum()),
                "border": int((ok_d & ok_n & ~ok_b).sum())}
    return ok_d & ok_n & ok_b, rejected


def closest_compatible_points(tree: ClosestPointTree, points, normals=None, *,
                              frame: NormalisedFrame | None = None,
                              max_distance: float | None = None,
                              max_normal_angle: float | None = None,
                              reject_border: bool = False, exclude=None,
                              fallback=None, neighbours: int = 16) -> Matches:
    """Closest surface points of query points, with the rejections of the module.

    Parameters
    ----------
    tree : ClosestPointTree
        The surface, in its own units.
    points : (m, 3) float64
        Query points (in ``frame`` when one is given).
    normals : (m, 3) float64, optional
        Unit normals of the queries (needed for the normal test).
    frame : NormalisedFrame, optional
        The queries live in this frame: they are mapped to the surface's units for
        the query, and points and distances come back in the frame (so
        ``max_distance`` is in the frame's units too).
    max_distance : float, optional
        Longest accepted distance; None: no distance test.
    max_normal_angle : float, optional
        Degrees; None: no normal test.
    reject_border : bool
        Reject points on the surface's border triangles.
    exclude : (m,) bool, optional
        Queries not to match (they are not looked up).
    fallback : scipy.spatial.cKDTree, optional
        Over ``tree.vertices``: a query rejected by the normal test takes the
        nearest of ``neighbours`` surface vertices whose vertex normal passes it
        (and the distance test), when there is one.
    neighbours : int
        Candidates of the fallback.

    Returns
    -------
    Matches

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> tree = ClosestPointTree(V, [[0, 1, 2]])
    >>> m = closest_compatible_points(tree, [[0.25, 0.25, 0.5], [0.25, 0.25, 3.0]],
    ...                               max_distance=1.0)
    >>> m.index.tolist(), m.points.tolist(), m.distances.tolist(), m.rejected["distance"]
    ([0], [[0.25, 0.25, 0.0]], [0.5], 1)
    """
    X = np.asarray(points, dtype=np.float64)
    m = len(X)
    looked_up = np.ones(m, bool) if exclude is None else ~np.asarray(exclude, bool)
    rows = np.flatnonzero(looked_up)
    queries = X[rows] if frame is None else frame.from_frame(X[rows])
    cp = tree.query(queries)
    found = cp.points if frame is None else frame.to_frame(cp.points)
    d = cp.distances if frame is None else cp.distances / frame.size
    query_normals = None if normals is None else np.asarray(normals, np.float64)[rows]
    ok, rejected = compatible(tree, d, cp.triangles, cp.normals, query_normals,
                              max_distance=max_distance,
                              max_normal_angle=max_normal_angle,
                              reject_border=reject_border)
    rejected = {"excluded": int(m - len(rows)), **rejected}
    surface_normals, tri = cp.normals, cp.triangles
    if fallback is not None and query_normals is not None and rejected["normal"]:
        found, surface_normals, d, tri, rescued = _nearest_vertex_fallback(
            tree, fallback, neighbours, queries, query_normals, found, surface_normals,
            d, tri, ok, frame, max_distance, max_normal_angle)
        ok |= rescued
        rejected["fallback"] = int(rescued.sum())
    accepted = np.zeros(m, bool)
    accepted[rows[ok]] = True
    return Matches(rows[ok], found[ok], surface_normals[ok], d[ok], tri[ok], accepted,
                   rejected)


def _nearest_vertex_fallback(tree, kdtree, neighbours, queries, query_normals, found,
                             surface_normals, d, tri, ok, frame, max_distance,
                             max_normal_angle):
    """Closest points rejected by the normal test replaced by the nearest surface
    vertex whose normal passes it (a closest point on the wrong side of a thin
    part often has a good vertex nearby)."""
    cos_max = np.cos(np.radians(max_normal_angle))
    ok_d = d <= max_distance if max_distance is not None else np.ones(len(d), bool)
    bad = np.flatnonzero(ok_d & ~ok)
    k = min(int(neighbours), kdtree.n)
    dist, idx = kdtree.query(queries[bad], k=k)
    dist, idx = dist.reshape(len(bad), k), idx.reshape(len(bad), k)
    good = np.einsum("ikj,ij->ik", tree.vertex_normals[idx], query_normals[bad]) >= cos_max
    if frame is not None:
        dist = dist / frame.size
    if max_distance is not None:
        good &= dist <= max_distance
    first = good.argmax(axis=1)
    hit = good[np.arange(len(bad)), first]
    at, vertex = bad[hit], idx[hit, first[hit]]
    found, surface_normals, d, tri = (found.copy(), surface_normals.copy(), d.copy(),
                                      tri.copy())
    points = tree.vertices[vertex]
    found[at] = points if frame is None else frame.to_frame(points)
    surface_normals[at] = tree.vertex_normals[vertex]
    d[at] = dist[hit, first[hit]]
    tri[at] = -1
    rescued = np.zeros(len(d), bool)
    rescued[at] = True
    return found, surface_normals, d, tri, rescued
