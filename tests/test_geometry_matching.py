"""The closest-compatible-point matcher against a brute-force oracle (all triangles)."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from facewrap.geometry import ClosestPointTree, vertex_normals
from facewrap.geometry.frames import NormalisedFrame
from facewrap.geometry.matching import closest_compatible_points, compatible


def _segment_closest(P, A, B):
    """Closest points of P (q, 1, 3) on segments AB (1, t, 3)."""
    AB = B - A
    t = np.clip(np.einsum("qti,qti->qt", P - A, np.broadcast_to(AB, (P.shape[0],) + AB.shape[1:]))
                / np.maximum(np.einsum("qti,qti->qt", AB, AB), 1e-300), 0, 1)
    return A + t[..., None] * AB


def brute_force_closest(V, T, X):
    """Closest point of every query over every triangle, in plain numpy."""
    P = X[:, None, :]
    A, B, C = (V[T[:, k]][None] for k in range(3))
    n = np.cross(B - A, C - A)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    plane = P - np.einsum("qti,qti->qt", P - A, np.broadcast_to(n, (len(X),) + n.shape[1:])
                          )[..., None] * n
    # inside test: barycentric signs of the plane projection
    inside = np.ones(plane.shape[:2], bool)
    for a, b in ((A, B), (B, C), (C, A)):
        inside &= np.einsum("qti,qti->qt", np.cross(b - a, plane - a),
                            np.broadcast_to(n, plane.shape)) >= 0
    candidates = [np.where(inside[..., None], plane, np.inf),
                  _segment_closest(P, A, B), _segment_closest(P, B, C),
                  _segment_closest(P, C, A)]
    best = np.full(len(X), np.inf)
    points = np.zeros((len(X), 3))
    triangles = np.zeros(len(X), np.int64)
    for Q in candidates:
        d = np.linalg.norm(np.where(np.isfinite(Q), Q - P, np.inf), axis=-1)
        t = d.argmin(axis=1)
        dt = d[np.arange(len(X)), t]
        better = dt < best
        best[better], triangles[better] = dt[better], t[better]
        points[better] = Q[np.arange(len(X)), t][better]
    return points, best, triangles


@pytest.fixture
def bumpy_patch():
    """A bumpy open grid (it has a border) and queries around it."""
    g = np.linspace(0, 1, 9)
    x, y = np.meshgrid(g, g)
    V = np.c_[x.ravel(), y.ravel(), 0.1 * np.sin(6 * x.ravel()) * np.cos(5 * y.ravel())]
    i = np.arange(8)
    a = (i[:, None] * 9 + i[None, :]).ravel()
    T = np.r_[np.c_[a, a + 1, a + 10], np.c_[a, a + 10, a + 9]]
    rng = np.random.default_rng(3)
    X = np.c_[rng.uniform(-0.2, 1.2, (200, 2)), rng.uniform(-0.4, 0.4, 200)]
    N = rng.normal(size=(200, 3)) + [0, 0, 2.0]
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    return V, T, X, N


def test_matches_follow_the_brute_force_oracle(bumpy_patch):
    V, T, X, N = bumpy_patch
    tree = ClosestPointTree(V, T)
    exclude = np.zeros(len(X), bool)
    exclude[::7] = True
    m = closest_compatible_points(tree, X, N, max_distance=0.25, max_normal_angle=40.0,
                                  reject_border=True, exclude=exclude)
    points, dist, tri = brute_force_closest(V, T, X)
    normals = tree.query(points).normals          # the tree's interpolated normals
    border = tree.boundary_triangles[tri]
    cos = np.einsum("ij,ij->i", normals, N)
    expected = (~exclude & (dist <= 0.25) & (cos >= np.cos(np.radians(40.0))) & ~border)
    assert m.accepted.tolist() == expected.tolist()
    assert m.index.tolist() == np.flatnonzero(expected).tolist()
    np.testing.assert_allclose(m.points, points[expected], atol=1e-12)
    np.testing.assert_allclose(m.distances, dist[expected], atol=1e-12)
    # each rejected query is counted once, under the first test it fails
    assert m.rejected["excluded"] == exclude.sum()
    assert m.rejected["distance"] == (~exclude & (dist > 0.25)).sum()
    assert sum(m.rejected.values()) + len(m) == len(X)


def test_the_frame_maps_queries_and_answers(bumpy_patch):
    V, T, X, N = bumpy_patch
    tree = ClosestPointTree(V, T)
    frame = NormalisedFrame(np.array([0.5, 0.5, 0.0]), 2.0)
    direct = closest_compatible_points(tree, X, N, max_distance=0.2, max_normal_angle=50.0)
    framed = closest_compatible_points(tree, frame.to_frame(X), N, frame=frame,
                                       max_distance=0.1, max_normal_angle=50.0)
    assert framed.index.tolist() == direct.index.tolist()
    np.testing.assert_allclose(frame.from_frame(framed.points), direct.points, atol=1e-12)
    np.testing.assert_allclose(framed.distances * 2.0, direct.distances, atol=1e-12)


def test_the_fallback_takes_the_nearest_vertex_whose_normal_agrees(bumpy_patch):
    V, T, X, N = bumpy_patch
    tree = ClosestPointTree(V, T)
    flipped = -vertex_normals(V, T)[:5]            # every closest point is rejected
    m = closest_compatible_points(tree, V[:5] + 0.01, flipped, max_normal_angle=90.0,
                                  fallback=cKDTree(V))
    assert m.rejected["normal"] == 5 and m.rejected["fallback"] == 0
    up = np.array([[0, 0, 1.0]] * 5)
    m = closest_compatible_points(tree, V[:5] + [0, 0, 0.01], up, max_normal_angle=0.0,
                                  fallback=cKDTree(V))
    assert (m.triangles == -1).sum() == m.rejected["fallback"]


def test_compatible_counts_each_rejection_once():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    tree = ClosestPointTree(V, [[0, 1, 2]])             # one triangle: all border
    up = np.array([[0, 0, 1.0]] * 3)
    ok, rejected = compatible(tree, [0.1, 0.5, 0.1], [0, 0, 0], up, up,
                              max_distance=0.2, max_normal_angle=10.0, reject_border=True)
    assert ok.tolist() == [False, False, False]
    assert rejected == {"distance": 1, "normal": 0, "border": 2}
