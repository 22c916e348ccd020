"""Per-vertex texture coordinates for a fitted template, from the scan (SPEC §1.4).

Each template vertex takes the scan's UV interpolated at its projection on the
scan, ``(u, v) = sum_k beta_k uv_{I,k}`` (:func:`scan_uvs_at`), with a cylindrical
projection (:func:`cylindrical_uvs`) for vertices that have no valid projection
(:func:`transfer_uvs`).  The template then points into the scan's own image.
"""

from __future__ import annotations

import numpy as np

from facewrap.geometry import ClosestPointTree
from facewrap.geometry.checks import as_points
from facewrap.mesh import Mesh, check_mesh

__all__ = ["checked_uv_mesh", "scan_uvs_at", "trusted_scan_uvs", "cylindrical_uvs",
           "transfer_uvs"]


def checked_uv_mesh(mesh, name: str) -> Mesh:
    """``mesh`` checked to be a :class:`~facewrap.mesh.Mesh` with faces, finite
    positions (:func:`~facewrap.mesh.check_mesh`) and finite texture coordinates.

    Raises
    ------
    ValueError
        Naming ``name``, when it is not a Mesh, its positions are not finite or too
        large, or its UVs are missing or not finite.
    """
    if not isinstance(mesh, Mesh):
        raise ValueError(f"{name} must be a facewrap Mesh, got {type(mesh).__name__}")
    # its positions too: a NaN was refused as "points" or "V" (naming neither mesh),
    # a 1e300 baked with overflow warnings
    check_mesh(mesh, name)
    if mesh.uvs is None or mesh.face_uvs is None:
        raise ValueError(f"{name} has no texture coordinates (uvs/face_uvs)")
    if not np.all(np.isfinite(mesh.uvs)):
        raise ValueError(f"{name} has NaN or infinite texture coordinates")
    return mesh


def scan_uvs_at(scan: Mesh, triangles, barycentric) -> np.ndarray:
    """The scan's texture coordinates at points given in its triangles.

    ``(u, v) = sum_k beta_k uv_{I,k}`` (SPEC §1.4), with the UVs of the corners of
    triangle ``I`` of ``scan.triangles`` taken per corner (:attr:`Mesh.triangle_uvs`),
    so points next to a UV seam take the UVs of their own side.

    Parameters
    ----------
    scan : Mesh
        With texture coordinates.
    triangles : (k,) int
        Indices into ``scan.triangles``.
    barycentric : (k, 3) float
        Coordinates of each point in its triangle.

    Returns
    -------
    (k, 2) float64
        ``(u, v)`` of each point.

    Examples
    --------
    >>> scan = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]],
    ...             uvs=[[0, 0], [1, 0], [0, 1.]], face_uvs=[[0, 1, 2]])
    >>> scan_uvs_at(scan, [0], [[0.5, 0.25, 0.25]]).tolist()
    [[0.25, 0.25]]
    """
    scan = checked_uv_mesh(scan, "scan")
    tri = np.asarray(triangles)
    if tri.ndim != 1 or not (np.issubdtype(tri.dtype, np.integer) or tri.size == 0):
        raise ValueError(f"triangles must be a 1-D int array, got shape {tri.shape} "
                         f"and dtype {tri.dtype}")
    tri = tri.astype(np.int64, copy=False)
    n_tri = len(scan.triangles)
    if tri.size and (tri.min() < 0 or tri.max() >= n_tri):
        raise ValueError(f"triangles must lie in [0, {n_tri}), got range "
                         f"[{tri.min()}, {tri.max()}]")
    bary = np.asarray(barycentric, dtype=np.float64)
    if bary.shape != (len(tri), 3):
        raise ValueError(f"barycentric must have shape ({len(tri)}, 3), got {bary.shape}")
    return trusted_scan_uvs(scan, tri, bary)


