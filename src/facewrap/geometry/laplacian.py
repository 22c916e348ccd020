"""Laplacians and mass matrices of triangle meshes.

This module owns the discrete Laplace operators used by smoothness terms and
deformation transfer, and the lumped mass matrices that go with them.

Sign convention: every Laplacian here is **positive semi-definite**, ``L = D - W``
with non-negative diagonal, off-diagonal ``-w_ij`` and rows summing to 0, so
``x @ L @ x >= 0`` is a smoothness energy.  This is the negative of libigl's
``igl.cotmatrix`` (which is negative semi-definite).
"""

from __future__ import annotations

import igl
import numpy as np
import scipy.sparse as sp

from facewrap.geometry.checks import as_count, as_mesh_arrays, as_triangles_or_edges
from facewrap.geometry.adjacency import adjacency_matrix, unique_edges
from facewrap.geometry.arrays import column_norms, cross_columns, edge_vectors

__all__ = ["cotangent_laplacian", "uniform_laplacian", "mass_matrix"]

# Triangles with |cross| <= _FLAT * (longest edge)^2 are degenerate and get zero
# cotangent weights (libigl's cotmatrix gives inf/NaN for them).
_FLAT = 1e-12

_MASS_TYPES = {
    "voronoi": igl.MassMatrixType.MASSMATRIX_TYPE_VORONOI,
    "barycentric": igl.MassMatrixType.MASSMATRIX_TYPE_BARYCENTRIC,
}


def _cotangent_laplacian(V: np.ndarray, T: np.ndarray) -> sp.csr_matrix:
    n = len(V)
    e01, e02 = edge_vectors(V, T)
    double_area = column_norms(cross_columns(e01, e02))
    l01_sq = np.einsum("ij,ij->j", e01, e01)
    l02_sq = np.einsum("ij,ij->j", e02, e02)
    d0 = np.einsum("ij,ij->j", e01, e02)       # at corner 0
    dots = np.stack([d0, l01_sq - d0, l02_sq - d0], axis=1)   # corners 0, 1, 2
    longest_sq = np.maximum(np.maximum(l01_sq, l02_sq), l01_sq + l02_sq - 2 * d0)
    ok = double_area > _FLAT * longest_sq
    inv = np.divide(0.5, double_area, out=np.zeros_like(double_area), where=ok)
    weight = dots * inv[:, None]              # cot(angle) / 2, per corner
    # corner c is opposite the edge (T[:, c + 1], T[:, c + 2])
    i = T[:, [1, 2, 0]].reshape(-1)
    j = T[:, [2, 0, 1]].reshape(-1)
    w = weight.reshape(-1)
    rows = np.concatenate([i, j, i, j])
    cols = np.concatenate([j, i, i, j])
    data = np.concatenate([-w, -w, w, w])
    L = sp.csr_matrix((data, (rows, cols)), shape=(n, n))
    L.eliminate_zeros()   # right angles and degenerate triangles give no entry
    return L


def cotangent_laplacian(V, T) -> sp.csr_matrix:
    """Cotangent Laplacian, positive semi-definite.

    Parameters
    ----------
    V : (n, 3) float64
        Vertex positions; the weights depend on the triangles' angles.
    T : (t, 3) int64
        Triangles; degenerate ones contribute nothing.

    Returns
    -------
    L : (n, n) scipy.sparse.csr_matrix
        Symmetric; ``L[i, j] = -(cot a_ij + cot b_ij) / 2`` for an edge ``ij`` with
        opposite angles ``a_ij, b_ij``, diagonal making rows sum to 0.  Equals
        ``-igl.cotmatrix(V, T)``, except that degenerate (zero-area) triangles
        contribute nothing instead of inf/NaN.  Not scaled by the mass matrix.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> cotangent_laplacian(V, [[0, 1, 2]]).toarray().tolist()
    [[1.0, -0.5, -0.5], [-0.5, 0.5, 0.0], [-0.5, 0.0, 0.5]]
    """
    V, T = as_mesh_arrays(V, T)
    return _cotangent_laplacian(V, T)


def uniform_laplacian(T_or_edges, n) -> sp.csr_matrix:
    """Graph (uniform) Laplacian ``D - A``, positive semi-definite.

    Parameters
    ----------
    T_or_edges : (t, 3) int64 or (e, 2) int64
        Triangles, or edges (for example
        :func:`~facewrap.geometry.edges_of_polygons` to use a quad mesh's own edges).
    n : int
        Number of vertices.

    Returns
    -------
    L : (n, n) scipy.sparse.csr_matrix
        Vertex degrees on the diagonal, -1.0 per edge off it.

    Examples
    --------
    >>> uniform_laplacian([[0, 1], [1, 2]], 3).toarray().tolist()
    [[1.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.0]]
    """
    n = as_count(n)
    arr, columns = as_triangles_or_edges(T_or_edges, n)
    A = adjacency_matrix(unique_edges(arr, columns), n)
    degree = np.asarray(A.sum(axis=1)).ravel()
    return (sp.diags(degree, format="csr") - A).tocsr()


def mass_matrix(V, T, kind: str = "voronoi") -> sp.csr_matrix:
    """Lumped (diagonal) mass matrix: the area each vertex stands for.

    Parameters
    ----------
    V : (n, 3) float64
    T : (t, 3) int64
        Triangles; a vertex in none of them has mass 0.
    kind : {"voronoi", "barycentric"}
        ``"voronoi"``: mixed Voronoi areas (Meyer et al. 2003; barycentric-like split
        on obtuse triangles); ``"barycentric"``: a third of each triangle's area to
        each corner.

    Returns
    -------
    M : (n, n) scipy.sparse.csr_matrix
        Diagonal, non-negative; its sum is the surface area.  Vertices used by no
        triangle get 0.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> mass_matrix(V, [[0, 1, 2]], "barycentric").diagonal().round(4).tolist()
    [0.1667, 0.1667, 0.1667]
    """
    V, T = as_mesh_arrays(V, T)
    if kind not in _MASS_TYPES:
        raise ValueError(f'kind must be "voronoi" or "barycentric", got {kind!r}')
    n = len(V)
    if len(T) == 0:
        return sp.csr_matrix((n, n))
    # libigl sizes M by the largest index in T, not by len(V): pad to n
    diagonal = np.zeros(n)
    m = igl.massmatrix(V, T, _MASS_TYPES[kind]).diagonal()
    diagonal[:len(m)] = m
    return sp.diags(diagonal, format="csr")
