"""Projection of template vertices onto the scan surface (SPEC §1.3), without tears.

For each template vertex ``V`` we look for the scan triangle ``ABC`` whose normal
prism contains it (Cohen et al., Simplification Envelopes): barycentric ``β`` and
offset ``s`` with ``Σ β_k (X_k + s N_k) = V``, so ``V`` lies on the line through the
surface point ``P = Σ β_k X_k`` along the interpolated normal ``N_P``, and ``V*=P``.
The three equations are bilinear in ``(β, s)``; a few vectorised Newton steps
solve them for all vertices and candidate triangles at once.  Candidates are the
closest triangle and its edge neighbours.

Fallbacks, in order: the first hit of the line along the template vertex normal
(both directions), then the closest point.  A vertex is left unprojected when its
move is longer than ``max_distance``, when the scan normal there and the template
normal differ by more than ``max_normal_angle``, when it lands on the scan's
boundary (holes, borders), or when a user mask excludes it (eyes, mouth interior,
back of head).  Unprojected vertices are not left behind: their displacement is
the smooth (bi)harmonic extension of their neighbours' over the template, so there
is no tear at the edge of the projected region.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facewrap.geometry import (ClosestPointTree, face_normals, turned, vertex_adjacency,
                               vertex_normals)
from facewrap.geometry.matching import compatible
from facewrap.geometry.arrays import cross_rows
from facewrap.mesh import Mesh
from facewrap.wrapping.blend import SmoothExtension, smooth_extension
from facewrap.wrapping.unfold import step_back_new_folds

__all__ = ["Projection", "project_to_surface", "prism_projection", "seen_fit_p95",
           "METHOD_NONE", "METHOD_PRISM", "METHOD_RAY", "METHOD_CLOSEST"]

METHOD_NONE, METHOD_PRISM, METHOD_RAY, METHOD_CLOSEST = 0, 1, 2, 3


@dataclass(frozen=True)
class Projection:
    """Result of :func:`project_to_surface`.

    Attributes
    ----------
    vertices : (n, 3) float64
        New template positions: on the scan where projected, smoothly blended
        elsewhere.
    projected : (n,) bool
    triangles : (n,) int64
        Scan triangle of each projected vertex, -1 otherwise.
    barycentric : (n, 3) float64
        Coordinates in that triangle (zeros where not projected).
    method : (n,) int8
        :data:`METHOD_PRISM`, :data:`METHOD_RAY`, :data:`METHOD_CLOSEST` or
        :data:`METHOD_NONE`.
    distances : (n,) float64
        How far each vertex moved.
    """
    vertices: np.ndarray
    projected: np.ndarray
    triangles: np.ndarray
    barycentric: np.ndarray
    method: np.ndarray
    distances: np.ndarray

    def summary(self) -> dict:
        """Counts per method and distance statistics (for reports)."""
        names = {METHOD_NONE: "none", METHOD_PRISM: "prism", METHOD_RAY: "ray",
                 METHOD_CLOSEST: "closest"}
        d = self.distances[self.projected]
        return {"vertices": int(len(self.projected)),
                "projected": int(self.projected.sum()),
                "by_method": {names[k]: int((self.method == k).sum()) for k in names},
                "mean_move": float(d.mean()) if len(d) else 0.0,
                "max_move": float(d.max()) if len(d) else 0.0}


def prism_projection(points, tree: ClosestPointTree, candidates, iterations: int = 8,
                     tol: float = 1e-10):
    """Solve Cohen's point-to-surface mapping for given candidate triangles.

    Parameters
    ----------
    points : (n, 3) float
    tree : ClosestPointTree
        The scan (vertices, triangles, vertex normals).
    candidates : (n, c) int64
        Candidate scan triangles per point (-1 = none).
    iterations : int
        Newton steps.
    tol : float
        Relative residual accepted as converged.

    Returns
    -------
    found : (n,) bool
    triangles : (n,) int64
    barycentric : (n, 3)
    offset : (n,) float
        ``s`` of ``V = P + s N_P`` (N_P not normalised).
    """
    X = np.asarray(points, dtype=np.float64)
    n, c = candidates.shape
    V, T, N = tree.vertices, tree.triangles, tree.vertex_normals
    valid = candidates >= 0
    tri = np.where(valid, candidates, 0).reshape(-1)
    Q = np.repeat(X, c, axis=0)
    A, B, C = (V[T[tri, k]] for k in range(3))
    NA, NB, NC = (N[T[tri, k]] for k in range(3))
    e1, e2, n1, n2 = B - A, C - A, NB - NA, NC - NA
    # start: projection onto the triangle plane
    fn = cross_rows(e1, e2)
    area2 = np.einsum("ij,ij->i", fn, fn)
    scale = np.sqrt(np.maximum(area2, 1e-300))
    w = Q - A
    b1 = np.einsum("ij,ij->i", cross_rows(w, e2), fn) / np.maximum(area2, 1e-300)
    b2 = np.einsum("ij,ij->i", cross_rows(e1, w), fn) / np.maximum(area2, 1e-300)
    s = np.zeros(len(Q))
    for _ in range(iterations):
        Np = NA + b1[:, None] * n1 + b2[:, None] * n2
        r = A + b1[:, None] * e1 + b2[:, None] * e2 + s[:, None] * Np - Q
        # J = [ja jb jc] (columns); Cramer's rule, vectorised: numpy's batched
        # LAPACK solve of many 3x3 systems is ~10x slower than these products
        ja, jb, jc = e1 + s[:, None] * n1, e2 + s[:, None] * n2, Np
        bc = cross_rows(jb, jc)
        det = np.einsum("ij,ij->i", ja, bc)
        ok = np.abs(det) > 1e-14 * scale ** 3
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        b1 = b1 - np.einsum("ij,ij->i", r, bc) * inv
        b2 = b2 - np.einsum("ij,ij->i", ja, cross_rows(r, jc)) * inv
        s = s - np.einsum("ij,ij->i", ja, cross_rows(jb, r)) * inv
    Np = NA + b1[:, None] * n1 + b2[:, None] * n2
    r = A + b1[:, None] * e1 + b2[:, None] * e2 + s[:, None] * Np - Q
    b0 = 1.0 - b1 - b2
    eps = 1e-9
    inside = (b0 >= -eps) & (b1 >= -eps) & (b2 >= -eps)
    conv = np.linalg.norm(r, axis=1) <= tol * np.maximum(1.0, np.sqrt(scale)) * 1e3
    good = (inside & conv & valid.reshape(-1) & np.isfinite(s)).reshape(n, c)
    # among valid candidates keep the smallest |s| (the nearest prism)
    score = np.where(good, np.abs(s).reshape(n, c), np.inf)
    best = np.argmin(score, axis=1)
    found = np.isfinite(score[np.arange(n), best])
    pick = np.arange(n) * c + best
    bary = np.clip(np.stack([b0, b1, b2], axis=1)[pick], 0.0, 1.0)
    bary /= bary.sum(axis=1, keepdims=True)
    return (found, np.where(found, tri[pick], -1), np.where(found[:, None], bary, 0.0),
            np.where(found, s[pick], np.nan))


def _landing_compatible(tree: ClosestPointTree, V, N, P, tri, bary, max_distance,
                        max_normal_angle, reject_boundary) -> np.ndarray:
    """Which landing points ``P`` (k, 3) on triangles ``tri`` of the scan the
    vertices ``V`` with normals ``N`` may move to: the matcher's distance, normal
    and border rules, with the scan normal interpolated at the landing point."""
    Ns = np.einsum("ij,ijk->ik", bary, tree.vertex_normals[tree.triangles[tri]])
    Ns /= np.maximum(np.linalg.norm(Ns, axis=1, keepdims=True), 1e-300)
    ok, _ = compatible(tree, np.linalg.norm(P - V, axis=1), tri, Ns, N,
                       max_distance=max_distance, max_normal_angle=max_normal_angle,
                       reject_border=reject_boundary)
    return ok


def _landing_points(Vt, Nt, tree: ClosestPointTree, allowed, methods, max_distance):
    """Each allowed vertex's landing point by the first method that finds one.

    Returns the method (n,) int8, scan triangle (n,) int64 (-1: none) and
    barycentric coordinates (n, 3) of every vertex.
    """
    n = len(Vt)
    method = np.zeros(n, dtype=np.int8)
    tri = np.full(n, -1, dtype=np.int64)
    bary = np.zeros((n, 3))
    todo = allowed.copy()
    # closest points of the allowed vertices only (a production head's parts and
    # cavities, half its vertices, never land)
    near = np.full(n, -1, dtype=np.int64)
    near[allowed] = np.arange(np.count_nonzero(allowed))
    cp = tree.query(Vt[allowed])
    if "prism" in methods and todo.any():
        idx = np.flatnonzero(todo)
        cand = np.concatenate([cp.triangles[near[idx], None],
                               tree.neighbours_of(cp.triangles[near[idx]])], axis=1)
        found, t_, b_, _ = prism_projection(Vt[idx], tree, cand)
        hit = idx[found]
        method[hit], tri[hit], bary[hit] = METHOD_PRISM, t_[found], b_[found]
        todo[hit] = False
    if "ray" in methods and todo.any():
        idx = np.flatnonzero(todo)
        rh = tree.ray_hits(Vt[idx], Nt[idx], max_distance=max_distance)
        hit = idx[rh.hit]
        method[hit], tri[hit], bary[hit] = METHOD_RAY, rh.triangles[rh.hit], \
            rh.barycentric[rh.hit]
        todo[hit] = False
    if "closest" in methods and todo.any():
        idx = np.flatnonzero(todo)
        method[idx], tri[idx], bary[idx] = METHOD_CLOSEST, cp.triangles[near[idx]], \
            cp.barycentric[near[idx]]
    return method, tri, bary


def _blend_without_folds(template: Mesh, Vt, P, ok, fold_angle: float,
                         fold_rounds: int, upright=None):
    """Projected vertices at ``P``, the others blended harmonically; the fold guard.

    On a coarse or faceted scan, neighbouring vertices can land on either side of a
    scan edge and turn a template triangle over.  Their vertices are not projected
    but follow the blend instead, until no triangle turns past ``fold_angle`` from
    where the fit left it (at most ``fold_rounds`` rounds).  A triangle the blend
    itself turns (no corner projected) lets go of the projected vertices nearest
    to it (up to ``_FOLD_REACH`` rings away).  ``upright`` (t, 3), when given, are
    normals no triangle may turn past 90 degrees from either.  Returns the
    positions (n, 3) and the final projected mask (n,).
    """
    T = template.triangles
    n0 = face_normals(Vt, T)
    ok = ok.copy()
    extend = SmoothExtension(template, 1)   # harmonic; one mesh, every round
    adjacency = None
    for _ in range(fold_rounds + 1):
        out = Vt + extend(P - Vt, ok)
        out[ok] = P[ok]  # exact landing points (no round-off from the blend)
        if fold_rounds == 0:
            break
        n1 = face_normals(out, T)
        # a triangle the projection collapsed (zero normal after, not before) has
        # lost its orientation: it is a fold too, though the turn test skips it
        collapsed = ~n1.any(axis=1) & n0.any(axis=1)
        bad = np.zeros(len(Vt), dtype=bool)
        folds = turned(n0, n1, fold_angle) | collapsed
        if upright is not None:
            folds |= turned(upright, n1, 90.0)
        bad[T[folds]] = True
        # a fold among blended vertices only: the offsets that drive the blend change
        # too fast there, so the projected vertices nearest to it are let go
        for _ in range(_FOLD_REACH):
            if (bad & ok).any() or not bad.any():
                break
            if adjacency is None:
                adjacency = vertex_adjacency(T, len(Vt))
            bad |= (adjacency @ bad.astype(np.float64)) > 0
        bad &= ok
        if not bad.any():
            break
        ok &= ~bad
    return out, ok


#: rings around a fold among blended vertices searched for projected ones to let go
_FOLD_REACH = 6


def project_to_surface(template: Mesh, tree: ClosestPointTree, *, vertices=None,
                       normals=None, mask=None, max_distance: float | None = None,
                       max_normal_angle: float = 60.0, methods=("prism", "ray", "closest"),
                       reject_boundary: bool = True, blend_order: int = 1,
                       fold_angle: float = 60.0, fold_rounds: int = 8,
                       upright=None, reference=None) -> Projection:
    """Move template vertices onto the scan along normals, blending the rest.

    Parameters
    ----------
    template : Mesh
        Topology (for normals and the blending Laplacian); positions are
        ``vertices`` when given, else ``template.vertices``.
    tree : ClosestPointTree
        The scan surface, built once.
    vertices : (n, 3) float, optional
        Current template positions (after alignment/warp).
    normals : (n, 3) float, optional
        Template vertex normals (default: computed).
    mask : (n,) bool, optional
        True where a vertex may be projected (default all).
    max_distance : float, optional
        Longest allowed move (default: 5 % of the template's bounding-box diagonal).
    max_normal_angle : float
        Degrees between template normal and scan normal at the landing point.
    methods : sequence of {"prism", "ray", "closest"}
        Which steps to try, in this order.
    reject_boundary : bool
        Do not land on triangles touching the scan's boundary (holes, borders).
    blend_order : {1, 2}
        Blending of unprojected vertices: harmonic; or, for those that ``mask``
        allows but did not land, biharmonic (smooth where projected and blended
        vertices meet, so a blended gap follows the scan's curvature) except
        where it would turn a triangle, or crease two, that the harmonic blend
        does not: there it steps back toward the harmonic blend
        (:func:`~facewrap.wrapping.unfold.step_back_new_folds`).  The
        vertices ``mask`` leaves out, and the fold guard below, use the harmonic
        blend in both cases.
    fold_angle : float
        Degrees: a template triangle whose normal turns further than this from
        its normal before projection un-projects its vertices (they follow the
        blend), up to ``fold_rounds`` times; 0 rounds: no guard.
    upright : (n, 3) float, optional
        Positions whose triangle orientation the result must keep: a triangle turned
        past 90 degrees from them un-projects its vertices too (a second projection
        from an unfolded pose keeps that pose's orientation).
    reference : (n, 3) float, optional
        Positions whose triangle orientation the biharmonic fill (``blend_order``
        2) must not turn where the harmonic blend does not: the aligned template
        or the fit's rest pose.  Default ``upright``, else ``vertices``.

    Returns
    -------
    Projection
    """
    Vt = np.asarray(template.vertices if vertices is None else vertices, dtype=np.float64)
    n = template.n_vertices
    if Vt.shape != (n, 3):
        raise ValueError(f"vertices must have shape ({n}, 3), got {Vt.shape}")
    unknown = set(methods) - {"prism", "ray", "closest"}
    if unknown:
        raise ValueError(f"unknown projection methods {sorted(unknown)}")
    Nt = (vertex_normals(Vt, template.triangles) if normals is None
          else np.asarray(normals, dtype=np.float64))
    allowed = np.ones(n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if allowed.shape != (n,):
        raise ValueError(f"mask must have shape ({n},), got {allowed.shape}")
    if max_distance is None:
        max_distance = 0.05 * float(np.linalg.norm(Vt.max(0) - Vt.min(0)))

    method, tri, bary = _landing_points(Vt, Nt, tree, allowed, methods, max_distance)
    has = tri >= 0
    P = np.zeros((n, 3))
    P[has] = np.einsum("ij,ijk->ik", bary[has], tree.vertices[tree.triangles[tri[has]]])
    ok = np.zeros(n, dtype=bool)
    ok[has] = _landing_compatible(tree, Vt[has], Nt[has], P[has], tri[has], bary[has],
                                  max_distance, max_normal_angle, reject_boundary)
    # the fold guard runs on the harmonic blend, which folds least and never
    # overshoots; with blend_order 2 a biharmonic blend then fills the gaps among
    # the vertices that may be projected (a harmonic one sags between landing
    # points; a biharmonic one follows the scan's curvature), stepping back to the
    # harmonic blend wherever it would fold (turn or crease) what the harmonic one
    # does not.
    # Vertices that may not be projected (parts, cavities) keep the harmonic blend:
    # a biharmonic one overshoots across such large regions.
    out, ok = _blend_without_folds(
        template, Vt, P, ok, fold_angle, fold_rounds,
        upright=None if upright is None else face_normals(
            np.asarray(upright, dtype=np.float64), template.triangles))
    gaps = allowed & ~ok
    if blend_order == 2 and gaps.any():
        smooth = Vt + smooth_extension(template, out - Vt, ~gaps, order=2)
        smooth[~gaps] = out[~gaps]    # exact landing points (no round-off from the fill)
        if reference is None:
            reference = Vt if upright is None else upright
        out = step_back_new_folds(template.triangles, reference, out, smooth, ~gaps)[0]
    method[~ok] = METHOD_NONE
    tri[~ok] = -1
    bary[~ok] = 0.0
    return Projection(out, ok, tri, bary, method, np.linalg.norm(out - Vt, axis=1))


def seen_fit_p95(tree: ClosestPointTree, points) -> float:
    """95th percentile of the distances from ``points`` (k, 3) to the scan, over
    those whose closest point is off the scan's border (as a fit is judged: a
    vertex beyond the scan's edge is not fitted by landing nearer to it); 0 when
    there are none.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0.]])
    >>> seen_fit_p95(ClosestPointTree(V, np.array([[0, 1, 2]])), [[1, 1, 0.5]])
    0.0
    """
    cp = tree.query(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    seen = ~tree.boundary_triangles[cp.triangles]
    return float(np.percentile(cp.distances[seen], 95)) if seen.any() else 0.0
