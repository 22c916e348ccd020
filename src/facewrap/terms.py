"""Energy terms of non-rigid ICP, each as (residual, Jacobian) — SPEC §2.1.

Every term is a function of the model's vertex Jacobian ``Jv`` (sparse
(3n, P), see :mod:`facewrap.models.base`) and returns the residual vector ``r``
and its Jacobian ``J`` (sparse (len(r), P)), *unweighted*; the solver
(:func:`facewrap.solve.gauss_newton_step`) weights and sums them.  Small pieces
so each can be tested alone against finite differences.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["point_to_point", "point_to_plane", "landmark_term", "robust_weights",
           "select_rows"]


def select_rows(Jv, vertices) -> sp.csr_matrix:
    """Rows of a (3n, P) vertex Jacobian for the given vertices, (3k, P)."""
    v = np.asarray(vertices, dtype=np.int64)
    rows = (3 * v[:, None] + np.arange(3)).ravel()
    return sp.csr_matrix(Jv)[rows]


def point_to_point(V, Jv, vertices, targets):
    """Eq. 2: ``v_i − c_i`` for the given vertices.

    Parameters
    ----------
    V : (n, 3) float64
        Current vertices.
    Jv : (3n, P) sparse
    vertices : (k,) int
        Vertex ids with a correspondence.
    targets : (k, 3) float64
        Their corresponding scan points ``c_i``.

    Returns
    -------
    r : (3k,) float64
    J : (3k, P) sparse
    """
    r = (V[vertices] - targets).ravel()
    return r, select_rows(Jv, vertices)


def point_to_plane(V, Jv, vertices, targets, normals):
    """Eq. 3: ``n_iᵀ (v_i − c_i)`` with the scan normals ``n_i`` (k, 3).

    Returns
    -------
    r : (k,) float64
    J : (k, P) sparse
    """
    k = len(vertices)
    r = np.einsum("ka,ka->k", V[vertices] - targets, normals)
    N = sp.csr_matrix((np.asarray(normals, dtype=np.float64).ravel(),
                       (np.repeat(np.arange(k), 3), np.arange(3 * k))), shape=(k, 3 * k))
    return r, N @ select_rows(Jv, vertices)


def landmark_term(V, Jv, landmark_matrix, targets):
    """Landmarks at their targets: ``L V − p`` (landmarks as sparse rows of ``L``).

    Parameters
    ----------
    landmark_matrix : (l, n) sparse
        Row ``q`` holds the vertex or barycentric weights of landmark ``q``.
    targets : (l, 3) float64

    Returns
    -------
    r : (3l,) float64
    J : (3l, P) sparse
    """
    L = sp.csr_matrix(landmark_matrix)
    r = (L @ V - targets).ravel()
    L3 = sp.kron(L, sp.identity(3), format="csr")
    return r, L3 @ Jv


def robust_weights(distances, scale: float, kind: str = "welsch") -> np.ndarray:
    """IRLS weights of a robust norm for residual lengths ``distances``.

    Parameters
    ----------
    distances : (k,) float
        Residual lengths (non-negative).
    scale : float
        The norm's scale σ (residuals well below σ count fully).
    kind : {"welsch", "huber", "geman_mcclure", "none"}

    Returns
    -------
    (k,) float64 in [0, 1]

    Examples
    --------
    >>> robust_weights([0.0, 1.0, 3.0], 1.0, "huber").tolist()
    [1.0, 1.0, 0.3333333333333333]
    """
    d = np.abs(np.asarray(distances, dtype=np.float64))
    if kind == "none":
        return np.ones_like(d)
    s = max(float(scale), 1e-300)
    if kind == "welsch":
        return np.exp(-0.5 * (d / s) ** 2)
    if kind == "huber":
        return np.minimum(1.0, s / np.maximum(d, 1e-300))
    if kind == "geman_mcclure":
        return (s * s / (s * s + d * d)) ** 2
    raise ValueError(f"unknown robust norm {kind!r}")


def landmark_rows(landmarks, n_vertices: int, triangles=None) -> sp.csr_matrix:
    """Sparse rows that give landmark positions from vertices: ``P = L @ V``.

    Parameters
    ----------
    landmarks : Landmarks
        Vertex or surface (triangle + barycentric) landmarks; free points are not
        allowed (snap them to the mesh first).
    n_vertices : int
    triangles : (t, 3) int, optional
        Needed for surface landmarks.

    Returns
    -------
    (l, n_vertices) scipy.sparse.csr_matrix
    """
    k = len(landmarks)
    rows, cols, vals = [], [], []
    iv = np.flatnonzero(landmarks.vertex >= 0)
    rows.append(iv)
    cols.append(landmarks.vertex[iv])
    vals.append(np.ones(len(iv)))
    it = np.flatnonzero(landmarks.triangle >= 0)
    if len(it):
        if triangles is None:
            raise ValueError("surface landmarks need the mesh triangles")
        T = np.asarray(triangles)
        rows.append(np.repeat(it, 3))
        cols.append(T[landmarks.triangle[it]].ravel())
        vals.append(np.asarray(landmarks.barycentric)[it].ravel())
    free = np.setdiff1d(np.arange(k), np.r_[iv, it])
    if len(free):
        raise ValueError(f"landmarks {free.tolist()} are free points, not on the mesh")
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                 np.concatenate(cols))),
                         shape=(k, n_vertices))
