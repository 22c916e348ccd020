"""The landmark RBF warp and the landmark pull (facewrap.wrapping.warp)."""

import numpy as np
import pytest

from facewrap.wrapping.warp import RBFWarp, pull_to_landmarks

from geometry_meshes import quad_ellipsoid


def test_rbf_recovers_smooth_field_from_landmarks():
    """A template deformed by a known smooth field: 30 landmarks recover it."""
    V, _ = quad_ellipsoid(30)
    field = lambda p: np.stack([0.1 * np.sin(2 * p[:, 1]), 0.08 * p[:, 0] * p[:, 2],
                                0.05 * np.cos(p[:, 0])], -1) + [0.3, 0, 0]
    rng = np.random.default_rng(1)
    idx = rng.choice(len(V), 30, replace=False)
    warp = RBFWarp().fit(V[idx], field(V[idx]))
    assert np.allclose(warp.transform(V[idx]), V[idx] + field(V[idx]), atol=1e-10)
    err = np.linalg.norm(warp.displacement(V) - field(V), axis=1)
    size = np.linalg.norm(V.max(0) - V.min(0))
    assert err.max() < 0.02 * size and err.mean() < 0.004 * size
    for kernel in ("thin_plate", "exponential", "gaussian"):
        w = RBFWarp(kernel=kernel).fit(V[idx], field(V[idx]))
        assert np.allclose(w.displacement(V[idx]), field(V[idx]), atol=1e-8)
    # smoothing approximates instead of interpolating
    noisy = field(V[idx]) + rng.normal(scale=0.02, size=(30, 3))
    smooth = RBFWarp(smoothing=1.0).fit(V[idx], noisy)
    assert not np.allclose(smooth.displacement(V[idx]), noisy, atol=1e-6)


def test_rbf_with_few_landmarks_is_a_translation_and_chunks_agree():
    C = np.array([[0, 0, 0], [1, 0, 0.]])
    w = RBFWarp().fit(C, np.array([[1, 1, 1], [1, 1, 1.]]))
    assert np.allclose(w.displacement(np.array([[5, 5, 5.]])), [[1, 1, 1]])
    rng = np.random.default_rng(2)
    C = rng.normal(size=(10, 3))
    P = rng.normal(size=(1000, 3))
    a = RBFWarp(chunk=7).fit(C, C ** 2).displacement(P)
    b = RBFWarp().fit(C, C ** 2).displacement(P)
    assert np.allclose(a, b)


@pytest.mark.parametrize("kwargs, C, D, msg", [
    (dict(kernel="cubic"), np.eye(3), np.eye(3), "unknown kernel"),
    (dict(smoothing=-1), np.eye(3), np.eye(3), "smoothing"),
    ({}, np.eye(3), np.eye(2), "both be"),
    ({}, np.array([[0, 0, 0], [0, 0, 0.]]), np.zeros((2, 3)), "same position"),
    ({}, np.array([[0, 0, np.nan]]), np.zeros((1, 3)), "finite"),
])
def test_rbf_rejects_bad_input(kwargs, C, D, msg):
    with pytest.raises(ValueError, match=msg):
        RBFWarp(**kwargs).fit(C, D)


def test_rbf_without_affine_part_is_local():
    rng = np.random.default_rng(3)
    C = rng.normal(size=(12, 3))
    D = rng.normal(size=(12, 3))
    w = RBFWarp(kernel="gaussian", width=0.5, affine=False).fit(C, D)
    assert np.allclose(w.displacement(C), D, atol=1e-8)      # interpolates
    assert np.allclose(w.affine_, 0)
    assert np.abs(w.displacement(np.array([[20.0, 0, 0]]))).max() < 1e-12   # vanishes
    # with the affine part the same data moves a far point
    assert np.abs(RBFWarp(kernel="gaussian", width=0.5).fit(C, D)
                  .displacement(np.array([[20.0, 0, 0]]))).max() > 1e-3


