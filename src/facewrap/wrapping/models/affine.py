"""Per-vertex affine model with stiffness (Amberg, Romdhani, Vetter 2007).

The classic non-rigid ICP baseline: each vertex ``i`` has its own affine map
``X_i`` (4 × 3), ``v_i = [b_i, 1] X_i``, and neighbouring maps are tied by

    E_stiff = Σ_(i,j) ‖ G (X_i − X_j) ‖²_F ,   G = diag(1, 1, 1, γ)

summed over mesh edges.  The model is linear in its parameters (Gauss–Newton
converges in one step per set of scan points), but it has 12 unknowns per
vertex, so it is the slowest model; it is here so users and benchmarks can
compare against the method most tools implement (trimesh's ``nricp_amberg``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from facewrap.geometry import edges as mesh_edges
from facewrap.wrapping.models.base import DeformationModel

__all__ = ["AffineModel"]


class AffineModel(DeformationModel):
    """Per-vertex affine transforms with stiffness.

    Parameters
    ----------
    base : (n, 3) float64
        Undeformed positions (the aligned template, ideally normalised to unit
        size so ``gamma`` weighs rotation against translation as in the paper).
    triangles : (t, 3) int
    gamma : float
        Weight of the translation part in the stiffness term.

    Parameters are an (n, 4, 3) array (identity maps initially); increments are
    added.  Regulariser ``"smooth"`` (normalised by the number of edges).
    """

    regularizer_names = ("smooth",)
    # 12 unknowns per vertex make a sparse Cholesky slow (seconds per step on a
    # 10k face); block-preconditioned CG capped at a few hundred iterations gives
    # steps that the Levenberg–Marquardt test accepts
    solver = "inexact"
    param_block = 12

    def __init__(self, base, triangles, gamma: float = 1.0):
        self.base = np.asarray(base, dtype=np.float64)
        self.n_vertices = n = len(self.base)
        self.n_params = 12 * n
        self.edges = mesh_edges(np.asarray(triangles, dtype=np.int64))
        H = np.c_[self.base, np.ones(n)]                       # (n, 4)
        rows = np.repeat(3 * np.arange(n), 12) + np.tile(np.repeat([0, 1, 2], 4), n)
        # column of X[i, a, c] is 12 i + 3 a + c; row 3 i + c takes Σ_a h_ia X[i,a,c]
        cols = (12 * np.arange(n))[:, None] + (3 * np.arange(4)[None, :, None]
                                               + np.arange(3)[None, None, :]
                                               ).transpose(0, 2, 1).reshape(1, 12)
        vals = np.repeat(H[:, None, :], 3, axis=1).reshape(n, 12)
        self._J = sp.csr_matrix((vals.ravel(), (rows, cols.ravel())), shape=(3 * n, 12 * n))
        g = np.ones(12)
        g[9:] = gamma                                          # the translation row a = 3
        e = len(self.edges)
        i, j = self.edges[:, 0], self.edges[:, 1]
        r_rows = np.repeat(np.arange(12 * e), 2)
        r_cols = np.stack([(12 * i)[:, None] + np.arange(12),
                           (12 * j)[:, None] + np.arange(12)], axis=2).ravel()
        r_vals = np.stack([np.tile(g, (e, 1)), -np.tile(g, (e, 1))], axis=2).ravel()
        scale = 1.0 / np.sqrt(max(e, 1))
        self._S = sp.csr_matrix((r_vals * scale, (r_rows, r_cols)), shape=(12 * e, 12 * n))

    def initial_params(self) -> np.ndarray:
        X = np.zeros((self.n_vertices, 4, 3))
        X[:, :3, :] = np.eye(3)
        return X

    def vertices(self, X) -> np.ndarray:
        return np.einsum("na,nac->nc", np.c_[self.base, np.ones(self.n_vertices)], X)

    def jacobian(self, X, vertices=None):
        if vertices is None:
            return self._J
        v = np.asarray(vertices)
        return self._J[(3 * v[:, None] + np.arange(3)).ravel()]

    def regularizers(self, X) -> dict:
        return {"smooth": (self._S @ X.ravel(), self._S)}

    def update(self, X, delta) -> np.ndarray:
        return X + np.asarray(delta).reshape(X.shape)

    def summary(self, X) -> dict:
        return {"vertices": self.n_vertices, "edges": int(len(self.edges))}
