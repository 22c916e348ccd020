"""The mesh model: what artists care about, kept exactly.

A :class:`Mesh` holds vertices in their original order, polygons of any size
(quads stay quads), per-corner texture-coordinate and normal indices (so UV seams
survive), per-face material and group ids, and the material library references of
the file it came from.  Geometry code works on a derived triangulation
(:attr:`Mesh.triangles`) with a map back to the polygons
(:attr:`Mesh.triangle_faces`).

Meshes are immutable: every array is stored as a read-only copy (a reader hands over
the arrays it made instead, ``copy=False``), and operations that change geometry
return a new mesh (:meth:`Mesh.with_vertices`) that shares topology, UVs and
materials with the old one.  That is how a fitted template keeps the
template's vertex count, order, faces and UVs exactly.

Polygons are stored flat, as in CSR sparse matrices: ``face_indices`` lists the
corners of all faces one after another and ``face_offsets[f]:face_offsets[f + 1]``
is the slice of face ``f``.
"""

from __future__ import annotations

from functools import cached_property
from typing import Sequence

import numpy as np

from facewrap.params import not_one_string
from facewrap.units import too_large

__all__ = ["Mesh", "polygons_from_list", "triangulate_polygons", "check_positions",
           "check_mesh"]


def _indices(a, name: str) -> np.ndarray:
    """:func:`facewrap.geometry.checks.as_whole_indices` (a face 2.5 is no vertex:
    refused, not cast to vertex 2)."""
    # imported here: a command's help reads meshes' docs, not the geometry
    from facewrap.geometry.checks import as_whole_indices
    return as_whole_indices(a, name)


def _readonly(a, dtype, copy: bool = True):
    if a is None:
        return None
    arr = np.array(a, dtype=dtype, copy=True) if copy else np.asarray(a, dtype=dtype)
    arr.setflags(write=False)
    return arr


def _used(ids: np.ndarray, n: int) -> np.ndarray:
    """The distinct values of ``ids`` (ints in ``[0, n)``), sorted."""
    used = np.zeros(n, dtype=bool)
    used[ids] = True
    return np.flatnonzero(used)


def polygons_from_list(faces, name: str = "faces") -> tuple[np.ndarray, np.ndarray]:
    """Flatten polygons into ``(offsets, indices)``.

    Parameters
    ----------
    faces : (m, k) int array_like, or sequence of int sequences
        Uniform polygons as a 2-D array, or polygons of mixed sizes.  Whole
        floats (2.0) are taken as indices, other numbers are refused.
    name : str
        The argument's name, for error messages.

    Returns
    -------
    offsets : (m + 1,) int64
    indices : (offsets[-1],) int64

    Examples
    --------
    >>> off, idx = polygons_from_list([[0, 1, 2], [2, 1, 3, 4]])
    >>> off.tolist(), idx.tolist()
    ([0, 3, 7], [0, 1, 2, 2, 1, 3, 4])
    """
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        m, k = faces.shape
        return (np.arange(m + 1, dtype=np.int64) * k,
                _indices(faces, name).reshape(-1).copy())
    if isinstance(faces, (str, bytes)) or not hasattr(faces, "__iter__"):
        raise TypeError(f"{name} must be a sequence of polygons (vertex index "
                        f"sequences), got {type(faces).__name__}")
    faces = list(faces)
    if not all(hasattr(f, "__len__") and not isinstance(f, (str, bytes)) for f in faces):
        raise TypeError(f"{name} must be a sequence of polygons, each a sequence of "
                        "vertex indices")
    sizes = np.fromiter((len(f) for f in faces), dtype=np.int64, count=len(faces))
    offsets = np.zeros(len(faces) + 1, dtype=np.int64)
    np.cumsum(sizes, out=offsets[1:])
    if len(faces) == 0:
        return offsets, np.zeros(0, dtype=np.int64)
    indices = _indices([i for f in faces for i in f], name)
    return offsets, indices


