"""Linear blendshapes with a similarity pose, and the rigid model (SPEC §2.2).

    v_i = s R ((n_i − c) + Σ_k w_k d_ik) + c + t                        [4]
    E_blend = Σ_k w_k²                                                  [5]

``d_ik`` are shape deltas (shape − neutral), ``c`` the centroid (so the pose
rotates about the face, which keeps rotation and translation decoupled).  The
pose is updated multiplicatively: ``R ← exp([δθ]×) R``, ``s ← s·exp(δσ)``.

With no shapes this is the **rigid** model (rotation, translation, optional
scale).  :func:`blendshape_basis` turns a shape dict into a delta matrix, raw or
as principal components scaled by their standard deviation (so the Tikhonov
term is a Gaussian prior on the coefficients, SPEC §2.2's PCA variant).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facewrap.solve import BlockJacobian
from facewrap.wrapping.models.base import (DeformationModel, LastBlend, cross_matrix_blocks,
                                           rotation_exp)

__all__ = ["BlendshapeParams", "BlendshapeModel", "RigidModel", "blendshape_basis"]


def blendshape_basis(neutral, shapes: dict, components: int | None = None):
    """Delta matrix of a blendshape set.

    Parameters
    ----------
    neutral : (n, 3) float64
    shapes : dict name -> (n, 3) float64
        Shape positions in the neutral's topology.
    components : int, optional
        Keep this many principal components (scaled by their standard deviation
        over the set) instead of the raw deltas.

    Returns
    -------
    D : (3n, K) float64
        Row ``3 i + c`` is coordinate ``c`` of vertex ``i``.
    names : list of str
        Shape names, or ``pc0, pc1, ...`` for components.
    """
    neutral = np.asarray(neutral, dtype=np.float64)
    names = list(shapes)
    if not names:
        return np.zeros((3 * len(neutral), 0)), []
    D = np.stack([(np.asarray(shapes[k], dtype=np.float64) - neutral).ravel()
                  for k in names], axis=1)
    if components is None:
        return D, names
    components = int(min(components, len(names)))
    U, S, _ = np.linalg.svd(D, full_matrices=False)  # uncentred: neutral is the mean
    scale = S[:components] / np.sqrt(len(names))
    return U[:, :components] * scale, [f"pc{i}" for i in range(components)]


def bound_violation(w, bounds) -> tuple[np.ndarray, np.ndarray]:
    """How far each weight lies outside ``bounds = (lo, hi)`` (signed, 0 inside)
    and the derivative (1 where outside): the residual of the ``"bounds"``
    regulariser, a one-sided quadratic penalty.

    Examples
    --------
    >>> r, d = bound_violation([-0.2, 0.5, 1.3], (0.0, 1.0))
    >>> np.round(r, 12).tolist(), d.tolist()
    ([-0.2, 0.0, 0.3], [1.0, 0.0, 1.0])
    """
    w = np.asarray(w, dtype=np.float64)
    lo, hi = bounds
    r = np.minimum(w - lo, 0.0) + np.maximum(w - hi, 0.0)
    return r, (r != 0).astype(np.float64)


@dataclass(frozen=True)
class BlendshapeParams:
    """Pose (``R`` (3, 3), ``t`` (3,), ``s``) and blend weights ``w`` (K,)."""
    R: np.ndarray
    t: np.ndarray
    s: float
    w: np.ndarray


class BlendshapeModel(DeformationModel):
    """Blendshapes plus a similarity pose.

    Parameters
    ----------
    base : (n, 3) float64
        Neutral positions (the aligned template).
    deltas : (3n, K) float64
        From :func:`blendshape_basis`, already in ``base``'s frame.
    scale : bool
        Optimise a uniform scale too.
    pose : bool
        Optimise the pose at all (False: weights only).
    bounds : (lo, hi), optional
        Range of the weights (an expression rig's [0, 1]); outside it the
        ``"bounds"`` regulariser (:func:`bound_violation`) pulls them back.

    Parameter increment order: [δθ (3), δt (3), δσ (1), δw (K)].
    Regulariser ``"blend"``: the weights themselves (eq. 5); ``"bounds"``.
    """

    regularizer_names = ("blend", "bounds")
    solver = "direct"  # a small dense system

    def __init__(self, base, deltas, *, scale: bool = True, pose: bool = True,
                 bounds=None):
        self.bounds = None if bounds is None else (float(bounds[0]), float(bounds[1]))
        self.base = np.asarray(base, dtype=np.float64)
        self.deltas = np.asarray(deltas, dtype=np.float64)
        self.center = self.base.mean(axis=0)
        self.scale = scale
        self.pose = pose
        self.n_vertices = len(self.base)
        self.n_shapes = self.deltas.shape[1]
        self.n_params = 7 + self.n_shapes
        self._last_blend = LastBlend(self.base, self.deltas)

    def initial_params(self, weights=None) -> BlendshapeParams:
        """Identity pose; blend weights ``weights`` (K,) or zeros."""
        w = np.zeros(self.n_shapes) if weights is None else np.asarray(weights)
        return BlendshapeParams(np.eye(3), np.zeros(3), 1.0, w)

    def blended(self, w) -> np.ndarray:
        """Neutral plus weighted deltas, before the pose: (n, 3), read-only."""
        return self._last_blend(w)

    def vertices(self, p: BlendshapeParams) -> np.ndarray:
        local = self.blended(p.w) - self.center
        return p.s * local @ p.R.T + self.center + p.t

    def jacobian(self, p: BlendshapeParams, vertices=None):
        sel = slice(None) if vertices is None else np.asarray(vertices)
        moved = p.s * (self.blended(p.w)[sel] - self.center) @ p.R.T
        n = len(moved)
        J = np.zeros((n, 3, self.n_params))
        if self.pose:
            J[:, :, 0:3] = cross_matrix_blocks(moved)
            J[:, :, 3:6] = np.eye(3)
            if self.scale:
                J[:, :, 6] = moved
        if self.n_shapes:
            Dw = self.deltas.reshape(-1, 3, self.n_shapes)[sel]
            J[:, :, 7:] = p.s * np.einsum("ab,nbk->nak", p.R, Dw)
        return BlockJacobian(None, J.reshape(3 * n, self.n_params))

    def regularizers(self, p: BlendshapeParams) -> dict:
        J = np.hstack([np.zeros((self.n_shapes, 7)), np.eye(self.n_shapes)])
        out = {"blend": (np.asarray(p.w, dtype=np.float64), BlockJacobian(None, J))}
        if self.bounds is not None:
            r, d = bound_violation(p.w, self.bounds)
            out["bounds"] = (r, BlockJacobian(None, J * np.r_[np.zeros(7), d]))
        return out

    def regularizer_residuals(self, p: BlendshapeParams) -> dict:
        out = {"blend": np.asarray(p.w, dtype=np.float64)}
        if self.bounds is not None:
            out["bounds"] = bound_violation(p.w, self.bounds)[0]
        return out

    def update(self, p: BlendshapeParams, delta) -> BlendshapeParams:
        d = np.asarray(delta, dtype=np.float64)
        return BlendshapeParams(rotation_exp(d[:3]) @ p.R, p.t + d[3:6],
                                float(p.s * np.exp(d[6])), p.w + d[7:])

    def summary(self, p: BlendshapeParams) -> dict:
        return {"shapes": self.n_shapes, "scale": float(p.s),
                "rotation_degrees": float(np.degrees(np.arccos(
                    np.clip((np.trace(p.R) - 1) / 2, -1, 1))))}


class RigidModel(BlendshapeModel):
    """Rotation, translation and (optionally) scale of the whole template."""

    regularizer_names = ()

    def __init__(self, base, *, scale: bool = True):
        super().__init__(base, np.zeros((3 * len(base), 0)), scale=scale)

    def regularizers(self, p) -> dict:
        return {}

    def regularizer_residuals(self, p) -> dict:
        return {}
