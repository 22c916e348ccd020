"""Argument checks shared by the public functions of :mod:`facewrap.geometry`.

Public functions call these once, at the door, and pass clean arrays to private
helpers that trust them.  Every failure is a ``ValueError`` naming the argument.
"""

from __future__ import annotations

import numpy as np

from facewrap.units import too_large


def as_points(P, name: str = "points", columns: int = 3) -> np.ndarray:
    """C-contiguous (k, columns) finite float64 array; raise ValueError naming ``name``."""
    try:
        P = np.asarray(P, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a float array of shape (k, {columns}): "
                         f"{exc}") from None
    if P.ndim != 2 or P.shape[1] != columns:
        raise ValueError(f"{name} must have shape (k, {columns}), got {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ValueError(f"{name} must be finite (found NaN or inf)")
    return np.ascontiguousarray(P)


def as_positions(P, name: str = "points") -> np.ndarray:
    """:func:`as_points` of a head's positions, each coordinate also within
    :data:`~facewrap.units.COORDINATE_LIMIT` as a file's reader requires (a 1e300
    overflows into inf distances); raise ValueError naming ``name`` and the row.

    The geometry itself takes any finite coordinates (its trees answer far from the
    origin); the functions that measure or move a head check with this.

    >>> as_positions([[0, 1e300, 0]], "targets")
    Traceback (most recent call last):
    ...
    ValueError: targets: row 0 has coordinate 1e+300, too large (more than 1e+15 in \
magnitude in any unit: not a scan, and its sizes would overflow)
    """
    P = as_points(P, name)
    problem = too_large(P, "row")
    if problem is not None:
        raise ValueError(f"{name}: {problem}")
    return P


def as_vertices(V, name: str = "V") -> np.ndarray:
    """(n, 3) finite float64 vertex positions; raise ValueError naming ``name``."""
    return as_points(V, name)


def as_index_array(T, columns: int, n: int | None, name: str) -> np.ndarray:
    """(m, columns) int64 indices, checked against ``[0, n)`` when ``n`` is given."""
    T = np.asarray(T)
    if T.size == 0:
        T = T.reshape(-1, columns)
    if not (np.issubdtype(T.dtype, np.integer) or T.size == 0):
        raise ValueError(f"{name} must hold integer indices, got dtype {T.dtype}")
    if T.ndim != 2 or T.shape[1] != columns:
        raise ValueError(f"{name} must have shape (m, {columns}), got {T.shape}")
    T = T.astype(np.int64, copy=False)
    if T.size and T.min() < 0:
        raise ValueError(f"{name} has a negative index ({T.min()})")
    if n is not None and T.size and T.max() >= n:
        raise ValueError(f"{name} index {T.max()} out of range for {n} vertices")
    return T


def as_whole_indices(a, name: str) -> np.ndarray:
    """``a`` as int64 indices of the same shape: integers as they are, floats only
    when every one is whole.

    A face or landmark table read as text is often float, and 2.0 is vertex 2;
    2.5 is no vertex, and casting would quietly make it vertex 2.  Booleans,
    strings and objects are refused too (True is no vertex id).

    Parameters
    ----------
    a : array_like of int or whole float
    name : str
        The argument's name, for error messages.

    Returns
    -------
    int64 array, ``a``'s shape

    Examples
    --------
    >>> as_whole_indices([[0, 1.0, 2]], "faces").tolist()
    [[0, 1, 2]]
    >>> as_whole_indices([0.5], "faces")
    Traceback (most recent call last):
    ...
    ValueError: faces must hold whole numbers (indices), got 0.5
    """
    try:
        arr = np.asarray(a)
    except (TypeError, ValueError) as exc:   # ragged nesting
        raise ValueError(f"{name} must be an array of integer indices: {exc}") from None
    if arr.size == 0:
        return arr.astype(np.int64)
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{name} must hold integer indices, got dtype {arr.dtype}")
    if arr.dtype.kind == "f":
        bad = ~np.isfinite(arr) | (arr != np.round(arr)) | (np.abs(arr) >= 2.0 ** 63)
        if bad.any():
            raise ValueError(f"{name} must hold whole numbers (indices), got "
                             f"{arr[bad].flat[0].item()!r}")
    elif arr.dtype.kind == "u" and arr.max() > np.iinfo(np.int64).max:
        raise ValueError(f"{name} index {arr.max()} is too large")
    return arr.astype(np.int64, copy=False)


def as_vertex_ids(ids, n: int, name: str, *, at_least: int = 1) -> np.ndarray:
    """(k,) int64 ids of vertices of a mesh of ``n`` (whole numbers in ``[0, n)``).

    Parameters
    ----------
    ids : (k,) int array_like
    n : int
        The mesh's vertex count.
    name : str
        The argument's name, for error messages.
    at_least : int
        Fewest ids allowed (an anchor set needs one, a rigid frame three).

    Returns
    -------
    (k,) int64

    Examples
    --------
    >>> as_vertex_ids([2, 0.0], 3, "anchors").tolist()
    [2, 0]
    >>> as_vertex_ids([3], 3, "anchors")
    Traceback (most recent call last):
    ...
    ValueError: anchors holds vertex id 3, outside [0, 3)
    """
    out = as_whole_indices(ids, name)
    if out.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {out.shape}")
    if len(out) < at_least:
        raise ValueError(f"{name} needs at least {at_least} vertex id(s), got {len(out)}")
    bad = (out < 0) | (out >= n)
    if bad.any():
        raise ValueError(f"{name} holds vertex id {out[bad][0]}, outside [0, {n})")
    return out


def as_shape_dict(shapes, n: int, name: str = "blendshapes") -> dict:
    """Blendshapes as ``{str: (n, 3) finite float64}``, new arrays in a new dict.

    Parameters
    ----------
    shapes : dict of str to (n, 3) float array_like
        Positions in one topology of ``n`` vertices.
    n : int
        That topology's vertex count.
    name : str
        The argument's name, for error messages.

    Returns
    -------
    dict of str to (n, 3) float64
        In ``shapes``' order; read-only copies, so nothing the caller holds changes
        them and nothing done with them changes the caller's.

    Examples
    --------
    >>> sorted(as_shape_dict({"a": np.zeros((2, 3))}, 2))
    ['a']
    >>> as_shape_dict({"a": np.zeros((3, 3))}, 2)
    Traceback (most recent call last):
    ...
    ValueError: blendshapes['a'] must have shape (2, 3), got (3, 3)
    """
    if not isinstance(shapes, dict):
        raise TypeError(f"{name} must be a dict of name to (n, 3) positions, got "
                        f"{type(shapes).__name__}")
    out = {}
    for key, value in shapes.items():
        where = f"{name}[{key!r}]"
        try:
            arr = np.array(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{where} must be a float array of shape ({n}, 3): "
                             f"{exc}") from None
        if arr.shape != (n, 3):
            raise ValueError(f"{where} must have shape ({n}, 3), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{where} must be finite (found NaN or inf)")
        problem = too_large(arr)
        if problem is not None:
            raise ValueError(f"{where}: {problem}")
        arr.setflags(write=False)
        out[key] = arr
    return out


def as_triangles(T, n: int | None = None, name: str = "T") -> np.ndarray:
    """(t, 3) int64 triangle indices, in ``[0, n)`` when ``n`` is given."""
    return as_index_array(T, 3, n, name)


def as_mesh_arrays(V, T) -> tuple[np.ndarray, np.ndarray]:
    """``V`` as (n, 3) finite float64 and ``T`` as (t, 3) int64 indices into it."""
    V = as_vertices(V)
    return V, as_triangles(T, len(V))


def as_count(n, name: str = "n") -> int:
    """A non-negative Python int."""
    if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)):
        raise ValueError(f"{name} must be a non-negative int, got {n!r}")
    if n < 0:
        raise ValueError(f"{name} must be a non-negative int, got {n}")
    return int(n)


