"""Global alignment: similarity from landmark pairs (Umeyama) and rigid ICP.

Alignment is the first step of every wrap: it brings the template into the scan's
frame so that the non-rigid steps start close.  :func:`similarity_transform` solves
for rotation, translation and (optionally) uniform scale from paired points in
closed form; :func:`rigid_icp` refines a transform against a whole surface with
point-to-plane steps, trimming, and distance/normal rejection.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Similarity", "similarity_transform", "rigid_icp", "RigidICPResult"]


@dataclass(frozen=True)
class Similarity:
    """``x -> scale * rotation @ x + translation``.

    Attributes
    ----------
    rotation : (3, 3) float64, orthonormal with determinant +1
    translation : (3,) float64
    scale : float
    """
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale: float = 1.0

    def apply(self, points) -> np.ndarray:
        """Transform (k, 3) points."""
        P = np.asarray(points, dtype=np.float64)
        return self.scale * P @ self.rotation.T + self.translation

    def apply_vectors(self, vectors) -> np.ndarray:
        """Rotate (k, 3) directions (normals): no scale, no translation."""
        return np.asarray(vectors, dtype=np.float64) @ self.rotation.T

    @property
    def matrix(self) -> np.ndarray:
        """(4, 4) homogeneous matrix."""
        M = np.eye(4)
        M[:3, :3] = self.scale * self.rotation
        M[:3, 3] = self.translation
        return M

    def inverse(self) -> "Similarity":
        Rt = self.rotation.T
        return Similarity(Rt, -(Rt @ self.translation) / self.scale, 1.0 / self.scale)

    def compose(self, first: "Similarity") -> "Similarity":
        """The transform applying ``first`` and then ``self``."""
        return Similarity(self.rotation @ first.rotation,
                          self.scale * self.rotation @ first.translation + self.translation,
                          self.scale * first.scale)

    @classmethod
    def from_matrix(cls, M) -> "Similarity":
        """From a (4, 4) similarity matrix (rotation * uniform scale + translation)."""
        M = np.asarray(M, dtype=np.float64)
        if M.shape != (4, 4):
            raise ValueError(f"matrix must be (4, 4), got {M.shape}")
        A = M[:3, :3]
        s = np.cbrt(np.linalg.det(A))
        if not np.isfinite(s) or s <= 0:
            raise ValueError("matrix is not a proper similarity (det <= 0)")
        R = A / s
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-6):
            raise ValueError("matrix is not a similarity (rotation part not orthonormal)")
        return cls(R, M[:3, 3].copy(), float(s))


def similarity_transform(source, target, weights=None, scale: bool = True) -> Similarity:
    """Least-squares similarity mapping ``source`` onto ``target`` (Umeyama 1991).

    Parameters
    ----------
    source, target : (k, 3) float
        Paired points, k >= 3 not collinear (k >= 1 gives a translation only).
    weights : (k,) float, optional
        Non-negative pair weights.
    scale : bool
        Estimate a uniform scale (else rigid).

    Returns
    -------
    Similarity

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> P = rng.normal(size=(10, 3))
    >>> R = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.]])
    >>> T = similarity_transform(P, 2 * P @ R.T + [1, 2, 3])
    >>> round(T.scale, 6), np.allclose(T.rotation, R), np.allclose(T.translation, [1, 2, 3])
    (2.0, True, True)
    """
    X = np.asarray(source, dtype=np.float64)
    Y = np.asarray(target, dtype=np.float64)
    if X.shape != Y.shape or X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f"source and target must both be (k, 3), got {X.shape} "
                         f"and {Y.shape}")
    if len(X) == 0:
        raise ValueError("need at least one point pair")
    w = np.ones(len(X)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (len(X),) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError("weights must be (k,) non-negative with a positive sum")
    w = w / w.sum()
    mx, my = w @ X, w @ Y
    Xc, Yc = X - mx, Y - my
    if len(X) < 3:
        return Similarity(np.eye(3), my - mx, 1.0)
    cov = (Yc * w[:, None]).T @ Xc
    U, S, Vt = np.linalg.svd(cov)
    D = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        D[2, 2] = -1.0  # reflection -> closest proper rotation
    R = U @ D @ Vt
    var_x = float(w @ (Xc ** 2).sum(axis=1))
    s = float(np.trace(np.diag(S) @ D) / var_x) if scale and var_x > 0 else 1.0
    return Similarity(R, my - s * R @ mx, s)


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
