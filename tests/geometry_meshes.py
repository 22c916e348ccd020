"""Test meshes and brute-force oracles shared by the tests of facewrap.geometry.

Meshes are built with numpy alone (an icosphere, grids, triangle soups with
degenerate triangles); the oracles answer closest-point and ray queries by
testing every triangle.
"""

from __future__ import annotations

import numpy as np


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


def flat_square(n=11, size=10.0):
    """A flat (n x n)-vertex square in the z = 0 plane, normals +z."""
    s = np.linspace(0, size, n)
    X, Y = np.meshgrid(s, s, indexing="ij")
    V = np.stack([X.ravel(), Y.ravel(), np.zeros(n * n)], axis=1)
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
    i = i.ravel()
    T = np.concatenate([np.stack([i, i + n, i + n + 1], 1), np.stack([i, i + n + 1, i + 1], 1)])
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


def quad_ellipsoid(n=40):
    """An open ellipsoid band of n x (n - 1) quads: (V (n*n, 3), quads (q, 4))."""
    u, v = np.meshgrid(np.linspace(0.2, np.pi - 0.2, n), np.linspace(0, 2 * np.pi, n,
                                                                      endpoint=False))
    V = np.stack([np.sin(u) * np.cos(v), np.sin(u) * np.sin(v) * 0.8, np.cos(u) * 1.2],
                 -1).reshape(-1, 3)
    i = np.arange(n * n).reshape(n, n)
    a, b = i, np.roll(i, -1, axis=0)
    c, d = np.roll(b, -1, axis=1), np.roll(a, -1, axis=1)
    quads = np.stack([a, b, c, d], -1)[:, :-1].reshape(-1, 4)
    return V, quads