def test_pull_to_landmarks_shortens_offsets_by_the_tolerance():
    rng = np.random.default_rng(4)
    grid = np.stack(np.meshgrid(*[np.linspace(0, 1, 11)] * 2, indexing="ij"), -1)
    P = np.column_stack([grid.reshape(-1, 2), np.zeros(121)])
    lm = np.array([0, 10, 60, 110, 120, 33])        # corners, centre, one inside
    targets = P[lm] + rng.normal(scale=0.01, size=(6, 3))
    targets[2] = P[60] + [0.2, 0.0, 0.0]           # far off: gets pulled
    tol = 0.05
    moved, pulls = pull_to_landmarks(P, P[lm], targets, tol)
    left = np.linalg.norm(moved[lm] - targets, axis=1)
    within = np.linalg.norm(P[lm] - targets, axis=1) <= tol
    assert np.allclose(pulls[within], 0) and np.allclose(moved[lm[within]], P[lm[within]])
    assert np.isclose(pulls[2], 0.15) and np.isclose(left[2], tol)
    assert np.allclose(moved[60] - P[60], [0.15, 0, 0])      # straight toward the target
    # exact pins, and no pull at all
    pinned, _ = pull_to_landmarks(P, P[lm], targets, 0.0)
    assert np.allclose(pinned[lm], targets)
    same, none = pull_to_landmarks(P, P[lm], targets, np.inf)
    assert np.array_equal(same, P) and not none.any()
    # two landmarks on one point share their pull (no singular system)
    both, _ = pull_to_landmarks(P, P[[60, 60]], P[[60, 60]] + [[0.2, 0, 0], [0, 0.2, 0]], 0)
    assert np.allclose(both[60] - P[60], [0.1, 0.1, 0])
    with pytest.raises(ValueError, match="tolerance"):
        pull_to_landmarks(P, P[lm], targets, -1.0)


def test_pull_never_folds_the_surface_between_disagreeing_landmarks():
    """Noisy landmarks pulled a spacing apart in opposite directions would turn
    the skin between them over: the pulls around the fold are cut until none is
    turned, while a landmark far from them keeps its whole pull."""
    from facewrap.geometry.quality import turned_triangles
    k = 20
    s = np.linspace(0, 1, k + 1)
    a, b = np.meshgrid(s, s, indexing="ij")
    P = np.stack([a.ravel(), b.ravel(), np.zeros(a.size)], axis=1)
    i = (np.arange(k)[:, None] * (k + 1) + np.arange(k)[None]).ravel()
    T = np.vstack([np.stack([i, i + k + 1, i + 1], 1),
                   np.stack([i + 1, i + k + 1, i + k + 2], 1)])
    lm = np.array([4 * 21 + 4, 4 * 21 + 6, 6 * 21 + 4, 6 * 21 + 6,    # a tight square
                   16 * 21 + 16])                                  # and one far off
    targets = P[lm].copy()
    targets[:4] = P[lm[[3, 2, 1, 0]]]          # each corner of the square to the opposite
    targets[4] += [0.05, 0.02, 0.0]
    free, free_pulls = pull_to_landmarks(P, P[lm], targets, 0.0)
    assert turned_triangles(free, P, T).sum() > 10
    held, pulls = pull_to_landmarks(P, P[lm], targets, 0.0, triangles=T)
    assert not turned_triangles(held, P, T).any()
    assert (pulls[:4] < 0.5 * free_pulls[:4]).all()
    np.testing.assert_allclose(pulls[4], free_pulls[4], rtol=1e-12)
    np.testing.assert_allclose(held[lm[4]], targets[4], atol=1e-6)
    # landmarks that agree are pulled exactly as without the guard
    gentle = P[lm] + [0.01, 0.005, 0.0]
    np.testing.assert_allclose(pull_to_landmarks(P, P[lm], gentle, 0.0, triangles=T)[0],
                               pull_to_landmarks(P, P[lm], gentle, 0.0)[0], atol=1e-12)


def test_nearest_other_distances_against_a_brute_force_oracle():
    from facewrap.wrapping.warp import nearest_other_distances
    rng = np.random.default_rng(3)
    for n in (2, 50, 2500):          # the table, and past it the KD-tree
        C = rng.normal(size=(n, 3))
        want = np.array([np.min(np.linalg.norm(np.delete(C, i, axis=0) - C[i], axis=1))
                         for i in range(n)])
        np.testing.assert_allclose(nearest_other_distances(C), want, rtol=1e-12)
