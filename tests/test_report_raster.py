"""facewrap.report.raster: the z-buffer against a brute-force oracle."""

import numpy as np
import pytest

from facewrap.report import rasterize


def inside_oracle(xy, T, W, H):
    """Brute force: pixel centres inside any triangle (either orientation)."""
    cx, cy = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    P = np.stack([cx.ravel(), cy.ravel()], 1)
    covered = np.zeros(len(P), bool)
    for a, b, c in xy[np.asarray(T)]:
        def edge(p, q):
            return (q[0] - p[0]) * (P[:, 1] - p[1]) - (q[1] - p[1]) * (P[:, 0] - p[0])
        e = np.stack([edge(a, b), edge(b, c), edge(c, a)], 1)
        covered |= (e >= -1e-9).all(1) | (e <= 1e-9).all(1)
    return covered.reshape(H, W)


def test_known_triangle_covers_the_expected_pixels():
    xy = np.array([[1.2, 0.7], [13.9, 3.1], [4.4, 11.6]])
    for T in ([[0, 1, 2]], [[0, 2, 1]]):                   # both orientations drawn
        r = rasterize(xy, np.zeros(3), T, (16, 12))
        assert np.array_equal(r.mask, inside_oracle(xy, T, 16, 12))
        assert np.allclose(r.barycentric.sum(1), 1) and (r.barycentric >= 0).all()
    # barycentric coordinates reproduce the pixel centres
    px = np.stack([r.pixels % 16 + 0.5, r.pixels // 16 + 0.5], 1)
    assert np.allclose(r.barycentric @ xy[[0, 2, 1]], px, atol=1e-4)


def test_nearer_triangle_wins_whatever_the_order():
    xy = np.array([[0, 0], [10, 0], [0, 10], [0, 0], [10, 0], [0, 10.]])
    for depth in ([1, 1, 1, 0, 0, 0], [0, 0, 0, 1, 1, 1]):
        r = rasterize(xy, depth, [[0, 1, 2], [3, 4, 5]], (10, 10))
        near = 1 if depth[0] == 1 else 0
        assert set(np.unique(r.triangle[r.mask])) == {near}
    # exact tie: the lower triangle index
    r = rasterize(xy, np.zeros(6), [[3, 4, 5], [0, 1, 2]], (10, 10))
    assert set(np.unique(r.triangle[r.mask])) == {0}


def test_shared_edges_leave_no_crack():
    rng = np.random.default_rng(3)
    n = 9
    s = np.linspace(0, 40, n)
    X, Y = np.meshgrid(s, s)
    xy = np.stack([X.ravel(), Y.ravel()], 1)
    xy[(xy > 0).all(1) & (xy < 40).all(1)] += rng.uniform(-1.5, 1.5, (49, 2))
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)).ravel()
    T = np.concatenate([np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)])
    r = rasterize(xy, rng.uniform(0, 1, len(xy)), T, (40, 40))
    assert r.mask.all()


def test_rasterize_validates():
    with pytest.raises(ValueError, match="xy"):
        rasterize(np.zeros((3, 3)), np.zeros(3), [[0, 1, 2]], (4, 4))
    with pytest.raises(ValueError, match="size"):
        rasterize(np.zeros((3, 2)), np.zeros(3), [[0, 1, 2]], (0, 4))
