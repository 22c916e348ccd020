"""Landmarks: an ordered list of named points on a mesh.

A landmark is one of three kinds, and one set may mix them:

* a **vertex** landmark, ``vertex[i] >= 0`` — follows the mesh as it deforms;
* a **surface** landmark, ``triangle[i] >= 0`` with ``barycentric[i]`` — a point
  inside a triangle of the mesh's triangulation (:attr:`Mesh.triangles`), also
  following the mesh;
* a **free** point, ``points[i]`` finite — a 3D position, typically picked on a scan.

:meth:`Landmarks.positions` turns any set into 3D points for given vertices.
:func:`pair_landmarks` matches two sets by name when both are named, else by order.
File formats live in :mod:`facewrap.io.landmarks`.
"""

from __future__ import annotations

import unicodedata
from typing import Sequence

import numpy as np

from facewrap.params import not_one_string
from facewrap.units import too_large

__all__ = ["Landmarks", "pair_landmarks", "snap_to_surface", "IBUG68_NAMES",
           "BARYCENTRIC_SLACK", "barycentric_problem"]

#: How far barycentric coordinates (written with a few decimals) may stray from
#: [0, 1] and from summing to 1.
BARYCENTRIC_SLACK = 1e-3


def barycentric_problem(bary) -> str | None:
    """What is wrong with rows of barycentric coordinates, or None.

    A point's coordinates in its triangle are each in [0, 1] and sum to 1
    (within :data:`BARYCENTRIC_SLACK`); others put it off the surface, NaN
    nowhere, and 1e300 overflows the alignment.

    Parameters
    ----------
    bary : (k, 3) float

    Returns
    -------
    str or None
        ``"... got [...]"`` naming the first bad row, or None when all are good.

    Examples
    --------
    >>> barycentric_problem([[0.2, 0.3, 0.5]]) is None
    True
    >>> barycentric_problem([[1.0, 1.0, 0.0]])
    'must be 3 numbers in [0, 1] that sum to 1, got [1.0, 1.0, 0.0]'
    """
    b = np.asarray(bary, dtype=np.float64).reshape(-1, 3)
    bad = (~np.isfinite(b).all(axis=1) | (b.min(axis=1, initial=0.0) < -BARYCENTRIC_SLACK)
           | (np.abs(b.sum(axis=1) - 1.0) > BARYCENTRIC_SLACK))
    if not bad.any():
        return None
    return f"must be 3 numbers in [0, 1] that sum to 1, got {b[bad][0].tolist()}"


def _names(prefix, count):
    return tuple(f"{prefix}_{k}" for k in range(count))


#: Names of the 68 iBUG/Multi-PIE face landmarks in their standard order.  "r"/"l"
#: are the *subject's* right/left: points 17-21 and 36-41 lie on the subject's right
#: (the image's left in a frontal photo).
IBUG68_NAMES: tuple[str, ...] = (
    _names("jaw", 17) + _names("brow_r", 5) + _names("brow_l", 5)
    + _names("nose_bridge", 4) + _names("nose_base", 5) + _names("eye_r", 6)
    + _names("eye_l", 6) + _names("mouth_outer", 12) + _names("mouth_inner", 8))


def _ro(a):
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


def _ids(values, name: str) -> np.ndarray:
    """(k,) int64 ids from a 1-D sequence (a scalar is one id)."""
    # imported here: a command's help reads landmarks' docs, not the geometry
    from facewrap.geometry.checks import as_whole_indices
    ids = as_whole_indices(values, f"landmark {name}")
    if ids.ndim > 1:
        raise ValueError(f"landmark {name} must be one-dimensional, got shape {ids.shape}")
    return ids.reshape(-1)


def _rows(values, k: int, name: str) -> np.ndarray:
    """(k, 3) float64 rows, one per landmark."""
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"landmark {name} must be a ({k}, 3) float array: {exc}") from None
    if arr.size != 3 * k:
        raise ValueError(f"landmark {name} must have shape ({k}, 3), got {arr.shape}")
    return arr.reshape(k, 3)


