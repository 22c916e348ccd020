"""facewrap.solve.fixed: systems with fixed unknowns against a dense solve."""

import numpy as np
import pytest
import scipy.sparse as sp

from facewrap.solve import FixedSystem, split_fixed


def _spd(n, seed=0):
    rng = np.random.default_rng(seed)
    B = sp.random(n, n, density=0.2, random_state=seed) + sp.identity(n)
    return (B @ B.T + sp.identity(n)).tocsr(), rng


def _dense_solution(A, known, b, y):
    A = A.toarray()
    free = np.setdiff1d(np.arange(len(A)), known)
    x = np.zeros((len(A),) + np.shape(b)[1:])
    x[known] = y
    x[free] = np.linalg.solve(A[np.ix_(free, free)], b[free] - A[np.ix_(free, known)] @ y)
    return x


@pytest.mark.parametrize("solves", ["many", "few"])
def test_fixed_system_matches_a_dense_solve(solves):
    A, rng = _spd(30)
    known = np.array([3, 7, 20])
    system = FixedSystem(A, known, solves=solves)
    for b, y in ((rng.standard_normal(30), rng.standard_normal(3)),
                 (rng.standard_normal((30, 4)), rng.standard_normal((3, 4)))):
        x = system.solve(b, y)
        np.testing.assert_allclose(x, _dense_solution(A, known, b, y), atol=1e-9)
        np.testing.assert_array_equal(x[known], y)


def test_a_mask_and_indices_give_the_same_system():
    A, rng = _spd(12, seed=1)
    mask = np.zeros(12, dtype=bool)
    mask[[0, 5]] = True
    b, y = rng.standard_normal((12, 3)), rng.standard_normal((2, 3))
    np.testing.assert_allclose(FixedSystem(A, mask).solve(b, y),
                               FixedSystem(A, [5, 0]).solve(b, y[[0, 1]]), atol=1e-12)


def test_defaults_are_zero_and_known_values_broadcast_over_columns():
    A, rng = _spd(10, seed=2)
    system = FixedSystem(A, [2])
    np.testing.assert_allclose(system.solve(), np.zeros(10), atol=0)
    b = rng.standard_normal((10, 2))
    x = system.solve(b, [1.5])
    np.testing.assert_allclose(x, _dense_solution(A, [2], b, np.full((1, 2), 1.5)),
                               atol=1e-9)


def test_split_fixed_blocks_are_the_sub_matrices():
    A, _ = _spd(15, seed=3)
    free, known, A_ff, A_fk = split_fixed(A, [1, 14, 8])
    np.testing.assert_array_equal(known, [1, 8, 14])
    D = A.toarray()
    np.testing.assert_array_equal(A_ff.toarray(), D[np.ix_(free, free)])
    np.testing.assert_array_equal(A_fk.toarray(), D[np.ix_(free, known)])


def test_ridge_keeps_a_piece_without_known_unknowns_at_zero():
    # two separate chains, only the first has known ends
    L = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(4, 4))
    L = L - sp.diags(np.r_[1.0, 0, 0, 1.0])          # free ends: a null space
    A = sp.block_diag([L, L]).tocsr()
    x = FixedSystem(A, [0, 3], ridge=1e-10).solve(None, [1.0, 1.0])
    np.testing.assert_allclose(x[:4], 1.0, atol=1e-6)
    np.testing.assert_allclose(x[4:], 0.0, atol=1e-6)


def test_wrong_sizes_are_refused():
    A, _ = _spd(6, seed=4)
    system = FixedSystem(A, [0])
    with pytest.raises(ValueError, match="known_values"):
        system.solve(None, [1.0, 2.0])
    with pytest.raises(ValueError, match="b has"):
        system.solve(np.zeros(5))
    with pytest.raises(ValueError, match="mask"):
        FixedSystem(A, np.ones(5, dtype=bool))
    with pytest.raises(ValueError, match="out of range"):
        FixedSystem(A, [6])


def test_free_rows_alone_give_the_same_system():
    A, rng = _spd(20, seed=5)
    known = np.ones(20, dtype=bool)
    known[[4, 5, 6, 11]] = False
    b, y = rng.standard_normal((20, 3)), rng.standard_normal((16, 3))
    whole = FixedSystem(A, known)
    part = FixedSystem.from_free_rows(A[np.flatnonzero(~known)], known)
    np.testing.assert_allclose(part.solve(b, y), whole.solve(b, y), atol=1e-12)
    with pytest.raises(ValueError, match="free unknowns"):
        FixedSystem.from_free_rows(A[:3], known)
