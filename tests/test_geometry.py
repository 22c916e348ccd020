"""Tests of facewrap.geometry against brute-force oracles and invariants."""

from __future__ import annotations

import igl
import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

import facewrap.geometry as geo
from facewrap.mesh import Mesh


# -- meshes ------------------------------------------------------------------------

def icosphere(subdivisions=3, noise=0.0, seed=0):
    """Unit icosphere (numpy only), radially perturbed by ``noise``."""
    t = (1 + 5 ** 0.5) / 2
    V = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
                 dtype=float)
    T = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]], dtype=np.int64)
    for _ in range(subdivisions):
        E = np.sort(np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(E, axis=0, return_inverse=True)
        mid = len(V) + inv.reshape(3, -1).T          # midpoints of edges 01, 12, 20
        V = np.vstack([V, V[uniq].mean(axis=1)])
        a, b, c = T.T
        m01, m12, m20 = mid.T
        T = np.concatenate([np.stack(x, axis=1) for x in (
            (a, m01, m20), (b, m12, m01), (c, m20, m12), (m01, m12, m20))])
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    if noise:
        V *= 1 + noise * np.random.default_rng(seed).standard_normal((len(V), 1))
    return V, T


def grid(nx=6, ny=5, noise=0.0, seed=0):
    """Triangulated grid on [0, nx-1] x [0, ny-1], z = noise."""
    x, y = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float),
                       indexing="ij")
    z = noise * np.random.default_rng(seed).standard_normal(x.shape)
    V = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="ij")
    a, b, c, d = i * ny + j, (i + 1) * ny + j, (i + 1) * ny + j + 1, i * ny + j + 1
    T = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                        np.stack([a, c, d], -1).reshape(-1, 3)]).astype(np.int64)
    return V, T


def soup(count=150, seed=0, degenerate=True):
    """Random triangle soup, with some degenerate triangles mixed in."""
    rng = np.random.default_rng(seed)
    centers = rng.uniform(-1, 1, (count, 1, 3))
    V = (centers + 0.3 * rng.standard_normal((count, 3, 3))).reshape(-1, 3)
    if degenerate:
        V[3:6] = V[3] + np.outer([0.0, 0.5, 1.0], V[4] - V[3])   # collinear
        V[6:9] = V[6]                                             # a point
        V[9:12] = V[9] + np.outer([0.0, 1.0, 1.0], V[10] - V[9])  # two coincide
    return V, np.arange(len(V), dtype=np.int64).reshape(-1, 3)


def near_points(V, count, spread, seed=1):
    rng = np.random.default_rng(seed)
    lo, hi = V.min(axis=0) - spread, V.max(axis=0) + spread
    return rng.uniform(lo, hi, (count, 3))


MESHES = {
    "sphere": lambda: icosphere(3, noise=0.05),
    "grid": lambda: grid(8, 7, noise=0.3),
    "soup": lambda: soup(),
}


# -- brute-force oracles -----------------------------------------------------------

def _segment_sq_dist(P, A, B):
    """(k, t) squared distances of points P (k, 3) to segments A-B (t, 3)."""
    d = B - A
    dd = np.einsum("ij,ij->i", d, d)
    w = P[:, None, :] - A[None]
    s = np.einsum("kti,ti->kt", w, d) / np.where(dd > 0, dd, 1.0)
    s = np.clip(s, 0, 1)
    diff = w - s[..., None] * d[None]
    return np.einsum("kti,kti->kt", diff, diff)


def brute_force_sq_dist(V, T, P):
    """(k, t) squared distance of each point to each triangle, vectorised."""
    A, B, C = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
    best = np.minimum(np.minimum(_segment_sq_dist(P, A, B), _segment_sq_dist(P, B, C)),
                      _segment_sq_dist(P, C, A))
    n = np.cross(B - A, C - A)
    nn = np.einsum("ij,ij->i", n, n)
    ok = nn > 1e-24 * np.einsum("ij,ij->i", B - A, B - A) ** 2
    w = P[:, None, :] - A[None]
    height = np.einsum("kti,ti->kt", w, n) / np.where(ok, nn, 1.0)
    foot = P[:, None, :] - height[..., None] * n[None]
    inside = np.ones(best.shape, dtype=bool)
    for X, Y in ((A, B), (B, C), (C, A)):
        side = np.einsum("kti,ti->kt", np.cross(Y - X, foot - X[None]), n)
        inside &= side >= 0
    inside &= ok[None]
    plane_sq = height ** 2 * nn[None]
    return np.where(inside, np.minimum(best, plane_sq), best)