def triangulate_polygons(offsets: np.ndarray, indices: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fan-triangulate flat polygons, vectorised.

    Polygon ``(c0, c1, ..., ck)`` becomes ``(c0, c1, c2), (c0, c2, c3), ...``.

    Parameters
    ----------
    offsets : (m + 1,) int
    indices : (offsets[-1],) int

    Returns
    -------
    triangles : (t, 3) int64
        Entries of ``indices`` for each triangle corner.
    triangle_faces : (t,) int64
        The polygon each triangle came from.
    corners : (t, 3) int64
        Positions in ``indices`` (corner ids) of each triangle corner, so per-corner
        data such as UV indices can be triangulated the same way.

    Examples
    --------
    >>> tri, tf, _ = triangulate_polygons(np.array([0, 4]), np.array([5, 6, 7, 8]))
    >>> tri.tolist(), tf.tolist()
    ([[5, 6, 7], [5, 7, 8]], [0, 0])
    """
    offsets = np.asarray(offsets, dtype=np.int64)
    sizes = np.diff(offsets)
    n_tri = np.maximum(sizes - 2, 0)
    triangle_faces = np.repeat(np.arange(len(sizes), dtype=np.int64), n_tri)
    # k-th triangle of its polygon: 0, 1, ... inside each polygon
    first = np.zeros(len(sizes) + 1, dtype=np.int64)
    np.cumsum(n_tri, out=first[1:])
    k = np.arange(len(triangle_faces), dtype=np.int64) - first[triangle_faces]
    base = offsets[:-1][triangle_faces]
    corners = np.stack([base, base + k + 1, base + k + 2], axis=1)
    return np.asarray(indices)[corners], triangle_faces, corners


class Mesh:
    """A polygon mesh with vertex order, polygons, UV seams and materials kept.

    Parameters
    ----------
    vertices : (n, 3) float array_like
    faces : (m, k) int array_like, sequence of int sequences, or (offsets, indices)
        Polygons as vertex indices (0-based; whole floats such as 2.0 are taken,
        2.5 is refused).  A tuple of two 1-D arrays is taken as flat
        ``(offsets, indices)``.
    uvs : (u, 2) float array_like, optional
        Texture coordinates.
    face_uvs : same layout as ``faces``, optional
        Per-corner indices into ``uvs``; required with ``uvs`` unless the UVs are
        per vertex (``len(uvs) == n``), then corner ``c`` uses ``uvs[faces[c]]``.
    normals : (q, 3) float array_like, optional
    face_normals : same layout as ``faces``, optional
        Per-corner indices into ``normals`` (as written by OBJ ``f v/vt/vn``).
    face_materials : (m,) int, optional
        Index into ``materials`` per face, -1 for none.
    materials : sequence of str
        Material names (OBJ ``usemtl``).
    face_groups : (m,) int, optional
        Index into ``groups`` per face, -1 for none.
    groups : sequence of str
        Group names (OBJ ``g``/``o``).
    mtllib : sequence of str
        Material library files referenced by the mesh (OBJ ``mtllib``).
    vertex_colors : (n, 3) or (n, 4) float, optional
        Colours in [0, 1].
    texture : str, optional
        Path of a texture image, when the file names one.
    copy : bool
        Copy the arrays given (the default), so that nothing the caller still holds
        can change the mesh.  False takes them as they are, made read-only: for a
        reader that made them and keeps no other reference (a million-triangle
        OBJ's arrays cost 0.1 s to copy).

    Examples
    --------
    >>> quad = Mesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.]], [[0, 1, 2, 3]])
    >>> quad.n_vertices, quad.n_faces, quad.triangles.tolist()
    (4, 1, [[0, 1, 2], [0, 2, 3]])
    >>> quad.with_vertices(quad.vertices * 2).face_sizes.tolist()
    [4]
    """

    def __init__(self, vertices, faces, *, uvs=None, face_uvs=None, normals=None,
                 face_normals=None, face_materials=None, materials: Sequence[str] = (),
                 face_groups=None, groups: Sequence[str] = (),
                 mtllib: Sequence[str] = (), vertex_colors=None,
                 texture: str | None = None, copy: bool = True):
        try:
            vertices = np.asarray(vertices, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"vertices must be a float array of shape (n, 3): "
                             f"{exc}") from None
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise ValueError(f"vertices must have shape (n, 3), got {vertices.shape}")
        self.vertices = _readonly(vertices, np.float64, copy)
        offsets, indices = self._flat(faces, "faces")
        self.face_offsets = _readonly(offsets, np.int64, copy)
        self.face_indices = _readonly(indices, np.int64, copy)
        n, m = len(vertices), len(offsets) - 1
        if len(indices) and (indices.min() < 0 or indices.max() >= n):
            raise ValueError(f"face indices must lie in [0, {n}), got range "
                             f"[{indices.min()}, {indices.max()}]")
        if np.any(np.diff(offsets) < 3):
            raise ValueError("every face needs at least 3 corners")

        self.uvs = _readonly(uvs, np.float64, copy)
        if self.uvs is not None:
            if self.uvs.ndim != 2 or self.uvs.shape[1] != 2:
                raise ValueError(f"uvs must have shape (u, 2), got {self.uvs.shape}")
            if face_uvs is None:
                if len(self.uvs) != n:
                    raise ValueError("face_uvs is required unless there is one uv per vertex")
                face_uvs = indices
        self.face_uvs = self._corner_indices(face_uvs, "face_uvs", self.uvs, copy)

        self.normals = _readonly(normals, np.float64, copy)
        if self.normals is not None and (self.normals.ndim != 2 or self.normals.shape[1] != 3):
            raise ValueError(f"normals must have shape (q, 3), got {self.normals.shape}")
        self.face_normals = self._corner_indices(face_normals, "face_normals", self.normals,
                                                 copy)

        for what, names in (("materials", materials), ("groups", groups),
                            ("mtllib", mtllib)):
            not_one_string(names, what)
        self.materials = tuple(materials)
        self.face_materials = self._per_face(face_materials, m, len(self.materials),
                                             "face_materials")
        self.groups = tuple(groups)
        self.face_groups = self._per_face(face_groups, m, len(self.groups), "face_groups")
        self.mtllib = tuple(mtllib)
        self.vertex_colors = _readonly(vertex_colors, np.float64, copy)
        if self.vertex_colors is not None and (
                self.vertex_colors.ndim != 2 or len(self.vertex_colors) != n
                or self.vertex_colors.shape[1] not in (3, 4)):
            raise ValueError("vertex_colors must have shape (n, 3) or (n, 4)")
        self.texture = texture

    # -- construction helpers ------------------------------------------------------
    @staticmethod
    def _flat(faces, name):
        if (isinstance(faces, tuple) and len(faces) == 2
                and all(np.ndim(x) == 1 for x in faces)):
            offsets = _indices(faces[0], f"{name} offsets")
            indices = _indices(faces[1], name)
            if len(offsets) == 0 or offsets[0] != 0 or offsets[-1] != len(indices) or np.any(np.diff(offsets) < 0):
                raise ValueError(f"{name}: offsets do not describe indices")
            return offsets, indices
        return polygons_from_list(faces if not hasattr(faces, "__array__")
                                  else np.asarray(faces), name)

    def _corner_indices(self, corner, name, table, copy: bool = True):
        if corner is None:
            return None
        if table is None:
            raise ValueError(f"{name} given without its table")
        if isinstance(corner, tuple) and len(corner) == 2:
            offsets, idx = self._flat(corner, name)
            if not np.array_equal(offsets, self.face_offsets):
                raise ValueError(f"{name} must have the same polygon sizes as faces")
        else:
            corner = np.asarray(corner) if hasattr(corner, "__array__") else corner
            offsets, idx = polygons_from_list(corner, name) if not (
                isinstance(corner, np.ndarray) and corner.ndim == 1) else (None, corner)
            if offsets is not None and not np.array_equal(offsets, self.face_offsets):
                raise ValueError(f"{name} must have the same polygon sizes as faces")
        idx = _indices(idx, name)
        if len(idx) != len(self.face_indices):
            raise ValueError(f"{name} needs one index per face corner")
        if len(idx) and (idx.min() < 0 or idx.max() >= len(table)):
            raise ValueError(f"{name} index out of range [0, {len(table)})")
        return _readonly(idx, np.int64, copy)

    @staticmethod
    def _per_face(values, m, count, name):
        if values is None:
            return None
        values = _indices(values, name)
        if values.shape != (m,):
            raise ValueError(f"{name} must have shape ({m},), got {values.shape}")
        if len(values) and (values.min() < -1 or values.max() >= count):
            raise ValueError(f"{name} must index its name list or be -1")
        return _readonly(values, np.int64)

    # -- sizes -----------------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        """Number of vertices."""
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        """Number of polygons."""
        return len(self.face_offsets) - 1

    @cached_property
    def face_sizes(self) -> np.ndarray:
        """(m,) int64: corner count of each polygon."""
        return np.diff(self.face_offsets)

    @property
    def is_triangle_mesh(self) -> bool:
        """True when every polygon is a triangle."""
        return bool(np.all(self.face_sizes == 3))

    def polygons(self) -> list[np.ndarray]:
        """Polygons as a list of int64 arrays (slow path, for display and tests)."""
        return np.split(np.asarray(self.face_indices), self.face_offsets[1:-1])

    def faces_array(self) -> np.ndarray:
        """(m, k) int64 polygons when all have the same size ``k``.

        Raises
        ------
        ValueError
            When polygon sizes differ.
        """
        sizes = self.face_sizes
        if len(sizes) and np.any(sizes != sizes[0]):
            raise ValueError("polygons have different sizes; use face_offsets/face_indices")
        k = int(sizes[0]) if len(sizes) else 3
        return np.asarray(self.face_indices).reshape(-1, k)

    # -- triangulation (derived, cached) ------------------------------------------------
    @cached_property
    def _triangulation(self):
        tri, tf, corners = triangulate_polygons(self.face_offsets, self.face_indices)
        for a in (tri, tf, corners):
            a.setflags(write=False)
        return tri, tf, corners

    @property
    def triangles(self) -> np.ndarray:
        """(t, 3) int64: fan triangulation of the polygons, for geometry queries."""
        return self._triangulation[0]

    @property
    def triangle_faces(self) -> np.ndarray:
        """(t,) int64: polygon that each triangle of :attr:`triangles` belongs to."""
        return self._triangulation[1]

    @property
    def triangle_corners(self) -> np.ndarray:
        """(t, 3) int64: corner ids (positions in ``face_indices``) of each triangle."""
        return self._triangulation[2]

    @property
    def triangle_uvs(self) -> np.ndarray | None:
        """(t, 3) int64 UV indices of each triangle corner, or None."""
        if self.face_uvs is None:
            return None
        return self.face_uvs[self.triangle_corners]

    # -- derived geometry -------------------------------------------------------------
    @cached_property
    def surface_vertex_ids(self) -> np.ndarray:
        """(k,) int64, sorted: the vertices some face uses (all of them, but for
        stray points an exporter or a scanner left in the file)."""
        ids = _used(self.face_indices, self.n_vertices)
        ids.setflags(write=False)
        return ids

    def surface_points(self) -> np.ndarray:
        """(k, 3) float64: the positions of :attr:`surface_vertex_ids` (every
        vertex, not a copy, when no vertex is stray; every vertex of a mesh
        without faces).  Sizes and units are measured on these: one stray point a
        metre away must not make a head a metre wide."""
        ids = self.surface_vertex_ids
        if len(ids) in (0, self.n_vertices):
            return self.vertices
        return self.vertices[ids]

    def bounding_box(self) -> np.ndarray:
        """(2, 3) float64: min and max corner of the :meth:`surface_points`."""
        # (imported here: a command's help reads meshes' docs, not the geometry)
        from facewrap.geometry.arrays import column_bounds
        return column_bounds(self.surface_points())

    def scale(self) -> float:
        """Length of the bounding-box diagonal of the :meth:`surface_points` (a
        size for tolerances)."""
        lo, hi = self.bounding_box()
        return float(np.linalg.norm(hi - lo))

    # -- new meshes --------------------------------------------------------------------
    def corner_attributes(self) -> dict:
        """The per-corner UVs and normals as :class:`Mesh` keyword arguments
        (``uvs``, ``face_uvs``, ``normals``, ``face_normals``; those it has), for
        building a mesh of the same faces with other vertices or materials.

        >>> m = Mesh(np.eye(3), [[0, 1, 2]], uvs=np.zeros((3, 2)), face_uvs=[[0, 1, 2]])
        >>> sorted(m.corner_attributes())
        ['face_uvs', 'uvs']
        """
        out = {}
        if self.face_uvs is not None:
            out.update(uvs=self.uvs, face_uvs=(self.face_offsets, self.face_uvs))
        if self.face_normals is not None:
            out.update(normals=self.normals,
                       face_normals=(self.face_offsets, self.face_normals))
        return out

    def with_vertices(self, vertices, normals="drop") -> "Mesh":
        """Same topology, UVs and materials, new vertex positions.

        Parameters
        ----------
        vertices : (n, 3) float array_like
            New positions, same count and order.
        normals : {"drop", "keep"}
            Stored normals belong to the old shape, so they are dropped by default.
        """
        vertices = np.asarray(vertices, dtype=np.float64)
        if vertices.shape != self.vertices.shape:
            raise ValueError(f"vertices must have shape {self.vertices.shape}, "
                             f"got {vertices.shape}")
        new = object.__new__(Mesh)
        new.__dict__.update({k: v for k, v in self.__dict__.items()})
        new.vertices = _readonly(vertices, np.float64)
        if normals == "drop":
            new.normals, new.face_normals = None, None
        return new

    def submesh(self, faces) -> tuple["Mesh", np.ndarray]:
        """Mesh made of a subset of polygons, unused vertices removed.

        Parameters
        ----------
        faces : (k,) int or (m,) bool
            Polygons to keep, in their original order.

        Returns
        -------
        mesh : Mesh
        vertex_map : (n_sub,) int64
            Original index of each vertex of ``mesh`` (increasing, so order is kept).

        Raises
        ------
        ValueError
            Naming ``faces``: ids outside the mesh's polygons, a mask of another
            length.
        """
        from facewrap.geometry.checks import as_vertex_mask   # light: numpy only
        keep = as_vertex_mask(faces, self.n_faces, "faces", what="polygon")
        sizes = self.face_sizes[keep]
        corner_mask = np.repeat(keep, self.face_sizes)
        old = self.face_indices[corner_mask]
        # the used ids by a mask, not np.unique: linear, and numpy >= 2.3 hashes a
        # many-valued np.unique of integers 20x slower than a sort
        vertex_map = _used(old, self.n_vertices)
        remap = np.full(self.n_vertices, -1, dtype=np.int64)
        remap[vertex_map] = np.arange(len(vertex_map))
        offsets = np.zeros(len(sizes) + 1, dtype=np.int64)
        np.cumsum(sizes, out=offsets[1:])
        kw = {}
        if self.uvs is not None:
            uv_old = self.face_uvs[corner_mask]
            uv_map = _used(uv_old, len(self.uvs))
            uv_remap = np.full(len(self.uvs), -1, dtype=np.int64)
            uv_remap[uv_map] = np.arange(len(uv_map))
            kw.update(uvs=self.uvs[uv_map], face_uvs=(offsets, uv_remap[uv_old]))
        if self.normals is not None:
            kw.update(normals=self.normals, face_normals=(offsets, self.face_normals[corner_mask]))
        if self.face_materials is not None:
            kw.update(face_materials=self.face_materials[keep])
        if self.face_groups is not None:
            kw.update(face_groups=self.face_groups[keep])
        if self.vertex_colors is not None:
            kw.update(vertex_colors=self.vertex_colors[vertex_map])
        sub = Mesh(self.vertices[vertex_map], (offsets, remap[old]),
                   materials=self.materials, groups=self.groups, mtllib=self.mtllib,
                   texture=self.texture, **kw)
        return sub, vertex_map

    def __repr__(self) -> str:
        sizes = np.unique(self.face_sizes)
        kind = {3: "triangles", 4: "quads"}.get(int(sizes[0]), "polygons") \
            if len(sizes) == 1 else "mixed polygons"
        uv = f", {len(self.uvs)} uvs" if self.uvs is not None else ""
        return f"<Mesh {self.n_vertices} vertices, {self.n_faces} {kind}{uv}>"


def check_positions(vertices: np.ndarray, name: str) -> None:
    """Raise unless every vertex is finite and within
    :data:`~facewrap.units.COORDINATE_LIMIT`, as the file readers require.

    Parameters
    ----------
    vertices : (n, 3) float64
    name : str
        What they are: errors start ``"{name}: "``.

    Raises
    ------
    ValueError
        Naming the first vertex that is NaN, infinite or too large.

    Examples
    --------
    >>> check_positions(np.array([[0.0, 1e300, 0.0]]), "scan")
    Traceback (most recent call last):
    ...
    ValueError: scan: vertex 0 has coordinate 1e+300, too large (more than 1e+15 in \
magnitude in any unit: not a scan, and its sizes would overflow)
    """
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{name}: vertex {i} is not finite ({vertices[i].tolist()})")
    problem = too_large(vertices)   # as a file's reader refuses it
    if problem is not None:
        raise ValueError(f"{name}: {problem}")


def check_mesh(mesh, name: str) -> None:
    """Raise unless ``mesh`` is a :class:`~facewrap.mesh.Mesh` with finite vertices
    within :data:`~facewrap.units.COORDINATE_LIMIT` and at least one face.

    Parameters
    ----------
    mesh : object
    name : str
        What it is ("template", "scan"): errors start ``"{name}: "``, which a job
        turns into its file's name.

    Raises
    ------
    TypeError
        Not a Mesh.
    ValueError
        A NaN, infinite or too large coordinate, or no faces.

    Examples
    --------
    >>> check_mesh(Mesh(np.eye(3), [[0, 1, 2]]), "scan")
    >>> check_mesh(Mesh(np.eye(3), []), "scan")
    Traceback (most recent call last):
    ...
    ValueError: scan: has no faces (3 vertices)
    """
    if not isinstance(mesh, Mesh):
        raise TypeError(f"{name} must be a Mesh, got {type(mesh).__name__}")
    check_positions(mesh.vertices, name)
    if mesh.n_faces == 0:
        raise ValueError(f"{name}: has no faces ({mesh.n_vertices} vertices)")
