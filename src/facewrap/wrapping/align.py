"""Global alignment of a wrap: rigid ICP against the whole scan.

Alignment is the first step of every wrap: it brings the template into the scan's
frame so that the non-rigid steps start close.  The closed-form similarity from
landmark pairs lives in :mod:`facewrap.geometry.similarity` (transfer and avatar
use it too); :func:`rigid_icp` refines a transform against a whole surface with
point-to-plane steps, trimming, and distance/normal rejection.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facewrap.geometry.matching import closest_compatible_points
from facewrap.geometry.similarity import Similarity, similarity_transform
from facewrap.wrapping.models.base import rotation_exp

__all__ = ["rigid_icp", "RigidICPResult"]


@dataclass
class RigidICPResult:
    """Outcome of :func:`rigid_icp`: the transform and a per-iteration log."""
    transform: Similarity
    history: list[dict]
    inliers: np.ndarray


def rigid_icp(points, tree, normals=None, init: Similarity | None = None, *,
              iterations: int = 30, trim: float = 0.9, max_distance: float | None = None,
              max_normal_angle: float = 60.0, scale: bool = False,
              point_to_plane: bool = True, tol: float = 1e-7,
              weights=None) -> RigidICPResult:
    """Refine a rigid (or similarity) transform of ``points`` onto a surface.

    Each iteration: closest compatible points on the surface (``tree``, built once
    by the caller; :func:`facewrap.geometry.matching.closest_compatible_points`),
    rejecting pairs farther than ``max_distance`` and, when ``normals`` are given,
    pairs whose normals differ by more than ``max_normal_angle`` degrees; keep the
    best ``trim`` fraction; one linearised point-to-plane step (or a closed-form
    point-to-point step).

    Parameters
    ----------
    points : (n, 3) float
        Source points (template vertices).
    tree : facewrap.geometry.ClosestPointTree
        The target surface.
    normals : (n, 3) float, optional
        Source normals, for the normal test.
    init : Similarity, optional
    iterations, trim, max_distance, max_normal_angle, scale, point_to_plane, tol
        See above; ``tol`` stops when the RMS change of the points is below
        ``tol`` times the point set's size.
    weights : (n,) float, optional
        Each point's pair weighs this much in the point-to-plane step (how much
        the point is trusted; default all alike).  Not with ``scale`` or
        ``point_to_plane=False``.

    Returns
    -------
    RigidICPResult
    """
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"points must be (n, 3), got {P.shape}")
    if not 0 < trim <= 1:
        raise ValueError("trim must be in (0, 1]")
    if weights is not None:
        weights = np.asarray(weights, dtype=np.float64).reshape(-1)
        if weights.shape != (len(P),) or not (weights >= 0).all():
            raise ValueError(f"weights must be ({len(P)},) and >= 0")
        if scale or not point_to_plane:
            raise ValueError("weights are for the rigid point-to-plane step only")
    similarity = init if init is not None else Similarity()
    size = float(np.linalg.norm(P.max(axis=0) - P.min(axis=0))) or 1.0
    history = []
    keep = np.ones(len(P), dtype=bool)
    for it in range(iterations):
        X = similarity.apply(P)
        matches = closest_compatible_points(
            tree, X, None if normals is None else similarity.apply_vectors(normals),
            max_distance=max_distance,
            max_normal_angle=None if normals is None else max_normal_angle)
        inlier = np.ones(len(matches), dtype=bool)
        if trim < 1 and len(matches) > 3:
            inlier = matches.distances <= np.quantile(matches.distances, trim)
        keep = matches.accepted.copy()
        keep[matches.index[~inlier]] = False
        if keep.sum() < 6:
            break
        Xk, Yk, Nk = X[keep], matches.points[inlier], matches.normals[inlier]
        if point_to_plane and not scale:
            # minimise sum ((R X + t - Y) . n)^2 with R = I + [omega]x (linearised)
            A = np.hstack([np.cross(Xk, Nk), Nk])
            b = np.einsum("ij,ij->i", Yk - Xk, Nk)
            if weights is not None:
                root = np.sqrt(weights[keep])
                A, b = A * root[:, None], b * root
            sol, *_ = np.linalg.lstsq(A, b, rcond=None)
            step = Similarity(rotation_exp(sol[:3]), sol[3:], 1.0)
        else:
            step = similarity_transform(Xk, Yk, scale=scale)
        updated = step.compose(similarity)
        change = float(np.sqrt(np.mean(((updated.apply(P) - X)) ** 2)))
        similarity = updated
        history.append({"iteration": it, "rms": float(np.sqrt(np.mean(
            matches.distances[inlier] ** 2))), "inliers": int(keep.sum()),
            "change": change})
        if change < tol * size:
            break
    return RigidICPResult(similarity, history, keep)
