"""facewrap.geometry.closest: closest points and ray hits against brute-force oracles."""

from __future__ import annotations

import os

import igl
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import facewrap.geometry as geo

from facewrap.geometry.search_trees import ENGINES
from geometry_meshes import (MESHES, brute_force_rays, brute_force_sq_dist, check_barycentric,
                             grid, icosphere, near_points, reconstruct, soup)


@pytest.fixture(scope="module", params=ENGINES, autouse=True)
def engine(request):
    """Every test here runs on each search-tree engine (module scope: hypothesis
    allows no function-scoped fixture)."""
    if request.param == "fcpw":
        pytest.importorskip("fcpw")
    before = os.environ.get("FACEWRAP_SEARCH_TREE")
    os.environ["FACEWRAP_SEARCH_TREE"] = request.param
    yield request.param
    if before is None:
        os.environ.pop("FACEWRAP_SEARCH_TREE", None)
    else:
        os.environ["FACEWRAP_SEARCH_TREE"] = before


@pytest.mark.parametrize("name", sorted(MESHES))
def test_query_matches_brute_force(name):
    V, T = MESHES[name]()
    P = near_points(V, 400, spread=0.5)
    cp = geo.ClosestPointTree(V, T).query(P)
    ref = np.sqrt(brute_force_sq_dist(V, T, P).min(axis=1))
    np.testing.assert_allclose(cp.distances, ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(P - cp.points, axis=1), cp.distances,
                               atol=1e-9)
    check_barycentric(cp.barycentric)
    np.testing.assert_allclose(reconstruct(V, T, cp.triangles, cp.barycentric),
                               cp.points, atol=1e-9)
    # the returned triangle really is a closest one
    own = brute_force_sq_dist(V, T, P)[np.arange(len(P)), cp.triangles]
    np.testing.assert_allclose(np.sqrt(own), ref, atol=1e-9)
    assert cp.points.shape == (400, 3) and cp.triangles.dtype == np.int64
    assert len(cp) == 400


@pytest.mark.parametrize("name", sorted(MESHES))
def test_query_normals_are_unit(name):
    V, T = MESHES[name]()
    cp = geo.closest_points(V, T, near_points(V, 300, spread=0.5, seed=3))
    norms = np.linalg.norm(cp.normals, axis=1)
    # zero only on degenerate triangles of the soup, where no normal exists
    fn = geo.face_normals(V, T)[cp.triangles]
    defined = np.linalg.norm(fn, axis=1) > 0
    np.testing.assert_allclose(norms[defined], 1.0, atol=1e-12)
    assert np.all(np.isfinite(cp.normals))


def test_query_normals_follow_the_surface():
    V, T = icosphere(4)
    P = near_points(V, 500, spread=0.3, seed=2)
    cp = geo.closest_points(V, T, P)
    radial = cp.points / np.linalg.norm(cp.points, axis=1, keepdims=True)
    assert np.min(np.einsum("ij,ij->i", cp.normals, radial)) > np.cos(np.radians(3))
    Vg, Tg = grid(5, 5)
    cp = geo.closest_points(Vg, Tg, near_points(Vg, 50, spread=1.0))
    np.testing.assert_allclose(cp.normals, np.tile([0, 0, 1.0], (50, 1)), atol=1e-12)


def test_vertex_normals_argument_is_interpolated():
    V, T = icosphere(1)
    N = np.tile([1.0, 0, 0], (len(V), 1))
    cp = geo.ClosestPointTree(V, T, vertex_normals=N).query(near_points(V, 20, 0.2))
    np.testing.assert_allclose(cp.normals, np.tile([1.0, 0, 0], (20, 1)))
    with pytest.raises(ValueError, match="vertex_normals"):
        geo.ClosestPointTree(V, T, vertex_normals=N[:-1])