def brute_force_rays(V, T, O, D):
    """Möller-Trumbore against all triangles: (k, t) signed t of the line's crossing
    (negative behind the origin), inf for misses."""
    A, B, C = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
    e1, e2 = B - A, C - A
    p = np.cross(D[:, None, :], e2[None])
    det = np.einsum("kti,ti->kt", p, e1)
    ok = np.abs(det) > 1e-14
    inv = 1 / np.where(ok, det, 1.0)
    s = O[:, None, :] - A[None]
    u = np.einsum("kti,kti->kt", s, p) * inv
    q = np.cross(s, e1[None])
    v = np.einsum("kti,ki->kt", q, D) * inv
    t = np.einsum("kti,ti->kt", q, e2) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1)
    return np.where(hit, t, np.inf)


def check_barycentric(bary):
    assert np.all(np.isfinite(bary))
    assert np.all(bary >= 0)
    np.testing.assert_allclose(bary.sum(axis=1), 1.0, atol=1e-12)


def reconstruct(V, T, tri, bary):
    return np.einsum("kc,kcd->kd", bary, V[T[tri]])


# -- closest points ----------------------------------------------------------------

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


# -- normals -----------------------------------------------------------------------

def test_face_normals_and_areas():
    V, T = icosphere(2, noise=0.1)
    N = geo.face_normals(V, T)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0)
    for a, b in ((0, 1), (1, 2)):
        np.testing.assert_allclose(np.einsum("ij,ij->i", N, V[T[:, b]] - V[T[:, a]]),
                                   0, atol=1e-12)
    centroid_dir = V[T].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", N, centroid_dir) > 0)   # outward winding
    A = geo.face_areas(V, T)
    np.testing.assert_allclose(A, 0.5 * np.linalg.norm(
        np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]), axis=1))
    Vg, Tg = grid(4, 3)
    assert geo.face_areas(Vg, Tg).sum() == pytest.approx(6.0)
    Vd, Td = soup(5)
    assert np.all(geo.face_normals(Vd, Td)[1:4] == 0)
    assert np.all(geo.face_areas(Vd, Td)[1:4] == 0)


@pytest.mark.parametrize("weighting", ["angle", "area"])
def test_vertex_normals_match_libigl(weighting):
    V, T = icosphere(3, noise=0.05)
    ours = geo.vertex_normals(V, T, weighting)
    kind = {"angle": "ANGLE", "area": "AREA"}[weighting]
    ref = igl.per_vertex_normals(V, T, getattr(
        igl.PerVertexNormalsWeightingType, f"PER_VERTEX_NORMALS_WEIGHTING_TYPE_{kind}"))
    np.testing.assert_allclose(ours, ref, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(ours, axis=1), 1.0)


def test_vertex_normals_angle_weighting_ignores_retriangulation():
    # apex 0 of a fan; splitting one triangle in two keeps its angle at the apex
    V = np.array([[0, 0, 1.0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0.5],
                  [0.5, 0.5, 0]])
    T1 = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]])
    T2 = np.array([[0, 1, 5], [0, 5, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]])
    np.testing.assert_allclose(geo.vertex_normals(V, T1)[0],
                               geo.vertex_normals(V, T2)[0], atol=1e-12)


def test_vertex_normals_degenerate_and_isolated():
    V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [7, 7, 7.]])
    N = geo.vertex_normals(V, [[0, 1, 2]])
    assert np.all(N == 0)
    with pytest.raises(ValueError, match="weighting"):
        geo.vertex_normals(V, [[0, 1, 2]], weighting="uniform")
    assert geo.vertex_normals(V, np.zeros((0, 3), int)).shape == (4, 3)


