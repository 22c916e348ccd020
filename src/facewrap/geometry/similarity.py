"""Similarity transforms: rotation, translation and uniform scale.

:func:`similarity_transform` solves for the best similarity between paired points
in closed form (Umeyama 1991, weighted); :class:`Similarity` applies, inverts and
composes one.  Wrapping aligns a template by it; transfer and avatar align their
reference meshes by it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Similarity", "similarity_transform", "mirror_fit", "MIRROR_RATIO",
           "PoseChange", "pose_change"]

#: a paired point set is mirrored when its best mirrored fit leaves less than this
#: fraction of the best proper fit's residual (nearly planar sets or few points fit
#: both alike)
MIRROR_RATIO = 0.5


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
    if not (np.isfinite(X).all() and np.isfinite(Y).all()):   # else "SVD did not converge"
        raise ValueError("source and target must be finite (found NaN or inf)")
    w = np.ones(len(X)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (len(X),) or not np.isfinite(w).all() or np.any(w < 0) or w.sum() <= 0:
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


def mirror_fit(source, target, weights=None, scale: bool = True) -> tuple[float, float]:
    """Residuals of the best proper similarity from ``source`` to ``target`` and of
    the best one from ``source`` mirrored (x negated): a pairing with left and
    right swapped fits far better mirrored (below :data:`MIRROR_RATIO` of the
    proper residual).

    Parameters
    ----------
    source, target : (k, 3) float
        Paired points, k >= 3.
    weights : (k,) float, optional
    scale : bool

    Returns
    -------
    proper, mirrored : float
        Weighted RMS distances, in ``target``'s units.

    Examples
    --------
    >>> P = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [2, 1, 3], [-1, 2, 0.5]])
    >>> proper, mirrored = mirror_fit(P, P * [-1, 1, 1])     # left and right swapped
    >>> bool(mirrored < MIRROR_RATIO * proper)
    True
    """
    X, Y = np.asarray(source, dtype=np.float64), np.asarray(target, dtype=np.float64)
    w = np.ones(len(X)) if weights is None else np.asarray(weights, dtype=np.float64)
    out = []
    for Z in (X, X * np.array([-1.0, 1.0, 1.0])):
        d2 = ((similarity_transform(Z, Y, weights=w, scale=scale).apply(Z) - Y) ** 2
              ).sum(axis=1)
        out.append(float(np.sqrt(w @ d2 / w.sum())))
    return out[0], out[1]


@dataclass(frozen=True)
class PoseChange:
    """How one vertex set in a topology sits against another of the same topology.

    Attributes
    ----------
    scale : float
        Of the best similarity from the first onto the second.
    angle : float
        Its rotation, in degrees.
    shift : float
        How far the centroid moves, in the sets' units.
    mirrored : bool
        The second is a mirror image of the first (:func:`mirror_fit`).
    """
    scale: float
    angle: float
    shift: float
    mirrored: bool


def pose_change(source, target) -> PoseChange:
    """The scale, turn, shift and handedness between two poses of one mesh: two
    frames of an animation, a fitted mesh and its ground truth.  An expression
    changes none of them much; other units, another frame or a mirrored file do.

    Parameters
    ----------
    source, target : (n, 3) float
        Vertex positions in one topology (rows with a NaN are left out).

    Returns
    -------
    PoseChange

    Examples
    --------
    >>> P = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3], [1, 1, 1.]])
    >>> c = pose_change(P, 10 * P)
    >>> round(c.scale, 6), round(c.angle, 6), c.mirrored
    (10.0, 0.0, False)
    >>> pose_change(P, P * [-1, 1, 1]).mirrored
    True
    """
    X, Y = np.asarray(source, np.float64), np.asarray(target, np.float64)
    keep = np.isfinite(X).all(axis=1) & np.isfinite(Y).all(axis=1)
    X, Y = X[keep], Y[keep]
    if len(X) < 4:
        return PoseChange(1.0, 0.0, 0.0, False)
    sim = similarity_transform(X, Y)
    cos = np.clip((np.trace(sim.rotation) - 1.0) / 2.0, -1.0, 1.0)
    size = float(np.linalg.norm(X.max(axis=0) - X.min(axis=0)))
    shift = float(np.linalg.norm(Y.mean(axis=0) - X.mean(axis=0)))
    proper, mirrored = mirror_fit(X, Y)
    # a flat set fits its mirror image as well (both residuals are rounding noise)
    flipped = mirrored < MIRROR_RATIO * proper and proper > 1e-3 * size
    return PoseChange(float(sim.scale), float(np.degrees(np.arccos(cos))), shift,
                      bool(flipped))