def test_barycentric_exact_on_vertices_and_edges():
    V, T = icosphere(2)
    tree = geo.ClosestPointTree(V, T)
    # beyond a vertex along its normal on a convex mesh: the vertex is closest
    cp = tree.query(V * 1.5)
    np.testing.assert_allclose(cp.points, V, atol=1e-12)
    assert np.all(np.sort(cp.barycentric, axis=1)[:, :2] == 0.0)
    assert np.all(cp.barycentric.max(axis=1) == 1.0)
    # beyond an edge midpoint, outward: on the edge, one coordinate exactly 0
    E = geo.edges(T)
    mid = V[E].mean(axis=1)
    cp = tree.query(mid * 1.2)
    np.testing.assert_allclose(cp.points, mid, atol=1e-12)
    assert np.all(cp.barycentric.min(axis=1) == 0.0)
    np.testing.assert_allclose(np.sort(cp.barycentric, axis=1)[:, 1:], 0.5, atol=1e-9)


def test_degenerate_triangles_never_nan():
    V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0],        # collinear
                  [0, 1, 0], [0, 1, 0], [0, 1, 0],        # a point
                  [0, 2, 0], [1, 2, 0], [1, 2, 0.]])      # two corners coincide
    T = np.arange(9).reshape(3, 3)
    P = near_points(V, 200, spread=1.0)
    cp = geo.closest_points(V, T, P)
    check_barycentric(cp.barycentric)
    assert np.all(np.isfinite(cp.normals)) and np.all(np.isfinite(cp.points))
    np.testing.assert_allclose(reconstruct(V, T, cp.triangles, cp.barycentric),
                               cp.points, atol=1e-12)
    ref = np.sqrt(brute_force_sq_dist(V, T, P).min(axis=1))
    np.testing.assert_allclose(cp.distances, ref, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), count=st.integers(1, 30))
def test_query_random_soups(seed, count):
    V, T = soup(count, seed=seed, degenerate=count >= 4)
    P = near_points(V, 50, spread=1.0, seed=seed)
    cp = geo.closest_points(V, T, P)
    ref = np.sqrt(brute_force_sq_dist(V, T, P).min(axis=1))
    np.testing.assert_allclose(cp.distances, ref, atol=1e-9)
    check_barycentric(cp.barycentric)
    np.testing.assert_allclose(reconstruct(V, T, cp.triangles, cp.barycentric),
                               cp.points, atol=1e-9)


def test_tree_copies_inputs_and_is_read_only():
    V, T = icosphere(1)
    V0, T0 = V.copy(), T.copy()
    tree = geo.ClosestPointTree(V, T)
    P = near_points(V, 10, 0.2)
    P0 = P.copy()
    before = tree.query(P)
    np.testing.assert_array_equal(P, P0)
    V += 5.0                       # the caller moves their mesh afterwards
    np.testing.assert_array_equal(tree.query(P).points, before.points)
    np.testing.assert_array_equal(tree.vertices, V0)
    np.testing.assert_array_equal(tree.triangles, T0)
    for a in (tree.vertices, tree.triangles, tree.vertex_normals):
        assert not a.flags.writeable
    assert "ClosestPointTree" in repr(tree)


def test_query_accepts_lists_float32_and_empty():
    V, T = icosphere(1)
    tree = geo.ClosestPointTree(V.astype(np.float32).tolist(), T.astype(np.int32))
    cp = tree.query(np.zeros((0, 3)))
    assert cp.points.shape == (0, 3) and cp.triangles.shape == (0,)
    cp = tree.query([[0, 0, 2.0]])
    assert cp.points.dtype == np.float64


@pytest.mark.parametrize("args, match", [
    ((np.zeros((3, 2)), [[0, 1, 2]]), "V"),
    ((np.zeros((3, 3)), [[0, 1, 3]]), "T"),
    ((np.zeros((3, 3)), [[0.0, 1, 2]]), "T"),
    ((np.zeros((3, 3)), np.zeros((0, 3), int)), "T"),
    ((np.full((3, 3), np.nan), [[0, 1, 2]]), "V"),
])
def test_tree_validation(args, match):
    with pytest.raises(ValueError, match=match):
        geo.ClosestPointTree(*args)


