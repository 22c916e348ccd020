"""Landmarks drawn over a picture of their mesh: what a detection found, at a glance.

:func:`landmark_picture` renders the mesh (:func:`~facewrap.report.render.render_mesh`)
and marks every landmark the camera sees with the same projection
(:func:`~facewrap.report.cameras.camera_pixels`): a filled diamond for a confident
point, a hollow ring for one flagged low-confidence, in the colours the report's
viewer gives them.  A landmark behind the surface (the far jaw in a turned view) is
not drawn: the z-buffer of the picture says which are seen.
"""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from facewrap.geometry.checks import mesh_arrays
from facewrap.report.cameras import camera_pixels, fit_pixel_size, image_size, view_rotation
from facewrap.report.raster import trusted_rasterize
from facewrap.report.render import render_mesh
from facewrap.report.viewer_data import FLAGGED_COLOR, POINT_COLORS

__all__ = ["landmark_picture"]

# a landmark is seen when it is at most this many pixels behind the nearest surface
# at its pixel (landmarks lie on the surface; the z-buffer is per pixel centre)
_SEEN_PIXELS = 3.0


def _seen(x, y, depth, raster_depth) -> np.ndarray:
    """(k,) bool: points inside the picture and not behind the surface."""
    h, w = raster_depth.shape
    col, row = np.rint(x).astype(np.int64), np.rint(y).astype(np.int64)
    inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    out = np.zeros(len(x), dtype=bool)
    z = raster_depth[row[inside], col[inside]]
    out[inside] = ~(depth[inside] > z + _SEEN_PIXELS)   # NaN (no surface): seen
    return out


def _depth_buffer(x, y, depth, T, w: int, h: int) -> np.ndarray:
    """(h, w) depth of the nearest surface at each pixel centre (NaN: none)."""
    raster = trusted_rasterize(x, y, depth, T, w, h)
    buf = np.full(h * w, np.nan)
    tri = raster.triangle.reshape(-1)[raster.pixels]
    buf[raster.pixels] = (raster.barycentric * depth[T[tri]]).sum(axis=1)
    return buf.reshape(h, w)


def landmark_picture(mesh, points, flagged=None, *, view="front", frame=None,
                     size=(440, 520), marker: float = 5.0) -> np.ndarray:
    """A shaded picture of ``mesh`` with its landmarks marked.

    Parameters
    ----------
    mesh : Mesh or (V, T)
    points : (k, 3) float
        Landmark positions (on or near the surface).
    flagged : (k,) bool, optional
        Points drawn as hollow rings (low-confidence); the others are diamonds.
    view : str or (azimuth, elevation)
        See :func:`~facewrap.report.cameras.view_rotation`.
    frame : (3, 3) float, optional
        Rotation into the frame where views are defined (front from +z, +y up).
    size : (width, height) int
    marker : float
        Marker radius in pixels.

    Returns
    -------
    (height, width, 3) uint8

    Examples
    --------
    >>> V = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0.]])
    >>> img = landmark_picture((V, [[0, 1, 2], [0, 2, 3]]), [[0, 0, 0], [0.5, 0.5, 0]],
    ...                        [False, True], size=(60, 60))
    >>> img.shape, tuple(img[30, 30]) == (0x1f, 0x6f, 0xd1)   # a diamond at the centre
    ((60, 60, 3), True)
    """
    V, T = mesh_arrays(mesh)
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    low = (np.zeros(len(P), bool) if flagged is None
           else np.asarray(flagged, dtype=bool).reshape(-1))
    if low.shape != (len(P),):
        raise ValueError(f"flagged must have one entry per point ({len(P)}), "
                         f"got {low.shape}")
    w, h = image_size(size)
    R = view_rotation(view, frame)
    C = V @ R.T
    pixel = fit_pixel_size(V, [view], (w, h), frame=frame)
    c2 = (C[:, :2].min(axis=0) + C[:, :2].max(axis=0)) / 2
    picture = render_mesh((V, T), view=view, size=(w, h), pixel_size=pixel,
                          center=R.T @ np.r_[c2, 0.0], frame=frame)
    depth = _depth_buffer(*camera_pixels(C, c2, 1.0 / pixel, (w, h)), T, w, h)
    x, y, d = camera_pixels(P @ R.T, c2, 1.0 / pixel, (w, h))
    seen = _seen(x, y, d / pixel, depth / pixel)
    image = Image.fromarray(np.ascontiguousarray(picture[..., :3]))
    draw = ImageDraw.Draw(image)
    r = float(marker)
    for i in np.flatnonzero(seen & ~low):
        draw.polygon([(x[i], y[i] - r), (x[i] + r, y[i]), (x[i], y[i] + r),
                      (x[i] - r, y[i])], fill=POINT_COLORS["scan"], outline="white")
    for i in np.flatnonzero(seen & low):
        draw.ellipse([x[i] - r, y[i] - r, x[i] + r, y[i] + r], outline=FLAGGED_COLOR,
                     width=2)
    return np.asarray(image)
