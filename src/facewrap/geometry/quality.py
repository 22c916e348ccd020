"""Triangle quality: the one flip test, and shape and change measures of triangles.

A triangle *turned* past an angle when the angle between its normal before and
after a deformation exceeds it; *flipped* is the 90° case (the normal points
backwards).  Degenerate triangles (a zero normal on either side) have no
direction and never count as turned.  Every caller — the projection's fold guard,
the transfer's flip repair, the evaluation's flipped-triangle count — asks this
module, each with its own angle.  :func:`folded_in` finds triangles a mesh itself
has inside out (facing away from every neighbour), which no fit should be blamed for;
:func:`new_creases` the edge neighbours a deformation turned to face apart (the
unfolding's crease test and the benchmarks' fold count).

:func:`triangle_quality` measures each triangle (minimum angle, area) and, against
a reference mesh in the same topology (similarity-aligned first), its flip, area
change and stretch (anisotropy of its deformation); :func:`triangle_to_vertex`
spreads such per-triangle values to vertices for pictures.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from facewrap.geometry.adjacency import triangle_adjacency
from facewrap.geometry.arrays import cross_columns, edge_vectors
from facewrap.geometry.checks import as_triangles, as_vertices
from facewrap.geometry.similarity import similarity_transform

__all__ = ["turned", "turned_triangles", "flipped_triangles", "turned_from", "folded_in",
           "adjacent_triangle_pairs", "facing_apart", "new_creases", "triangle_normals", "TriangleQuality", "triangle_quality", "triangle_to_vertex"]


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
    if not np.isfinite(P).all():   # a NaN normal turns nowhere: it would pass as upright
        raise ValueError("vertices must be finite (found NaN or inf)")
    n0 = triangle_normals(V0, T)
    if P.ndim == 2:
        return turned(n0, triangle_normals(P, T), angle)
    return turned_from(n0, P, T, angle)


def flipped_triangles(vertices, reference, triangles) -> np.ndarray:
    """Triangles whose normal turned by more than 90° (see :func:`turned_triangles`).

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> flipped_triangles(np.stack([V, V[[0, 2, 1]]]), V, [[0, 1, 2]]).tolist()
    [[False], [True]]
    """
    return turned_triangles(vertices, reference, triangles, 90.0)


def folded_in(normals, T) -> np.ndarray:
    """(t,) bool: triangles facing away (> 90 degrees) from each of their edge
    neighbours, two at least, given the triangles' ``normals`` (t, 3): folded
    inside out.

    >>> T = np.array([[0, 1, 2], [1, 3, 2], [1, 4, 3]])
    >>> n = np.array([[0, 0, 1.], [0, 0, -1], [0, 0, 1]])
    >>> folded_in(n, T).tolist()
    [False, True, False]
    """
    nb = triangle_adjacency(T)
    has = nb >= 0
    dots = np.where(has, np.einsum("ij,ikj->ik", normals, normals[np.maximum(nb, 0)]), 1.0)
    return (has.sum(axis=1) >= 2) & ((dots < 0) | ~has).all(axis=1)


def adjacent_triangle_pairs(T) -> np.ndarray:
    """(p, 2) int64 pairs ``i < j`` of triangles sharing an edge.

    >>> adjacent_triangle_pairs(np.array([[0, 1, 2], [1, 3, 2], [3, 4, 2]])).tolist()
    [[0, 1], [1, 2]]
    """
    TT = triangle_adjacency(T)
    i = np.repeat(np.arange(len(TT), dtype=np.int64), 3)
    j = TT.reshape(-1)
    keep = j > i
    return np.stack([i[keep], j[keep]], axis=1)


def facing_apart(V, T, pairs) -> np.ndarray:
    """(p,) bool: which ``pairs`` (p, 2) of triangles of ``T`` over ``V`` have normals
    more than 90 degrees apart (a crease or a fold between them; degenerate
    triangles have no direction and face nothing)."""
    n = triangle_normals(np.asarray(V, dtype=np.float64), np.asarray(T, dtype=np.int64))
    return turned(n[pairs[:, 0]], n[pairs[:, 1]], 90.0)


def new_creases(vertices, reference, triangles) -> np.ndarray:
    """Edge-adjacent triangle pairs facing apart (:func:`facing_apart`) in
    ``vertices`` but not in ``reference``: a crease or fold a deformation made
    (pairs already that sharp in the reference are its own).  Invariant to a
    similarity of either mesh, so a template need not be aligned first.

    Parameters
    ----------
    vertices, reference : (n, 3) float
        The result and the template, in one topology.
    triangles : (t, 3) int

    Returns
    -------
    (c, 2) int64
        The new creases as pairs ``i < j`` of triangle indices.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.]])
    >>> T = np.array([[0, 1, 2], [1, 3, 2]])
    >>> folded = V.copy(); folded[3] = [0.2, 0.2, 0.1]     # 3 folded back over
    >>> new_creases(folded, V, T).tolist(), new_creases(V, folded, T).tolist()
    ([[0, 1]], [])
    """
    V0 = as_vertices(reference, "reference")
    V = as_vertices(vertices, "vertices")
    if V.shape != V0.shape:
        raise ValueError(f"vertices and reference must be one topology, got {V.shape} "
                         f"and {V0.shape}")
    T = as_triangles(triangles, len(V0), "triangles")
    pairs = adjacent_triangle_pairs(T)
    return pairs[facing_apart(V, T, pairs) & ~facing_apart(V0, T, pairs)]


def triangle_normals(V: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Unnormalised normals (t, 3) of clean triangles ``T`` (t, 3) over ``V`` (n, 3).

    Coordinate-major (:mod:`facewrap.geometry.arrays`): contiguous 1-D arrays,
    several times faster than ``np.cross`` of gathered rows, which matters where
    every pose of a shape set is tested.

    >>> triangle_normals(np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0.]]), np.array([[0, 1, 2]]))
    array([[0., 0., 2.]])
    """
    return cross_columns(*edge_vectors(V, T)).T


