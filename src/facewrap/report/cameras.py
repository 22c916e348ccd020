"""Cameras of the software renderer: named views, rotations, scale, image sizes.

Conventions: the camera is orthographic.  ``view="front"`` looks at the mesh from
+z with +y up (the built-in sample face looks toward +z); a view ``(azimuth,
elevation)`` in degrees turns the camera around +y (positive azimuth moves it
toward +x) and then raises it toward +y.  Camera coordinates: x to the right of the
image, y up, z toward the viewer.
"""

from __future__ import annotations

import numpy as np

__all__ = ["VIEWS", "view_rotation", "frame_from_axes", "fit_pixel_size", "image_size",
           "camera_pixels"]

#: Named views, ``name -> (azimuth, elevation)`` in degrees.
VIEWS = {
    "front": (0.0, 0.0),
    "three_quarter": (35.0, 8.0),
    "side": (90.0, 0.0),
    "left": (90.0, 0.0),       # camera on +x: the subject's left profile
    "right": (-90.0, 0.0),
    "top": (0.0, 89.0),
    "back": (180.0, 0.0),
}

# 17 evenly spaced sRGB stops of public colour maps (matplotlib's viridis, inferno,


def _view_angles(view) -> tuple[float, float]:
    if isinstance(view, str):
        if view not in VIEWS:
            raise ValueError(f"view must be one of {sorted(VIEWS)} or (azimuth, "
                             f"elevation), got {view!r}")
        return VIEWS[view]
    try:
        az, el = (float(a) for a in view)
    except (TypeError, ValueError):
        raise ValueError(f"view must be a name or (azimuth, elevation) degrees, "
                         f"got {view!r}") from None
    if not (np.isfinite(az) and np.isfinite(el)):
        raise ValueError(f"view angles must be finite, got {view!r}")
    return az, el


def view_rotation(view="front", frame=None) -> np.ndarray:
    """Rotation from model coordinates to camera coordinates.

    Camera coordinates: x to the right of the image, y up, z toward the viewer.

    Parameters
    ----------
    view : str or (azimuth, elevation)
        A name of :data:`VIEWS` or two angles in degrees.
    frame : (3, 3) float, optional
        Rotation applied to the model first, taking it to the "face" frame in which
        the views are defined (front looks from +z, +y up).

    Returns
    -------
    R : (3, 3) float64
        ``camera = model @ R.T``.

    Examples
    --------
    >>> np.round(view_rotation("side") @ [1.0, 0, 0], 12).tolist()   # +x toward us
    [0.0, 0.0, 1.0]
    """
    az, el = np.radians(_view_angles(view))
    back = np.array([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)])
    right = np.array([np.cos(az), 0.0, -np.sin(az)])
    up = np.cross(back, right)
    R = np.stack([right, up, back])
    if frame is not None:
        F = np.asarray(frame, dtype=np.float64)
        if F.shape != (3, 3) or not np.allclose(F @ F.T, np.eye(3), atol=1e-6):
            raise ValueError("frame must be a (3, 3) rotation matrix")
        R = R @ F
    return R


def frame_from_axes(up=(0.0, 1.0, 0.0), front=(0.0, 0.0, 1.0)) -> np.ndarray:
    """The ``frame`` rotation of a model whose face looks along ``front``, ``up`` up.

    Parameters
    ----------
    up, front : (3,) float
        Directions in model coordinates; ``up`` is made orthogonal to ``front``.

    Returns
    -------
    (3, 3) float64
        Rotation taking ``front`` to +z and ``up`` to +y.

    Examples
    --------
    >>> F = frame_from_axes(up=(0, 0, 1), front=(0, -1, 0))   # z-up, looking at -y
    >>> np.round(F @ [0, -1.0, 0], 12).tolist(), np.round(F @ [0, 0, 1.0], 12).tolist()
    ([0.0, 0.0, 1.0], [0.0, 1.0, 0.0])
    """
    f = np.asarray(front, dtype=np.float64).reshape(-1)
    u = np.asarray(up, dtype=np.float64).reshape(-1)
    if f.shape != (3,) or u.shape != (3,) or not np.all(np.isfinite(np.r_[f, u])):
        raise ValueError("up and front must be finite 3-vectors")
    nf = np.linalg.norm(f)
    u = u - (u @ f) / (nf * nf) * f if nf > 0 else u
    nu = np.linalg.norm(u)
    if nf == 0 or nu < 1e-9 * max(1.0, np.linalg.norm(up)):
        raise ValueError("up and front must be non-zero and not parallel")
    z, y = f / nf, u / nu
    return np.stack([np.cross(y, z), y, z])


