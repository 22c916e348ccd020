"""facewrap.solve.factor: the split (forward / backward) halves of a CHOLMOD solve,
against dense solves."""

import numpy as np
import scipy.sparse as sp

from facewrap.solve import factorize


def _spd(k=15, seed=0):
    L = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(k, k))
    I = sp.identity(k)
    A = (sp.kron(L, I) + sp.kron(I, L)).tocsr()
    rng = np.random.default_rng(seed)
    return (A + sp.diags(rng.uniform(0.1, 1.0, k * k))).tocsr()


def test_forward_half_gives_the_quadratic_form_and_backward_finishes_the_solve():
    A = _spd()
    B = np.random.default_rng(1).normal(size=(A.shape[0], 4))
    factor = factorize(A, solves="few")
    assert factor.method == "cholmod"
    Y = factor.forward(B)
    want = np.linalg.solve(A.toarray(), B)
    # YᵀY = Bᵀ A⁻¹ B: what a Schur complement needs, from half a solve
    np.testing.assert_allclose(Y.T @ Y, B.T @ want, rtol=1e-10, atol=1e-12)
    for j in range(B.shape[1]):
        np.testing.assert_allclose(factor.backward(Y[:, j]), want[:, j], rtol=1e-10,
                                   atol=1e-12)


def test_back_ends_that_do_not_split_their_solves_say_so():
    A = _spd(8)
    factor = factorize(A)                       # cholespy: for many solves
    assert factor.method == "cholesky"
    assert factor.forward(np.ones((A.shape[0], 2))) is None