def turned_from(rest_normals: np.ndarray, poses: np.ndarray, T: np.ndarray,
                angle: float = 90.0) -> np.ndarray:
    """(k, t) bool: triangles of each pose (k, n, 3) turned past ``angle`` degrees
    from ``rest_normals`` (t, 3), for callers that test many poses against one rest
    shape (the normals at rest computed once; the poses one at a time, in cache)."""
    if not len(poses):
        return np.zeros((0, len(T)), dtype=bool)
    return np.stack([turned(rest_normals, triangle_normals(X, T), angle) for X in poses])


@dataclass(frozen=True, eq=False)
class TriangleQuality:
    """Shape of each triangle, and its change from a reference.

    Attributes
    ----------
    min_angle : (t,) float64
        Smallest interior angle, degrees (0 for degenerate triangles).
    area : (t,) float64
    degenerate : (t,) bool
        Zero area (in the mesh or in the reference).
    flipped : (t,) bool or None
        Normal turned more than 90 degrees from the aligned reference's
        (:func:`turned`; never for degenerate triangles).
    area_ratio : (t,) float64 or None
        Area over the aligned reference's area (1 = unchanged; the global scale of
        the alignment is taken out); NaN for degenerate triangles.
    stretch : (t,) float64 or None
        Anisotropy of the in-plane deformation from the reference, ``s_max / s_min``
        of its singular values (1 = shape kept, only scaled and rotated); NaN for
        degenerate triangles.
    """

    min_angle: np.ndarray
    area: np.ndarray
    degenerate: np.ndarray
    flipped: np.ndarray | None = None
    area_ratio: np.ndarray | None = None
    stretch: np.ndarray | None = None

    def summary(self, prefix: str = "triangles_") -> dict:
        """Counts and percentiles (JSON-able)."""
        t = len(self.area)
        s = {prefix + "count": int(t), prefix + "degenerate": int(self.degenerate.sum())}
        ang = self.min_angle[~self.degenerate]
        s[prefix + "min_angle_min"] = float(ang.min()) if len(ang) else None
        s[prefix + "min_angle_p5"] = float(np.percentile(ang, 5)) if len(ang) else None
        if self.flipped is not None:
            s[prefix + "flipped"] = int(self.flipped.sum())
            s[prefix + "flipped_fraction"] = float(self.flipped.mean()) if t else 0.0
            r = self.area_ratio[np.isfinite(self.area_ratio)]
            st = self.stretch[np.isfinite(self.stretch)]
            for q in (5, 50, 95):
                s[prefix + f"area_ratio_p{q}"] = float(np.percentile(r, q)) if len(r) else None
            s[prefix + "stretch_p95"] = float(np.percentile(st, 95)) if len(st) else None
            s[prefix + "stretch_max"] = float(st.max()) if len(st) else None
        return s


def _triangle_frames(V, T):
    """Edges e1 = V1 - V0, e2 = V2 - V0 and doubled-area normals, each (3, t)."""
    e1, e2 = edge_vectors(V, T)
    return e1, e2, cross_columns(e1, e2)


def _min_angles(V, T) -> np.ndarray:
    e1, e2, n = _triangle_frames(V, T)
    e3 = e2 - e1
    two_a = np.sqrt(np.einsum("ij,ij->j", n, n))
    angles = []
    for a, b in ((e1, e2), (-e1, e3), (-e2, -e3)):
        dot = np.einsum("ij,ij->j", a, b)
        angles.append(np.arctan2(two_a, dot))
    ang = np.degrees(np.min(angles, axis=0))
    return np.where(two_a > 0, ang, 0.0)