# -- adjacency ---------------------------------------------------------------------

def test_edges_of_closed_sphere():
    V, T = icosphere(2)
    E = geo.edges(T)
    assert len(E) == 3 * len(T) // 2
    assert len(V) - len(E) + len(T) == 2          # Euler characteristic
    assert np.all(E[:, 0] < E[:, 1])
    assert len(np.unique(E, axis=0)) == len(E)
    assert geo.edges([[0, 0, 1]]).tolist() == [[0, 1]]


def test_edges_of_polygons_skips_diagonals():
    nx, ny = 5, 4
    quads = [[i * ny + j, (i + 1) * ny + j, (i + 1) * ny + j + 1, i * ny + j + 1]
             for i in range(nx - 1) for j in range(ny - 1)]
    mesh = Mesh(np.zeros((nx * ny, 3)), quads)
    E = geo.edges_of_polygons(mesh.face_offsets, mesh.face_indices)
    assert len(E) == (nx - 1) * ny + nx * (ny - 1)
    assert len(geo.edges(mesh.triangles)) == len(E) + len(quads)
    diagonals = {tuple(sorted((q[0], q[2]))) for q in quads}
    assert not diagonals & set(map(tuple, E.tolist()))
    mixed = geo.edges_of_polygons([0, 3, 3, 8], [0, 1, 2, 2, 1, 3, 4, 5])
    assert mixed.tolist() == [[0, 1], [0, 2], [1, 2], [1, 3], [2, 5], [3, 4], [4, 5]]
    with pytest.raises(ValueError, match="offsets"):
        geo.edges_of_polygons([0, 5], [0, 1, 2])


def test_vertex_adjacency():
    V, T = icosphere(1)
    A = geo.vertex_adjacency(T, len(V) + 1)
    assert isinstance(A, sp.csr_matrix) and A.shape == (len(V) + 1,) * 2
    assert (A != A.T).nnz == 0
    assert A.diagonal().sum() == 0
    assert A.sum() == 2 * len(geo.edges(T))
    degree = np.asarray(A.sum(axis=1)).ravel()
    assert set(degree[:-1]) == {5, 6} and degree[-1] == 0
    B = geo.vertex_adjacency(np.vstack([geo.edges(T), geo.edges(T)[:, ::-1]]),
                             len(V) + 1)
    assert (A != B).nnz == 0
    with pytest.raises(ValueError, match="T_or_edges"):
        geo.vertex_adjacency(np.zeros((3, 4), int), 5)
    with pytest.raises(ValueError, match="n"):
        geo.vertex_adjacency(T, -1)


def _shares_edge(T, i, j, k):
    a, b = T[i, j], T[i, (j + 1) % 3]
    return {a, b} <= set(T[k])


def test_triangle_adjacency_closed_and_open():
    _, T = icosphere(2)
    TT = geo.triangle_adjacency(T)
    assert TT.shape == T.shape and TT.dtype == np.int64 and np.all(TT >= 0)
    i, j = np.indices(T.shape).reshape(2, -1)
    assert all(_shares_edge(T, a, b, TT[a, b]) for a, b in zip(i, j))
    assert all(a in TT[TT[a, b]] for a, b in zip(i, j))       # symmetric
    assert np.all(TT != np.arange(len(T))[:, None])
    _, Tg = grid(5, 4)
    TTg = geo.triangle_adjacency(Tg)
    assert np.count_nonzero(TTg == -1) == len(geo.boundary_edges(Tg))


def test_triangle_adjacency_non_manifold():
    T = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [2, 1, 5]])   # edge 0-1 thrice
    TT = geo.triangle_adjacency(T)
    fan = [TT[0, 0], TT[1, 0], TT[2, 0]]
    assert sorted(fan) == [0, 1, 2] and all(f != k for k, f in enumerate(fan))
    assert TT[0, 1] == 3 and TT[3, 0] == 0


