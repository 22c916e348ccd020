"""The z-buffer of the software renderer: which triangle is seen at each pixel.

Every triangle's bounding-box pixels are enumerated at once (``np.repeat`` /
``cumsum``, in blocks of about a fixed number of candidates so memory stays
bounded), tested with edge functions, and the nearest candidate per pixel is kept by
one ``np.minimum.at`` on a key packing quantised depth and triangle index (ties go
to the lower triangle index, so output is deterministic).
"""

from __future__ import annotations

import numpy as np

from facewrap.geometry.arrays import blocks_by_budget
from facewrap.geometry.checks import as_triangles
from facewrap.report.cameras import image_size

__all__ = ["Raster", "rasterize", "trusted_rasterize"]

_DEPTH_BITS = 31                     # quantised depth in the z-buffer key
_CHUNK = 1 << 22                     # candidate pixels processed at once
_EDGE_TOL = 2e-6                     # barycentric tolerance: shared edges leave no crack


class Raster:
    """Which triangle is visible at each pixel, and where in it.

    Attributes
    ----------
    triangle : (H, W) int64
        Visible triangle per pixel, -1 where no triangle covers the pixel centre.
    pixels : (p,) int64
        Flat indices (``row * W + col``) of the covered pixels, increasing.
    barycentric : (p, 3) float32
        Coordinates of each covered pixel centre in its triangle (sum to 1).
    """

    def __init__(self, triangle, pixels, barycentric):
        self.triangle = triangle
        self.pixels = pixels
        self.barycentric = barycentric

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool: covered pixels."""
        return self.triangle >= 0


def rasterize(xy, depth, T, size) -> Raster:
    """Z-buffer rasterisation of triangles given in pixel coordinates.

    Pixel ``(row, col)`` has its centre at ``x = col + 0.5``, ``y = row + 0.5``; a
    pixel belongs to a triangle when its centre lies inside it (within a tolerance of
    2e-6 in barycentric coordinates, so centres on shared edges are never lost).  The
    candidate with the smallest depth wins, the lower triangle index on a tie.
    Both orientations are drawn; zero-area triangles are skipped.

    Parameters
    ----------
    xy : (n, 2) float
        Vertex positions in pixels (x to the right, y down).
    depth : (n,) float
        Smaller is nearer.
    T : (t, 3) int
    size : (width, height) int

    Returns
    -------
    Raster

    Examples
    --------
    >>> r = rasterize([[0, 0], [4, 0], [0, 4.]], [0, 0, 0], [[0, 1, 2]], (4, 4))
    >>> r.mask.astype(int).tolist()
    [[1, 1, 1, 1], [1, 1, 1, 0], [1, 1, 0, 0], [1, 0, 0, 0]]
    """
    xy = np.asarray(xy, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2 or not np.all(np.isfinite(xy)):
        raise ValueError(f"xy must be a finite (n, 2) array, got shape {xy.shape}")
    depth = np.asarray(depth, dtype=np.float64)
    if depth.shape != (len(xy),) or not np.all(np.isfinite(depth)):
        raise ValueError(f"depth must be a finite ({len(xy)},) array")
    T = as_triangles(T, len(xy))
    W, H = image_size(size)
    return trusted_rasterize(xy[:, 0] - 0.5, xy[:, 1] - 0.5, depth, T, W, H)


def trusted_rasterize(x, y, z, T, W, H) -> Raster:
    """:func:`rasterize` without input checks, pixel centres at integer ``(x, y)``.

    Parameters
    ----------
    x, y : (n,) float64
        Vertex positions in pixels, shifted so that pixel ``(row, col)`` has its
        centre at ``x = col``, ``y = row``.
    z : (n,) float64
        Depth, finite; smaller is nearer.
    T : (t, 3) int64
        Indices in range.
    W, H : int
        Image width and height.

    Returns
    -------
    Raster
    """
    if H * W >= 2 ** 31:
        raise ValueError(f"image of {W} x {H} pixels is too large (2**31 at most)")
    empty = np.iinfo(np.int64).max
    buf = np.full(H * W, empty, dtype=np.int64)
    found = []
    if len(T):
        X, Y = x[T], y[T]
        e1x, e1y = X[:, 1] - X[:, 0], Y[:, 1] - Y[:, 0]
        e2x, e2y = X[:, 2] - X[:, 0], Y[:, 2] - Y[:, 0]
        det = e1x * e2y - e1y * e2x
        # corner by corner: a reduction along rows of three is four times slower
        lo_x, hi_x = _corner_range(X)
        lo_y, hi_y = _corner_range(Y)
        c0 = np.clip(np.ceil(lo_x - 1e-6), 0, W).astype(np.int64)
        c1 = np.clip(np.floor(hi_x + 1e-6), -1, W - 1).astype(np.int64)
        r0 = np.clip(np.ceil(lo_y - 1e-6), 0, H).astype(np.int64)
        r1 = np.clip(np.floor(hi_y + 1e-6), -1, H - 1).astype(np.int64)
        width = np.maximum(c1 - c0 + 1, 0)
        counts = width * np.maximum(r1 - r0 + 1, 0)
        counts[det == 0] = 0
        span = float(np.ptp(z)) if len(z) else 0.0
        zq = (z - z.min()) * ((2.0 ** _DEPTH_BITS - 1) / span) if span > 0 \
            else np.zeros_like(z)
        Zq = zq[T]
        for sel in blocks_by_budget(counts, _CHUNK):
            found.append(_scan_chunk(sel, counts[sel], X, Y, Zq, e1x, e1y, e2x, e2y,
                                     det, c0, r0, width, W, buf))
    # the winner of each pixel is the candidate whose packed key survived
    l1 = np.zeros(H * W, dtype=np.float32)
    l2 = np.zeros(H * W, dtype=np.float32)
    for key, packed, c1_, c2_ in found:
        win = buf[key] == packed
        k = key[win]
        l1[k], l2[k] = c1_[win], c2_[win]
    pixels = np.flatnonzero(buf != empty)
    tri = buf[pixels] & np.int64(0xFFFFFFFF)
    triangle = np.full(H * W, -1, dtype=np.int64)
    triangle[pixels] = tri
    b1, b2 = l1[pixels], l2[pixels]
    bary = np.clip(np.stack([1.0 - b1 - b2, b1, b2], axis=1), 0.0, 1.0)
    bary /= bary.sum(axis=1, keepdims=True)
    return Raster(triangle.reshape(H, W), pixels, bary)


def _corner_range(C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Smallest and largest of each row of a (t, 3) array."""
    return (np.minimum(np.minimum(C[:, 0], C[:, 1]), C[:, 2]),
            np.maximum(np.maximum(C[:, 0], C[:, 1]), C[:, 2]))


