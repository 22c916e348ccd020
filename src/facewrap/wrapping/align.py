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

from facewrap.geometry.similarity import Similarity, similarity_transform

__all__ = ["rigid_icp", "RigidICPResult"]


@dataclass
class RigidICPResult:
    """Outcome of :func:`rigid_icp`: the transform and a per-iteration log."""
    transform: Similarity
    history: list[dict]
    inliers: np.ndarray


def _small_rotation(omega) -> np.ndarray:
    """Rotation matrix of the rotation vector ``omega`` (Rodrigues)."""
    theta = float(np.linalg.norm(omega))
    if theta < 1e-12:
        return np.eye(3)
    k = omega / theta
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * K @ K


def rigid_icp(points, tree, normals=None, init: Similarity | None = None, *,
              iterations: int = 30, trim: float = 0.9, max_distance: float | None = None,
              max_normal_angle: float = 60.0, scale: bool = False,
              point_to_plane: bool = True, tol: float = 1e-7) -> RigidICPResult:
    """Refine a rigid (or similarity) transform of ``points`` onto a surface.

    Each iteration: closest points on the surface (``tree``, built once by the
    caller); reject pairs farther than ``max_distance``, whose normals differ by more
    than ``max_normal_angle`` degrees, or that land on the surface's boundary is the
    caller's choice via ``max_distance``; keep the best ``trim`` fraction; one
    linearised point-to-plane step (or a closed-form point-to-point step).

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

    Returns
    -------
    RigidICPResult
    """
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"points must be (n, 3), got {P.shape}")
    if not 0 < trim <= 1:
        raise ValueError("trim must be in (0, 1]")
    T = init if init is not None else Similarity()
    size = float(np.linalg.norm(P.max(axis=0) - P.min(axis=0))) or 1.0
    cos_max = np.cos(np.radians(max_normal_angle))
    history = []
    keep = np.ones(len(P), dtype=bool)
    for it in range(iterations):
        X = T.apply(P)
        cp = tree.query(X)
        keep = np.ones(len(P), dtype=bool)
        if max_distance is not None:
            keep &= cp.distances <= max_distance
        if normals is not None:
            keep &= np.einsum("ij,ij->i", T.apply_vectors(normals), cp.normals) >= cos_max
        if trim < 1 and keep.sum() > 3:
            cut = np.quantile(cp.distances[keep], trim)
            keep &= cp.distances <= cut
        if keep.sum() < 6:
            break
        Xk, Yk, Nk = X[keep], cp.points[keep], cp.normals[keep]
        if point_to_plane and not scale:
            # minimise sum ((R X + t - Y) . n)^2 with R = I + [omega]x (linearised)
            A = np.hstack([np.cross(Xk, Nk), Nk])
            b = np.einsum("ij,ij->i", Yk - Xk, Nk)
            sol, *_ = np.linalg.lstsq(A, b, rcond=None)
            step = Similarity(_small_rotation(sol[:3]), sol[3:], 1.0)
        else:
            step = similarity_transform(Xk, Yk, scale=scale)
        T_new = step.compose(T)
        change = float(np.sqrt(np.mean(((T_new.apply(P) - X)) ** 2)))
        T = T_new
        history.append({"iteration": it, "rms": float(np.sqrt(np.mean(
            cp.distances[keep] ** 2))), "inliers": int(keep.sum()), "change": change})
        if change < tol * size:
            break
    return RigidICPResult(T, history, keep)
