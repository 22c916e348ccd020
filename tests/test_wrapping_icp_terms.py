"""Energy terms of the non-rigid ICP (facewrap.wrapping.icp.terms), and the
Gauss–Newton solve they feed."""

import numpy as np
import pytest
import scipy.sparse as sp

from facewrap.landmarks import Landmarks
from facewrap.solve import BlockJacobian, factorize, gauss_newton_step, refactorize
from facewrap.wrapping.icp.terms import (landmark_residual, landmark_rows, landmark_term,
                                         point_and_plane, point_and_plane_residual,
                                         point_to_plane, point_to_point, robust_weights)


@pytest.mark.parametrize("kind", ["welsch", "huber", "geman_mcclure", "none"])
def test_robust_weights_are_one_at_zero_and_decrease(kind):
    d = np.linspace(0, 10, 50)
    w = robust_weights(d, 1.0, kind)
    assert w[0] == 1 and ((w >= 0) & (w <= 1)).all()
    assert (np.diff(w) <= 1e-15).all()
    if kind != "none":
        assert w[-1] < 0.2


def test_robust_weights_reject_unknown_norm():
    with pytest.raises(ValueError, match="unknown robust norm"):
        robust_weights([1.0], 1.0, "cauchyish")


@pytest.mark.parametrize("method", ["cg", "direct"])
def test_gauss_newton_step_solves_the_linear_least_squares(method):
    rng = np.random.default_rng(0)
    S1 = sp.random(40, 12, density=0.3, random_state=3, format="csr") + sp.eye(40, 12)
    D1 = rng.normal(size=(40, 2))
    r1 = rng.normal(size=40)
    S2 = sp.eye(14, 12, format="csr")
    r2 = rng.normal(size=14)
    rw = rng.random(40)
    terms = [(0.7, r1, BlockJacobian(S1, D1), rw),
             (0.3, r2, BlockJacobian(S2, np.zeros((14, 2))), None)]
    delta = gauss_newton_step(terms, damping=0.0, method=method, block=3)
    A = np.vstack([np.sqrt(0.7 * rw)[:, None] * np.hstack([S1.toarray(), D1]),
                   np.sqrt(0.3) * np.hstack([S2.toarray(), np.zeros((14, 2))])])
    b = np.concatenate([np.sqrt(0.7 * rw) * r1, np.sqrt(0.3) * r2])
    expected = -np.linalg.lstsq(A, b, rcond=None)[0]
    assert np.allclose(delta, expected, atol=1e-5)


def test_both_factor_back_ends_and_refactorize_solve_exactly():
    """cholespy ("many" solves) and CHOLMOD ("few"), vectors and blocks; a
    refactorisation on the same pattern reuses the analysis; indefinite matrices
    still get a finite answer."""
    rng = np.random.default_rng(5)
    n = 60
    L = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    A = (L @ L + 0.1 * sp.identity(n)).tocsr()
    B = rng.normal(size=(n, 4))
    for solves, method in (("many", "cholesky"), ("few", "cholmod")):
        f = factorize(A, solves=solves)
        assert f.method == method
        np.testing.assert_allclose(A @ f.solve(B), B, atol=1e-9)
        np.testing.assert_allclose(A @ f.solve(B[:, 0]), B[:, 0], atol=1e-9)
    f = factorize(A, solves="few")
    A2 = (A + sp.diags(rng.uniform(0, 5, n))).tocsr()      # same pattern
    g = refactorize(f, A2)
    assert g is f and g.method == "cholmod"
    np.testing.assert_allclose(A2 @ g.solve(B), B, atol=1e-9)
    indefinite = sp.diags([1.0, -1.0, 2.0]).tocsr()
    f = factorize(indefinite, solves="few")
    assert f.method == "lu" and np.allclose(f.solve([1.0, 1.0, 1.0]), [1, -1, 0.5])
    with pytest.raises(ValueError, match="solves"):
        factorize(A, solves="some")


def test_data_and_landmark_terms_match_their_definitions():
    rng = np.random.default_rng(1)
    V = rng.normal(size=(6, 3))
    Jv = sp.identity(18, format="csr")  # vertices are the parameters
    verts = np.array([1, 4])
    targets, normals = rng.normal(size=(2, 3)), np.array([[0, 0, 1.0], [1, 0, 0]])
    r, J = point_to_point(V, Jv, verts, targets)
    assert np.allclose(r, (V[verts] - targets).ravel()) and J.shape == (6, 18)
    r, J = point_to_plane(V, Jv, verts, targets, normals)
    assert np.allclose(r, [V[1, 2] - targets[0, 2], V[4, 0] - targets[1, 0]])
    assert np.allclose(J.toarray()[0, 3:6], [0, 0, 1])
    T = np.array([[0, 1, 2], [3, 4, 5]])
    lm = Landmarks.from_barycentric([1], [[0.2, 0.3, 0.5]])
    L = landmark_rows(lm, 6, T)
    r, J = landmark_term(V, Jv, L, np.zeros((1, 3)))
    assert np.allclose(r, 0.2 * V[3] + 0.3 * V[4] + 0.5 * V[5])
    with pytest.raises(ValueError, match="free points"):
        landmark_rows(Landmarks.from_points([[0, 0, 0.0]]), 6, T)




def test_residual_functions_are_the_residuals_of_the_terms():
    """The step and the energy of the engine use the same residuals."""
    rng = np.random.default_rng(4)
    V = rng.normal(size=(8, 3))
    Jv = sp.identity(24, format="csr")
    verts = np.array([0, 3, 7])
    targets = rng.normal(size=(3, 3))
    normals = rng.normal(size=(3, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    r, _ = point_and_plane(V, Jv, verts, targets, normals, 0.1)
    np.testing.assert_allclose(point_and_plane_residual(V, verts, targets, normals, 0.1),
                               r, rtol=1e-14)
    # and its square is point-to-plane plus point_weight x point-to-point
    diff = V[verts] - targets
    expected = (np.einsum("ka,ka->k", diff, normals) ** 2).sum() + 0.1 * (diff ** 2).sum()
    np.testing.assert_allclose(r @ r, expected, rtol=1e-12)
    lm = Landmarks.from_vertices([1, 5])
    L = landmark_rows(lm, 8)
    r, _ = landmark_term(V, Jv, L, targets[:2])
    np.testing.assert_allclose(landmark_residual(V, L, targets[:2]), r, rtol=1e-14)
