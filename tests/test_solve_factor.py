"""facewrap.solve.factor: the split (forward / backward) halves of a CHOLMOD solve,
against dense solves."""

import numpy as np
import pytest
import scipy.sparse as sp

from facewrap.solve import factorize, refactorize


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


def test_refactorize_reuses_the_analysis_of_the_same_pattern():
    A = _spd(12)
    factor = factorize(A, solves="few")
    A2 = (A + sp.diags(np.linspace(0.5, 2.0, A.shape[0]))).tocsr()
    b = np.random.default_rng(2).normal(size=A.shape[0])
    again = refactorize(factor, A2)
    assert again is factor                      # refilled in place, same analysis
    np.testing.assert_allclose(again.solve(b), np.linalg.solve(A2.toarray(), b),
                               rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("check", [True, False])
def test_refactorize_factors_another_pattern_afresh_and_correctly(check):
    # CHOLMOD given another pattern than its analysis returns a wrong factor without
    # complaint: refactorize must notice and start over
    A = _spd(12)
    n = A.shape[0]
    factor = factorize(A, solves="few")
    extra = sp.coo_matrix(([0.3, 0.3], ([0, n - 1], [n - 1, 0])), shape=(n, n))
    A2 = (A + extra).tocsr()
    b = np.random.default_rng(3).normal(size=n)
    again = refactorize(factor, A2, check=check)
    np.testing.assert_allclose(again.solve(b), np.linalg.solve(A2.toarray(), b),
                               rtol=1e-10, atol=1e-12)
    # and a pattern with fewer entries (explicit zeros dropped) is another pattern too
    fewer = A.tolil()
    fewer[0, 1] = fewer[1, 0] = 0.0
    fewer = fewer.tocsr()
    fewer.eliminate_zeros()
    third = refactorize(again, fewer, check=check)
    np.testing.assert_allclose(third.solve(b), np.linalg.solve(fewer.toarray(), b),
                               rtol=1e-10, atol=1e-12)


def test_refactorize_of_an_indefinite_matrix_falls_back_to_another_method():
    A = _spd(6)
    factor = factorize(A, solves="few")
    bad = (A - sp.identity(A.shape[0]) * 10.0).tocsr()    # same pattern, indefinite
    b = np.ones(A.shape[0])
    again = refactorize(factor, bad)
    assert again.method != "cholmod"
    np.testing.assert_allclose(again.solve(b), np.linalg.solve(bad.toarray(), b),
                               rtol=1e-9, atol=1e-12)