def triangle_quality(vertices, triangles, reference=None, *,
                     align: bool = True) -> TriangleQuality:
    """Shape quality of triangles, and their change from a reference.

    Parameters
    ----------
    vertices : (n, 3) float
    triangles : (t, 3) int
        For a polygon mesh, its fan triangulation (``mesh.triangles``): a square
        quad gives two 45-degree triangles.
    reference : (n, 3) float, optional
        The same mesh before fitting (e.g. the template).  With it, flipped
        triangles, area ratios and stretch are computed.
    align : bool
        Fit the reference onto ``vertices`` with a similarity (Umeyama, all
        vertices) first, so a global rotation, translation or scale counts as no
        change.

    Returns
    -------
    TriangleQuality
        Per-triangle arrays; the reference-based ones are None without a reference.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> q = triangle_quality(V, [[0, 1, 2]], V[[0, 2, 1]] * [1, 1, 1], align=False)
    >>> q.min_angle.round(6).tolist(), q.flipped.tolist(), q.area_ratio.tolist()
    ([45.0], [True], [1.0])
    """
    V = as_vertices(vertices, "vertices")
    T = as_triangles(triangles, len(V), "triangles")
    _, _, n = _triangle_frames(V, T)
    two_a = np.sqrt(np.einsum("ij,ij->j", n, n))
    min_angle = _min_angles(V, T)
    degenerate = two_a == 0
    if reference is None:
        return TriangleQuality(min_angle, 0.5 * two_a, degenerate)
    Rf = as_vertices(reference, "reference")
    if Rf.shape != V.shape:
        raise ValueError(f"reference must have shape {V.shape}, got {Rf.shape}")
    if align and len(V) >= 3:
        Rf = similarity_transform(Rf, V).apply(Rf)
    r1, r2, rn = _triangle_frames(Rf, T)
    ref_two_a = np.sqrt(np.einsum("ij,ij->j", rn, rn))
    degenerate = degenerate | (ref_two_a == 0)
    flipped = turned(rn.T, n.T, 90.0)
    ok = ~degenerate
    ratio = np.full(len(T), np.nan)
    ratio[ok] = two_a[ok] / ref_two_a[ok]
    stretch = np.full(len(T), np.nan)
    stretch[ok] = _anisotropy(r1[:, ok], r2[:, ok], rn[:, ok], ref_two_a[ok],
                              *edge_vectors(V, T[ok]))
    return TriangleQuality(min_angle, 0.5 * two_a, degenerate, flipped, ratio, stretch)


def _anisotropy(r1, r2, rn, ref_two_a, f1, f2) -> np.ndarray:
    """``s_max / s_min`` of the map from each reference triangle to the deformed one.

    Reference edges in an orthonormal in-plane frame ``(u, w)``: ``E = [[a, b],
    [0, c]]`` with ``a = |r1|``, ``b = r2 . u``, ``c = |rn| / a``; the Jacobian is
    ``J = [f1 f2] E^-1`` (3 x 2) and its singular values come from the 2 x 2 Gram
    matrix ``J^T J`` in closed form.  Inputs are (3, t) columns.
    """
    a = np.sqrt(np.einsum("ij,ij->j", r1, r1))
    b = np.einsum("ij,ij->j", r2, r1) / a
    c = ref_two_a / a
    # E^-1 = [[1/a, -b/(a c)], [0, 1/c]]: columns of J
    j1 = f1 / a
    j2 = (f2 - f1 * (b / a)) / c
    g11 = np.einsum("ij,ij->j", j1, j1)
    g22 = np.einsum("ij,ij->j", j2, j2)
    g12 = np.einsum("ij,ij->j", j1, j2)
    mid = 0.5 * (g11 + g22)
    rad = np.sqrt(np.maximum(0.25 * (g11 - g22) ** 2 + g12 ** 2, 0.0))
    s_max = np.sqrt(mid + rad)
    s_min = np.sqrt(np.maximum(mid - rad, 0.0))
    return np.divide(s_max, s_min, out=np.full_like(s_max, np.inf), where=s_min > 0)


def triangle_to_vertex(values, triangles, n_vertices: int, reduce: str = "mean"
                       ) -> np.ndarray:
    """Per-vertex values from per-triangle values (for pictures).

    Parameters
    ----------
    values : (t,) float
        NaN values are ignored.
    triangles : (t, 3) int
    n_vertices : int
    reduce : {"mean", "max", "min"}
        Over the triangles around each vertex.

    Returns
    -------
    (n_vertices,) float64
        NaN for vertices with no finite value around them.

    Examples
    --------
    >>> triangle_to_vertex([1.0, 3.0], [[0, 1, 2], [0, 2, 3]], 5).tolist()
    [2.0, 1.0, 2.0, 3.0, nan]
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    T = as_triangles(triangles, n_vertices, "triangles")
    if len(v) != len(T):
        raise ValueError(f"values must have one entry per triangle ({len(T)}), "
                         f"got {len(v)}")
    ok = np.isfinite(v)
    idx = T[ok].reshape(-1)
    vals = np.repeat(v[ok], 3)
    if reduce == "mean":
        inc = sp.csr_matrix((np.ones(len(idx)), (idx, np.arange(len(idx)))),
                            shape=(n_vertices, len(idx)))
        total = inc @ vals
        count = np.bincount(idx, minlength=n_vertices)
        return np.divide(total, count, out=np.full(n_vertices, np.nan), where=count > 0)
    if reduce in ("max", "min"):
        fill = -np.inf if reduce == "max" else np.inf
        out = np.full(n_vertices, fill)
        (np.maximum if reduce == "max" else np.minimum).at(out, idx, vals)
        out[out == fill] = np.nan
        return out
    raise ValueError(f"reduce must be 'mean', 'max' or 'min', got {reduce!r}")
