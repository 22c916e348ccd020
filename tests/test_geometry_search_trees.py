"""facewrap.geometry.search_trees: the engines behind ClosestPointTree, and the
exact point-on-triangle they are measured again with."""

from __future__ import annotations

import numpy as np
import pytest

import facewrap.geometry as geo
from facewrap.geometry import search_trees
from facewrap.geometry.search_trees import VertexFans, closest_on_triangles, search_tree

from geometry_meshes import brute_force_sq_dist, grid, icosphere, near_points, soup

needs_fcpw = pytest.mark.skipif(search_trees.load_fcpw() is None, reason="fcpw not installed")


def test_closest_on_triangles_matches_brute_force_in_every_region():
    rng = np.random.default_rng(3)
    k = 4000
    corners = rng.normal(size=(k, 3, 3))
    corners[: k // 4, 2] = corners[: k // 4, 0] + 3 * (corners[: k // 4, 1]
                                                       - corners[: k // 4, 0]) \
        + 0.05 * rng.normal(size=(k // 4, 3))                # obtuse slivers
    P = rng.normal(scale=2.0, size=(k, 3))
    points, sq, bary = closest_on_triangles(P, corners)
    V = corners.reshape(-1, 3)
    T = np.arange(3 * k).reshape(k, 3)
    ref = np.array([brute_force_sq_dist(V, T[i:i + 1], P[i:i + 1])[0, 0]
                    for i in range(k)])
    np.testing.assert_allclose(sq, ref, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.einsum("kc,kcd->kd", bary, corners), points, atol=1e-12)
    assert (bary >= 0).all()
    np.testing.assert_allclose(bary.sum(axis=1), 1.0, atol=1e-12)
    # every region was met: three corners, three edges and the inside
    zeros = (bary == 0).sum(axis=1)
    assert {0, 1, 2} <= set(zeros.tolist())


def test_closest_on_triangles_leaves_triangles_without_area_to_the_caller():
    P = np.array([[0.5, 1.0, 0.0], [3.0, 3.0, 3.0]])
    corners = np.array([[[0, 0, 0], [1, 0, 0], [1, 0, 0.]],     # a segment
                        [[1, 1, 1], [1, 1, 1], [1, 1, 1.]]])    # a point
    points, sq, bary = closest_on_triangles(P, corners)
    assert np.isfinite(points).all() and np.isfinite(bary).all()
    # a segment's corners may decide it, a point never: no NaN either way
    assert not np.isnan(sq).any()


@needs_fcpw
@pytest.mark.parametrize("mesh", [lambda: icosphere(3, noise=0.05), lambda: grid(30, 20, 0.3),
                                  lambda: soup(200, seed=5)])
def test_the_engines_agree_with_brute_force(mesh):
    V, T = mesh()
    P = near_points(V, 3000, spread=0.7, seed=2)
    P[:200] = V[np.arange(200) % len(V)] + [0, 0, 0.3]    # over corners: ties
    ref = np.sqrt(brute_force_sq_dist(V, T, P).min(axis=1))
    found = {}
    for engine in search_trees.ENGINES:
        tree = geo.ClosestPointTree(V, T)
        tree._search = search_tree(tree.vertices, tree.triangles, engine)
        cp = found[engine] = tree.query(P)
        assert tree.engine == engine
        np.testing.assert_allclose(cp.distances, ref, rtol=0, atol=1e-9, err_msg=engine)
    # the same points (where several triangles are nearest, the engines may name
    # different ones: one point on their shared edge or corner; but for a float32
    # near tie between triangles far apart, which neither engine owes the other)
    same = np.linalg.norm(found["fcpw"].points - found["libigl"].points, axis=1) < 1e-9
    assert same.mean() > 0.995, np.flatnonzero(~same)


@needs_fcpw
def test_the_walk_across_edges_reaches_the_nearest_triangle():
    # a fan of 8 triangles about an apex, lifted into a cone, and a point just over
    # triangle 0 near the apex: a triangle named wrongly by the float32 tree (here
    # on purpose) meets the point on an edge or at the apex, and the walk goes on
    # across edges and round the apex's fan to triangle 0
    angles = np.linspace(0, 2 * np.pi, 9)[:-1]
    V = np.vstack([[0, 0, 1.0], np.c_[np.cos(angles), np.sin(angles), np.zeros(8)]])
    T = np.array([[0, 1 + i, 1 + (i + 1) % 8] for i in range(8)])
    fans = VertexFans(V, T)
    n = np.cross(V[T[0, 1]] - V[T[0, 0]], V[T[0, 2]] - V[T[0, 0]])
    P = (0.8 * V[0] + 0.1 * V[1] + 0.1 * V[2] + 0.01 * n / np.linalg.norm(n))[None]
    ref = brute_force_sq_dist(V, T, P)[0]
    assert int(np.argmin(ref)) == 0
    walked = []
    for start in range(1, 8):
        tri = np.array([start])
        points, sq, bary = closest_on_triangles(P, V[T[tri]])
        if not (bary == 0).any():
            continue                          # met inside: not a near tie
        walked.append(start)
        fans.walk_to_nearest(P, sq, tri, points, bary)
        assert tri[0] == 0, start
        np.testing.assert_allclose(sq, ref.min(), rtol=1e-12)
    assert {1, 7} <= set(walked) and len(walked) >= 4


@needs_fcpw
def test_fcpw_keeps_float64_answers_far_from_the_origin():
    V, T = icosphere(3, noise=0.05)
    offset = np.array([1e6, -2e6, 5e5])
    P = near_points(V, 500, spread=0.5, seed=4)
    ref = geo.ClosestPointTree(V, T).query(P)
    far = geo.ClosestPointTree(V + offset, T)
    far._search = search_tree(far.vertices, far.triangles, "fcpw")
    assert far.engine == "fcpw"
    cp = far.query(P + offset)
    np.testing.assert_allclose(cp.distances, ref.distances, atol=1e-8)
    # and points very far from the mesh still get their closest point
    P_far = np.array([[1e35, 0, 0], [0, -1e33, 1e33]])
    tree = geo.ClosestPointTree(V, T)
    tree._search = search_tree(tree.vertices, tree.triangles, "fcpw")
    cp = tree.query(P_far)
    ref = np.sqrt(brute_force_sq_dist(V, T, P_far).min(axis=1))
    np.testing.assert_allclose(cp.distances, ref, rtol=1e-12)


@needs_fcpw
def test_fcpw_ray_hits_match_libigl():
    V, T = icosphere(3, noise=0.05)
    rng = np.random.default_rng(0)
    O = rng.normal(scale=0.3, size=(500, 3))
    D = rng.normal(size=(500, 3))
    hits = {}
    for engine in search_trees.ENGINES:
        tree = geo.ClosestPointTree(V, T)
        tree._search = search_tree(tree.vertices, tree.triangles, engine)
        hits[engine] = tree.ray_hits(O, D, max_distance=0.9)
    a, b = hits["fcpw"], hits["libigl"]
    assert a.hit.sum() > 100 and (a.hit == b.hit).mean() > 0.99
    both = a.hit & b.hit
    np.testing.assert_allclose(a.t[both], b.t[both], atol=1e-9)


def test_the_engine_is_chosen_by_the_environment_and_falls_back(monkeypatch):
    V, T = icosphere(1)
    monkeypatch.setenv("FACEWRAP_SEARCH_TREE", "libigl")
    assert geo.ClosestPointTree(V, T).engine == "libigl"
    monkeypatch.setenv("FACEWRAP_SEARCH_TREE", "embree")
    with pytest.raises(ValueError, match="FACEWRAP_SEARCH_TREE must be one of fcpw, "
                                         "libigl, got 'embree'"):
        geo.ClosestPointTree(V, T)
    monkeypatch.delenv("FACEWRAP_SEARCH_TREE")
    # by size: libigl below FCPW_FROM triangles, FCPW from there on
    assert geo.ClosestPointTree(V, T).engine == "libigl"
    monkeypatch.setattr(search_trees, "FCPW_FROM", len(T))
    if search_trees.load_fcpw() is not None:
        assert geo.ClosestPointTree(V, T).engine == "fcpw"
        # a mesh float32 cannot hold is searched by libigl
        assert geo.ClosestPointTree(V * 1e31, T).engine == "libigl"
    monkeypatch.setattr(search_trees, "load_fcpw", lambda: None)      # no wheel here
    assert geo.ClosestPointTree(V, T).engine == "libigl"


@pytest.mark.parametrize("mesh", [lambda: grid(12, 9), lambda: icosphere(2),
                                  lambda: soup(120, seed=7)])
def test_border_and_neighbours_without_the_whole_adjacency(mesh):
    from facewrap.geometry.adjacency import triangle_adjacency
    V, T = mesh()
    if len(T) > 40:                       # holes: a border inside too
        T = np.delete(T, [5, 17, 18, 30], axis=0)
    tree = geo.ClosestPointTree(V, T)
    TT = triangle_adjacency(T)
    a, b = T, T[:, [1, 2, 0]]
    border = (TT < 0) & (a != b)
    on = np.zeros(len(V), dtype=bool)
    on[a[border]] = on[b[border]] = True
    np.testing.assert_array_equal(tree.boundary_triangles, on[T].any(axis=1))
    some = np.arange(0, len(T), 3)
    np.testing.assert_array_equal(tree.neighbours_of(some), TT[some])
