"""facewrap.transfer.gradients: deformation-gradient operators against the
direct formula and their invariants."""

import numpy as np

from facewrap.sample import make_template
from facewrap.transfer import (adjacent_triangle_pairs, deformation_gradients,
                               fourth_vertices, gradient_operator,
                               triangle_smoothness_operator)
from transfer_cases import random_rotation


def test_operator_matches_direct_formula():
    rng = np.random.default_rng(1)
    V = rng.normal(size=(30, 3))
    T = np.array([rng.choice(30, 3, replace=False) for _ in range(40)])
    X = V + 0.3 * rng.normal(size=V.shape)
    op = gradient_operator(V, T)
    Q = op.gradients(X)
    for i in (0, 7, 39):
        a, b, c = T[i]

        def edges(P):
            n = np.cross(P[b] - P[a], P[c] - P[a])
            return np.column_stack([P[b] - P[a], P[c] - P[a], n / np.sqrt(np.linalg.norm(n))])
        np.testing.assert_allclose(Q[i], edges(X) @ np.linalg.inv(edges(V)), atol=1e-9)
    assert op.matrix.shape == (3 * len(T), len(V) + len(T))
    np.testing.assert_allclose(np.asarray(op.matrix.sum(axis=1)).ravel(), 0, atol=1e-9)


def test_gradient_of_similarity_and_affine_map():
    rng = np.random.default_rng(2)
    mesh = make_template(20).mesh
    V, T = mesh.vertices, mesh.triangles
    R = random_rotation(rng)
    Q, degenerate = deformation_gradients(V, 1.7 * V @ R.T + [1, 2, 3], T)
    assert not degenerate.any()
    np.testing.assert_allclose(Q, np.broadcast_to(1.7 * R, Q.shape), atol=1e-9)
    A = rng.normal(size=(3, 3)) + 3 * np.eye(3)        # general affine: edges map as A
    Q, _ = deformation_gradients(V, V @ A.T, T)
    E = V[T[:, 1]] - V[T[:, 0]]
    np.testing.assert_allclose(np.einsum("tij,tj->ti", Q, E), E @ A.T, atol=1e-9)


def test_degenerate_triangles_are_finite_and_reported():
    V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [5, 5, 5.]])
    T = np.array([[0, 1, 3], [0, 1, 2], [4, 4, 4], [1, 2, 3]])  # collinear, a point
    op = gradient_operator(V, T)
    assert op.degenerate.tolist() == [False, True, True, False]
    assert np.isfinite(op.matrix.data).all()
    assert np.isfinite(fourth_vertices(V, T)).all()
    Q = op.gradients(V)
    assert np.isfinite(Q).all()
    np.testing.assert_allclose(Q[~op.degenerate], np.broadcast_to(np.eye(3), (2, 3, 3)),
                               atol=1e-12)


def test_smoothness_operator_vanishes_on_rigid_motion():
    mesh = make_template(20).mesh
    op = gradient_operator(mesh.vertices, mesh.triangles)
    D = triangle_smoothness_operator(op, adjacent_triangle_pairs(mesh.triangles))
    R = random_rotation(np.random.default_rng(3))
    X = op.extend(mesh.vertices @ R.T + 5)
    assert np.abs(D @ X).max() < 1e-9
    assert np.abs(op.matrix @ X - np.tile(R.T, (op.n_triangles, 1))).max() < 1e-9


def test_eliminating_the_fourth_vertices_keeps_the_vertex_solution():
    """The reduced system's minimiser is the full (n + t) system's, vertex for vertex,
    with weighted rows and several right-hand sides, dense or sparse."""
    import scipy.sparse as sp
    from facewrap.transfer import FourthVertexElimination
    mesh = make_template(16).mesh
    V, T = mesh.vertices, mesh.triangles
    op = gradient_operator(V, T)
    n, t = len(V), len(T)
    rng = np.random.default_rng(4)
    W = sp.diags(np.repeat(rng.uniform(0.5, 2.0, t), 3))
    H = (op.matrix.T @ W @ op.matrix).tocsr() + sp.diags(np.r_[np.ones(n), np.zeros(t)])
    b = rng.normal(size=(n + t, 4))
    full = np.linalg.solve(H.toarray(), b)[:n]
    fourth = FourthVertexElimination(H, n)
    reduced = np.linalg.solve(fourth.matrix.toarray(), fourth.reduce(b))
    np.testing.assert_allclose(reduced, full, atol=1e-9 * np.abs(full).max())
    sparse_b = fourth.reduce(sp.csr_matrix(b)).toarray()
    np.testing.assert_allclose(sparse_b, fourth.reduce(b), atol=1e-12)


def test_a_fourth_vertex_block_without_a_positive_diagonal_is_refused():
    import pytest
    import scipy.sparse as sp
    from facewrap.transfer import FourthVertexElimination
    op = gradient_operator(np.eye(3), [[0, 1, 2]])
    H = op.matrix.T @ op.matrix
    with pytest.raises(ValueError, match="positive diagonal"):
        FourthVertexElimination(H - sp.diags(np.r_[0, 0, 0, 2 * H.diagonal()[3]]), 3)
