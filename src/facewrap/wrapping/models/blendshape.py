"""Linear blendshapes with a similarity pose, and the rigid model (SPEC §2.2).

    v_i = s R ((n_i − c) + Σ_k w_k d_ik) + c + t                        [4]
    E_blend = Σ_k w_k²                                                  [5]

``d_ik`` are shape deltas (shape − neutral), ``c`` the centroid (so the pose
rotates about the face, which keeps rotation and translation decoupled).  The
pose is updated multiplicatively: ``R ← exp([δθ]×) R``, ``s ← s·exp(δσ)``.

Beyond the SPEC, a pose may also **stretch**: ``E = Q diag(exp(λ)) Qᵀ`` scales the
face along its own principal axes ``Q`` (height, width, depth) before ``s R``:

    v_i = s R E ((n_i − c) + Σ_k w_k d_ik) + c + t,   E_stretch = |λ|²

because heads differ in proportions, not only in size (a face 8 % wider and 7 %
shorter than the template is within two standard deviations), and the local
deformation that follows resists a global stretch as it resists a global scale
(its rotation term).  The Tikhonov term keeps ``λ`` at 0 unless the scan's surface
asks for more.

With no shapes this is the **rigid** model (rotation, translation, optional
scale).  :func:`blendshape_basis` turns a shape dict into a delta matrix, raw or
as principal components scaled by their standard deviation (so the Tikhonov
term is a Gaussian prior on the coefficients, SPEC §2.2's PCA variant).
"""

from __future__ import annotations

