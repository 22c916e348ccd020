"""Scanline spans of triangles on a pixel grid: which pixels a rasteriser need test.

A rasteriser that tests every pixel of each triangle's bounding box tests about
twice the pixels the triangle covers, and many times more for long thin triangles
lying across the grid (ICT-FaceKit's eye materials in UV space: 4.1M box pixels for
1.9M covered).  :func:`triangle_row_spans` gives, row by row, the columns a
triangle can cover instead: the pixels an inside test with a tolerance can accept
are all among them, so a rasteriser that tests only these finds the same pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RowSpans", "triangle_row_spans"]

#: Pixels a rounding error away from a span are kept in it (pixel units).
_MARGIN = 1e-6


@dataclass(frozen=True, eq=False)
class RowSpans:
    """Runs of pixel columns, one per (triangle, row), in order of triangle then row.

    Attributes
    ----------
    triangles : (p,) int64
        Triangle of each run (increasing).
    rows : (p,) int64
        Pixel row of each run.
    first_columns : (p,) int64
        First column of each run.
    widths : (p,) int64
        Number of columns of each run (> 0).
    """

    triangles: np.ndarray
    rows: np.ndarray
    first_columns: np.ndarray
    widths: np.ndarray

    def __len__(self) -> int:
        """Number of runs."""
        return len(self.triangles)

    def pixels_of(self, runs: np.ndarray):
        """Every pixel of some runs, in their order, each run's columns in turn.

        Parameters
        ----------
        runs : (k,) int64
            Indices of runs.

        Returns
        -------
        triangle, row, column : (m,) int64 each
        """
        width = self.widths[runs]
        run = np.repeat(runs, width)
        start = np.cumsum(width) - width
        column = (self.first_columns[run] + np.arange(len(run), dtype=np.int64)
                  - np.repeat(start, width))
        return self.triangles[run], self.rows[run], column


def triangle_row_spans(X, Y, box, grow: float = 0.0) -> RowSpans:
    """Per triangle and pixel row, the columns its (slightly grown) area can reach.

    Pixel ``(row, col)`` has its centre at ``x = col``, ``y = row``.  A triangle
    grown by ``grow`` is the set of points whose barycentric coordinates are all
    ``>= -grow`` (the pixels an inside test with that tolerance accepts); its corner
    ``i`` is ``v_i + grow (3 v_i - v_0 - v_1 - v_2)``.  For every row of the
    triangle's pixel box, the run is the grown triangle's extent along that row
    (the row's height clamped into the triangle's), widened by a rounding margin of
    1e-6 pixels and cut to the box.

    Parameters
    ----------
    X, Y : (t, 3) float64
        Corner coordinates in pixels.
    box : tuple of four (t,) int64
        ``(c0, c1, r0, r1)``: first and last column and row of each triangle's
        pixel box (clipped to the image; an empty box, ``c1 < c0`` or ``r1 < r0``,
        gives no run).
    grow : float
        The inside test's tolerance in barycentric coordinates, >= 0.

    Returns
    -------
    RowSpans
        Runs of at least one pixel, by triangle then row.

    Examples
    --------
    A right triangle with its corners on pixel centres (0, 0), (4, 0), (0, 4):
    row ``r`` runs from column 0 to ``4 - r``.

    >>> X, Y = np.array([[0.0, 4.0, 0.0]]), np.array([[0.0, 0.0, 4.0]])
    >>> box = tuple(np.array([v]) for v in (0, 4, 0, 4))
    >>> s = triangle_row_spans(X, Y, box)
    >>> s.rows.tolist(), s.first_columns.tolist(), s.widths.tolist()
    ([0, 1, 2, 3, 4], [0, 0, 0, 0, 0], [5, 4, 3, 2, 1])
    """
    X = np.asarray(X, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    c0, c1, r0, r1 = (np.asarray(b, dtype=np.int64) for b in box)
    if grow:
        X = X + grow * (3.0 * X - X.sum(axis=1, keepdims=True))
        Y = Y + grow * (3.0 * Y - Y.sum(axis=1, keepdims=True))
    heights = np.maximum(r1 - r0 + 1, 0) * (c1 >= c0)
    tri = np.repeat(np.arange(len(X), dtype=np.int64), heights)
    start = np.cumsum(heights) - heights
    row = r0[tri] + np.arange(len(tri), dtype=np.int64) - np.repeat(start, heights)
    Xt, Yt = X[tri], Y[tri]
    # the row's height, clamped into the triangle's: the box may reach a margin
    # beyond it
    y = np.clip(row, Yt.min(axis=1), Yt.max(axis=1))
    lo = np.full(len(tri), np.inf)
    hi = np.full(len(tri), -np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        ya, yb, xa, xb = Yt[:, i], Yt[:, j], Xt[:, i], Xt[:, j]
        dy = yb - ya
        crosses = (np.minimum(ya, yb) <= y) & (y <= np.maximum(ya, yb)) & (dy != 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = xa + (y - ya) * (xb - xa) / dy
        np.minimum(lo, np.where(crosses, x, np.inf), out=lo)
        np.maximum(hi, np.where(crosses, x, -np.inf), out=hi)
    found = hi >= lo          # every row of a triangle with area (a flat one: none)
    first = np.full(len(tri), 0, dtype=np.int64)
    last = np.full(len(tri), -1, dtype=np.int64)
    first[found] = np.maximum(np.ceil(lo[found] - _MARGIN), c0[tri[found]])
    last[found] = np.minimum(np.floor(hi[found] + _MARGIN), c1[tri[found]])
    width = last - first + 1
    keep = width > 0
    return RowSpans(tri[keep], row[keep], first[keep], width[keep])