def test_boundary_edges_and_vertices():
    nx, ny = 6, 5
    V, T = grid(nx, ny)
    B = geo.boundary_edges(T)
    assert len(B) == 2 * (nx - 1 + ny - 1)
    directed = set(map(tuple, np.concatenate([T[:, [0, 1]], T[:, [1, 2]],
                                              T[:, [2, 0]]]).tolist()))
    assert set(map(tuple, B.tolist())) <= directed
    mask = geo.boundary_vertices(T, len(V) + 1)
    x, y = V[:, 0], V[:, 1]
    expected = (x == 0) | (y == 0) | (x == nx - 1) | (y == ny - 1)
    np.testing.assert_array_equal(mask[:-1], expected)
    assert not mask[-1]
    assert len(geo.boundary_edges(icosphere(1)[1])) == 0


def _check_loop(loop, B):
    pairs = set(zip(loop.tolist(), np.roll(loop, -1).tolist()))
    assert pairs <= set(map(tuple, B.tolist()))
    return pairs


def test_boundary_loops_with_hole():
    V, T = grid(8, 8)
    centroid = V[T].mean(axis=1)
    hole = (np.abs(centroid[:, 0] - 3.5) < 1.5) & (np.abs(centroid[:, 1] - 3.5) < 1.5)
    T = T[~hole]
    loops = geo.boundary_loops(T)
    B = geo.boundary_edges(T)
    assert [len(loop) for loop in loops] == [28, 12]
    used = set()
    for loop in loops:
        used |= _check_loop(loop, B)
        assert len(set(loop.tolist())) == len(loop)
    assert len(used) == len(B)
    assert geo.boundary_loops(icosphere(1)[1]) == []
    assert geo.boundary_loops(np.zeros((0, 3), int)) == []


def test_boundary_loops_touching_at_a_vertex():
    T = np.array([[0, 1, 2], [0, 3, 4]])       # bow tie around vertex 0
    loops = geo.boundary_loops(T)
    B = geo.boundary_edges(T)
    assert sum(len(loop) for loop in loops) == 6
    used = set().union(*(_check_loop(loop, B) for loop in loops))
    assert len(used) == 6


def test_boundary_loops_of_a_large_grid():
    _, T = grid(300, 300)
    loops = geo.boundary_loops(T)
    assert [len(loop) for loop in loops] == [4 * 299]


def test_connected_components():
    V1, T1 = icosphere(1)
    T = np.vstack([T1, T1 + len(V1)])
    labels = geo.connected_components(T, 2 * len(V1) + 1)
    assert labels.dtype == np.int64
    np.testing.assert_array_equal(labels, np.repeat([0, 1, 2], [len(V1), len(V1), 1]))


# -- Laplacians --------------------------------------------------------------------

def _check_laplacian(L, n):
    assert isinstance(L, sp.csr_matrix) and L.shape == (n, n)
    assert abs(L - L.T).max() < 1e-12
    np.testing.assert_allclose(np.asarray(L.sum(axis=1)).ravel(), 0, atol=1e-10)
    assert np.linalg.eigvalsh(L.toarray()).min() >= -1e-9


def test_cotangent_laplacian_matches_libigl():
    V, T = icosphere(2, noise=0.1)
    L = geo.cotangent_laplacian(V, T)
    _check_laplacian(L, len(V))
    assert abs(L + igl.cotmatrix(V, T)).max() < 1e-10
    assert np.all(L.diagonal() > 0)


def test_cotangent_laplacian_linear_precision():
    V, T = grid(7, 6, noise=0.0)
    V = V + np.random.default_rng(0).uniform(-0.2, 0.2, V.shape) * [1, 1, 0]
    L = geo.cotangent_laplacian(V, T)
    interior = ~geo.boundary_vertices(T, len(V))
    f = V @ [0.3, -1.2, 0.0] + 2.0
    np.testing.assert_allclose((L @ f)[interior], 0, atol=1e-12)
    np.testing.assert_allclose((L @ V[:, :2])[interior], 0, atol=1e-12)


def test_cotangent_laplacian_degenerate_is_finite():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [1, 1, 0.]])
    T = np.array([[0, 1, 2], [0, 1, 3], [1, 4, 2]])
    L = geo.cotangent_laplacian(V, T)
    assert np.all(np.isfinite(L.data))
    _check_laplacian(L, 5)


