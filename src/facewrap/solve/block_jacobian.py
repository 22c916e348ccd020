"""Jacobians with a sparse block (graph nodes) beside a dense block (blend weights).

Models whose parameters are a few dense columns (blend weights, a similarity) next
to many sparse ones (graph nodes) keep the two apart, so products and Gram matrices
never densify the sparse part.  Used by the models (their vertex Jacobians) and by
:func:`facewrap.solve.factor.gauss_newton_step`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["BlockJacobian"]


class BlockJacobian:
    """A Jacobian ``[S | D]``: sparse columns first, then a few dense columns.

    Deformation-graph parameters touch a handful of vertices each (sparse), blend
    weights touch every vertex (dense).  Keeping the dense columns as a numpy
    block lets the normal equations use BLAS for them instead of sparse products
    over fully populated columns.

    Parameters
    ----------
    sparse : (r, Ps) scipy.sparse matrix, optional
    dense : (r, Pd) float64, optional
    """

    def __init__(self, sparse=None, dense=None):
        if sparse is None and dense is None:
            raise ValueError("a BlockJacobian needs a sparse or a dense block")
        rows = sparse.shape[0] if sparse is not None else dense.shape[0]
        self.sparse = (sp.csr_matrix((rows, 0)) if sparse is None
                       else sp.csr_matrix(sparse))
        self.dense = (np.zeros((rows, 0)) if dense is None
                      else np.asarray(dense, dtype=np.float64))
        if self.dense.shape[0] != rows:
            raise ValueError("sparse and dense blocks have different row counts")

    @property
    def shape(self):
        return (self.sparse.shape[0], self.sparse.shape[1] + self.dense.shape[1])

    def rows(self, index) -> "BlockJacobian":
        index = np.asarray(index, dtype=np.int64)
        return BlockJacobian(self.sparse[index], self.dense[index])

    def left(self, M) -> "BlockJacobian":
        """``M @ self`` for a sparse (or dense) matrix ``M``."""
        return BlockJacobian(sp.csr_matrix(M @ self.sparse), np.asarray(M @ self.dense))

    def left_blocks(self, M) -> "BlockJacobian":
        """``blockdiag(M_0, M_1, ...) @ self`` for (k, 3, 3) blocks over row triples.

        When the three rows of each triple share their columns (vertex rows of
        the graph Jacobian do), the product is done on the stored values, which
        keeps that structure (and its explicit zeros) for the fast Gram product
        in :func:`facewrap.solve.factor.gauss_newton_step`.
        """
        M = np.asarray(M, dtype=np.float64)
        k = len(M)
        S = self.sparse
        q = np.diff(S.indptr)
        # (a stacked matmul: 3-4x faster than the same einsum for 3 x 3 blocks)
        dense = np.matmul(M, self.dense.reshape(k, 3, -1)).reshape(3 * k, -1)
        if k and S.shape[1] and q[0] > 0 and (q == q[0]).all():
            idx = S.indices.reshape(k, 3, q[0])
            if (idx == idx[:, :1]).all():
                vals = np.matmul(M, S.data.reshape(k, 3, q[0]))
                out = sp.csr_matrix((vals.ravel(), S.indices.copy(), S.indptr.copy()),
                                    shape=S.shape)
                return BlockJacobian(out, dense)
        rows = np.repeat(np.arange(3 * k), 3)
        cols = (3 * np.arange(k)[:, None, None] + np.zeros((1, 3, 1), int)
                + np.arange(3)[None, None, :]).ravel()
        Mbig = sp.csr_matrix((M.ravel(), (rows, cols)), shape=(3 * k, 3 * k))
        return BlockJacobian(sp.csr_matrix(Mbig @ S), dense)

    def scale_rows(self, w) -> "BlockJacobian":
        """``diag(w) @ self`` without a sparse product."""
        w = np.asarray(w, dtype=np.float64)
        S = self.sparse.copy()
        S.data *= np.repeat(w, np.diff(S.indptr))
        return BlockJacobian(S, self.dense * w[:, None])

    def __mul__(self, scalar: float) -> "BlockJacobian":
        return BlockJacobian(self.sparse * scalar, self.dense * scalar)

    __rmul__ = __mul__

    def __matmul__(self, x):
        x = np.asarray(x)
        k = self.sparse.shape[1]
        return self.sparse @ x[:k] + self.dense @ x[k:]

    def toarray(self) -> np.ndarray:
        return np.hstack([self.sparse.toarray(), self.dense])

    @staticmethod
    def of(J) -> "BlockJacobian":
        """Wrap a sparse matrix, dense array or BlockJacobian."""
        if isinstance(J, BlockJacobian):
            return J
        if sp.issparse(J):
            return BlockJacobian(J, None)
        return BlockJacobian(None, J)
