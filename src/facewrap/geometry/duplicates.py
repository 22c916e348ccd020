"""Rows that are bit for bit the same: duplicated vertices of a mesh.

Exporters split a mesh's vertices where its UVs or normals are cut (a seam):
the two copies are one point of the surface.  :func:`duplicate_rows` finds such
copies among rows of any width (a position, or a position and its place in every
blendshape); :func:`any_duplicate_positions` answers "none" cheaply for the
common case of a mesh without any; :func:`welded` merges a mesh's copies;
:func:`unique_faces` finds triangles listed twice.
"""

from __future__ import annotations

import numpy as np

from facewrap.geometry.arrays import unique_integers

__all__ = ["duplicate_rows", "any_duplicate_positions", "welded", "unique_faces"]

# odd 64-bit multipliers mixing a position's three bit patterns into one hash
_MIX = np.array([0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9],
                dtype=np.uint64)


def duplicate_rows(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The first occurrence of each distinct row, bit for bit.

    Parameters
    ----------
    A : (n, d) float64

    Returns
    -------
    first : (u,) int64
        Index of the first row of each distinct value, in order of value.
    inverse : (n,) int64
        ``A[first][inverse] == A``.

    Examples
    --------
    >>> first, inverse = duplicate_rows(np.array([[1.0, 2], [0, 0], [1, 2]]))
    >>> first.tolist(), inverse.tolist()
    ([1, 0], [1, 0, 1])
    """
    A = np.ascontiguousarray(A, dtype=np.float64)
    rows = A.view(np.dtype((np.void, A.dtype.itemsize * A.shape[1])))[:, 0]
    _, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
    return first.astype(np.int64), inverse.reshape(-1).astype(np.int64)


def any_duplicate_positions(V: np.ndarray) -> bool:
    """Whether two rows of ``V`` are bit for bit the same position.

    Parameters
    ----------
    V : (n, 3) float64

    Returns
    -------
    bool

    Most meshes have no duplicates, so a hash of each row's bits and one sort of the
    hashes (integers: several times cheaper than :func:`duplicate_rows`'s sort of
    24-byte rows) answers "none" first; only when two hashes meet are rows compared.

    Examples
    --------
    >>> any_duplicate_positions(np.array([[0, 0, 1.0], [2, 0, 0], [0, 0, 1]]))
    True
    >>> any_duplicate_positions(np.array([[0, 0, 1.0], [0, 0, -1]]))
    False
    """
    V = np.ascontiguousarray(V, dtype=np.float64)
    if len(V) < 2:
        return False
    bits = V.view(np.uint64)
    with np.errstate(over="ignore"):
        h = np.sort(bits[:, 0] * _MIX[0] ^ bits[:, 1] * _MIX[1] ^ bits[:, 2] * _MIX[2])
    if not np.any(h[1:] == h[:-1]):   # no equal hashes: no equal rows
        return False
    return len(duplicate_rows(V)[0]) < len(V)


def welded(V: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``V`` without duplicate positions and ``T`` on the merged vertices.

    A triangle soup (every triangle with corners of its own, as STL and some
    scanners write) becomes a connected surface again, with neighbours, borders
    only where the surface ends, and smooth vertex normals.

    Parameters
    ----------
    V : (n, 3) float64
    T : (t, 3) int64

    Returns
    -------
    V : (u, 3) float64
        ``V`` itself when no two rows are the same.
    T : (t, 3) int64
        Same triangles, same order.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.]])
    >>> W, F = welded(V, np.array([[0, 1, 2], [3, 5, 4]]))
    >>> len(W), F.tolist()
    (4, [[0, 2, 1], [2, 3, 1]])
    """
    if not any_duplicate_positions(V):
        return V, T
    first, inverse = duplicate_rows(V)
    return np.asarray(V)[first], inverse[np.asarray(T)]


def unique_faces(triangles) -> np.ndarray:
    """(m,) bool: the first of every set of triangles on the same three vertices
    (whatever their order or winding).

    >>> unique_faces([[0, 1, 2], [1, 2, 3], [2, 1, 0], [0, 1, 2]]).tolist()
    [True, True, False, False]
    """
    T = np.asarray(triangles, dtype=np.int64)
    keep = np.zeros(len(T), dtype=bool)
    if not len(T):
        return keep
    # each row's ids in order, by columns (np.sort(axis=1) of a million rows of
    # three: 20 ms against 8)
    a, b, c = T.T
    lo = np.minimum(np.minimum(a, b), c)
    hi = np.maximum(np.maximum(a, b), c)
    mid = a + b + c - lo - hi
    if hi.max() < 2 ** 21 and lo.min() >= 0:
        # one int64 key per sorted row: a 1-D unique, several times faster than
        # np.unique(axis=0) on a million triangles
        key = (lo << 42) | (mid << 21) | hi
        keep[unique_integers(key, return_index=True)[1]] = True
    else:
        keep[np.unique(np.stack([lo, mid, hi], axis=1), axis=0, return_index=True)[1]] = True
    return keep