def test_query_validation():
    V, T = icosphere(0)
    tree = geo.ClosestPointTree(V, T)
    with pytest.raises(ValueError, match="points"):
        tree.query(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="points"):
        tree.query([[np.nan, 0, 0]])


# -- rays --------------------------------------------------------------------------

def test_libigl_ray_barycentric_convention():
    """Documents libigl: uv such that point = (1-u-v) V0 + u V1 + v V2, float32."""
    rng = np.random.default_rng(0)
    V = rng.standard_normal((3, 3))
    T = np.array([[0, 1, 2]])
    tree = igl.AABB()
    tree.init(V, T)
    b = np.array([0.2, 0.3, 0.5])
    X = b @ V
    O = X + 3 * rng.standard_normal(3)
    tri, t, uv = tree.intersect_ray_first(V, T, O[None], (X - O)[None])
    assert tri[0] == 0
    np.testing.assert_allclose([1 - uv[0].sum(), *uv[0]], b, atol=1e-6)
    np.testing.assert_allclose(t[0], 1.0, atol=1e-6)
    # min_t bounds t from above; a miss gives -1 and NaN t
    tri, t, _ = tree.intersect_ray_first(V, T, O[None], (X - O)[None], 0.5)
    assert tri[0] == -1 and np.isnan(t[0])


def test_rays_on_plane():
    V, T = grid(5, 5)
    tree = geo.ClosestPointTree(V, T)
    xy = np.random.default_rng(0).uniform(0.1, 3.9, (20, 2))
    O = np.column_stack([xy, np.full(20, 2.5)])
    down = np.tile([0, 0, -5.0], (20, 1))   # not unit: t is still a distance
    hits = tree.ray_hits(O, down)
    assert hits.hit.all()
    np.testing.assert_allclose(hits.t, 2.5, atol=1e-12)
    np.testing.assert_allclose(hits.points, np.column_stack([xy, np.zeros(20)]),
                               atol=1e-12)
    check_barycentric(hits.barycentric)
    np.testing.assert_allclose(reconstruct(V, T, hits.triangles, hits.barycentric),
                               hits.points, atol=1e-12)
    up = -down
    back = tree.ray_hits(O, up)
    np.testing.assert_allclose(back.t, -2.5, atol=1e-12)
    np.testing.assert_allclose(back.points, hits.points, atol=1e-12)
    assert not tree.ray_hits(O, up, both_directions=False).hit.any()
    assert not tree.ray_hits(O, down, max_distance=2.4).hit.any()
    assert tree.ray_hits(O, down, max_distance=2.5 + 1e-9).hit.all()
    # misses: outside the grid, and zero directions
    miss = tree.ray_hits([[10.0, 10, 1], [1, 1, 1]], [[0, 0, 1.0], [0, 0, 0]])
    assert not miss.hit.any()
    assert (miss.triangles == -1).all() and np.isnan(miss.t).all()
    assert np.isnan(miss.points).all() and (miss.barycentric == 0).all()
    hit, tri, bary, pts, t = miss          # unpacks as a tuple
    assert hit.shape == (2,)


