"""Benchmark: closest-point queries, facewrap's ClosestPointTree against raw libigl.

Builds a noise-perturbed torus of 500k triangles (numpy only), draws 20k query points
near its surface, and times, best of 3 runs:

(a) raw libigl: ``igl.AABB().init`` + ``squared_distance``;
(b) facewrap: ``ClosestPointTree(V, T)`` + ``query`` (which adds vertex normals,
    barycentric coordinates and interpolated normals), on each of its search-tree
    engines (:mod:`facewrap.geometry.search_trees`: FCPW, the default, and libigl);
(c) the ratios (b) / (a).

It then checks :func:`facewrap.geometry.closest_points` on each engine against an
exact reference that uses neither: on 2k of the points, against every triangle whose
centroid is close enough to possibly beat the answer (a complete candidate set), and
on 20 points, against all 500k triangles.

Run ``python benchmarks/bench_closest.py``; ``run()`` returns the numbers as a dict.
"""

from __future__ import annotations

import os
import time

import igl
import numpy as np
from scipy.spatial import cKDTree

from facewrap.geometry import ClosestPointTree
from facewrap.geometry.search_trees import ENGINES, load_fcpw, search_tree

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


def _tree(V, T, engine: str) -> ClosestPointTree:
    """``ClosestPointTree(V, T)`` on ``engine``'s search tree (built once)."""
    tree = ClosestPointTree.__new__(ClosestPointTree)
    previous = os.environ.get("FACEWRAP_SEARCH_TREE")
    os.environ["FACEWRAP_SEARCH_TREE"] = engine
    try:
        tree.__init__(V, T)
    finally:
        if previous is None:
            os.environ.pop("FACEWRAP_SEARCH_TREE")
        else:
            os.environ["FACEWRAP_SEARCH_TREE"] = previous
    assert tree.engine == engine
    return tree


def run(n_queries: int = 20_000, n_check: int = 2_000, n_brute: int = 20,
        seed: int = 1) -> dict:
    """Time raw libigl and ClosestPointTree on each engine; check accuracy.
    Returns a dict."""
    V, T = torus()
    rng = np.random.default_rng(seed)
    P = V[rng.integers(0, len(V), n_queries)] + 0.02 * rng.standard_normal((n_queries, 3))
    engines = [e for e in ENGINES if e != "fcpw" or load_fcpw() is not None]

    def raw():
        tree = igl.AABB()
        tree.init(V, T)
        return tree

    times = {name: ([], []) for name in ["raw", *engines]}
    for name in times:                                  # warm-up
        (raw() if name == "raw" else _tree(V, T, name))
    # interleave them so that machine noise hits all alike
    for _ in range(REPEATS):
        for name, (build, query) in times.items():
            t0 = time.perf_counter()
            tree = raw() if name == "raw" else _tree(V, T, name)
            t1 = time.perf_counter()
            tree.squared_distance(V, T, P) if name == "raw" else tree.query(P)
            build.append(t1 - t0), query.append(time.perf_counter() - t1)
    results = {"triangles": len(T), "vertices": len(V), "queries": n_queries,
               "check_points": n_check, "brute_force_points": n_brute, "rows": {}}
    sub = P[:n_check]
    brute = None
    for name, (build, query) in times.items():
        row = {"build_s": min(build), "query_s": min(query),
               "total_s": min(b + q for b, q in zip(build, query))}
        if name != "raw":           # accuracy against exact references
            cp = _tree(V, T, name).query(sub)
            ref, candidates = reference_distances(V, T, sub, cp.distances)
            if brute is None:
                brute = brute_force_distances(V, T, sub[:n_brute])
            recon = np.einsum("kc,kcd->kd", cp.barycentric, V[T[cp.triangles]])
            row.update(
                max_abs_distance_error=float(np.abs(cp.distances - ref).max()),
                mean_candidates_per_point=candidates,
                max_barycentric_reconstruction_error=float(np.abs(recon - cp.points).max()),
                max_abs_error_vs_all_triangles=float(
                    np.abs(cp.distances[:n_brute] - brute).max()))
        results["rows"][name] = row
    return results


def markdown(results: dict) -> str:
    r = results
    raw = r["rows"]["raw"]
    lines = [
        f"### Closest points: {r['queries']} queries on a {r['triangles']}-triangle mesh "
        f"(best of {REPEATS})",
        "",
        "`ClosestPointTree` adds vertex normals and barycentric coordinates; on "
        "FCPW's float32 tree also the point measured again in float64 on the "
        "triangle it names, and the walk that settles points on an edge or a corner "
        "on the nearest triangle around (its vertex fans are built by the first "
        "query, timed here; on this noisy torus most points land on an edge or a "
        "corner, in a wrap about one in nine); ratios are to raw libigl.",
        "",
        "| | build (s) | query (s) | total (s) | build ÷ raw | query ÷ raw | total ÷ raw |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    names = {"raw": "raw `igl.AABB`",
             "fcpw": "`ClosestPointTree`, FCPW (the default from 500k triangles)",
             "libigl": "`ClosestPointTree`, libigl (the default below)"}
    for name, row in r["rows"].items():
        lines.append(f"| {names[name]} | {row['build_s']:.3f} | {row['query_s']:.3f} | "
                     f"{row['total_s']:.3f} | {row['build_s'] / raw['build_s']:.2f} | "
                     f"{row['query_s'] / raw['query_s']:.2f} | "
                     f"**{row['total_s'] / raw['total_s']:.2f}** |")
    lines += ["", "| accuracy check | " + " | ".join(
        names[n].split(", ")[-1] for n in r["rows"] if n != "raw") + " |",
        "|---|" + "---:|" * (len(r["rows"]) - 1)]
    checked = [row for n, row in r["rows"].items() if n != "raw"]
    if checked:
        first = checked[0]
        for key, label in (
                ("max_abs_distance_error",
                 f"max distance error, {r['check_points']} points vs exact reference "
                 f"(~{first['mean_candidates_per_point']:.0f} candidate triangles each)"),
                ("max_abs_error_vs_all_triangles",
                 f"max distance error, {r['brute_force_points']} points vs all triangles"),
                ("max_barycentric_reconstruction_error",
                 "max \\|barycentric @ corners - point\\|")):
            lines.append(f"| {label} | " + " | ".join(f"{row[key]:.1e}" for row in checked)
                         + " |")
    lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    t0 = time.perf_counter()
    res = run()
    print(markdown(res))
    print(f"\n(benchmark ran in {time.perf_counter() - t0:.1f} s)")
