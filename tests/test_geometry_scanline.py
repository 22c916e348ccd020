"""Scanline spans: every pixel an inside test accepts is among them, and few others."""

import numpy as np
import pytest

from facewrap.geometry.scanline import triangle_row_spans


def _boxes(X, Y, W, H):
    c0 = np.clip(np.ceil(X.min(axis=1) - 1e-6), 0, W).astype(np.int64)
    c1 = np.clip(np.floor(X.max(axis=1) + 1e-6), -1, W - 1).astype(np.int64)
    r0 = np.clip(np.ceil(Y.min(axis=1) - 1e-6), 0, H).astype(np.int64)
    r1 = np.clip(np.floor(Y.max(axis=1) + 1e-6), -1, H - 1).astype(np.int64)
    return c0, c1, r0, r1


def _accepted(X, Y, box, grow):
    """(triangle, row, col) of every box pixel whose barycentric coordinates are all
    >= -grow, tested pixel by pixel over the whole box."""
    out = set()
    for t in range(len(X)):
        c0, c1, r0, r1 = (int(b[t]) for b in box)
        (x0, x1, x2), (y0, y1, y2) = X[t], Y[t]
        det = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
        if det == 0 or c1 < c0 or r1 < r0:
            continue
        col, row = np.meshgrid(np.arange(c0, c1 + 1), np.arange(r0, r1 + 1))
        dx, dy = col - x0, row - y0
        l1 = (dx * (y2 - y0) - dy * (x2 - x0)) / det
        l2 = ((x1 - x0) * dy - (y1 - y0) * dx) / det
        ok = np.minimum(np.minimum(1 - l1 - l2, l1), l2) >= -grow
        out.update((t, int(r), int(c)) for r, c in zip(row[ok], col[ok]))
    return out


def _triangles(rng, n, W, H):
    """Ordinary triangles, needles across the grid, slivers, corners on pixel centres
    and on rows, some beyond the image."""
    X = rng.uniform(-5, W + 5, (n, 3))
    Y = rng.uniform(-5, H + 5, (n, 3))
    k = n // 4
    # needles: two corners far apart, the third a hair off their line
    t = rng.uniform(0, 1, k)
    X[:k, 2] = X[:k, 0] + t * (X[:k, 1] - X[:k, 0]) + rng.uniform(-0.05, 0.05, k)
    Y[:k, 2] = Y[:k, 0] + t * (Y[:k, 1] - Y[:k, 0])
    # corners on pixel centres, edges along rows and columns
    X[k:2 * k] = np.round(X[k:2 * k])
    Y[k:2 * k] = np.round(Y[k:2 * k])
    Y[2 * k:3 * k, 1] = Y[2 * k:3 * k, 0]
    return X, Y


@pytest.mark.parametrize("grow", [0.0, 1e-7, 0.05])
def test_spans_hold_every_pixel_the_inside_test_accepts(grow):
    rng = np.random.default_rng(7)
    W, H = 40, 30
    X, Y = _triangles(rng, 80, W, H)
    box = _boxes(X, Y, W, H)
    s = triangle_row_spans(X, Y, box, grow=grow)
    found = set()
    for t, r, c, w in zip(s.triangles, s.rows, s.first_columns, s.widths):
        found.update((int(t), int(r), int(c) + i) for i in range(int(w)))
    wanted = _accepted(X, Y, box, grow)
    assert wanted and wanted <= found
    # nothing outside the box, runs by triangle then row
    assert np.all(s.widths > 0)
    assert np.all(s.first_columns >= box[0][s.triangles])
    assert np.all(s.first_columns + s.widths - 1 <= box[1][s.triangles])
    order = np.lexsort((s.rows, s.triangles))
    np.testing.assert_array_equal(order, np.arange(len(s)))
    # and few others: the surplus is a pixel or two per row, not the box
    assert len(found) - len(wanted) <= 2 * len(s)


def test_a_needle_across_the_grid_tests_its_pixels_not_its_box():
    X, Y = np.array([[0.0, 999.0, 999.2]]), np.array([[0.0, 999.0, 998.8]])
    box = _boxes(X, Y, 1000, 1000)
    s = triangle_row_spans(X, Y, box)
    assert s.widths.sum() < 3000            # its box: a million pixels
    t, r, c = s.pixels_of(np.arange(len(s)))
    assert len(t) == s.widths.sum() and np.all(np.abs(r - c) <= 1)


def test_a_flat_row_and_a_triangle_off_the_image_have_no_runs():
    X = np.array([[0.0, 5.0, 10.0], [-9.0, -8.0, -9.0], [1.0, 3.0, 1.0]])
    Y = np.array([[2.0, 2.0, 2.0], [1.0, 1.0, 5.0], [1.0, 1.0, 3.0]])
    s = triangle_row_spans(X, Y, _boxes(X, Y, 20, 20))
    assert set(s.triangles.tolist()) == {2}
    assert s.rows.tolist() == [1, 2, 3] and s.widths.tolist() == [3, 2, 1]
