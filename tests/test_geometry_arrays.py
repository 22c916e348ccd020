"""facewrap.geometry.arrays: the trusted primitives agree with numpy's own."""

import numpy as np
import pytest

from facewrap.geometry.arrays import (blocks_by_budget, column_norms, cross_columns, cross_rows,
                                      edge_vectors, normalize_rows, safe_inverse,
                                      stable_sort_order, spatial_order, unique_integers)


def test_cross_products_match_numpy():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    np.testing.assert_allclose(cross_rows(a, b), np.cross(a, b), atol=1e-12)
    np.testing.assert_allclose(cross_columns(a.T, b.T), np.cross(a, b).T, atol=1e-12)
    np.testing.assert_allclose(column_norms(a.T), np.linalg.norm(a, axis=1), rtol=1e-12)


def test_normalize_rows_keeps_zero_rows_zero():
    a = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0]])
    unit, norm = normalize_rows(a)
    np.testing.assert_allclose(unit, [[0.6, 0.8, 0.0], [0.0, 0.0, 0.0]], atol=1e-15)
    np.testing.assert_allclose(norm, [5.0, 0.0])
    assert safe_inverse(np.array([0.0, -2.0, 4.0])).tolist() == [0.0, 0.0, 0.25]


def test_edge_vectors_are_corner_differences():
    rng = np.random.default_rng(1)
    V = rng.normal(size=(10, 3))
    T = rng.integers(0, 10, size=(20, 3))
    e01, e02 = edge_vectors(V, T)
    np.testing.assert_allclose(e01.T, V[T[:, 1]] - V[T[:, 0]], atol=1e-15)
    np.testing.assert_allclose(e02.T, V[T[:, 2]] - V[T[:, 0]], atol=1e-15)


@pytest.mark.parametrize("budget", [1, 3, 7, 100])
def test_blocks_cover_every_nonempty_item_once_in_order(budget):
    counts = np.random.default_rng(2).integers(0, 5, size=200)
    blocks = list(blocks_by_budget(counts, budget))
    joined = np.concatenate(blocks)
    assert joined.tolist() == np.flatnonzero(counts).tolist()
    for block in blocks:                    # about the budget: over it by less than one item
        assert counts[block].sum() < budget + counts.max()
    assert list(blocks_by_budget(np.zeros(4, int), budget)) == []


@pytest.mark.parametrize("values", [
    np.array([5, 1, 5, 3, 1, 1]),                     # ties: input order kept
    np.random.default_rng(3).integers(-50, 50, 2000),
    np.array([2 ** 62, -2 ** 62, 0, 2 ** 62]),         # codes would overflow: argsort
    np.zeros(0, np.int64)])
def test_stable_sort_order_is_the_stable_argsort(values):
    order, s = stable_sort_order(values)
    np.testing.assert_array_equal(order, np.argsort(values, kind="stable"))
    np.testing.assert_array_equal(s, values[np.argsort(values, kind="stable")])


def test_unique_integers_gives_what_np_unique_gives():
    a = np.random.default_rng(4).integers(0, 300, 5000)
    got = unique_integers(a, return_index=True, return_inverse=True, return_counts=True)
    want = np.unique(a, return_index=True, return_inverse=True, return_counts=True)
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w.reshape(-1))


def test_spatial_order_is_a_permutation_that_keeps_neighbours_together():
    rng = np.random.default_rng(4)
    P = rng.uniform(-3.0, 5.0, size=(2000, 3))
    order = spatial_order(P)
    assert order.dtype == np.int64
    assert np.array_equal(np.sort(order), np.arange(len(P)))
    # consecutive points in the order are far nearer each other than in random order
    step = np.linalg.norm(np.diff(P[order], axis=0), axis=1)
    random_step = np.linalg.norm(np.diff(P, axis=0), axis=1)
    assert np.median(step) < 0.25 * np.median(random_step)


def test_spatial_order_of_degenerate_sets():
    assert spatial_order(np.zeros((0, 3))).tolist() == []
    assert spatial_order(np.ones((1, 3))).tolist() == [0]
    # all points equal: any permutation is right, and it is the stable one
    assert spatial_order(np.ones((5, 3))).tolist() == [0, 1, 2, 3, 4]
