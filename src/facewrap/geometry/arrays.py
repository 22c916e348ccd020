"""Trusted array primitives shared by the geometry, texture and report modules.

These functions take clean arrays (float64 positions, int64 indices in range) and do
no validation: the public functions that call them check their input once, at the
door.  The bulk work runs on coordinate-major ``(3, t)`` arrays where it can: on
large meshes contiguous rows per coordinate beat row-major ``(t, 3)`` arithmetic
and fancy indexing.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

__all__ = ["cross_rows", "normalize_rows", "safe_inverse", "edge_vectors",
           "cross_columns", "column_norms", "blocks_by_budget", "unique_integers",
           "stable_sort_order", "spatial_order", "column_bounds"]


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product (faster than ``np.cross``).

    Parameters
    ----------
    a, b : (..., 3) float64
        Broadcast against each other.

    Returns
    -------
    (..., 3) float64

    Examples
    --------
    >>> cross_rows(np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]])).tolist()
    [[0.0, 0.0, 1.0]]
    """
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def normalize_rows(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit rows and row norms; zero rows stay zero (no NaN).

    Parameters
    ----------
    a : (k, 3) float64
        Not changed.

    Returns
    -------
    unit : (k, 3) float64
        ``a`` divided by its row norms, a new array.
    norm : (k,) float64
        Euclidean length of each row of ``a``.

    Examples
    --------
    >>> unit, norm = normalize_rows(np.array([[0, 0, 2.0], [0, 0, 0]]))
    >>> unit.tolist(), norm.tolist()
    ([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]], [2.0, 0.0])
    """
    norm = np.sqrt(np.einsum("ij,ij->i", a, a))
    return a * safe_inverse(norm)[:, None], norm


def safe_inverse(x: np.ndarray) -> np.ndarray:
    """``1 / x`` where ``x > 0``, else 0.

    Parameters
    ----------
    x : (k,) float64

    Returns
    -------
    (k,) float64

    Examples
    --------
    >>> safe_inverse(np.array([2.0, 0.0, -1.0])).tolist()
    [0.5, 0.0, 0.0]
    """
    return np.divide(1.0, x, out=np.zeros_like(x), where=x > 0)


def edge_vectors(V: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Edges ``V1 - V0`` and ``V2 - V0`` of each triangle, coordinate-major.

    Parameters
    ----------
    V : (n, 3) float64
    T : (t, 3) int64
        Indices in range.

    Returns
    -------
    e01, e02 : (3, t) float64
        Coordinate-major, contiguous: row ``k`` holds coordinate ``k`` of every edge.

    Examples
    --------
    >>> e01, e02 = edge_vectors(np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0.]]),
    ...                         np.array([[0, 1, 2]]))
    >>> e01.T.tolist(), e02.T.tolist()
    ([[2.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    """
    Vt = np.ascontiguousarray(V.T)
    Tt = np.ascontiguousarray(T.T)
    p0 = np.take(Vt, Tt[0], axis=1)
    return np.take(Vt, Tt[1], axis=1) - p0, np.take(Vt, Tt[2], axis=1) - p0


