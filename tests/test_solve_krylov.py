"""facewrap.solve.krylov: the one preconditioned conjugate gradient, both stopping
rules, against direct solves."""

import inspect

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from facewrap.solve import block_jacobi, conjugate_gradients, factorize


def _laplacian_2d(k):
    L = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(k, k))
    I = sp.identity(k)
    return (sp.kron(L, I) + sp.kron(I, L)).tocsr()


def test_error_rule_reuses_a_nearby_factor_and_gives_up_on_a_far_one():
    L = _laplacian_2d(20)
    H0 = (L @ L + 1e-3 * sp.identity(L.shape[0])).tocsr()
    M = factorize(H0)
    rng = np.random.default_rng(0)
    b = rng.normal(size=(H0.shape[0], 3))
    # a small diagonal change: converges to the exact answer in a few iterations
    near = (H0 + sp.diags(rng.uniform(0, 1e-3, H0.shape[0]))).tocsr()
    run = conjugate_gradients(near, b, np.zeros_like(b), M, rtol=1e-10,
                              max_iterations=40, stop="error", give_up=True)
    assert run.converged and 0 < run.iterations < 15
    np.testing.assert_allclose(run.x, spla.spsolve(near.tocsc(), b), rtol=0,
                               atol=1e-8 * np.abs(run.x).max())
    # a diagonal that dominates the smooth modes: predicted over budget, gives up early
    far = (H0 + 100.0 * sp.identity(H0.shape[0])).tocsr()
    run = conjugate_gradients(far, b, np.zeros_like(b), M, rtol=1e-10,
                              max_iterations=40, stop="error", give_up=True)
    assert not run.converged and run.iterations < 40


@pytest.mark.parametrize("columns", [None, 2])
def test_residual_rule_with_block_jacobi_reaches_the_tolerance(columns):
    rng = np.random.default_rng(1)
    n = 120
    B = sp.random(n, n, density=0.05, random_state=2)
    H = (B @ B.T + sp.diags(rng.uniform(1, 3, n))).tocsr()
    b = rng.normal(size=n if columns is None else (n, columns))
    run = conjugate_gradients(H, b, None, block_jacobi(H, 6) if columns is None else None,
                              rtol=1e-8)
    assert run.converged
    residual = np.linalg.norm(H @ run.x - b, axis=0)
    assert np.all(residual < 1e-8 * np.linalg.norm(b, axis=0))
    np.testing.assert_allclose(run.x, np.linalg.solve(H.toarray(), b), atol=1e-6)


def test_one_column_follows_scipys_cg():
    rng = np.random.default_rng(3)
    n = 200
    B = sp.random(n, n, density=0.03, random_state=4)
    H = (B @ B.T + sp.identity(n)).tocsr()
    b, x0 = rng.normal(size=n), rng.normal(size=n)
    M = block_jacobi(H, 6)
    # scipy < 1.12 (the lowest pyproject allows) calls the relative tolerance ``tol``
    tolerance = "rtol" if "rtol" in inspect.signature(spla.cg).parameters else "tol"
    want, _ = spla.cg(H, b, x0=x0, maxiter=400, M=M, **{tolerance: 1e-3})
    run = conjugate_gradients(H, b, x0, M, rtol=1e-3, max_iterations=400)
    np.testing.assert_allclose(run.x, want, rtol=1e-12, atol=1e-12)


def test_zero_right_hand_side_and_iteration_cap():
    H = _laplacian_2d(6)
    run = conjugate_gradients(H, np.zeros(36), np.ones(36))
    assert run.converged and run.iterations == 0 and not run.x.any()
    run = conjugate_gradients(H, np.ones(36), rtol=1e-14, max_iterations=2)
    assert not run.converged and run.iterations == 2
    with pytest.raises(ValueError, match="stop"):
        conjugate_gradients(H, np.ones(36), stop="both")


def test_block_jacobi_inverts_the_diagonal_blocks():
    rng = np.random.default_rng(5)
    blocks = [rng.normal(size=(3, 3)) for _ in range(4)]
    blocks = [b @ b.T + 3 * np.eye(3) for b in blocks]
    H = sp.block_diag(blocks + [np.array([[2.0]])]).tocsr()
    x = rng.normal(size=13)
    np.testing.assert_allclose(block_jacobi(H, 3).matvec(x),
                               np.linalg.solve(H.toarray(), x), atol=1e-12)