def test_uniform_laplacian():
    V, T = icosphere(1)
    L = geo.uniform_laplacian(T, len(V))
    _check_laplacian(L, len(V))
    A = geo.vertex_adjacency(T, len(V))
    np.testing.assert_array_equal(L.diagonal(), np.asarray(A.sum(axis=1)).ravel())
    assert abs(L - geo.uniform_laplacian(geo.edges(T), len(V))).max() == 0


@pytest.mark.parametrize("kind", ["voronoi", "barycentric"])
def test_mass_matrix(kind):
    V, T = icosphere(2, noise=0.1)
    V = np.vstack([V, [[9.0, 9, 9]]])          # an unused vertex
    M = geo.mass_matrix(V, T, kind)
    assert isinstance(M, sp.csr_matrix) and M.shape == (len(V), len(V))
    assert M.nnz <= len(V) and np.all(M.diagonal() >= 0)
    assert abs(M - sp.diags(M.diagonal())).max() == 0
    assert M.diagonal()[-1] == 0
    assert M.sum() == pytest.approx(geo.face_areas(V, T).sum(), rel=1e-12)
    with pytest.raises(ValueError, match="kind"):
        geo.mass_matrix(V, T, "full")


# -- sampling ----------------------------------------------------------------------

def test_sample_surface():
    V, T = icosphere(2, noise=0.1)
    P, tri, bary = geo.sample_surface(V, T, 2000, seed=3)
    P2, tri2, bary2 = geo.sample_surface(V, T, 2000, seed=3)
    np.testing.assert_array_equal(P, P2)
    np.testing.assert_array_equal(tri, tri2)
    assert not np.array_equal(P, geo.sample_surface(V, T, 2000, seed=4)[0])
    check_barycentric(bary)
    np.testing.assert_allclose(reconstruct(V, T, tri, bary), P, atol=1e-12)
    assert geo.closest_points(V, T, P).distances.max() < 1e-12
    assert tri.dtype == np.int64 and P.shape == (2000, 3)
    assert geo.sample_surface(V, T, 0)[0].shape == (0, 3)


def test_sample_surface_is_area_weighted():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [3, 0, 0], [0, 2, 0],
                  [5, 5, 5], [6, 6, 6], [7, 7, 7.]])
    T = np.array([[5, 6, 7], [0, 1, 2], [0, 3, 4], [5, 6, 7]])   # areas 0, .5, 3, 0
    _, tri, _ = geo.sample_surface(V, T, 20000, seed=0)
    counts = np.bincount(tri, minlength=4)
    assert counts[0] == 0 and counts[3] == 0
    assert counts[1] / 20000 == pytest.approx(0.5 / 3.5, abs=0.01)
    with pytest.raises(ValueError, match="area"):
        geo.sample_surface(V, T[[0]], 10)
    with pytest.raises(ValueError, match="count"):
        geo.sample_surface(V, T, -1)


def _fps_reference(V, count, start):
    chosen = [start]
    for _ in range(count - 1):
        d = np.min(np.linalg.norm(V[:, None] - V[chosen][None], axis=2), axis=1)
        d[chosen] = -1
        chosen.append(int(np.argmax(d)))
    return chosen


def test_farthest_point_sampling():
    V, _ = icosphere(2, noise=0.1)
    idx = geo.farthest_point_sampling(V, 40, start=7)
    assert idx.dtype == np.int64 and idx[0] == 7
    assert idx.tolist() == _fps_reference(V, 40, 7)
    dup = np.vstack([V[:3], V[:3]])
    assert sorted(geo.farthest_point_sampling(dup, 6).tolist()) == list(range(6))
    assert len(geo.farthest_point_sampling(V, 0)) == 0
    with pytest.raises(ValueError, match="count"):
        geo.farthest_point_sampling(V, len(V) + 1)
    with pytest.raises(ValueError, match="start"):
        geo.farthest_point_sampling(V, 3, start=len(V))