class Landmarks:
    """An ordered, optionally named set of landmarks (see module docstring).

    Use the constructors :meth:`from_vertices`, :meth:`from_points` and
    :meth:`from_barycentric`, or the readers in :mod:`facewrap.io.landmarks`.

    Parameters
    ----------
    vertex : (k,) int, -1 where the landmark is not a vertex
        Ids are whole numbers (2.0 is vertex 2; 2.5 is refused).
    triangle : (k,) int, -1 where the landmark is not a surface point
    barycentric : (k, 3) float, used where ``triangle >= 0``
        Each row in [0, 1] and summing to 1 there (:func:`barycentric_problem`).
    points : (k, 3) float, NaN where the landmark is not a free point
    names : sequence of k str, optional
        Kept in Unicode's composed form (NFC), so that names typed either way pair.

    Examples
    --------
    >>> lm = Landmarks.from_vertices([2, 0], names=["nose_tip", "chin"])
    >>> lm.positions(np.eye(3)).tolist()
    [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]
    """

    def __init__(self, vertex, triangle, barycentric, points,
                 names: Sequence[str] | None = None):
        # ids 2.5 are no vertex: refused, not cast to vertex 2
        vertex = _ids(vertex, "vertex")
        k = len(vertex)
        triangle = _ids(triangle, "triangle")
        if len(triangle) != k:
            raise ValueError("vertex and triangle must have the same length")
        barycentric = _rows(barycentric, k, "barycentric")
        points = _rows(points, k, "points")
        kinds = ((vertex >= 0).astype(int) + (triangle >= 0)
                 + np.isfinite(points).all(axis=1))
        if np.any(kinds != 1):
            i = int(np.argmax(kinds != 1))
            raise ValueError(f"landmark {i} must be exactly one of vertex, surface "
                             "point or free point (vertex and triangle ids are >= 0, "
                             f"-1 for none; got vertex {vertex[i]}, triangle "
                             f"{triangle[i]})")
        problem = barycentric_problem(barycentric[triangle >= 0])
        if problem:
            raise ValueError(f"barycentric coordinates {problem}")
        problem = too_large(points, "landmark")   # as a file's reader refuses it
        if problem:   # (a 1e300 failed in the fit as "weights must be ... positive")
            raise ValueError(problem)
        not_one_string(names, "names")
        if names is not None:
            # one spelling of each name: 'é' typed as one character (NFC) or as 'e'
            # and an accent (NFD, as macOS tools may write) looks the same to the
            # user, yet failed to pair with the other and was left out of the fit
            names = tuple(unicodedata.normalize("NFC", str(n)) for n in names)
            if len(names) != k:
                raise ValueError(f"{len(names)} names for {k} landmarks")
            if len(set(names)) != k:
                seen = set()
                twice = next(n for n in names if n in seen or seen.add(n))
                raise ValueError(f"landmark names must be unique ({twice!r} is given "
                                 "twice)")
        self.vertex, self.triangle = _ro(vertex), _ro(triangle)
        self.barycentric, self.points = _ro(barycentric), _ro(points)
        self.names = names

    # -- constructors ---------------------------------------------------------------
    @classmethod
    def from_vertices(cls, indices, names=None) -> "Landmarks":
        """Landmarks at mesh vertices (0-based indices), (k,) int."""
        idx = _ids(indices, "indices")
        k = len(idx)
        return cls(idx, np.full(k, -1), np.zeros((k, 3)), np.full((k, 3), np.nan), names)

    @classmethod
    def from_points(cls, points, names=None) -> "Landmarks":
        """Free 3D points, (k, 3)."""
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"points must have shape (k, 3), got {pts.shape}")
        if not np.isfinite(pts).all():
            raise ValueError("landmark points must be finite")
        k = len(pts)
        return cls(np.full(k, -1), np.full(k, -1), np.zeros((k, 3)), pts, names)

    @classmethod
    def from_barycentric(cls, triangles, barycentric, names=None) -> "Landmarks":
        """Points inside triangles: (k,) triangle ids and (k, 3) barycentric coords."""
        tri = _ids(triangles, "triangles")
        k = len(tri)
        return cls(np.full(k, -1), tri, barycentric, np.full((k, 3), np.nan), names)

    # -- queries ------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.vertex)

    @property
    def kinds(self) -> np.ndarray:
        """(k,) str: 'vertex', 'surface' or 'point' for each landmark."""
        out = np.full(len(self), "point", dtype=object)
        out[self.vertex >= 0] = "vertex"
        out[self.triangle >= 0] = "surface"
        return out

    @property
    def on_mesh(self) -> bool:
        """True when no landmark is a free point (all follow a mesh)."""
        return bool(np.all((self.vertex >= 0) | (self.triangle >= 0)))

    def check(self, n_vertices: int | None = None, n_triangles: int | None = None):
        """Raise ``ValueError`` if an index does not fit a mesh of the given size."""
        if n_vertices is not None and len(self) and self.vertex.max() >= n_vertices:
            i = int(np.argmax(self.vertex >= n_vertices))
            raise ValueError(f"landmark {self.label(i)}: vertex {self.vertex[i]} "
                             f"out of range (mesh has {n_vertices} vertices)")
        if n_triangles is not None and len(self) and self.triangle.max() >= n_triangles:
            i = int(np.argmax(self.triangle >= n_triangles))
            raise ValueError(f"landmark {self.label(i)}: triangle {self.triangle[i]} "
                             f"out of range (mesh has {n_triangles} triangles)")

    def label(self, i: int) -> str:
        """Name of landmark ``i``, or its index when unnamed."""
        return self.names[i] if self.names is not None else str(i)

    def positions(self, vertices, triangles=None) -> np.ndarray:
        """3D positions for the given mesh geometry.

        Parameters
        ----------
        vertices : (n, 3) float, or a Mesh
        triangles : (t, 3) int, optional
            Needed for surface landmarks (taken from the Mesh when one is given).

        Returns
        -------
        (k, 3) float64
        """
        if hasattr(vertices, "triangles") and hasattr(vertices, "vertices"):
            triangles = vertices.triangles if triangles is None else triangles
            vertices = vertices.vertices
        V = np.asarray(vertices, dtype=np.float64)
        out = np.array(self.points, dtype=np.float64)
        iv = self.vertex >= 0
        if iv.any():
            self.check(n_vertices=len(V))
            out[iv] = V[self.vertex[iv]]
        it = self.triangle >= 0
        if it.any():
            if triangles is None:
                raise ValueError("surface landmarks need the mesh triangles")
            T = np.asarray(triangles)
            self.check(n_triangles=len(T))
            corners = V[T[self.triangle[it]]]  # (k, 3, 3)
            out[it] = np.einsum("kj,kjd->kd", self.barycentric[it], corners)
        return out

    def subset(self, index) -> "Landmarks":
        """Landmarks ``index`` (int array or bool mask), names kept, in the order
        ``index`` gives; ids outside ``[0, len)`` or a mask of another length are
        refused naming ``index``.

        >>> Landmarks.from_vertices([4, 5, 6]).subset([2, 0]).vertex.tolist()
        [6, 4]
        """
        from facewrap.geometry.checks import as_vertex_mask   # light: numpy only
        m = np.asarray(index)
        mask = as_vertex_mask(m, len(self), "index", what="landmark")   # either form
        idx = np.flatnonzero(mask) if m.dtype == bool else m.astype(np.int64)
        names = None if self.names is None else [self.names[i] for i in idx]
        return Landmarks(self.vertex[idx], self.triangle[idx], self.barycentric[idx],
                         self.points[idx], names)

    def __repr__(self) -> str:
        kinds, counts = np.unique(self.kinds.astype(str), return_counts=True)
        what = ", ".join(f"{c} {k}" for k, c in zip(kinds, counts))
        return f"<Landmarks {len(self)}: {what}{', named' if self.names else ''}>"


