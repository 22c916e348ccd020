"""Argument checks shared by the public functions of :mod:`facewrap.geometry`.

Public functions call these once, at the door, and pass clean arrays to private
helpers that trust them.  Every failure is a ``ValueError`` naming the argument.
"""

from __future__ import annotations

import numpy as np


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
        return V, np.asarray(mesh.triangles)
    if isinstance(mesh, (tuple, list)) and len(mesh) == 2:
        V = as_vertices(mesh[0], f"{name} vertices")
        return V, as_triangles(mesh[1], len(V), f"{name} triangles")
    raise ValueError(f"{name} must be a Mesh or a (V, T) pair, got {type(mesh).__name__}")


def as_vertex_mask(mask, n: int, name: str = "mask", default: bool = True) -> np.ndarray:
    """(n,) bool from a bool mask or vertex ids; every vertex ``default`` for None.

    >>> as_vertex_mask([0, 2], 3).tolist(), as_vertex_mask(None, 2, default=False).tolist()
    ([True, False, True], [False, False])
    """
    if mask is None:
        return np.full(n, default, dtype=bool)
    m = np.asarray(mask)
    if m.dtype == bool:
        if m.shape != (n,):
            raise ValueError(f"{name} must have shape ({n},), got {m.shape}")
        return m.copy()
    if not np.issubdtype(m.dtype, np.integer) or m.ndim != 1:
        raise ValueError(f"{name} must be a ({n},) bool mask or 1-D vertex ids")
    if len(m) and (m.min() < 0 or m.max() >= n):
        raise ValueError(f"{name} holds vertex ids outside [0, {n})")
    out = np.zeros(n, dtype=bool)
    out[m] = True
    return out
