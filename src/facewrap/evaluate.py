"""How good is a registration: distances, landmark and ground-truth errors, triangles.

This module owns the numbers by which a fitted mesh is judged (``facewrap evaluate``,
tests and benchmarks), each from a small function that returns a result object with
per-item arrays (for pictures) and a ``summary()`` of JSON-able statistics:

* :func:`surface_distances`: from points to a surface, aware of the surface's border:
  a point whose closest surface point lies on a border triangle (holes, crop) is
  not *covered* and is left out of the statistics, since a template usually
  reaches beyond what a scanner saw (and a scan beyond the template).  Used both
  ways: result vertices → scan and scan vertices → result.
* :func:`landmark_errors`: distances between paired landmark positions.
* :func:`ground_truth_errors`: per-vertex distance to a ground-truth mesh in the
  same topology (NaN rows of the truth, e.g. parts it does not cover, are skipped).
* triangle quality (:func:`facewrap.geometry.triangle_quality`): minimum angles,
  and against a reference mesh flipped triangles, area change and stretch.

:func:`evaluate` runs all that apply and returns an :class:`Evaluation`.
Distances are in the meshes' units (see :mod:`facewrap.units`).
:func:`role_codes` reads a run report's ``vertex_roles`` (half-open vertex-id
ranges per role), so that measures can be taken over the fitted vertices only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facewrap.geometry import (ClosestPointTree, TriangleQuality, triangle_quality,
                               triangle_to_vertex)
from facewrap.geometry.checks import as_positions, as_vertex_mask, mesh_arrays
from facewrap.landmarks import Landmarks, pair_landmarks

__all__ = ["SurfaceDistances", "LandmarkErrors", "GroundTruthErrors", "Evaluation",
           "surface_distances", "landmark_errors", "ground_truth_errors", "evaluate",
           "VERTEX_ROLE_NAMES", "role_codes"]

#: Roles of template vertices in a wrap (a run report's ``vertex_roles`` keys, in
#: code order): pulled onto the scan, or following it (parts that are not skin,
#: cavities no camera sees, the user's exclusions, pinned vertices).
VERTEX_ROLE_NAMES = ("fitted", "part", "cavity", "excluded", "pinned")


def _stats(values: np.ndarray) -> dict:
    """mean / median / p95 / max / rms of finite values; None for an empty set."""
    v = values[np.isfinite(values)]
    if len(v) == 0:
        return {"mean": None, "median": None, "p95": None, "max": None, "rms": None}
    return {"mean": float(v.mean()), "median": float(np.median(v)),
            "p95": float(np.percentile(v, 95)), "max": float(v.max()),
            "rms": float(np.sqrt(np.mean(v * v)))}


# -- vertex roles -----------------------------------------------------------------------------

def role_codes(vertex_roles, n: int) -> np.ndarray:
    """(n,) int8 role code per vertex (index into :data:`VERTEX_ROLE_NAMES`).

    Parameters
    ----------
    vertex_roles : dict of str to list of [start, stop)
        A run report's ``vertex_roles``: half-open vertex-id ranges per role.
    n : int
        Vertices of the template.

    Raises
    ------
    ValueError
        For an unknown role, a malformed or out-of-range range, or a vertex in no
        role or in two.

    Examples
    --------
    >>> role_codes({"fitted": [[0, 3], [5, 6]], "part": [[3, 5]]}, 6).tolist()
    [0, 0, 0, 1, 1, 0]
    """
    if not isinstance(vertex_roles, dict):
        raise ValueError("vertex_roles must map role names to [start, stop) ranges")
    codes = np.full(n, -1, dtype=np.int8)
    for role, ranges in vertex_roles.items():
        if role not in VERTEX_ROLE_NAMES:
            raise ValueError(f"vertex_roles: unknown role {role!r}; roles are "
                             f"{', '.join(VERTEX_ROLE_NAMES)}")
        R = np.asarray(ranges if len(ranges) else np.zeros((0, 2)))
        if R.ndim != 2 or R.shape[1] != 2 or not np.all(R == np.round(R)) or (
                len(R) and (R.min() < 0 or R.max() > n or np.any(R[:, 0] >= R[:, 1]))):
            raise ValueError(f"vertex_roles[{role!r}] must be [start, stop) ranges "
                             f"with 0 <= start < stop <= {n}")
        # per-vertex marks from the ranges without a loop over vertices
        marks = np.zeros(n + 1, dtype=np.int64)
        np.add.at(marks, R[:, 0].astype(np.int64), 1)
        np.add.at(marks, R[:, 1].astype(np.int64), -1)
        inside = np.cumsum(marks[:-1])
        if np.any(inside > 1) or np.any(codes[inside > 0] >= 0):
            raise ValueError(f"vertex_roles: a vertex of {role!r} is in two ranges")
        codes[inside > 0] = VERTEX_ROLE_NAMES.index(role)
    if np.any(codes < 0):
        raise ValueError(f"vertex_roles: vertex {int(np.argmax(codes < 0))} has no role")
    return codes


# -- surface distances ----------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class SurfaceDistances:
    """Distances from query points to a surface.

    Attributes
    ----------
    distances : (k,) float64
        Unsigned distance of each point to the surface.
    signed : (k,) float64
        The same, positive on the side the surface normal points to (outside a
        scan), negative behind it.
    covered : (k,) bool
        Point counts in the statistics: its closest surface point is not on a
        border triangle of the surface (when borders are excluded) and it is in the
        mask.
    eligible : (k,) bool or None
        Points in the mask (None: all), the denominator of :attr:`coverage`.
    """

    distances: np.ndarray
    signed: np.ndarray
    covered: np.ndarray
    eligible: np.ndarray | None = None

    @property
    def coverage(self) -> float:
        """Fraction of the eligible points (the mask's) that are covered."""
        n = len(self.covered) if self.eligible is None else int(self.eligible.sum())
        return float(self.covered.sum()) / n if n else 0.0

    def counted(self) -> np.ndarray:
        """Distances of the covered points (all points when none is covered)."""
        return self.distances[self.covered] if self.covered.any() else self.distances

    def values(self, signed: bool = False) -> np.ndarray:
        """(k,) float64 per-point values for pictures, NaN where not covered."""
        out = np.where(self.covered, self.signed if signed else self.distances, np.nan)
        return out

    def summary(self, prefix: str = "") -> dict:
        """``{prefix}mean``, ``p95``, ``max``, ``median``, ``rms``, ``coverage``.

        Statistics are over the covered points, or over all points when none is
        covered (``coverage`` is then 0); None when there are no points.
        ``coverage`` is the covered fraction of the mask's points.
        """
        s = _stats(self.counted())
        s["coverage"] = self.coverage
        return {prefix + k: v for k, v in s.items()}


def surface_distances(points, surface, *, exclude_border: bool = True,
                      mask=None) -> SurfaceDistances:
    """Distance from each point to a triangle surface, border-aware.

    Parameters
    ----------
    points : (k, 3) float
    surface : ClosestPointTree, Mesh or (V, T)
        A tree is reused as it is (build one per surface and share it).
    exclude_border : bool
        Points whose closest surface point lies on a border triangle (a triangle
        with a vertex on the mesh boundary: holes, cropped edges) are not covered.
    mask : (k,) bool or int ids, optional
        Only these points can be covered.

    Returns
    -------
    SurfaceDistances
        One row per point, unsigned and signed, and which points are covered.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> d = surface_distances([[0.2, 0.2, 0.5], [0.2, 0.2, -1.0]], (V, [[0, 1, 2]]),
    ...                       exclude_border=False)
    >>> d.distances.tolist(), d.signed.tolist(), d.summary()["mean"]
    ([0.5, 1.0], [0.5, -1.0], 0.75)
    """
    P = as_positions(points, "points")
    tree = surface if isinstance(surface, ClosestPointTree) else \
        ClosestPointTree(*mesh_arrays(surface, "surface"))
    eligible = as_vertex_mask(mask, len(P))
    if len(P) == 0:
        z = np.zeros(0)
        return SurfaceDistances(z, z.copy(), eligible.copy(), eligible)
    cp = tree.query(P)
    side = np.einsum("ij,ij->i", P - cp.points, cp.normals)
    signed = np.where(side < 0, -cp.distances, cp.distances)
    covered = eligible.copy()
    if exclude_border:
        covered &= ~tree.boundary_triangles[cp.triangles]
    return SurfaceDistances(cp.distances, signed, covered, eligible)


# -- landmarks ---------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class LandmarkErrors:
    """Distances between paired landmarks.

    Attributes
    ----------
    errors : (k,) float64
    names : tuple of str
        One per pair (indices as text when unnamed).
    positions, targets : (k, 3) float64 or None
        The paired positions the errors are measured between (e.g. result and
        scan landmarks), kept so that their plausibility can be checked
        (``facewrap evaluate`` warns of a mirrored or mis-paired file).
    """

    errors: np.ndarray
    names: tuple
    positions: np.ndarray | None = None
    targets: np.ndarray | None = None

    def summary(self, prefix: str = "landmark_") -> dict:
        """Statistics, the worst landmark and every error by name."""
        s = {prefix + k: v for k, v in _stats(self.errors).items()}
        s[prefix + "count"] = int(len(self.errors))
        if len(self.errors):
            s[prefix + "worst"] = self.names[int(np.argmax(self.errors))]
        s[prefix + "errors"] = {n: float(e) for n, e in zip(self.names, self.errors)}
        return s


def landmark_errors(positions, targets, names=None) -> LandmarkErrors:
    """Euclidean distance between paired landmark positions.

    Parameters
    ----------
    positions, targets : (k, 3) float
        Paired positions (e.g. landmarks of the fitted mesh and of the scan).
    names : sequence of k str, optional

    Returns
    -------
    LandmarkErrors

    Examples
    --------
    >>> e = landmark_errors([[0, 0, 0], [1, 1, 1.]], [[3, 4, 0], [1, 1, 1.]])
    >>> e.errors.tolist(), e.targets[0].tolist()
    ([5.0, 0.0], [3.0, 4.0, 0.0])
    """
    A = as_positions(positions, "positions")
    B = as_positions(targets, "targets")
    if A.shape != B.shape:
        raise ValueError(f"positions {A.shape} and targets {B.shape} must match")
    names = tuple(str(i) for i in range(len(A))) if names is None else \
        tuple(str(n) for n in names)
    if len(names) != len(A):
        raise ValueError(f"{len(names)} names for {len(A)} landmarks")
    return LandmarkErrors(np.linalg.norm(A - B, axis=1), names, A, B)


# -- ground truth --------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class GroundTruthErrors:
    """Per-vertex distance to ground truth in the same topology.

    Attributes
    ----------
    errors : (n,) float64
        NaN where the truth is NaN or the vertex is outside the mask.
    """

    errors: np.ndarray

    @property
    def count(self) -> int:
        """Vertices evaluated."""
        return int(np.isfinite(self.errors).sum())

    def summary(self, prefix: str = "correspondence_") -> dict:
        """Statistics and the count, keys ``{prefix}mean`` ... ``{prefix}count``.

        The default prefix is the key the report pages and ``facewrap evaluate``
        read (``correspondence_mean``: how far each vertex is from its true
        correspondent).
        """
        s = {prefix + k: v for k, v in _stats(self.errors).items()}
        s[prefix + "count"] = self.count
        return s


def ground_truth_errors(vertices, ground_truth, mask=None) -> GroundTruthErrors:
    """Distance of each vertex to where it should be.

    Parameters
    ----------
    vertices : (n, 3) float
        The fitted mesh's vertices.
    ground_truth : (n, 3) float
        True positions, same order; NaN rows are not evaluated.
    mask : (n,) bool or int ids, optional
        Vertices to evaluate.

    Returns
    -------
    GroundTruthErrors

    Examples
    --------
    >>> e = ground_truth_errors([[0, 0, 0], [1, 0, 0.]], [[0, 0, 2], [np.nan] * 3])
    >>> e.errors.tolist()[0], e.count
    (2.0, 1)
    """
    V = as_positions(vertices, "vertices")
    G = np.asarray(ground_truth, dtype=np.float64)
    if G.shape != V.shape:
        raise ValueError(f"ground_truth must have shape {V.shape}, got {G.shape}")
    keep = as_vertex_mask(mask, len(V)) & np.isfinite(G).all(axis=1)
    err = np.full(len(V), np.nan)
    err[keep] = np.linalg.norm(V[keep] - G[keep], axis=1)
    return GroundTruthErrors(err)


# -- everything ---------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Evaluation:
    """Outcome of :func:`evaluate`.

    Attributes
    ----------
    result_to_scan : SurfaceDistances
        One row per result vertex (distance to the scan; covered where the closest
        scan point is not on the scan's border).
    scan_to_result : SurfaceDistances
        One row per scan vertex (distance to the result; covered where the closest
        result point is not on the result's border).
    landmarks : LandmarkErrors or None
    ground_truth : GroundTruthErrors or None
    quality : TriangleQuality
        Of the result's triangulation (against the reference when one was given).
    triangles : (t, 3) int64
        The result's triangulation, which ``quality`` describes.
    n_vertices : int
        Vertices of the result.
    """

    result_to_scan: SurfaceDistances
    scan_to_result: SurfaceDistances
    landmarks: LandmarkErrors | None
    ground_truth: GroundTruthErrors | None
    quality: TriangleQuality
    triangles: np.ndarray
    n_vertices: int

    def summary(self) -> dict:
        """All statistics as a JSON-able dict (floats, ints, str, None, dicts).

        Keys: ``fit_*`` (result → scan: mean, median, p95, max, rms, coverage, as
        :func:`facewrap.wrapping.stages.fit_metrics` names them), ``scan_to_result_*``,
        ``landmark_*``, ``correspondence_*`` and ``triangles_*``.
        """
        out = {"vertices": int(self.n_vertices)}
        out.update(self.result_to_scan.summary("fit_"))
        out.update(self.scan_to_result.summary("scan_to_result_"))
        if self.landmarks is not None:
            out.update(self.landmarks.summary())
        if self.ground_truth is not None:
            out.update(self.ground_truth.summary())
        out.update(self.quality.summary())
        return out

    def vertex_values(self) -> dict:
        """Per-result-vertex (n,) float64 arrays for pictures, NaN where undefined.

        ``"fit"`` (distance to the scan, covered vertices only), ``"fit_signed"``,
        ``"correspondence"`` (with ground truth), ``"area_ratio"`` and ``"stretch"``
        (with a reference; mean over the triangles around each vertex),
        ``"flipped"`` (1.0 next to a flipped triangle, else 0.0).
        """
        out = {"fit": self.result_to_scan.values(),
               "fit_signed": self.result_to_scan.values(signed=True)}
        if self.ground_truth is not None:
            out["correspondence"] = self.ground_truth.errors.copy()
        tq = self.quality
        if tq.flipped is not None:
            T, n = self.triangles, self.n_vertices
            out["area_ratio"] = triangle_to_vertex(tq.area_ratio, T, n)
            out["stretch"] = triangle_to_vertex(tq.stretch, T, n)
            out["flipped"] = np.nan_to_num(
                triangle_to_vertex(tq.flipped.astype(float), T, n, "max"))
        return out


def _landmark_positions(lm, mesh_v, mesh_t, name):
    if isinstance(lm, Landmarks):
        return lm.positions(mesh_v, mesh_t)
    return as_positions(lm, name)


def evaluate(result, scan, *, ground_truth=None, result_landmarks=None,
             scan_landmarks=None, reference=None, mask=None,
             exclude_border: bool = True, scan_tree: ClosestPointTree | None = None
             ) -> Evaluation:
    """Every measure of a fitted mesh that its inputs allow.

    Parameters
    ----------
    result : Mesh or (V, T)
        The fitted mesh (template topology).
    scan : Mesh or (V, T)
        The target scan.
    ground_truth : (n, 3) float or Mesh, optional
        True positions of the result's vertices (same topology; NaN rows skipped).
    result_landmarks, scan_landmarks : Landmarks or (k, 3) float, optional
        Landmarks on the result (vertex / surface landmarks are placed on
        ``result``) and on the scan; paired by name when both are named
        :class:`~facewrap.landmarks.Landmarks`, else by order.
    reference : (n, 3) float or Mesh, optional
        The template before fitting, same topology: enables flipped triangles,
        area change and stretch.
    mask : (n,) bool or int ids, optional
        Result vertices to evaluate (fit distances, their coverage, and
        ground-truth errors): the fitted ones (:func:`role_codes`), e.g. the face
        without eyeballs and teeth.
    exclude_border : bool
        Leave points whose closest point is on the other mesh's border out of the
        distance statistics (see :func:`surface_distances`).
    scan_tree : ClosestPointTree, optional
        A tree already built on the scan.

    Returns
    -------
    Evaluation
    """
    V, T = mesh_arrays(result, "result")
    SV, ST = mesh_arrays(scan, "scan")
    tree = scan_tree if scan_tree is not None else ClosestPointTree(SV, ST)
    r2s = surface_distances(V, tree, exclude_border=exclude_border, mask=mask)
    s2r = surface_distances(SV, ClosestPointTree(V, T), exclude_border=exclude_border)
    lm = None
    if (result_landmarks is None) != (scan_landmarks is None):
        raise ValueError("give both result_landmarks and scan_landmarks, or neither")
    if result_landmarks is not None:
        names = None
        if isinstance(result_landmarks, Landmarks) and isinstance(scan_landmarks,
                                                                   Landmarks):
            ia, ib = pair_landmarks(result_landmarks, scan_landmarks)
            names = [result_landmarks.label(i) for i in ia]
        A = _landmark_positions(result_landmarks, V, T, "result_landmarks")
        B = _landmark_positions(scan_landmarks, SV, ST, "scan_landmarks")
        if names is None:
            if len(A) != len(B):
                raise ValueError(f"landmark counts differ: {len(A)} vs {len(B)}")
            ia = ib = np.arange(len(A))
        lm = landmark_errors(A[ia], B[ib], names)
    truth = None
    if ground_truth is not None:
        G = ground_truth.vertices if hasattr(ground_truth, "vertices") else ground_truth
        truth = ground_truth_errors(V, G, mask=mask)
    ref = None
    if reference is not None:
        ref = reference.vertices if hasattr(reference, "vertices") else reference
    tq = triangle_quality(V, T, ref)
    return Evaluation(r2s, s2r, lm, truth, tq, np.asarray(T, dtype=np.int64), len(V))
