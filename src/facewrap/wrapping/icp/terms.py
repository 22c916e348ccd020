"""Energy terms of non-rigid ICP, each as (residual, Jacobian) — SPEC §2.1.

Every term is a function of the model's vertex Jacobian ``Jv`` (sparse
(3n, P), see :mod:`facewrap.wrapping.models.base`) and returns the residual vector ``r``
and its Jacobian ``J`` (sparse (len(r), P)), *unweighted*; the solver
(:func:`facewrap.solve.gauss_newton_step`) weights and sums them.  Small pieces
so each can be tested alone against finite differences.  The data and landmark
terms also come as residual-only functions (``*_residual``): the engine's energy,
which decides whether a step is accepted, is built from them, so the step and the
acceptance test cannot disagree on what a term is.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from facewrap.solve import BlockJacobian

#: the robust norms of :func:`robust_weights`
ROBUST_NORMS = ("welsch", "huber", "geman_mcclure", "none")

__all__ = ["ROBUST_NORMS", "point_to_point", "point_to_plane", "point_and_plane",
           "point_and_plane_residual", "landmark_term", "landmark_residual",
           "robust_weights", "landmark_rows"]


def _rows_of(vertices) -> np.ndarray:
    v = np.asarray(vertices, dtype=np.int64)
    return (3 * v[:, None] + np.arange(3)).ravel()


def point_to_point(V, Jv, vertices, targets):
    """Eq. 2: ``v_i − c_i`` for the given vertices.

    Parameters
    ----------
    V : (n, 3) float64
        Current vertices.
    Jv : (3n, P) sparse or BlockJacobian
    vertices : (k,) int
        Vertex ids with a scan point.
    targets : (k, 3) float64
        Their corresponding scan points ``c_i``.

    Returns
    -------
    r : (3k,) float64
    J : (3k, P) BlockJacobian
    """
    r = (V[vertices] - targets).ravel()
    return r, BlockJacobian.of(Jv).rows(_rows_of(vertices))


def point_to_plane(V, Jv, vertices, targets, normals):
    """Eq. 3: ``n_iᵀ (v_i − c_i)`` with the scan normals ``n_i`` (k, 3).

    Returns
    -------
    r : (k,) float64
    J : (k, P) BlockJacobian
    """
    k = len(vertices)
    r = np.einsum("ka,ka->k", V[vertices] - targets, normals)
    N = sp.csr_matrix((np.asarray(normals, dtype=np.float64).ravel(),
                       (np.repeat(np.arange(k), 3), np.arange(3 * k))), shape=(k, 3 * k))
    return r, BlockJacobian.of(Jv).rows(_rows_of(vertices)).left(N)


def point_and_plane(V, Jv, vertices, targets, normals, point_weight: float,
                    jacobian_rows=None):
    """Point-to-plane plus ``point_weight`` × point-to-point, as one term.

    ``(v − c)ᵀ (n nᵀ + λ I) (v − c)`` equals eq. 3 + λ·eq. 2; it is written as
    ``‖√M (v − c)‖²`` with ``√M = √λ I + (√(1+λ) − √λ) n nᵀ``: 3 rows per vertex
    instead of 4, one sparse product instead of two.

    ``jacobian_rows`` (k,) gives the vertices' positions in ``Jv`` when it holds
    the rows of a subset of vertices only (default: ``vertices``).

    Returns
    -------
    r : (3k,) float64
    J : (3k, P) BlockJacobian
    """
    S = _point_and_plane_metric(normals, point_weight)
    r = np.einsum("kab,kb->ka", S, V[vertices] - targets).ravel()
    at = vertices if jacobian_rows is None else jacobian_rows
    return r, BlockJacobian.of(Jv).rows(_rows_of(at)).left_blocks(S)


def point_and_plane_residual(V, vertices, targets, normals, point_weight: float):
    """The residual of :func:`point_and_plane` alone (no Jacobian), (3k,) float64.

    What an energy evaluation needs: the acceptance test of a step uses the
    same residual as the step itself.
    """
    S = _point_and_plane_metric(normals, point_weight)
    return np.einsum("kab,kb->ka", S, V[vertices] - targets).ravel()


def _point_and_plane_metric(normals, point_weight: float) -> np.ndarray:
    """``√M = √λ I + (√(1+λ) − √λ) n nᵀ`` per scan point, (k, 3, 3)."""
    n = np.asarray(normals, dtype=np.float64)
    lam = float(point_weight)
    a, b = np.sqrt(lam), np.sqrt(1.0 + lam) - np.sqrt(lam)
    return a * np.eye(3) + b * np.einsum("ka,kb->kab", n, n)


def landmark_term(V, Jv, landmark_matrix, targets, jacobian_vertices=None):
    """Landmarks at their targets: ``L V − p`` (landmarks as sparse rows of ``L``).

    Parameters
    ----------
    landmark_matrix : (l, n) sparse
        Row ``q`` holds the vertex or barycentric weights of landmark ``q``.
    targets : (l, 3) float64
    jacobian_vertices : (v,) int, optional
        The vertices whose rows ``Jv`` holds (in that order), when it is the
        Jacobian of a subset; they must include every landmark vertex.

    Returns
    -------
    r : (3l,) float64
    J : (3l, P) BlockJacobian
    """
    L = sp.csr_matrix(landmark_matrix)
    r = landmark_residual(V, L, targets)
    if jacobian_vertices is not None:
        L = L[:, np.asarray(jacobian_vertices)]
    L3 = sp.kron(L, sp.identity(3), format="csr")
    return r, BlockJacobian.of(Jv).left(L3)


def landmark_residual(V, landmark_matrix, targets) -> np.ndarray:
    """The residual of :func:`landmark_term` alone, ``(L V − p)`` as (3l,) float64."""
    return (landmark_matrix @ V - targets).ravel()


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