def cross_columns(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of the columns of two coordinate-major arrays.

    Parameters
    ----------
    a, b : (3, t) float64

    Returns
    -------
    (3, t) float64

    Examples
    --------
    >>> cross_columns(np.array([[1.0], [0], [0]]), np.array([[0], [1.0], [0]])).T.tolist()
    [[0.0, 0.0, 1.0]]
    """
    out = np.empty(a.shape)
    for k, (i, j) in enumerate(((1, 2), (2, 0), (0, 1))):
        np.subtract(a[i] * b[j], a[j] * b[i], out=out[k])
    return out


def column_norms(a: np.ndarray) -> np.ndarray:
    """Euclidean norm of each column.

    Parameters
    ----------
    a : (3, t) float64

    Returns
    -------
    (t,) float64

    Examples
    --------
    >>> column_norms(np.array([[3.0], [4.0], [0.0]])).tolist()
    [5.0]
    """
    return np.sqrt(np.einsum("ij,ij->j", a, a))


def blocks_by_budget(counts: np.ndarray, budget: int) -> Iterator[np.ndarray]:
    """Split items into runs whose work adds up to about ``budget``.

    Rasterisers enumerate candidate pixels per triangle; processing all triangles at
    once would need memory proportional to all candidates, one at a time would be
    slow in Python.  Consecutive blocks of about ``budget`` candidates keep both in
    check.

    Parameters
    ----------
    counts : (k,) int
        Work of each item (e.g. candidate pixels per triangle); items with 0 are
        left out.
    budget : int
        Work per block (a block holds at least one item, so it may exceed this).

    Yields
    ------
    (j,) int64
        Indices of the non-empty items of one block, increasing; the blocks cover
        every non-empty item once, in order.

    Examples
    --------
    >>> [b.tolist() for b in blocks_by_budget(np.array([2, 0, 3, 1, 4]), 4)]
    [[0], [2, 3], [4]]
    """
    nz = np.flatnonzero(counts)
    if len(nz) == 0:
        return
    cum = np.cumsum(counts[nz])
    cuts = np.searchsorted(cum, np.arange(budget, cum[-1], budget), side="right")
    for part in np.split(nz, np.unique(cuts)):
        if len(part):
            yield part


def stable_sort_order(a) -> tuple[np.ndarray, np.ndarray]:
    """``np.argsort(a, kind="stable")`` of a 1-D integer array, and ``a`` in that order.

    Each value and its place are packed into one int64, ``(a - min) * k + place``,
    and those distinct codes are sorted as plain numbers (numpy's vectorised sort),
    which is 2-3x faster than a stable argsort of the values (3M edge keys of a 1M
    triangle mesh: 27 ms against 110 ms here).  Ties keep their input order either
    way, so the result is the same; when the codes would overflow int64 it is the
    stable argsort itself.

    Parameters
    ----------
    a : (k,) int array

    Returns
    -------
    order : (k,) int64
        Stable sorting permutation.
    sorted : (k,) int64
        ``a[order]``.

    Examples
    --------
    >>> order, s = stable_sort_order(np.array([5, 1, 5, 3]))
    >>> order.tolist(), s.tolist()
    ([1, 3, 0, 2], [1, 3, 5, 5])
    """
    a = np.asarray(a).reshape(-1).astype(np.int64, copy=False)
    k = len(a)
    if k == 0:
        return np.zeros(0, np.int64), a.copy()
    lo, hi = int(a.min()), int(a.max())
    if (hi - lo + 1) * k >= 2 ** 63:
        order = np.argsort(a, kind="stable")
        return order, a[order]
    code = a - lo
    code *= k
    code += np.arange(k, dtype=np.int64)
    code.sort()
    order = code % k
    code //= k
    code += lo
    return order, code


def _spread_bits(q: np.ndarray) -> np.ndarray:
    """The low 10 bits of each uint64 in ``q``, two zero bits after each (bit ``b``
    moved to bit ``3 b``): one coordinate of a 30-bit Morton code."""
    q = q & np.uint64(0x3FF)
    q = (q | (q << np.uint64(16))) & np.uint64(0x030000FF)
    q = (q | (q << np.uint64(8))) & np.uint64(0x0300F00F)
    q = (q | (q << np.uint64(4))) & np.uint64(0x030C30C3)
    q = (q | (q << np.uint64(2))) & np.uint64(0x09249249)
    return q


def spatial_order(points: np.ndarray) -> np.ndarray:
    """(k,) int64 permutation putting points that are near each other next to
    each other: the order of their Morton (z-order) codes on a 1024³ grid over
    their bounding box.

    Tree queries in this order walk the same nodes one after another, which keeps
    them in cache: libigl's closest points for a template's vertices on a 60k
    triangle scan ran about 1.5x faster in it than in the vertices' file order.

    Parameters
    ----------
    points : (k, 3) float64, finite

    Returns
    -------
    (k,) int64

    Examples
    --------
    >>> P = np.array([[1.0, 1, 1], [0, 0, 0], [0.9, 1, 1], [0.1, 0, 0]])
    >>> spatial_order(P).tolist()
    [1, 3, 2, 0]
    """
    P = np.asarray(points, dtype=np.float64)
    if len(P) < 2:
        return np.arange(len(P), dtype=np.int64)
    lo, hi = column_bounds(P)
    extent = float((hi - lo).max())
    q = ((P - lo) * (1023.0 / extent if extent > 0 else 0.0)).astype(np.uint64)
    code = (_spread_bits(q[:, 0]) | (_spread_bits(q[:, 1]) << np.uint64(1))
            | (_spread_bits(q[:, 2]) << np.uint64(2)))
    return np.argsort(code, kind="stable").astype(np.int64, copy=False)


def unique_integers(a, *, return_index: bool = False, return_inverse: bool = False,
                    return_counts: bool = False):
    """``np.unique`` of a 1-D integer array, always by sorting.

    NumPy 2.3 and later answer a plain ``np.unique`` of integers from a hash table:
    fast for a few distinct values, 20-60x slower than a sort when most values are
    distinct (edge keys of a mesh: 4.4 s against 0.2 s for 3M keys, measured here
    with numpy 2.4.6).  This sorts whatever the numpy version, and gives the same
    arrays as ``np.unique`` (``return_index``: each value's first place).

    Parameters
    ----------
    a : (k,) int array
    return_index, return_inverse, return_counts : bool
        As for ``np.unique``.

    Returns
    -------
    unique : (u,) the sorted distinct values
    index : (u,) int64, optional
    inverse : (k,) int64, optional
        ``unique[inverse] == a``.
    counts : (u,) int64, optional

    Examples
    --------
    >>> unique_integers(np.array([5, 1, 5, 3])).tolist()
    [1, 3, 5]
    >>> [x.tolist() for x in unique_integers(np.array([5, 1, 5, 3]), return_index=True,
    ...                                      return_inverse=True, return_counts=True)]
    [[1, 3, 5], [1, 3, 0], [2, 0, 2, 1], [1, 1, 2]]
    """
    a = np.asarray(a).reshape(-1)
    extras = return_index or return_inverse or return_counts
    # a stable sort keeps equal values in input order: the first of a run is the
    # value's first place, as np.unique's return_index gives it
    order, s = stable_sort_order(a) if extras else (None, np.sort(a))
    first = np.empty(len(s), dtype=bool)
    first[:1] = True
    np.not_equal(s[1:], s[:-1], out=first[1:])
    out = [s[first]]
    if return_index:
        out.append(order[first].astype(np.int64))
    if return_inverse:
        inverse = np.empty(len(a), dtype=np.int64)
        inverse[order] = np.cumsum(first) - 1
        out.append(inverse)
    if return_counts:
        starts = np.flatnonzero(first)
        out.append(np.diff(np.append(starts, len(s))).astype(np.int64))
    return tuple(out) if extras else out[0]


def column_bounds(P) -> np.ndarray:
    """(2, d) float64: the smallest and the largest value of each column of ``P``
    (n, d), n >= 1; NaN where a column holds one, as ``P.min(axis=0)`` gives.

    numpy reduces axis 0 of a narrow row-major array a row at a time: column by
    column is 25 times faster on a million-vertex scan (12 ms against 0.5 ms for
    the three minima), and a scan's size is asked for several times.

    Examples
    --------
    >>> column_bounds(np.array([[0, 5.0], [2, -1]])).tolist()
    [[0.0, -1.0], [2.0, 5.0]]
    """
    columns = np.asarray(P).T
    return np.array([[c.min() for c in columns], [c.max() for c in columns]],
                    dtype=np.float64)
