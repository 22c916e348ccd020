"""Energy terms of non-rigid ICP, each as (residual, Jacobian) — SPEC §2.1.

Every term is a function of the model's vertex Jacobian ``Jv`` (sparse
(3n, P), see :mod:`facewrap.wrapping.models.base`) and returns the residual vector ``r``
and its Jacobian ``J`` (sparse (len(r), P)), *unweighted*; the solver
(:func:`facewrap.solve.factor.gauss_newton_step`) weights and sums them.  Small pieces
so each can be tested alone against finite differences.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["BlockJacobian", "point_to_point", "point_to_plane", "point_and_plane",
           "landmark_term",
           "robust_weights", "landmark_rows"]


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
        dense = np.einsum("kab,kbp->kap", M, self.dense.reshape(k, 3, -1)).reshape(3 * k, -1)
        if k and S.shape[1] and q[0] > 0 and (q == q[0]).all():
            idx = S.indices.reshape(k, 3, q[0])
            if (idx == idx[:, :1]).all():
                vals = np.einsum("kab,kbq->kaq", M, S.data.reshape(k, 3, q[0]))
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


def _rows_of(vertices) -> np.ndarray:
    v = np.asarray(vertices, dtype=np.int64)
    return (3 * v[:, None] + np.arange(3)).ravel()


def point_to_point(V, Jv, vertices, targets):
    """Eq. 2: ``v_i − c_i`` for the given vertices.

    Parameters
    ----------
    V : (n, 3) float64
        Current vertices.
    Jv : (3n, P) sparse or BlockJacobian
    vertices : (k,) int
        Vertex ids with a correspondence.
    targets : (k, 3) float64
        Their corresponding scan points ``c_i``.

    Returns
    -------
    r : (3k,) float64
    J : (3k, P) BlockJacobian
    """
    r = (V[vertices] - targets).ravel()
    return r, BlockJacobian.of(Jv).rows(_rows_of(vertices))


def point_to_plane(V, Jv, vertices, targets, normals):
    """Eq. 3: ``n_iᵀ (v_i − c_i)`` with the scan normals ``n_i`` (k, 3).

    Returns
    -------
    r : (k,) float64
    J : (k, P) BlockJacobian
    """
    k = len(vertices)
    r = np.einsum("ka,ka->k", V[vertices] - targets, normals)
    N = sp.csr_matrix((np.asarray(normals, dtype=np.float64).ravel(),
                       (np.repeat(np.arange(k), 3), np.arange(3 * k))), shape=(k, 3 * k))
    return r, BlockJacobian.of(Jv).rows(_rows_of(vertices)).left(N)


def point_and_plane(V, Jv, vertices, targets, normals, point_weight: float,
                    jacobian_rows=None):
    """Point-to-plane plus ``point_weight`` × point-to-point, as one term.

    ``(v − c)ᵀ (n nᵀ + λ I) (v − c)`` equals eq. 3 + λ·eq. 2; it is written as
    ``‖√M (v − c)‖²`` with ``√M = √λ I + (√(1+λ) − √λ) n nᵀ``: 3 rows per vertex
    instead of 4, one sparse product instead of two.

    ``jacobian_rows`` (k,) gives the vertices' positions in ``Jv`` when it holds
    the rows of a subset of vertices only (default: ``vertices``).

    Returns
    -------
    r : (3k,) float64
    J : (3k, P) BlockJacobian
    """
    n = np.asarray(normals, dtype=np.float64)
    lam = float(point_weight)
    a, b = np.sqrt(lam), np.sqrt(1.0 + lam) - np.sqrt(lam)
    S = a * np.eye(3) + b * np.einsum("ka,kb->kab", n, n)          # (k, 3, 3)
    r = np.einsum("kab,kb->ka", S, V[vertices] - targets).ravel()
    at = vertices if jacobian_rows is None else jacobian_rows
    return r, BlockJacobian.of(Jv).rows(_rows_of(at)).left_blocks(S)


def landmark_term(V, Jv, landmark_matrix, targets, jacobian_vertices=None):
    """Landmarks at their targets: ``L V − p`` (landmarks as sparse rows of ``L``).

    Parameters
    ----------
    landmark_matrix : (l, n) sparse
        Row ``q`` holds the vertex or barycentric weights of landmark ``q``.
    targets : (l, 3) float64
    jacobian_vertices : (v,) int, optional
        The vertices whose rows ``Jv`` holds (in that order), when it is the
        Jacobian of a subset; they must include every landmark vertex.

    Returns
    -------
    r : (3l,) float64
    J : (3l, P) BlockJacobian
    """
    L = sp.csr_matrix(landmark_matrix)
    r = (L @ V - targets).ravel()
    if jacobian_vertices is not None:
        L = L[:, np.asarray(jacobian_vertices)]
    L3 = sp.kron(L, sp.identity(3), format="csr")
    return r, BlockJacobian.of(Jv).left(L3)


def robust_weights(distances, scale: float, kind: str = "welsch") -> np.ndarray:
    """IRLS weights of a robust norm for residual lengths ``distances``.

    Parameters
    ----------
    distances : (k,) float
        Residual lengths (non-negative).
    scale : float
        The norm's scale σ (residuals well below σ count fully).
    kind : {"welsch", "huber", "geman_mcclure", "none"}

    Returns
    -------
    (k,) float64 in [0, 1]

    Examples
    --------
    >>> robust_weights([0.0, 1.0, 3.0], 1.0, "huber").tolist()
    [1.0, 1.0, 0.3333333333333333]
    """
    d = np.abs(np.asarray(distances, dtype=np.float64))
    if kind == "none":
        return np.ones_like(d)
    s = max(float(scale), 1e-300)
    if kind == "welsch":
        return np.exp(-0.5 * (d / s) ** 2)
    if kind == "huber":
        return np.minimum(1.0, s / np.maximum(d, 1e-300))
    if kind == "geman_mcclure":
        return (s * s / (s * s + d * d)) ** 2
    raise ValueError(f"unknown robust norm {kind!r}")


def landmark_rows(landmarks, n_vertices: int, triangles=None) -> sp.csr_matrix:
    """Sparse rows that give landmark positions from vertices: ``P = L @ V``.

    Parameters
    ----------
    landmarks : Landmarks
        Vertex or surface (triangle + barycentric) landmarks; free points are not
        allowed (snap them to the mesh first).
    n_vertices : int
    triangles : (t, 3) int, optional
        Needed for surface landmarks.

    Returns
    -------
    (l, n_vertices) scipy.sparse.csr_matrix
    """
    k = len(landmarks)
    rows, cols, vals = [], [], []
    iv = np.flatnonzero(landmarks.vertex >= 0)
    rows.append(iv)
    cols.append(landmarks.vertex[iv])
    vals.append(np.ones(len(iv)))
    it = np.flatnonzero(landmarks.triangle >= 0)
    if len(it):
        if triangles is None:
            raise ValueError("surface landmarks need the mesh triangles")
        T = np.asarray(triangles)
        rows.append(np.repeat(it, 3))
        cols.append(T[landmarks.triangle[it]].ravel())
        vals.append(np.asarray(landmarks.barycentric)[it].ravel())
    free = np.setdiff1d(np.arange(k), np.r_[iv, it])
    if len(free):
        raise ValueError(f"landmarks {free.tolist()} are free points, not on the mesh")
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                 np.concatenate(cols))),
                         shape=(k, n_vertices))