def snap_to_surface(landmarks: Landmarks, vertices, triangles
                    ) -> tuple[Landmarks, np.ndarray]:
    """Free-point landmarks moved to their closest surface points (triangle +
    barycentric), so they follow the mesh when it deforms; vertex and surface
    landmarks are kept.  Templates often come with landmarks as x, y, z points
    (MeshMonk's CSV files).

    Parameters
    ----------
    landmarks : Landmarks
    vertices : (n, 3) float
    triangles : (t, 3) int

    Returns
    -------
    snapped : Landmarks
        Same order and names.
    distances : (k,) float64
        How far each landmark moved (0 for those already on the mesh).
    """
    from facewrap.geometry import ClosestPointTree  # loads libigl (~0.2 s): only snapping needs it
    free = ~((landmarks.vertex >= 0) | (landmarks.triangle >= 0))
    dist = np.zeros(len(landmarks))
    if not free.any():
        return landmarks, dist
    from facewrap.geometry.checks import as_positions   # light: numpy only
    # a head's positions: a 1e300 snapped with "invalid value" warnings, silently
    cp = ClosestPointTree(as_positions(vertices, "vertices"), triangles).query(
        landmarks.points[free])
    tri = np.array(landmarks.triangle)
    bary = np.array(landmarks.barycentric)
    points = np.array(landmarks.points)
    tri[free], bary[free], points[free] = cp.triangles, cp.barycentric, np.nan
    dist[free] = cp.distances
    return Landmarks(landmarks.vertex, tri, bary, points, landmarks.names), dist