def test_rays_on_sphere_match_brute_force():
    V, T = icosphere(3, noise=0.02)
    tree = geo.ClosestPointTree(V, T)
    rng = np.random.default_rng(5)
    O = 0.5 * rng.uniform(-1, 1, (200, 3))
    D = rng.standard_normal((200, 3))
    hits = tree.ray_hits(O, D)
    Du = D / np.linalg.norm(D, axis=1, keepdims=True)
    t_all = brute_force_rays(V, T, O, Du)         # every crossing of the line
    nearest = t_all[np.arange(200), np.abs(t_all).argmin(axis=1)]
    assert hits.hit.all()
    np.testing.assert_allclose(hits.t, nearest, atol=1e-9)
    np.testing.assert_allclose(hits.points, O + hits.t[:, None] * Du, atol=1e-12)
    np.testing.assert_allclose(reconstruct(V, T, hits.triangles, hits.barycentric),
                               hits.points, atol=1e-9)
    # from the centre of the unperturbed sphere, every hit is within the polyhedron
    Vs, Ts = icosphere(3)
    out = geo.ClosestPointTree(Vs, Ts).ray_hits(np.zeros((100, 3)), D[:100],
                                                both_directions=False)
    assert out.hit.all() and np.all((out.t > 0.99) & (out.t <= 1.0 + 1e-12))
    # forward only: the positive root
    fwd = tree.ray_hits(O, D, both_directions=False)
    t_line = brute_force_rays(V, T, O, Du)
    np.testing.assert_allclose(fwd.t, np.where(t_line >= 0, t_line, np.inf).min(axis=1),
                               atol=1e-9)


def test_ray_validation():
    V, T = icosphere(0)
    tree = geo.ClosestPointTree(V, T)
    with pytest.raises(ValueError, match="directions"):
        tree.ray_hits(np.zeros((2, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="max_distance"):
        tree.ray_hits(np.zeros((2, 3)), np.ones((2, 3)), max_distance=-1)
    with pytest.raises(ValueError, match="origins"):
        tree.ray_hits(np.zeros((2, 4)), np.ones((2, 3)))
    empty = tree.ray_hits(np.zeros((0, 3)), np.zeros((0, 3)))
    assert empty.hit.shape == (0,)


def test_a_collinear_triangle_is_measured_as_its_longest_edge():
    """libigl's closest point on a zero-area triangle was 7e-4 too far here (found by
    test_query_random_soups, seed 66135060): such triangles are measured as segments."""
    V, T = soup(23, seed=66135060, degenerate=True)
    P = near_points(V, 50, spread=1.0, seed=66135060)
    cp = geo.closest_points(V, T, P)
    ref = np.sqrt(brute_force_sq_dist(V, T, P).min(axis=1))
    np.testing.assert_allclose(cp.distances, ref, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(cp.points - P, axis=1), cp.distances,
                               atol=1e-9)


def test_query_finds_a_collinear_triangle_libigl_misses():
    # found by hypothesis: libigl's tree measured the collinear triangle 1 too far
    # and answered triangle 25 (0.207 away) for a point 0.153 from triangle 1's edge
    V, T = soup(30, seed=49808353, degenerate=True)
    P = near_points(V, 50, spread=1.0, seed=49808353)
    cp = geo.closest_points(V, T, P)
    ref = np.sqrt(brute_force_sq_dist(V, T, P).min(axis=1))
    np.testing.assert_allclose(cp.distances, ref, atol=1e-9)
    assert cp.triangles[49] == 1
    check_barycentric(cp.barycentric)


def test_many_queries_give_each_point_its_own_answer_in_any_order():
    # many points (2,000: above closest.py's _ORDERED_FROM) are asked of libigl in
    # spatial order and the answers put back: shuffling the queries must shuffle the
    # answers with them
    V, T = icosphere(3, noise=0.05)
    P = near_points(V, 2000, spread=0.5, seed=5)
    tree = geo.ClosestPointTree(V, T)
    cp = tree.query(P)
    ref = np.sqrt(brute_force_sq_dist(V, T, P).min(axis=1))
    np.testing.assert_allclose(cp.distances, ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(P - cp.points, axis=1), cp.distances,
                               atol=1e-9)
    shuffle = np.random.default_rng(6).permutation(len(P))
    again = tree.query(P[shuffle])
    np.testing.assert_allclose(again.points, cp.points[shuffle], atol=1e-12)
    np.testing.assert_allclose(again.distances, cp.distances[shuffle], atol=1e-12)
