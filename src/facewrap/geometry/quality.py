"""Triangles that turned: the one flip test of wrapping, transfer, avatar and evaluation.

A triangle *turned* past an angle when the angle between its normal before and
after a deformation exceeds it; *flipped* is the 90° case (the normal points
backwards).  Degenerate triangles (a zero normal on either side) have no
direction and never count as turned.  Every caller — the projection's fold guard,
the transfer's flip repair, the evaluation's flipped-triangle count — asks this
module, each with its own angle.
"""

from __future__ import annotations

import numpy as np

from facewrap.geometry.checks import as_triangles, as_vertices

__all__ = ["turned", "turned_triangles", "flipped_triangles"]


def turned(normals_before, normals_after, angle: float = 90.0) -> np.ndarray:
    """Whether each direction turned by more than ``angle`` degrees.

    Parameters
    ----------
    normals_before, normals_after : (t, 3) float64
        Directions before and after (any lengths; zero rows mean "no direction").
    angle : float
        Degrees in [0, 180].

    Returns
    -------
    (t,) bool
        ``cos(turn) < cos(angle)``; False where either row is zero.

    Examples
    --------
    >>> n0 = np.array([[0, 0, 1.], [0, 0, 1.], [0, 0, 0.]])
    >>> n1 = np.array([[0, 1, 1.], [0, 0, -2.], [0, 0, 1.]])
    >>> turned(n0, n1, 30.0).tolist(), turned(n0, n1).tolist()
    ([True, True, False], [False, True, False])
    """
    if not 0.0 <= angle <= 180.0:
        raise ValueError(f"angle must be in [0, 180] degrees; got {angle!r}")
    a = np.asarray(normals_before, dtype=np.float64)
    b = np.asarray(normals_after, dtype=np.float64)
    if a.shape != b.shape or a.shape[-1] != 3:
        raise ValueError(f"normals_before and normals_after must both be (t, 3); got "
                         f"{a.shape} and {b.shape}")
    dot = np.einsum("...i,...i->...", a, b)
    scale = np.sqrt(np.einsum("...i,...i->...", a, a) * np.einsum("...i,...i->...", b, b))
    return (dot < np.cos(np.radians(angle)) * scale) & (scale > 0)


def turned_triangles(vertices, reference, triangles, angle: float = 90.0) -> np.ndarray:
    """Triangles whose normal turned more than ``angle`` degrees from the reference's.

    Parameters
    ----------
    vertices : (n, 3) or (k, n, 3) float64
        Deformed positions (one pose or a stack of poses).
    reference : (n, 3) float64
        Positions the turn is measured from.
    triangles : (t, 3) int64
    angle : float
        Degrees in [0, 180].

    Returns
    -------
    (t,) or (k, t) bool
        Same leading shape as ``vertices``.

    Raises
    ------
    ValueError
        When the shapes disagree or an index is out of range.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> turned_triangles(V * [1, -1, 1], V, [[0, 1, 2]]).tolist()
    [True]
    """
    V0 = as_vertices(reference, "reference")
    T = as_triangles(triangles, len(V0), "triangles")
    P = np.asarray(vertices, dtype=np.float64)
    if P.ndim not in (2, 3) or P.shape[-2:] != V0.shape:
        raise ValueError(f"vertices must be {V0.shape} or (k, *{V0.shape}) like reference;"
                         f" got {P.shape}")
    n0 = _normals(V0, T)
    n1 = _normals(P, T)
    return turned(np.broadcast_to(n0, n1.shape), n1, angle)


def flipped_triangles(vertices, reference, triangles) -> np.ndarray:
    """Triangles whose normal turned by more than 90° (see :func:`turned_triangles`).

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> flipped_triangles(np.stack([V, V[[0, 2, 1]]]), V, [[0, 1, 2]]).tolist()
    [[False], [True]]
    """
    return turned_triangles(vertices, reference, triangles, 90.0)


def _normals(V: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Unnormalised triangle normals, (..., t, 3), for one pose or a stack."""
    a, b, c = V[..., T[:, 0], :], V[..., T[:, 1], :], V[..., T[:, 2], :]
    return np.cross(b - a, c - a)
