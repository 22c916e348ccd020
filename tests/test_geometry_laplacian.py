"""facewrap.geometry.laplacian: Laplacians and mass matrices against libigl."""

from __future__ import annotations

import igl
import numpy as np
import pytest
import scipy.sparse as sp

import facewrap.geometry as geo

from geometry_meshes import grid, icosphere


def _check_laplacian(L, n):
    assert isinstance(L, sp.csr_matrix) and L.shape == (n, n)
    assert abs(L - L.T).max() < 1e-12
    np.testing.assert_allclose(np.asarray(L.sum(axis=1)).ravel(), 0, atol=1e-10)
    assert np.linalg.eigvalsh(L.toarray()).min() >= -1e-9


def test_cotangent_laplacian_matches_libigl():
    V, T = icosphere(2, noise=0.1)
    L = geo.cotangent_laplacian(V, T)
    _check_laplacian(L, len(V))
    assert abs(L + igl.cotmatrix(V, T)).max() < 1e-10
    assert np.all(L.diagonal() > 0)


def test_cotangent_laplacian_linear_precision():
    V, T = grid(7, 6, noise=0.0)
    V = V + np.random.default_rng(0).uniform(-0.2, 0.2, V.shape) * [1, 1, 0]
    L = geo.cotangent_laplacian(V, T)
    interior = ~geo.boundary_vertices(T, len(V))
    f = V @ [0.3, -1.2, 0.0] + 2.0
    np.testing.assert_allclose((L @ f)[interior], 0, atol=1e-12)
    np.testing.assert_allclose((L @ V[:, :2])[interior], 0, atol=1e-12)


def test_cotangent_laplacian_degenerate_is_finite():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [1, 1, 0.]])
    T = np.array([[0, 1, 2], [0, 1, 3], [1, 4, 2]])
    L = geo.cotangent_laplacian(V, T)
    assert np.all(np.isfinite(L.data))
    _check_laplacian(L, 5)


def test_uniform_laplacian():
    V, T = icosphere(1)
    L = geo.uniform_laplacian(T, len(V))
    _check_laplacian(L, len(V))
    A = geo.vertex_adjacency(T, len(V))
    np.testing.assert_array_equal(L.diagonal(), np.asarray(A.sum(axis=1)).ravel())
    assert abs(L - geo.uniform_laplacian(geo.edges(T), len(V))).max() == 0


@pytest.mark.parametrize("kind", ["voronoi", "barycentric"])
def test_mass_matrix(kind):
    V, T = icosphere(2, noise=0.1)
    V = np.vstack([V, [[9.0, 9, 9]]])          # an unused vertex
    M = geo.mass_matrix(V, T, kind)
    assert isinstance(M, sp.csr_matrix) and M.shape == (len(V), len(V))
    assert M.nnz <= len(V) and np.all(M.diagonal() >= 0)
    assert abs(M - sp.diags(M.diagonal())).max() == 0
    assert M.diagonal()[-1] == 0
    assert M.sum() == pytest.approx(geo.face_areas(V, T).sum(), rel=1e-12)
    with pytest.raises(ValueError, match="kind"):
        geo.mass_matrix(V, T, "full")
