"""The deformation-model interface every non-rigid ICP model implements.

A deformation model maps parameters to template vertex positions.  The ICP
engine (:mod:`facewrap.wrapping.icp.engine`) only needs four pure methods, so the engine,
the energy terms and the solver are shared by all models (SPEC §2):

- ``initial_params()`` — the parameters of "no deformation" (or a warm start),
- ``vertices(params)`` — (n, 3) deformed vertex positions,
- ``jacobian(params, vertices=None)`` — (3n, P) derivative of the flattened
  vertices (row ``3 i + c`` is coordinate ``c`` of vertex ``i``) with respect to
  a parameter *increment* ``delta`` (P = ``n_params``); sparse, dense or a
  :class:`~facewrap.solve.BlockJacobian`; with ``vertices``, only their rows
  (3v, P) — the ICP engine asks only for vertices that have a scan point
  or carry a landmark,
- ``regularizers(params)`` — dict name → (residual (r,), Jacobian (r, P)),
  unweighted; the schedule weights them by name ("smooth", "blend"),
- ``regularizer_residuals(params)`` — the same residuals without Jacobians,
- ``update(params, delta)`` — apply an increment (rotations are updated on the
  rotation group, ``R ← exp([δθ]×) R``, so they stay orthonormal exactly).

Parameters are model-specific objects (arrays or small dataclasses); they are
never modified in place.
"""

from __future__ import annotations

import numpy as np

__all__ = ["DeformationModel", "LastBlend", "skew", "rotation_exp", "cross_matrix_blocks",
           "nearest_rotations"]


class DeformationModel:
    """Base class: subclasses set ``n_vertices`` and ``n_params`` and implement
    the methods below."""

    n_vertices: int
    n_params: int
    #: names of the regularisers this model returns (weights come from the schedule)
    regularizer_names: tuple = ()
    #: linear solver of the Gauss–Newton steps ("cg" or "direct", see
    #: :func:`facewrap.solve.gauss_newton_step`)
    solver: str = "cg"
    #: unknowns per node / vertex in the sparse block (preconditioner blocks)
    param_block: int = 1

    def initial_params(self):
        raise NotImplementedError

    def vertices(self, params) -> np.ndarray:
        raise NotImplementedError

    def jacobian(self, params, vertices=None):
        raise NotImplementedError

    def regularizers(self, params) -> dict:
        return {}

    def regularizer_residuals(self, params) -> dict:
        """Residuals of :meth:`regularizers` only (cheaper: for energy checks)."""
        return {name: r for name, (r, _) in self.regularizers(params).items()}

    def update(self, params, delta):
        raise NotImplementedError

    def summary(self, params) -> dict:
        """JSON-able description of the parameters (for reports)."""
        return {}


class LastBlend:
    """``base + deltas @ w`` as (n, 3), remembering the last ``w``.

    The ICP engine asks a blendshape model for the same weights several times per
    iteration (the step's vertices, the next Jacobian, regularisers, energy): the
    last blend is kept and returned read-only.

    Examples
    --------
    >>> blend = LastBlend(np.zeros((2, 3)), np.ones((6, 1)))
    >>> a = blend([2.0]); a.tolist(), blend([2.0]) is a
    ([[2.0, 2.0, 2.0], [2.0, 2.0, 2.0]], True)
    """

    def __init__(self, base, deltas):
        self.base, self.deltas = base, deltas
        self._w, self._blend = None, None

    def __call__(self, w) -> np.ndarray:
        w = np.asarray(w, dtype=np.float64)
        if self._w is not None and np.array_equal(self._w, w):
            return self._blend
        B = self.base + (self.deltas @ w).reshape(-1, 3)
        B.setflags(write=False)
        self._w, self._blend = w.copy(), B
        return B


def skew(v) -> np.ndarray:
    """Cross-product matrices ``[v]×`` of rows of ``v``.

    Parameters
    ----------
    v : (..., 3) float

    Returns
    -------
    (..., 3, 3) float with ``skew(a) @ b == cross(a, b)``.

    Examples
    --------
    >>> a, b = np.array([1., 2, 3]), np.array([-1., 0.5, 2])
    >>> bool(np.allclose(skew(a) @ b, np.cross(a, b)))
    True
    """
    v = np.asarray(v, dtype=np.float64)
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def rotation_exp(omega) -> np.ndarray:
    """Rotation matrices ``exp([ω]×)`` of axis-angle vectors (Rodrigues).

    Parameters
    ----------
    omega : (..., 3) float

    Returns
    -------
    (..., 3, 3) float, orthonormal with determinant 1.

    Examples
    --------
    >>> R = rotation_exp([0, 0, np.pi / 2])
    >>> np.round(R @ [1, 0, 0], 12).tolist()
    [0.0, 1.0, 0.0]
    """
    w = np.asarray(omega, dtype=np.float64)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    K = skew(w)
    small = theta < 1e-8
    # sin(θ)/θ and (1 - cos θ)/θ² with their Taylor limits near zero
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta ** 2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta ** 2 / 24.0, (1.0 - np.cos(safe)) / safe ** 2)
    return np.eye(3) + a * K + b * (K @ K)


def cross_matrix_blocks(p) -> np.ndarray:
    """``-[p]×``: the derivative of ``exp([δθ]×) p`` with respect to ``δθ`` at 0.

    Parameters
    ----------
    p : (..., 3) float

    Returns
    -------
    (..., 3, 3) float
    """
    return -skew(p)


def nearest_rotations(M) -> np.ndarray:
    """The rotations closest to matrices ``M`` in the Frobenius norm (polar part,
    reflections removed).

    Parameters
    ----------
    M : (..., 3, 3) float

    Returns
    -------
    (..., 3, 3) float, orthonormal with determinant 1.

    Examples
    --------
    >>> R = nearest_rotations(2.0 * rotation_exp([0.0, 0.3, 0.0]))
    >>> bool(np.allclose(R, rotation_exp([0.0, 0.3, 0.0])))
    True
    """
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=np.float64))
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0, 1.0, d)
    U = U.copy()
    U[..., :, 2] *= d[..., None]
    return U @ Vt