def _scan_chunk(sel, cnt, X, Y, Zq, e1x, e1y, e2x, e2y, det, c0, r0, width, W, buf):
    """Candidates of triangles ``sel``: inside test, packed depth, scatter-min.

    Returns the inside candidates' ``(pixel, packed key, l1, l2)``.
    """
    inv = 1.0 / det[sel]
    x0, y0 = X[sel, 0], Y[sel, 0]
    # barycentric l1, l2 are affine in (col, row): l = a * col + b * row + k
    a1, b1 = e2y[sel] * inv, -e2x[sel] * inv
    a2, b2 = -e1y[sel] * inv, e1x[sel] * inv
    cs, rs = c0[sel], r0[sel]
    f32 = np.float32
    base1 = (a1 * (cs - x0) + b1 * (rs - y0)).astype(f32)   # at the box corner
    base2 = (a2 * (cs - x0) + b2 * (rs - y0)).astype(f32)
    a1, b1, a2, b2 = (c.astype(f32) for c in (a1, b1, a2, b2))
    n = int(cnt.sum())                                     # <= _CHUNK: int32 is enough
    i32 = np.int32
    owner = np.repeat(np.arange(len(sel), dtype=i32), cnt)
    start = (np.cumsum(cnt) - cnt).astype(i32)
    local = np.arange(n, dtype=i32) - np.repeat(start, cnt)
    w = np.repeat(width[sel].astype(i32), cnt)
    dr = local // w
    dc = local - dr * w
    dcf, drf = dc.astype(f32), dr.astype(f32)
    l1 = base1[owner] + a1[owner] * dcf + b1[owner] * drf
    l2 = base2[owner] + a2[owner] * dcf + b2[owner] * drf
    inside = (l1 >= -_EDGE_TOL) & (l2 >= -_EDGE_TOL) & (l1 + l2 <= 1.0 + _EDGE_TOL)
    idx = np.flatnonzero(inside)
    o, l1, l2 = owner[idx], l1[idx], l2[idx]
    z = Zq[sel[o]]
    zz = z[:, 0] + l1 * (z[:, 1] - z[:, 0]) + l2 * (z[:, 2] - z[:, 0])
    zz = np.clip(zz, 0.0, 2.0 ** _DEPTH_BITS - 1)
    key = (rs[o] + dr[idx]) * W + (cs[o] + dc[idx])
    packed = (zz.astype(np.int64) << 32) | sel[o]
    np.minimum.at(buf, key, packed)
    return key, packed, l1, l2