def fit_pixel_size(points_list, views=("front",), size=(640, 640), margin=0.06,
                   frame=None) -> float:
    """Model units per pixel that fit every point set in every view.

    Parameters
    ----------
    points_list : sequence of (k, 3) float, or one (k, 3) array
    views : sequence of views (see :func:`view_rotation`)
    size : (width, height) int
    margin : float
        Blank border on each side, as a fraction of the image size.
    frame : (3, 3) float, optional

    Returns
    -------
    float
        Give it to :func:`render_mesh` as ``pixel_size`` so that several pictures
        share one scale.
    """
    if isinstance(points_list, np.ndarray) and points_list.ndim == 2:
        points_list = [points_list]
    if isinstance(views, str) or (len(views) == 2 and not isinstance(views[0], str)
                                  and np.ndim(views[0]) == 0):
        views = [views]
    w, h = image_size(size)
    best = 0.0
    for P in points_list:
        P = np.asarray(P, dtype=np.float64)
        for v in views:
            Q = P @ view_rotation(v, frame)[:2].T
            ext = np.ptp(Q, axis=0) if len(Q) else np.zeros(2)
            best = max(best, ext[0] / (w * (1 - 2 * margin)),
                       ext[1] / (h * (1 - 2 * margin)))
    return best if best > 0 else 1.0


def camera_pixels(C, center, scale: float, size) -> tuple[np.ndarray, np.ndarray,
                                                        np.ndarray]:
    """Pixel coordinates and depth of points in camera coordinates.

    The one projection of the renderer: what :func:`~facewrap.report.render.render_mesh`
    draws and what is drawn over its pictures (landmarks) land on the same pixels.

    Parameters
    ----------
    C : (n, 3) float
        Camera coordinates (``V @ view_rotation(...).T``).
    center : (2,) float
        Camera x, y at the image centre.
    scale : float
        Pixels per model unit.
    size : (width, height) int

    Returns
    -------
    x, y : (n,) float64
        Pixels, x to the right, y down; pixel ``(row, col)`` has its centre at
        ``x = col``, ``y = row`` (as :func:`~facewrap.report.raster.trusted_rasterize`
        takes them).
    depth : (n,) float64
        Smaller is nearer.

    Examples
    --------
    >>> x, y, d = camera_pixels(np.array([[0.0, 0, 1], [1, 1, 0]]), (0, 0), 2.0, (8, 8))
    >>> x.tolist(), y.tolist(), d.tolist()
    ([3.5, 5.5], [3.5, 1.5], [-1.0, -0.0])
    """
    C = np.asarray(C, dtype=np.float64)
    w, h = size
    x = (C[:, 0] - center[0]) * scale + w / 2 - 0.5
    y = h / 2 - (C[:, 1] - center[1]) * scale - 0.5
    return x, y, -C[:, 2]


def image_size(size) -> tuple[int, int]:
    """``(width, height)`` of an image, checked.

    Parameters
    ----------
    size : (width, height) int
        Positive.

    Returns
    -------
    (int, int)

    Raises
    ------
    ValueError
        When ``size`` is not two positive integers.

    Examples
    --------
    >>> image_size((640.0, 480))
    (640, 480)
    """
    try:
        w, h = (int(s) for s in size)
    except (TypeError, ValueError):
        raise ValueError(f"size must be (width, height), got {size!r}") from None
    if w < 1 or h < 1:
        raise ValueError(f"size must be positive, got {size!r}")
    return w, h

