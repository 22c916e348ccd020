"""Benchmark: closest-point queries, facewrap's ClosestPointTree against raw libigl.

Builds a noise-perturbed torus of 500k triangles (numpy only), draws 20k query points
near its surface, and times, best of 3 runs:

(a) raw libigl: ``igl.AABB().init`` + ``squared_distance``;
(b) facewrap: ``ClosestPointTree(V, T)`` + ``query`` (which adds vertex normals,
    barycentric coordinates and interpolated normals);
(c) the ratio (b) / (a), target <= 1.2.

It then checks :func:`facewrap.geometry.closest_points` against an exact reference
that does not use libigl: on 2k of the points, against every triangle whose centroid
is close enough to possibly beat the answer (a complete candidate set), and on 20
points, against all 500k triangles.

Run ``python benchmarks/bench_closest.py``; ``run()`` returns the numbers as a dict.
"""

from __future__ import annotations

import time

import igl
import numpy as np
from scipy.spatial import cKDTree

from facewrap.geometry import ClosestPointTree, closest_points

REPEATS = 3


def torus(nu: int = 500, nv: int = 500, R: float = 1.0, r: float = 0.4,
          noise: float = 0.002, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Closed torus of ``2 * nu * nv`` triangles, radius perturbed by ``noise``."""
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    v = np.linspace(0, 2 * np.pi, nv, endpoint=False)
    U, W = np.meshgrid(u, v, indexing="ij")
    rr = r + noise * np.random.default_rng(seed).standard_normal(U.shape)
    V = np.stack([(R + rr * np.cos(W)) * np.cos(U), (R + rr * np.cos(W)) * np.sin(U),
                  rr * np.sin(W)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = i * nv + j, ((i + 1) % nu) * nv + j
    c, d = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    T = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                        np.stack([a, c, d], -1).reshape(-1, 3)]).astype(np.int64)
    return V, T


def point_triangle_sq_dist(P, A, B, C):
    """Squared distance of each point to its triangle, rows paired (Ericson 5.1.5)."""
    ab, ac, ap = B - A, C - A, P - A
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = P - B
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = P - C
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        conds = [
            (d1 <= 0) & (d2 <= 0),                                   # vertex A
            (d3 >= 0) & (d4 <= d3),                                  # vertex B
            (vc <= 0) & (d1 >= 0) & (d3 <= 0),                       # edge AB
            (d6 >= 0) & (d5 <= d6),                                  # vertex C
            (vb <= 0) & (d2 >= 0) & (d6 <= 0),                       # edge AC
            (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),             # edge BC
        ]
        s_ab, s_ac = d1 / (d1 - d3), d2 / (d2 - d6)
        s_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        denom = 1.0 / (va + vb + vc)
        choices = [A, B, A + s_ab[:, None] * ab, C, A + s_ac[:, None] * ac,
                   B + s_bc[:, None] * (C - B)]
        inside = A + (vb * denom)[:, None] * ab + (vc * denom)[:, None] * ac
        Q = inside.copy()
        for cond, X in zip(conds[::-1], choices[::-1]):   # first matching region wins
            Q[cond] = X[cond]
    diff = P - Q
    return np.einsum("ij,ij->i", diff, diff)


def reference_distances(V, T, P, found):
    """Exact distances, testing every triangle that could be closer than ``found``."""
    A, B, C = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
    centroid = (A + B + C) / 3
    reach = np.sqrt(np.max([np.einsum("ij,ij->i", X - centroid, X - centroid).max()
                            for X in (A, B, C)]))
    groups = cKDTree(centroid).query_ball_point(P, found + reach + 1e-9)
    sizes = np.fromiter((len(g) for g in groups), dtype=np.int64, count=len(P))
    tri = np.concatenate([np.asarray(g, dtype=np.int64) for g in groups])
    pts = np.repeat(np.arange(len(P)), sizes)
    sq = point_triangle_sq_dist(P[pts], A[tri], B[tri], C[tri])
    best = np.full(len(P), np.inf)
    np.minimum.at(best, pts, sq)
    return np.sqrt(best), float(sizes.mean())


def brute_force_distances(V, T, P, chunk=250_000):
    """Exact distances against all triangles (slow: use few points)."""
    A, B, C = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
    out = np.empty(len(P))
    for k, p in enumerate(P):
        best = np.inf
        for s in range(0, len(T), chunk):
            sl = slice(s, s + chunk)
            Pk = np.broadcast_to(p, A[sl].shape)
            best = min(best, point_triangle_sq_dist(Pk, A[sl], B[sl], C[sl]).min())
        out[k] = np.sqrt(best)
    return out


def run(n_queries: int = 20_000, n_check: int = 2_000, n_brute: int = 20,
        seed: int = 1) -> dict:
    """Time raw libigl and ClosestPointTree; check accuracy. Returns a flat dict."""
    V, T = torus()
    rng = np.random.default_rng(seed)
    P = V[rng.integers(0, len(V), n_queries)] + 0.02 * rng.standard_normal((n_queries, 3))

    def raw_init():
        tree = igl.AABB()
        tree.init(V, T)
        return tree

    def ours_init():
        return ClosestPointTree(V, T)

    raw_tree, ours_tree = raw_init(), ours_init()     # warm-up
    results = {}
    # interleave the two so that machine noise hits both alike
    raw_i, raw_q, our_i, our_q, raw_t, our_t = [], [], [], [], [], []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        raw_tree = raw_init()
        t1 = time.perf_counter()
        raw_tree.squared_distance(V, T, P)
        t2 = time.perf_counter()
        ours_tree = ours_init()
        t3 = time.perf_counter()
        ours_tree.query(P)
        t4 = time.perf_counter()
        raw_i.append(t1 - t0), raw_q.append(t2 - t1), raw_t.append(t2 - t0)
        our_i.append(t3 - t2), our_q.append(t4 - t3), our_t.append(t4 - t2)
    results.update(
        triangles=len(T), vertices=len(V), queries=n_queries,
        raw_init_s=min(raw_i), raw_query_s=min(raw_q), raw_total_s=min(raw_t),
        ours_init_s=min(our_i), ours_query_s=min(our_q), ours_total_s=min(our_t),
    )
    results["ratio_total"] = results["ours_total_s"] / results["raw_total_s"]
    results["ratio_query_only"] = results["ours_query_s"] / results["raw_query_s"]

    # accuracy: one-shot closest_points on a subset against exact references
    sub = P[:n_check]
    cp = closest_points(V, T, sub)
    ref, candidates = reference_distances(V, T, sub, cp.distances)
    recon = np.einsum("kc,kcd->kd", cp.barycentric, V[T[cp.triangles]])
    brute = brute_force_distances(V, T, sub[:n_brute])
    results.update(
        check_points=n_check,
        max_abs_distance_error=float(np.abs(cp.distances - ref).max()),
        mean_candidates_per_point=candidates,
        max_barycentric_reconstruction_error=float(np.abs(recon - cp.points).max()),
        brute_force_points=n_brute,
        max_abs_error_vs_all_triangles=float(np.abs(cp.distances[:n_brute] - brute).max()),
    )
    return results


def markdown(results: dict) -> str:
    r = results
    lines = [
        f"### Closest points: {r['queries']} queries on a {r['triangles']}-triangle mesh "
        f"(best of {REPEATS})",
        "",
        "| | build (s) | query (s) | total (s) |",
        "|---|---:|---:|---:|",
        f"| raw `igl.AABB` | {r['raw_init_s']:.3f} | {r['raw_query_s']:.3f} | "
        f"{r['raw_total_s']:.3f} |",
        f"| `ClosestPointTree` | {r['ours_init_s']:.3f} | {r['ours_query_s']:.3f} | "
        f"{r['ours_total_s']:.3f} |",
        f"| ratio | {r['ours_init_s'] / r['raw_init_s']:.2f} | "
        f"{r['ratio_query_only']:.2f} | **{r['ratio_total']:.2f}** |",
        "",
        "| accuracy check | value |",
        "|---|---:|",
        f"| max distance error, {r['check_points']} points vs exact reference "
        f"(~{r['mean_candidates_per_point']:.0f} candidate triangles each) | "
        f"{r['max_abs_distance_error']:.1e} |",
        f"| max distance error, {r['brute_force_points']} points vs all triangles | "
        f"{r['max_abs_error_vs_all_triangles']:.1e} |",
        f"| max \\|barycentric @ corners - point\\| | "
        f"{r['max_barycentric_reconstruction_error']:.1e} |",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    t0 = time.perf_counter()
    res = run()
    print(markdown(res))
    print(f"\n(benchmark ran in {time.perf_counter() - t0:.1f} s)")