def trusted_scan_uvs(scan: Mesh, tri: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """:func:`scan_uvs_at` without input checks.

    Parameters
    ----------
    scan : Mesh
        With texture coordinates.
    tri : (k,) int64
        Indices into ``scan.triangles``, in range.
    bary : (k, 3) float64

    Returns
    -------
    (k, 2) float64
    """
    corner_uvs = scan.uvs[scan.triangle_uvs[tri]]          # (k, 3, 2)
    return np.einsum("kc,kcd->kd", bary, corner_uvs)


def cylindrical_uvs(points, axis=(0.0, 1.0, 0.0), center=None) -> np.ndarray:
    """Cylindrical texture coordinates around a vertical axis, in [0, 1].

    ``u`` is the angle around ``axis`` (through ``center``) mapped to [0, 1], with
    the front direction at ``u = 0.5`` and the seam ``u = 0 / 1`` behind.  The front
    is +z made perpendicular to ``axis`` (+y when ``axis`` is within ~25 degrees of
    z); ``u`` grows towards ``axis x front`` (+x for the default axis).  ``v`` is the height along
    ``axis``, normalised by the point set's extent (0 at the lowest point, 1 at the
    highest; 0.5 for all when the points have no height extent).  A point on the
    axis gets ``u = 0.5``.

    Parameters
    ----------
    points : (k, 3) float
    axis : (3,) float
        Direction of the cylinder axis (normalised internally).
    center : (3,) float, optional
        A point on the axis; by default the centre of the points' bounding box.

    Returns
    -------
    (k, 2) float64
        In [0, 1].

    Examples
    --------
    >>> cylindrical_uvs([[0, 0, 1], [1, 2, 0], [0, 4, -1.]], center=[0, 0, 0]
    ...                 ).round(3).tolist()
    [[0.5, 0.0], [0.75, 0.5], [1.0, 1.0]]
    """
    P = as_points(points, "points")
    a = np.asarray(axis, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)) or not np.linalg.norm(a) > 0:
        raise ValueError(f"axis must be a finite non-zero 3-vector, got {axis!r}")
    a = a / np.linalg.norm(a)
    if len(P) == 0:
        return np.zeros((0, 2))
    if center is None:
        c = 0.5 * (P.min(axis=0) + P.max(axis=0))
    else:
        c = np.asarray(center, dtype=np.float64)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise ValueError(f"center must be a finite 3-vector, got {center!r}")
    # frame: front (u = 0.5) and side (+u) directions perpendicular to the axis
    ref = np.array([0.0, 0.0, 1.0]) if abs(a[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    front = ref - (ref @ a) * a
    front /= np.linalg.norm(front)
    side = np.cross(a, front)
    d = P - c
    angle = np.arctan2(d @ side, d @ front)               # (-pi, pi], 0 in front
    u = 0.5 + angle / (2 * np.pi)
    h = d @ a
    extent = h.max() - h.min()
    v = (h - h.min()) / extent if extent > 0 else np.full(len(P), 0.5)
    return np.clip(np.stack([u, v], axis=1), 0.0, 1.0)


def transfer_uvs(scan: Mesh, points_or_closest, mask=None, *, vertices=None,
                 tree=None, axis=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Per-vertex texture coordinates for a template from the scan it was fitted to.

    Vertices with a valid projection on the scan take the scan's UV there
    (:func:`scan_uvs_at`); the others take :func:`cylindrical_uvs` of the template
    vertices (height normalised over all of them).

    Parameters
    ----------
    scan : Mesh
        With texture coordinates.
    points_or_closest : (n, 3) float, or a projection result
        Either template vertex positions, projected here on the scan by closest
        point, or the projection already made: any object with ``triangles (n,)``
        and ``barycentric (n, 3)`` in ``scan.triangles`` and ``points (n, 3)``, such
        as :class:`facewrap.geometry.ClosestPoints` or a ``RayHits`` (whose ``hit``
        is then and-ed into ``mask`` and whose ``triangles == -1`` rows count as
        unmapped).
    mask : (n,) bool, optional
        Which projections are valid; all by default.
    vertices : (n, 3) float, optional
        Template vertex positions for the cylindrical fallback when a projection
        result is given; by default its ``points`` (which must then be finite).
    tree : facewrap.geometry.ClosestPointTree, optional
        A tree already built on the scan, used when positions are given.
    axis : (3,) float
        Cylinder axis for the fallback.

    Returns
    -------
    (n, 2) float64
        ``(u, v)`` per template vertex: the scan's where valid, cylindrical elsewhere.

    Examples
    --------
    >>> scan = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]],
    ...             uvs=[[0, 0], [1, 0], [0, 1.]], face_uvs=[[0, 1, 2]])
    >>> transfer_uvs(scan, [[0.5, 0.25, 0.1], [0, 0, 9.]], mask=[True, False]
    ...              ).round(3).tolist()
    [[0.5, 0.25], [0.491, 0.0]]
    """
    scan = checked_uv_mesh(scan, "scan")
    if hasattr(points_or_closest, "triangles") and hasattr(points_or_closest,
                                                           "barycentric"):
        proj = points_or_closest
        tri = np.asarray(proj.triangles)
        if tri.ndim != 1:
            raise ValueError(f"projection triangles must be 1-D, got shape {tri.shape}")
        n = len(tri)
        valid = tri >= 0
        if hasattr(proj, "hit"):
            valid &= np.asarray(proj.hit, dtype=bool)
        P = as_points(vertices if vertices is not None else proj.points,
                    "vertices" if vertices is not None
                    else "projection points (pass vertices=)")
        bary = np.asarray(proj.barycentric, dtype=np.float64)
        if bary.shape != (n, 3):
            raise ValueError(f"projection barycentric must have shape ({n}, 3), "
                             f"got {bary.shape}")
    else:
        P = as_points(points_or_closest, "points_or_closest")
        if tree is None:
            tree = ClosestPointTree(scan.vertices, scan.triangles)
        elif tree.triangles.shape != scan.triangles.shape:
            raise ValueError("tree was not built on scan (triangle counts differ)")
        cp = tree.query(P)
        n, tri, bary = len(P), cp.triangles, cp.barycentric
        valid = np.ones(n, dtype=bool)
    if P.shape != (n, 3):
        raise ValueError(f"vertices must have shape ({n}, 3), got {P.shape}")
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != (n,) or mask.dtype != bool:
            raise ValueError(f"mask must be a bool array of shape ({n},), "
                             f"got {mask.dtype} {mask.shape}")
        valid = valid & mask
    tri = tri.astype(np.int64, copy=False)
    if np.any(tri[valid] >= len(scan.triangles)):
        raise ValueError("projection triangles out of range for scan.triangles")
    out = cylindrical_uvs(P, axis=axis)
    out[valid] = trusted_scan_uvs(scan, tri[valid], bary[valid])
    return out