def pair_landmarks(a: Landmarks, b: Landmarks, what: tuple[str, str] = ("first", "second")
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(ia, ib)`` such that ``a[ia[j]]`` corresponds to ``b[ib[j]]``.

    Both named: matched by name (landmarks whose name is only in one set are left
    out; no common name is an error).  Both unnamed: by order, and the counts must
    agree.  Names on one side only: paired by order when the named side is
    :data:`IBUG68_NAMES` in that order (the convention of 68-point files, as a
    menpo ``.ljson`` is read) and the other has 68 landmarks; otherwise an error,
    since the named side's order is not known to be the other's (pairing them by
    order silently mis-pairs a file in another order).  ``what`` names the two
    sets in error messages (e.g. ``("template", "scan")``).

    Examples
    --------
    >>> a = Landmarks.from_vertices([0, 1, 2], names=["a", "b", "c"])
    >>> b = Landmarks.from_points(np.zeros((2, 3)), names=["c", "a"])
    >>> [x.tolist() for x in pair_landmarks(a, b)]
    [[0, 2], [1, 0]]
    """
    for name, given in zip(what, (a, b)):
        if not isinstance(given, Landmarks):
            raise TypeError(f"the {name} landmarks must be a Landmarks, got "
                            f"{type(given).__name__}")
    if a.names is not None and b.names is not None:
        pos_b = {n: j for j, n in enumerate(b.names)}
        ia = [i for i, n in enumerate(a.names) if n in pos_b]
        if not ia:
            raise ValueError("the two landmark sets have no name in common")
        ib = [pos_b[a.names[i]] for i in ia]
        return np.asarray(ia, dtype=np.int64), np.asarray(ib, dtype=np.int64)
    one_sided = (a.names is None) != (b.names is None)
    named_set = a if a.names is not None else b
    if one_sided and not (len(a) == len(b) == 68
                          and tuple(named_set.names) == IBUG68_NAMES):
        named, unnamed = what if a.names is not None else what[::-1]
        raise ValueError(f"the {named} landmarks have names and the {unnamed} landmarks "
                         "have none: cannot tell which correspond (give both sets "
                         "names, or neither and the same order)")
    if len(a) != len(b):
        raise ValueError(f"landmark counts differ: {len(a)} vs {len(b)}")
    idx = np.arange(len(a), dtype=np.int64)
    return idx, idx.copy()