def as_index_vector(x, name: str) -> np.ndarray:
    """(m,) non-negative int64 indices."""
    x = np.asarray(x)
    if x.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {x.shape}")
    return as_index_array(x.reshape(-1, 1), 1, None, name)[:, 0]


def as_triangles_or_edges(T_or_edges, n: int, name: str = "T_or_edges"
                          ) -> tuple[np.ndarray, int]:
    """Indices of shape (t, 3) or (e, 2) in ``[0, n)``, and that column count."""
    arr = np.asarray(T_or_edges)
    if arr.size == 0 and arr.ndim < 2:
        return np.zeros((0, 2), dtype=np.int64), 2
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise ValueError(f"{name} must have shape (t, 3) or (e, 2), got {arr.shape}")
    return as_index_array(arr, arr.shape[1], n, name), arr.shape[1]


def mesh_arrays(mesh, name: str = "mesh") -> tuple[np.ndarray, np.ndarray]:
    """``(V, T)`` of a :class:`~facewrap.mesh.Mesh` or of a ``(V, T)`` pair, checked.

    Parameters
    ----------
    mesh : Mesh or (V, T)
        ``V : (n, 3) float``, ``T : (t, 3) int``.  Polygons of a Mesh are taken as
        its fan triangulation (:attr:`~facewrap.mesh.Mesh.triangles`).
    name : str
        The argument's name, for error messages.

    Returns
    -------
    V : (n, 3) float64
        Finite.
    T : (t, 3) int64
        Indices into ``V``.
    """
    if hasattr(mesh, "vertices") and hasattr(mesh, "triangles"):
        V = np.asarray(mesh.vertices, dtype=np.float64)
        if not np.all(np.isfinite(V)):
            raise ValueError(f"{name} vertices must be finite (found NaN or inf)")
        problem = too_large(V)   # as a file's reader refuses it: sizes would overflow
        if problem is not None:
            raise ValueError(f"{name}: {problem}")
        return V, np.asarray(mesh.triangles)
    if isinstance(mesh, (tuple, list)) and len(mesh) == 2:
        V = as_vertices(mesh[0], f"{name} vertices")
        return V, as_triangles(mesh[1], len(V), f"{name} triangles")
    raise ValueError(f"{name} must be a Mesh or a (V, T) pair, got {type(mesh).__name__}")


def as_vertex_mask(mask, n: int, name: str = "mask", default: bool = True, *,
                   what: str = "vertex") -> np.ndarray:
    """(n,) bool from a bool mask or ids of ``what`` (vertices, or polygons or
    landmarks); every one ``default`` for None.

    >>> as_vertex_mask([0, 2], 3).tolist(), as_vertex_mask(None, 2, default=False).tolist()
    ([True, False, True], [False, False])
    >>> as_vertex_mask([7], 3, "faces", what="polygon")
    Traceback (most recent call last):
    ...
    ValueError: faces holds polygon ids outside [0, 3)
    """
    if mask is None:
        return np.full(n, default, dtype=bool)
    m = np.asarray(mask)
    if m.dtype == bool:
        if m.shape != (n,):
            raise ValueError(f"{name} must have shape ({n},), got {m.shape}")
        return m.copy()
    if not np.issubdtype(m.dtype, np.integer) or m.ndim != 1:
        raise ValueError(f"{name} must be a ({n},) bool mask or 1-D {what} ids")
    if len(m) and (m.min() < 0 or m.max() >= n):
        raise ValueError(f"{name} holds {what} ids outside [0, {n})")
    out = np.zeros(n, dtype=bool)
    out[m] = True
    return out
