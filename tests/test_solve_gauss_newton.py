"""facewrap.solve.gauss_newton: every solve path of a Gauss–Newton step against a
dense least-squares oracle, and the block Gram products against SᵀS."""

import numpy as np
import pytest
import scipy.sparse as sp

from facewrap.solve import BlockJacobian, gauss_newton_step, gram_matrix, sparse_gram_matrix
from facewrap.solve.gauss_newton import BORDERED_FROM, DENSE_LIMIT


def _vertex_rows(rng, n, m, k=4):
    """Vertex rows of a graph Jacobian: each vertex skinned by ``k`` of ``m`` nodes
    (6 unknowns each), columns unsorted as the skinning gives them."""
    nodes = np.stack([rng.choice(m, k, replace=False) for _ in range(n)])
    cols = (6 * nodes)[:, None, :, None] + np.arange(6)
    return sp.csr_matrix((rng.normal(size=(n, 3, k, 6)).ravel(),
                          np.broadcast_to(cols, (n, 3, k, 6)).ravel(),
                          np.arange(0, 18 * k * n + 1, 6 * k)), shape=(3 * n, 6 * m))


def test_gram_matrices_equal_the_plain_product():
    rng = np.random.default_rng(2)
    S = _vertex_rows(rng, 300, 30)
    want = (S.T @ S).toarray()
    np.testing.assert_allclose(gram_matrix(S), want, atol=1e-12)
    np.testing.assert_allclose(sparse_gram_matrix(S).toarray(), want, atol=1e-12)
    T = sp.random(50, 40, density=0.1, random_state=1, format="csr")  # no triples
    np.testing.assert_allclose(gram_matrix(T), (T.T @ T).toarray(), atol=1e-12)
    np.testing.assert_allclose(sparse_gram_matrix(T).toarray(), (T.T @ T).toarray(),
                               atol=1e-12)


def _oracle(terms, damping):
    """The damped step from dense normal equations (same diagonal floor)."""
    rows, rhs = [], []
    for weight, r, J, rw in terms:
        J = BlockJacobian.of(J)
        w = weight * (np.ones(len(r)) if rw is None else np.asarray(rw))
        dense = np.hstack([J.sparse.toarray(), J.dense])
        rows.append(np.sqrt(w)[:, None] * dense)
        rhs.append(np.sqrt(w) * r)
    A, b = np.vstack(rows), np.concatenate(rhs)
    H = A.T @ A
    d = np.diag(H).copy()
    H[np.diag_indices_from(H)] += damping * d + 1e-9 * d.max()
    return -np.linalg.solve(H, A.T @ b)


def _terms(rng, n_vertices, n_nodes, n_blend):
    S = _vertex_rows(rng, n_vertices, n_nodes)
    D = rng.normal(size=(S.shape[0], n_blend))
    smooth = sp.random(6 * n_nodes, 6 * n_nodes, density=0.01, random_state=3,
                       format="csr") + sp.identity(6 * n_nodes, format="csr")
    return [(1.0, rng.normal(size=S.shape[0]), BlockJacobian(S, D),
             rng.uniform(0.5, 1.0, S.shape[0])),
            (0.3, rng.normal(size=smooth.shape[0]),
             BlockJacobian(smooth, np.zeros((smooth.shape[0], n_blend))), None)]


@pytest.mark.parametrize("n_nodes, n_blend, method", [
    (20, 5, "direct"),                     # dense assembly
    (110, 5, "direct"),                    # sparse block + dense Schur complement
    (110, 0, "direct"),                    # ... without blend columns
    pytest.param(420, 0, "direct", marks=pytest.mark.slow),  # large: sparse factor
    pytest.param(420, 0, "cg", marks=pytest.mark.slow),      # large: conjugate gradients
])
def test_every_path_solves_the_damped_normal_equations(n_nodes, n_blend, method):
    P = 6 * n_nodes + n_blend
    # the parametrisation really takes the path its comment names
    assert (P <= DENSE_LIMIT) == (n_nodes < 420)
    assert (6 * n_nodes >= BORDERED_FROM) == (n_nodes >= 110)
    rng = np.random.default_rng(n_nodes + n_blend)
    terms = _terms(rng, 2 * n_nodes, n_nodes, n_blend)
    for damping in (0.0, 1e-2):
        got = gauss_newton_step(terms, damping=damping, method=method, block=6,
                                cg_rtol=1e-10, max_cg=2000)
        want = _oracle(terms, damping)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * np.abs(want).max())


def test_no_terms_give_a_zero_step():
    assert gauss_newton_step([], n_params=4).tolist() == [0.0] * 4
    J = sp.csr_matrix(np.eye(3))
    assert not gauss_newton_step([(0.0, np.ones(3), J, None)], n_params=3).any()


@pytest.mark.parametrize("n_nodes, n_blend", [(20, 5), (110, 5), (110, 0)])
def test_normal_equations_solve_again_for_every_damping(n_nodes, n_blend):
    """One assembly answers every damping of a Levenberg–Marquardt retry as the
    dense oracle does, in any order (the bordered path reuses its factor's
    pattern); its energy is the weighted squared residual."""
    from facewrap.solve import normal_equations
    rng = np.random.default_rng(7 * n_nodes + n_blend)
    terms = _terms(rng, 2 * n_nodes, n_nodes, n_blend)
    system = normal_equations(terms, block=6)
    assert system.path == ("bordered" if 6 * n_nodes >= BORDERED_FROM else "dense")
    want_energy = sum(w * float(((np.ones(len(r)) if rw is None else rw) * r) @ r)
                      for w, r, _, rw in terms)
    assert system.energy == pytest.approx(want_energy, rel=1e-12)
    for damping in (1e-4, 1e-3, 1e-2, 1e-1, 1e-4):
        want = _oracle(terms, damping)
        np.testing.assert_allclose(system.step(damping), want, rtol=0,
                                   atol=1e-6 * np.abs(want).max())
    # more damping, a shorter step in the damping's metric
    d = np.diag(_oracle_hessian(terms))
    norms = [float(np.sqrt(d @ system.step(mu) ** 2)) for mu in (1e-3, 1e-1, 10.0)]
    assert norms[0] > norms[1] > norms[2]


def _oracle_hessian(terms):
    rows = []
    for weight, r, J, rw in terms:
        J = BlockJacobian.of(J)
        w = weight * (np.ones(len(r)) if rw is None else np.asarray(rw))
        rows.append(np.sqrt(w)[:, None] * np.hstack([J.sparse.toarray(), J.dense]))
    A = np.vstack(rows)
    return A.T @ A


def test_normal_equations_of_no_terms_give_zero_steps():
    from facewrap.solve import normal_equations
    system = normal_equations([], n_params=4)
    assert system.path == "zero" and system.energy == 0.0
    assert system.step(1.0).tolist() == [0.0] * 4
