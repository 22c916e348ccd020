"""Cameras and pictures of a mesh for the face detector, with what each pixel shows.

A :class:`Camera` is orthographic: a rotation from model to camera coordinates (x to
the right of the image, y up, z toward the viewer), the model point at the image
centre, a pixel size in model units and an image size.  :func:`render_view` draws the
mesh through the report's z-buffer (:func:`facewrap.report.raster.trusted_rasterize`),
textured when an image is given and shaded otherwise, and keeps the raster, so every
pixel knows the triangle and barycentric coordinates it shows: a detected 2D point is
lifted onto the surface through it (:meth:`RenderedView.lift`).

Why not :func:`facewrap.report.render.render_mesh`: it returns the picture only, and
the detector needs the picture and the raster of one rasterisation; a detector also
needs no studio light rig, only contrast (one head light, grey levels).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facewrap.geometry import boundary_edges, connected_components
from facewrap.geometry.normals import trusted_vertex_normals
from facewrap.report.raster import Raster, trusted_rasterize
from facewrap.texture.bake import sample_image

__all__ = ["Camera", "SceneArrays", "RenderedView", "render_view", "rotation_about",
           "skin_triangles"]

_AMBIENT = 0.25          # grey level of a surface seen edge-on (shaded pictures)
_BACKGROUND = 0          # black: the detector sees the head's outline
_LIGHT = np.array([0.0, 0.42, 0.91])    # camera coordinates: in front, above
_TEXTURE_SHADING = 0.6   # how much of the shading a textured picture takes on
_EDGE_SLACK = 0.05       # barycentric slack: a point on a shared edge stays exact


def rotation_about(axis, degrees: float) -> np.ndarray:
    """Rotation matrix of ``degrees`` about ``axis`` (right-handed).

    Parameters
    ----------
    axis : (3,) float
    degrees : float

    Returns
    -------
    (3, 3) float64

    Examples
    --------
    >>> np.round(rotation_about([0, 0, 1], 90) @ [1.0, 0, 0], 12).tolist()
    [0.0, 1.0, 0.0]
    """
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    t = np.radians(degrees)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * (K @ K)


@dataclass(frozen=True)
class Camera:
    """An orthographic camera.

    Attributes
    ----------
    rotation : (3, 3) float64
        Model to camera coordinates: ``camera = model @ rotation.T``.
    center : (3,) float64
        Model point at the image centre.
    pixel_size : float
        Model units per pixel.
    size : (int, int)
        Image width and height in pixels.
    """
    rotation: np.ndarray
    center: np.ndarray
    pixel_size: float
    size: tuple

    @property
    def direction(self) -> np.ndarray:
        """(3,) unit vector from the subject toward the camera, in model coordinates."""
        return self.rotation[2]

    def project(self, points) -> np.ndarray:
        """(k, 2) pixel coordinates (x right, y down; pixel centres at integers) of
        (k, 3) model points."""
        C = (np.asarray(points, dtype=np.float64) - self.center) @ self.rotation.T
        w, h = self.size
        return np.column_stack([C[:, 0] / self.pixel_size + w / 2 - 0.5,
                                h / 2 - C[:, 1] / self.pixel_size - 0.5])

    def unproject(self, pixels, depth: float = 0.0) -> np.ndarray:
        """(k, 3) model points of (k, 2) pixel coordinates at camera depth ``depth``
        (model units toward the viewer from ``center``)."""
        p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        w, h = self.size
        C = np.column_stack([(p[:, 0] - w / 2 + 0.5) * self.pixel_size,
                             (h / 2 - 0.5 - p[:, 1]) * self.pixel_size,
                             np.full(len(p), float(depth))])
        return C @ self.rotation + self.center


@dataclass(frozen=True, eq=False)
class SceneArrays:
    """What a render needs of a mesh, computed once for all views.

    Attributes
    ----------
    V : (n, 3) float64
    T : (t, 3) int64
    normals : (n, 3) float64
        Vertex normals (angle-weighted).
    corner_uvs : (t, 3, 2) float64 or None
        Texture coordinates of each triangle corner (when there is a texture).
    texture : (H, W, 3) uint8 or None
    skin : (s,) int64 or None
        The triangles a detected point may be lifted onto, when not all of them:
        the skin of a template whose lashes, tear films and eyeballs are pieces of
        their own in front of it (see :func:`skin_triangles`).  They are all drawn;
        a lift looks through the others.
    """
    V: np.ndarray
    T: np.ndarray
    normals: np.ndarray
    corner_uvs: np.ndarray | None
    texture: np.ndarray | None
    skin: np.ndarray | None = None

    @classmethod
    def of(cls, V, T, triangle_uvs=None, texture=None, skin=None) -> "SceneArrays":
        """Arrays of a mesh; ``triangle_uvs`` (t, 3, 2) and ``texture`` both or
        neither; ``skin`` (s,) triangle ids or None (all)."""
        V = np.asarray(V, dtype=np.float64)
        T = np.asarray(T, dtype=np.int64)
        uvs = None if texture is None or triangle_uvs is None else \
            np.asarray(triangle_uvs, dtype=np.float64)
        return cls(V, T, trusted_vertex_normals(V, T, "angle"), uvs,
                   None if uvs is None else texture,
                   None if skin is None else np.asarray(skin, dtype=np.int64))


@dataclass(frozen=True, eq=False)
class RenderedView:
    """A picture of the mesh and the raster it came from.

    Attributes
    ----------
    camera : Camera
    gray : (H, W) uint8
        Grey levels, row 0 at the top; the background is black.
    raster : Raster
        Visible triangle (of the full mesh) and barycentric coordinates of each
        pixel, among the scene's ``skin`` triangles when it names them.
    """
    camera: Camera
    gray: np.ndarray
    raster: Raster

    def lift(self, scene: SceneArrays, pixels, reach: float = 0.0
             ) -> tuple[np.ndarray, np.ndarray]:
        """Surface points seen at (k, 2) pixel coordinates (nearest pixel centre).

        Parameters
        ----------
        scene : SceneArrays
        pixels : (k, 2) float
        reach : float
            A point on the background within this many pixels of the surface lifts
            from the nearest pixel showing it (a chin point just below a cropped
            scan's edge); 0: none.

        Returns
        -------
        points : (k, 3) float64
            NaN where the pixel shows the background or lies outside the image.
        triangle : (k,) int64
            -1 there.
        """
        pixels = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        if reach > 0:
            pixels = self._onto_surface(pixels, reach)
        p = np.rint(pixels).astype(np.int64)
        h, w = self.gray.shape
        inside = (p[:, 0] >= 0) & (p[:, 0] < w) & (p[:, 1] >= 0) & (p[:, 1] < h)
        tri = np.full(len(p), -1, dtype=np.int64)
        tri[inside] = self.raster.triangle[p[inside, 1], p[inside, 0]]
        out = np.full((len(p), 3), np.nan)
        hit = tri >= 0
        if hit.any():
            flat = p[hit, 1] * w + p[hit, 0]
            row = np.searchsorted(self.raster.pixels, flat)
            bary = self.raster.barycentric[row].astype(np.float64)
            corners = scene.V[scene.T[tri[hit]]]                       # (k, 3, 3)
            # the exact point inside the pixel's triangle when it lies there
            exact = _barycentric_2d(self.camera.project(corners.reshape(-1, 3))
                                    .reshape(-1, 3, 2), pixels[hit])
            inside = np.all(exact >= -_EDGE_SLACK, axis=1)
            bary[inside] = _clamped(exact[inside])
            out[hit] = np.einsum("kj,kjd->kd", bary, corners)
        return out, tri

    def _onto_surface(self, pixels: np.ndarray, reach: float) -> np.ndarray:
        """``pixels`` with those on the background within ``reach`` of the surface
        moved onto the nearest covered pixel centre."""
        h, w = self.gray.shape
        p = np.clip(np.rint(pixels).astype(np.int64), 0, [w - 1, h - 1])
        mask = self.raster.triangle >= 0
        off = ~mask[p[:, 1], p[:, 0]]
        if not off.any() or not mask.any():
            return pixels
        dist, rows, cols = _nearest_covered(mask)
        move = off & (dist[p[:, 1], p[:, 0]] <= reach)
        out = pixels.copy()
        out[move] = np.column_stack([cols[p[move, 1], p[move, 0]],
                                     rows[p[move, 1], p[move, 0]]])
        return out


def skin_triangles(V, T, hit=None) -> np.ndarray | None:
    """(s,) int64 ids of the triangles a lift may land on, or None for all of them.

    A scan is one surface (stray bits of it included); a production template is
    several: lashes, tear films and eye occlusion shells are open pieces of their
    own lying in front of the eyelids' skin, where the eye landmarks are.  A lift
    looks through those: through every piece that is not skin by
    :mod:`facewrap.wrapping.roles`'s rule
    (:func:`~facewrap.wrapping.roles.find_hidden_surface`, cached by content) and
    has a border.  Closed pieces (eyeballs) stay: looking through them would
    land in the socket behind.  A mesh of one piece skips all of it, and so does
    a mesh whose lifts (``hit``) all landed on its largest piece: the skin test
    costs seconds on a 200k-triangle scan with a few stray bits, which no lift
    lands on.

    Parameters
    ----------
    V : (n, 3) float64
    T : (t, 3) int64
    hit : (k,) int64, optional
        Triangles (-1: none) that lifts through every triangle landed on.

    Returns
    -------
    (s,) int64 or None

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> skin_triangles(V, [[0, 1, 2]]) is None
    True
    """
    T = np.asarray(T, dtype=np.int64)
    labels = connected_components(T, len(V))
    if len(T) == 0:
        return None
    piece = labels[T[:, 0]]
    largest = np.argmax(np.bincount(piece))          # by triangles: the face surface
    landed = piece if hit is None else piece[np.asarray(hit)[np.asarray(hit) >= 0]]
    if np.all(landed == largest):
        return None
    from facewrap.wrapping.roles import find_hidden_surface   # only multi-piece meshes

    part = find_hidden_surface(V, T).part
    bordered = np.zeros(int(labels.max()) + 1, dtype=bool)
    border = boundary_edges(T)
    if len(border):
        bordered[labels[border[:, 0]]] = True
    through = part & bordered[labels]
    skin = np.flatnonzero(~through[T].any(axis=1))
    return None if len(skin) in (0, len(T)) else skin


def _nearest_covered(mask: np.ndarray):
    """(distance, rows, cols) of the nearest covered pixel to every pixel."""
    from scipy.ndimage import distance_transform_edt

    dist, (rows, cols) = distance_transform_edt(~mask, return_indices=True)
    return dist, rows, cols


def _interpolated(values, corners, bary) -> np.ndarray:
    """(p, d) float32: ``values`` at the (p, 3) ``corners`` (or, for per-corner
    (p, 3, d) values, corners (3,)) weighted by (p, 3) barycentric coordinates."""
    if values.ndim == 3:
        picks = [values[:, j].astype(np.float32) for j in range(3)]
    else:
        picks = [values[corners[:, j]].astype(np.float32) for j in range(3)]
    return (bary[:, 0:1] * picks[0] + bary[:, 1:2] * picks[1] + bary[:, 2:3] * picks[2])


def _barycentric_2d(corners: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(k, 3) barycentric coordinates of (k, 2) points in (k, 3, 2) triangles (NaN
    for degenerate ones)."""
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    d = points - corners[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        b1 = (d[:, 0] * e2[:, 1] - d[:, 1] * e2[:, 0]) / det
        b2 = (e1[:, 0] * d[:, 1] - e1[:, 1] * d[:, 0]) / det
    return np.column_stack([1.0 - b1 - b2, b1, b2])


def _clamped(bary: np.ndarray) -> np.ndarray:
    b = np.clip(bary, 0.0, 1.0)
    return b / b.sum(axis=1, keepdims=True)


def render_view(scene: SceneArrays, camera: Camera) -> RenderedView:
    """Grey picture of the mesh from ``camera`` (textured or shaded), and its raster.

    Parameters
    ----------
    scene : SceneArrays
    camera : Camera

    Returns
    -------
    RenderedView

    Examples
    --------
    >>> V = np.array([[-1, -1, 0], [1, -1, 0], [0, 1, 0.]])
    >>> scene = SceneArrays.of(V, [[0, 1, 2]])
    >>> cam = Camera(np.eye(3), np.zeros(3), 0.1, (32, 32))
    >>> view = render_view(scene, cam)
    >>> int(view.gray[0, 0]), bool(view.gray[16, 16] > 200)   # background, surface
    (0, True)
    >>> point, tri = view.lift(scene, [[15.5, 15.5]])
    >>> np.round(point, 2).tolist(), tri.tolist()
    ([[0.0, 0.0, 0.0]], [0])
    """
    w, h = camera.size
    C = (scene.V - camera.center) @ camera.rotation.T
    x = C[:, 0] / camera.pixel_size + w / 2 - 0.5
    y = h / 2 - C[:, 1] / camera.pixel_size - 0.5
    raster = trusted_rasterize(x, y, -C[:, 2], scene.T, w, h)
    gray = _grey(scene, camera, raster, w, h)
    if scene.skin is not None:
        raster = _renumbered(trusted_rasterize(x, y, -C[:, 2], scene.T[scene.skin], w, h),
                             scene.skin)
    return RenderedView(camera, gray, raster)


def _renumbered(raster: Raster, triangles: np.ndarray) -> Raster:
    """A raster of a subset of the triangles, numbered as in the full mesh."""
    full = np.where(raster.triangle >= 0, triangles[np.maximum(raster.triangle, 0)], -1)
    return Raster(full, raster.pixels, raster.barycentric)


def _grey(scene: SceneArrays, camera: Camera, raster: Raster, w: int, h: int):
    """(h, w) uint8 picture of the raster: textured or shaded, black background."""
    gray = np.full(h * w, _BACKGROUND, dtype=np.float32)
    if len(raster.pixels):
        tri = raster.triangle.reshape(-1)[raster.pixels]
        bary = raster.barycentric
        # one light, from the camera's side and a little above it (as a portrait is
        # lit: shadows under the brows and the nose), both sides of a triangle lit
        corners = scene.T[tri]
        n = _interpolated(scene.normals, corners, bary)
        light = camera.rotation.T @ _LIGHT
        lit = np.abs(n @ light.astype(np.float32))
        lit /= np.maximum(np.linalg.norm(n, axis=1), 1e-12)
        shade = _AMBIENT + (1 - _AMBIENT) * lit
        if scene.texture is not None:
            uv = _interpolated(scene.corner_uvs[tri], np.arange(3), bary)
            albedo = sample_image(scene.texture, uv) @ np.array([0.299, 0.587, 0.114])
            gray[raster.pixels] = albedo * (_TEXTURE_SHADING * shade + 1 - _TEXTURE_SHADING)
        else:
            gray[raster.pixels] = 255.0 * shade
    return np.clip(np.rint(gray), 0, 255).astype(np.uint8).reshape(h, w)