from dataclasses import dataclass, field

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
    """Pose (``R`` (3, 3), ``t`` (3,), ``s``), blend weights ``w`` (K,) and the
    log-stretch ``stretch`` (3,) along the model's principal axes (zeros: none)."""
    R: np.ndarray
    t: np.ndarray
    s: float
    w: np.ndarray
    stretch: np.ndarray = field(default_factory=lambda: np.zeros(3))


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
    stretch : bool
        Optimise a stretch along the base's principal axes too (with ``scale``
        and ``pose`` only): the coarse pre-fits of the local models do.
    body : (b,) int, optional
        The vertices the pose turns about (their centroid) and stretches along
        (their principal axes): the skin's (default all).

    Parameter increment order: [δθ (3), δt (3), δσ (1), δλ (3, with ``stretch``),
    δw (K)].  Regularisers: ``"blend"``, the weights themselves (eq. 5);
    ``"bounds"``; ``"stretch"``, the log-stretch λ.
    """

    regularizer_names = ("blend", "bounds", "stretch")
    solver = "direct"  # a small dense system

    def __init__(self, base, deltas, *, scale: bool = True, pose: bool = True,
                 bounds=None, stretch: bool = False, body=None):
        self.bounds = None if bounds is None else (float(bounds[0]), float(bounds[1]))
        self.base = np.asarray(base, dtype=np.float64)
        self.deltas = np.asarray(deltas, dtype=np.float64)
        # the pivot and the stretch axes of the skin alone (``body``): a template's
        # eyeballs and teeth must not move them
        skin = self.base if body is None else self.base[np.asarray(body, dtype=np.int64)]
        self.center = skin.mean(axis=0)
        self.scale = scale
        self.pose = pose
        self.stretch = bool(stretch and scale and pose)
        # principal axes of the base (columns): the directions a face stretches in
        self.axes = np.linalg.eigh(np.cov((skin - self.center).T))[1] \
            if self.stretch else np.eye(3)
        self.n_vertices = len(self.base)
        self.n_shapes = self.deltas.shape[1]
        self._w0 = 10 if self.stretch else 7        # first blend-weight column
        self.n_params = self._w0 + self.n_shapes
        self._last_blend = LastBlend(self.base, self.deltas)

    def _linear(self, p: BlendshapeParams) -> np.ndarray:
        """(3, 3) ``s R E``: the pose's linear part (``E``, the stretch along the
        principal axes, is the identity without ``stretch``)."""
        if not self.stretch:
            return p.s * p.R
        Q = self.axes
        return p.s * p.R @ (Q * np.exp(p.stretch)) @ Q.T

    def initial_params(self, weights=None) -> BlendshapeParams:
        """Identity pose; blend weights ``weights`` (K,) or zeros."""
        w = np.zeros(self.n_shapes) if weights is None else np.asarray(weights)
        return BlendshapeParams(np.eye(3), np.zeros(3), 1.0, w)

    def blended(self, w) -> np.ndarray:
        """Neutral plus weighted deltas, before the pose: (n, 3), read-only."""
        return self._last_blend(w)

    def vertices(self, p: BlendshapeParams) -> np.ndarray:
        return (self.blended(p.w) - self.center) @ self._linear(p).T + self.center + p.t

    def posed_deltas(self, p: BlendshapeParams) -> np.ndarray:
        """(3n, K): the deltas as the pose moves them (``s R E d``)."""
        D = self.deltas.reshape(self.n_vertices, 3, self.n_shapes)
        return np.matmul(self._linear(p), D).reshape(3 * self.n_vertices, -1)

    def jacobian(self, p: BlendshapeParams, vertices=None):
        sel = slice(None) if vertices is None else np.asarray(vertices)
        local = self.blended(p.w)[sel] - self.center
        M = self._linear(p)
        moved = local @ M.T
        n = len(moved)
        J = np.zeros((n, 3, self.n_params))
        if self.pose:
            J[:, :, 0:3] = cross_matrix_blocks(moved)
            J[:, :, 3:6] = np.eye(3)
            if self.scale:
                J[:, :, 6] = moved
            if self.stretch:
                # d(E x)/dλ_k = exp(λ_k) (q_k · x) q_k, then s R
                Q = self.axes
                along = (local @ Q) * np.exp(p.stretch)                    # (n, 3)
                dirs = p.s * Q.T @ p.R.T                                    # (3, 3)
                J[:, :, 7:10] = along[:, None, :] * dirs.T[None, :, :]
        if self.n_shapes:
            Dw = self.deltas.reshape(-1, 3, self.n_shapes)[sel]
            J[:, :, self._w0:] = np.matmul(M, Dw)
        return BlockJacobian(None, J.reshape(3 * n, self.n_params))

    def regularizers(self, p: BlendshapeParams) -> dict:
        J = np.hstack([np.zeros((self.n_shapes, self._w0)), np.eye(self.n_shapes)])
        out = {"blend": (np.asarray(p.w, dtype=np.float64), BlockJacobian(None, J))}
        if self.bounds is not None:
            r, d = bound_violation(p.w, self.bounds)
            out["bounds"] = (r, BlockJacobian(None, J * np.r_[np.zeros(self._w0), d]))
        if self.stretch:
            Js = np.zeros((3, self.n_params))
            Js[:, 7:10] = np.eye(3)
            out["stretch"] = (np.asarray(p.stretch, dtype=np.float64),
                              BlockJacobian(None, Js))
        return out

    def regularizer_residuals(self, p: BlendshapeParams) -> dict:
        out = {"blend": np.asarray(p.w, dtype=np.float64)}
        if self.bounds is not None:
            out["bounds"] = bound_violation(p.w, self.bounds)[0]
        if self.stretch:
            out["stretch"] = np.asarray(p.stretch, dtype=np.float64)
        return out

    def update(self, p: BlendshapeParams, delta) -> BlendshapeParams:
        d = np.asarray(delta, dtype=np.float64)
        stretch = p.stretch + d[7:10] if self.stretch else p.stretch
        return BlendshapeParams(rotation_exp(d[:3]) @ p.R, p.t + d[3:6],
                                float(p.s * np.exp(d[6])), p.w + d[self._w0:], stretch)

    def summary(self, p: BlendshapeParams) -> dict:
        out = {"shapes": self.n_shapes, "scale": float(p.s),
               "rotation_degrees": float(np.degrees(np.arccos(
                   np.clip((np.trace(p.R) - 1) / 2, -1, 1))))}
        if self.stretch:
            out["stretch"] = np.exp(p.stretch).round(6).tolist()
        return out


class RigidModel(BlendshapeModel):
    """Rotation, translation and (optionally) scale of the whole template."""

    regularizer_names = ("stretch",)

    def __init__(self, base, *, scale: bool = True, stretch: bool = False, body=None):
        super().__init__(base, np.zeros((3 * len(base), 0)), scale=scale, stretch=stretch,
                         body=body)

    def regularizers(self, p) -> dict:
        return {k: v for k, v in super().regularizers(p).items() if k == "stretch"}

    def regularizer_residuals(self, p) -> dict:
        return {k: v for k, v in super().regularizer_residuals(p).items()
                if k == "stretch"}