def _poisson_reference(V, radius, seed):
    tree = cKDTree(V)
    covered = np.zeros(len(V), dtype=bool)
    kept = []
    for v in np.random.default_rng(seed).permutation(len(V)):
        if not covered[v]:
            kept.append(v)
            covered[tree.query_ball_point(V[v], radius)] = True
    return sorted(kept)


@pytest.mark.parametrize("radius", [0.05, 0.2, 0.7, 5.0])
def test_poisson_disk_vertices(radius):
    V, _ = icosphere(3, noise=0.05)
    idx = geo.poisson_disk_vertices(V, radius, seed=2)
    assert idx.dtype == np.int64
    assert idx.tolist() == _poisson_reference(V, radius, 2)
    if len(idx) > 1:
        assert cKDTree(V[idx]).query(V[idx], k=2)[0][:, 1].min() > radius
    assert cKDTree(V[idx]).query(V)[0].max() <= radius


def test_poisson_disk_vertices_on_many_points_and_validated():
    V = np.random.default_rng(0).uniform(0, 1, (10000, 3))
    idx = geo.poisson_disk_vertices(V, 0.05)
    assert cKDTree(V[idx]).query(V[idx], k=2)[0][:, 1].min() > 0.05
    with pytest.raises(ValueError, match="radius"):
        geo.poisson_disk_vertices(V, 0.0)


# -- shared validation -------------------------------------------------------------

@pytest.mark.parametrize("fn", [geo.face_normals, geo.face_areas, geo.vertex_normals,
                                geo.cotangent_laplacian, geo.mass_matrix])
def test_vertex_functions_validate(fn):
    with pytest.raises(ValueError, match="V"):
        fn(np.zeros((3, 4)), [[0, 1, 2]])
    with pytest.raises(ValueError, match="T"):
        fn(np.zeros((3, 3)), [[0, 1, 5]])
    with pytest.raises(ValueError, match="T"):
        fn(np.zeros((3, 3)), [[0, 1]])


def test_functions_do_not_mutate_inputs():
    V, T = icosphere(2, noise=0.1)
    V.setflags(write=False)
    T.setflags(write=False)
    for fn in (geo.face_normals, geo.face_areas, geo.vertex_normals,
               geo.cotangent_laplacian, geo.mass_matrix, geo.closest_points):
        fn(V, T) if fn is not geo.closest_points else fn(V, T, V[:5])
    for fn in (geo.edges, geo.triangle_adjacency, geo.boundary_edges,
               geo.boundary_loops):
        fn(T)
    geo.sample_surface(V, T, 10)
    geo.farthest_point_sampling(V, 5)
    geo.poisson_disk_vertices(V, 0.3)


@pytest.mark.parametrize("call, match", [
    (lambda: geo.edges([[0, 1, 2.5]]), "T"),
    (lambda: geo.edges([[0, -1, 2]]), "negative"),
    (lambda: geo.edges([[True, False, True]]), "T"),
    (lambda: geo.boundary_vertices([[0, 1, 2]], True), "n"),
    (lambda: geo.connected_components([[0, 1, 2]], 2), "T"),
    (lambda: geo.edges_of_polygons([[0, 3]], [0, 1, 2]), "offsets"),
    (lambda: geo.edges_of_polygons([0, 3], [0, -1, 2]), "indices"),
    (lambda: geo.uniform_laplacian([[0, 1]], 1), "T_or_edges"),
    (lambda: geo.sample_surface(np.zeros((3, 3)), [[0, 1, 2]], 2.5), "count"),
])
def test_index_validation(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_empty_inputs():
    assert geo.edges(np.zeros((0, 3), int)).shape == (0, 2)
    assert geo.triangle_adjacency(np.zeros((0, 3), int)).shape == (0, 3)
    assert geo.boundary_edges([]).shape == (0, 2)
    assert geo.vertex_adjacency([], 3).nnz == 0
    assert geo.connected_components([], 3).tolist() == [0, 1, 2]
    assert geo.uniform_laplacian([], 2).nnz == 0
    assert geo.mass_matrix(np.zeros((2, 3)), []).shape == (2, 2)
