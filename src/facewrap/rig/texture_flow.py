"""An expression's wrap refined by its texture: skin that slid is put back on its skin.

A closest-point fit puts every template vertex on the expression scan's surface
but not necessarily on the *same skin* as in the neutral: where skin slides along
smooth skin (the forehead under a brow raise, the cheeks under a smile), nothing
in the geometry says how far.  The texture says it.  The neutral's wrap carries
the neutral scan's texture baked into the template's layout; drawn at the
expression wrap's positions it must look like the expression scan wherever the
wrap is right.  :func:`refine_by_texture` runs rounds of

1. draw both from cameras around the face and match them by optical flow
   (:func:`~facewrap.rig.flow_match.flow_matches`: each match a template surface
   point, a scan point and a confidence);
2. solve for the smooth displacement of the skin that carries the template points
   onto their matches: weighted least squares with a Laplacian smoothness term
   (one sparse factorisation, three right-hand sides), matches far off the
   solution down-weighted (Welsch) and solved again;
3. put the vertices the geometric wrap had on the scan back onto it (closest
   points: the texture moves them along the surface, not off it), and let the
   template's parts follow the skin.

A round is kept only when the flow's disagreement measured after it (the
confidence-weighted mean distance of the matches, fresh flow) is smaller than
before it by ``min_gain`` at least (the flow's own noise keeps the disagreement
from reaching zero: a small drop only fits that noise); the first round that
does not help ends the refinement, so a scan whose texture
says nothing (no texture detail, a texture from another session) leaves the wrap
as it is, and so does one whose pictures match in too few places to say much.

Why a displacement solve of its own rather than the flow points as landmarks of
the wrap's ICP: the ICP's landmark term is a mean over all landmarks with one
weight (thousands of flow points would drown the 68 real ones and cannot carry a
confidence each), and the deformation model's graph is coarser than the skin's
slide; the geometric wrap is already on the surface, so only the tangential
placement is left to fix, which a smooth field on the template does directly.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from facewrap.geometry import ClosestPointTree
from facewrap.geometry.laplacian import uniform_laplacian
from facewrap.mesh import Mesh
from facewrap.params import Flag, Interval
from facewrap.geometry.normals import trusted_vertex_normals
from facewrap.rig.flow_match import (FlowMatches, MatchRules, ScanViews,
                                     TexturedSurface, face_cameras, flow_matches,
                                     prefiltered)
from facewrap.solve.factor import factorize
from facewrap.texture.bake import MAX_SIDE

__all__ = ["TextureFlowSettings", "TextureRefinement", "refine_by_texture",
           "flow_available", "FLOW_EXTRA"]

#: the fewest pixels an image has along each side for the flow to run
MIN_IMAGE_SIDE = 2

#: the optional extra that installs OpenCV (headless)
FLOW_EXTRA = "facewrap[flow]"
#: Welsch scale of the robust re-solve, in median absolute residuals
_ROBUST = 3.0
#: smallest robust scale, fraction of the mesh size (flow noise)
_ROBUST_FLOOR = 2e-4
#: fewest matches per skin vertex the pictures show for a round to be tried: a
#: texture that says nothing (another session's, none at all) leaves a few chance
#: matches only
_MIN_MATCHES = 0.25


@dataclass(frozen=True)
class TextureFlowSettings(MatchRules):
    """Settings of :func:`refine_by_texture`: the flow's match rules
    (:class:`~facewrap.rig.flow_match.MatchRules`, their one home: ``method``,
    ``consistency``, ``min_gradient``, ``max_angle``, ``max_distance``, ``step``,
    the distance a fraction of the wrap's skin size) and the refinement's own.

    Attributes
    ----------
    enabled : bool
        Refine expression wraps by texture when both scans carry one (and OpenCV,
        the extra ``facewrap[flow]``, is installed).
    rounds : int
        Most rounds of (flow, solve).
    views : int
        Cameras around the face: the front, then 30-degree turns about two axes.
    image_size : int
        Width and height of each picture, pixels.
    smoothness : float
        Weight of the Laplacian term against the matches (a vertex's matches count
        1 together): larger, smoother corrections.
    min_gain : float
        A round is kept when it cuts the flow's disagreement by this fraction.
    texture_size : int
        Size of the neutral's texture baked into the template's layout, pixels
        (:func:`~facewrap.rig.build_rig`: the reference of the refinement and the
        rig's texture, :attr:`~facewrap.rig.Rig.texture`; a rig job's
        ``texture_size``).
    """
    enabled: bool = True
    rounds: int = 1
    views: int = 5
    image_size: int = 640
    smoothness: float = 1.0
    min_gain: float = 0.15
    texture_size: int = 1024
    constraints = {**MatchRules.constraints,
                   "enabled": Flag(), "rounds": Interval(int, 1, 10),
                   "views": Interval(int, 1, 5), "image_size": Interval(int, 64, 4096),
                   "smoothness": Interval(float, 0, None, closed="neither"),
                   "min_gain": Interval(float, 0, 1, closed="left"),
                   "texture_size": Interval(int, 1, MAX_SIDE)}


@dataclass(frozen=True)
class TextureRefinement:
    """Outcome of :func:`refine_by_texture`.

    Attributes
    ----------
    vertices : (n, 3) float64
        The refined wrap.
    rounds : list of dict
        Per round tried: ``matches`` (kept), ``disagreement`` (confidence-weighted
        mean distance of the matches before the round's solve, mesh units),
        ``kept`` (whether the round's solve was kept), ``rejected`` (pixels
        dropped per reason).
    moved : float
        Mean distance the skin vertices moved, mesh units.
    seconds : float
    """
    vertices: np.ndarray
    rounds: list = field(default_factory=list)
    moved: float = 0.0
    seconds: float = 0.0


def flow_available(warn: bool = True) -> bool:
    """Whether OpenCV's optical flow can be imported; when not and ``warn``, one
    warning line naming the extra to install."""
    try:
        import cv2
        cv2.DISOpticalFlow_create   # noqa: B018 - the headless build has it
    except (ImportError, AttributeError):
        if warn:
            warnings.warn(f"texture refinement skipped: OpenCV is not installed "
                          f"(pip install '{FLOW_EXTRA}')", RuntimeWarning, stacklevel=3)
        return False
    return True


def _disagreement(matches: FlowMatches, V, T) -> float:
    """Confidence-weighted mean distance between matched points, mesh units."""
    if not len(matches):
        return np.inf
    d = np.linalg.norm(matches.sources(V, T) - matches.targets, axis=1)
    return float(np.average(d, weights=matches.confidence))


def _match_rows(matches: FlowMatches, T, n: int) -> sp.csr_matrix:
    """(k, n) rows of barycentric weights: template point ``k`` = row ``k`` @ V."""
    cols = np.asarray(T)[matches.triangle].ravel()
    rows = np.repeat(np.arange(len(matches)), 3)
    return sp.csr_matrix((matches.barycentric.ravel(), (rows, cols)), shape=(len(matches), n))


def _solve_displacement(V, B, targets, confidence, L, smoothness: float, movable,
                        size: float) -> np.ndarray:
    """The smooth displacement (n, 3) of the movable vertices that carries the
    template points ``B @ V`` onto ``targets``: weighted least squares, solved
    twice (the second time with Welsch weights on the first solution's residuals)."""
    n = len(V)
    seen = np.asarray(abs(B).sum(axis=0)).ravel() > 0
    # a vertex's matches count 1 together, as its Laplacian row does
    per_vertex = max(float(confidence.sum()) / max(int(np.count_nonzero(seen)), 1), 1e-12)
    keep = sp.diags((~movable).astype(np.float64) * 1e6 + 1e-6)
    residual = targets - B @ V
    weights = confidence
    D = np.zeros_like(V)
    for _ in range(2):
        W = sp.diags(weights / per_vertex)
        A = (B.T @ W @ B + smoothness * (L.T @ L) + keep).tocsr()
        D = factorize(A, solves="few").solve(B.T @ (W @ residual))
        r = np.linalg.norm(B @ D - residual, axis=1)
        scale = max(_ROBUST * 1.4826 * float(np.median(r)), _ROBUST_FLOOR * size)
        weights = confidence * np.exp(-0.5 * (r / scale) ** 2)
    D[~movable] = 0.0
    return D


def _on_scan(V, tree: ClosestPointTree, on_scan) -> np.ndarray:
    """``V`` with the ``on_scan`` vertices moved to their closest scan points."""
    out = V.copy()
    if on_scan.any():
        out[on_scan] = tree.query(V[on_scan]).points
    return out


def refine_by_texture(template: Mesh, vertices, reference_image, scan: Mesh, scan_image,
                      settings: TextureFlowSettings | None = None, *, movable=None,
                      on_scan=None, scan_tree: ClosestPointTree | None = None,
                      follow=None) -> TextureRefinement:
    """Refine a wrap of ``scan`` by matching its texture (see the module's docstring).

    Parameters
    ----------
    template : Mesh
        The template, with texture coordinates (its layout holds ``reference_image``).
    vertices : (n, 3) float
        The geometric wrap of ``scan`` (template topology, scan frame).
    reference_image : (H, W, 3) uint8
        The texture the template should show (the neutral's, baked in its layout).
    scan : Mesh
        The scan, with texture coordinates into ``scan_image``.
    scan_image : (h, w, 3) uint8
    settings : TextureFlowSettings, optional
    movable : (n,) bool, optional
        Vertices the texture may move (the skin); default all.
    on_scan : (n,) bool, optional
        Vertices kept on the scan's surface (the wrap's projected ones); default
        the movable ones.
    scan_tree : ClosestPointTree, optional
        A tree already built on the scan.
    follow : callable (n, 3) -> (n, 3), optional
        Moves what is not skin (parts) with the refined skin.

    Returns
    -------
    TextureRefinement
    """
    t0 = time.perf_counter()
    s = settings or TextureFlowSettings()
    V0 = np.asarray(vertices, dtype=np.float64)
    n, T = len(V0), template.triangles
    if V0.shape != (n, 3) or n != template.n_vertices:
        raise ValueError(f"vertices must have shape ({template.n_vertices}, 3), got "
                         f"{V0.shape}")
    for name, image in (("reference_image", reference_image), ("scan_image", scan_image)):
        shape = np.shape(image)
        if len(shape) not in (2, 3) or min(shape[:2], default=0) < MIN_IMAGE_SIDE:
            raise ValueError(f"{name} must be an (H, W) or (H, W, 3) image, got shape "
                             f"{shape}")
    for name, mesh in (("template", template), ("scan", scan)):
        if mesh.uvs is None or mesh.triangle_uvs is None:
            raise ValueError(f"{name} has no texture coordinates")
    movable = np.ones(n, dtype=bool) if movable is None else np.asarray(movable, bool)
    on_scan = movable if on_scan is None else np.asarray(on_scan, bool) & movable
    tree = scan_tree or ClosestPointTree(scan.vertices, scan.triangles)
    skin = np.flatnonzero(movable[T].all(axis=1))
    L = uniform_laplacian(T, n)
    size = float(np.linalg.norm(np.ptp(V0[movable], axis=0)))
    V, rounds = V0, []
    # the cameras frame the skin as the geometric wrap has it; the scan, which does
    # not move, is drawn once
    seen = np.unique(T[skin])
    cameras = face_cameras(V0[seen], trusted_vertex_normals(V0, T)[seen], s.views,
                           s.image_size)
    views = ScanViews.of(TexturedSurface.of(scan, scan_image), cameras)
    # the reference is blurred once, to the detail the pictures show of the geometric
    # wrap (a round moves the skin too little to change that)
    reference = prefiltered(TexturedSurface.of(template, reference_image, V0, skin),
                            views.pixel_size).image

    def matches_at(X):
        return flow_matches(TexturedSurface.of(template, reference, X, skin), views,
                            rules=s, prefilter=False, size=size)

    matches = matches_at(V)
    before = _disagreement(matches, V, T)
    for _ in range(s.rounds):
        if len(matches) < max(3.0, _MIN_MATCHES * len(seen)):
            break
        D = _solve_displacement(V, _match_rows(matches, T, n), matches.targets,
                                matches.confidence, L, s.smoothness, movable, size)
        moved = _on_scan(V + D, tree, on_scan)
        moved = moved if follow is None else follow(moved)
        after_matches = matches_at(moved)
        after = _disagreement(after_matches, moved, T)
        kept = after < (1.0 - s.min_gain) * before
        rounds.append({"matches": len(matches), "disagreement": before, "kept": kept,
                       "rejected": dict(matches.rejected)})
        if not kept:
            break
        V, matches, before = moved, after_matches, after
    shift = np.linalg.norm(V - V0, axis=1)[movable]
    return TextureRefinement(V, rounds, float(shift.mean()) if len(shift) else 0.0,
                             time.perf_counter() - t0)
