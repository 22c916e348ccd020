"""Headless mesh pictures: a vectorised numpy software rasteriser.

This module owns turning a triangle mesh into an image: cameras (:data:`VIEWS`,
:func:`view_rotation`), the z-buffer (:func:`rasterize`), colour maps
(:func:`colormap`, :func:`apply_colormap`) and shading (:func:`render_mesh`).
Composing several images with text (colour bars, titles, sheets) is
:mod:`facewrap.report.figures`' job.

Why a software rasteriser: it needs nothing but numpy (no OpenGL, no display, no
GPU, no system library), so pictures render the same on a laptop, a headless
server and a CI machine with only pip wheels, byte for byte.  Every triangle's
bounding-box pixels are enumerated at once (``np.repeat`` / ``cumsum``), tested
with edge functions, and the nearest candidate per pixel is kept by one
``np.minimum.at`` on a key packing quantised depth and triangle index (ties go to
the lower triangle index, so output is deterministic).  Shading runs per pixel on
the winners only: interpolated vertex normals (Phong normals), a soft three-light
studio rig plus hemispheric ambient, in linear light; the image is rendered at
``supersample`` times the size and box-filtered down (anti-aliasing).  A
100k-triangle mesh at 800 x 800 (2x supersampled) takes about 0.5 s on one core.

Conventions: the camera is orthographic.  ``view="front"`` looks at the mesh from
+z with +y up (the built-in sample face looks toward +z); a view ``(azimuth,
elevation)`` in degrees turns the camera around +y (positive azimuth moves it
toward +x) and then raises it toward +y.  Images are ``(H, W, 3)`` or
``(H, W, 4)`` uint8 with row 0 at the top.  Triangles are two-sided: back faces
are lit with their normal flipped toward the viewer and drawn a little darker.
"""

from __future__ import annotations

import numpy as np

from facewrap.geometry.checks import as_triangles, as_vertices
from facewrap.geometry.arrays import blocks_by_budget
from facewrap.geometry.normals import trusted_face_normals, trusted_vertex_normals

__all__ = ["VIEWS", "COLORMAPS", "view_rotation", "frame_from_axes", "rasterize",
           "Raster", "colormap", "apply_colormap", "render_mesh", "fit_pixel_size",
           "mesh_arrays"]

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
# magma, coolwarm, turbo; CC0 / BSD), interpolated linearly to 256 entries.
_STOPS = {
    "viridis": "440154 48186a 472d7b 424086 3b528b 33638d 2c728e 26828e 21918c 1fa088 "
               "28ae80 3fbc73 5ec962 84d44b addc30 d8e219 fde725",
    "inferno": "000004 0b0724 210c4a 3d0965 57106e 71196e 8a226a a32c61 bc3754 d24644 "
               "e45a31 f1731d f98e09 fcac11 f9cb35 f2ea69 fcffa4",
    "magma": "000004 0a0822 1d1147 36106b 51127c 6a1c81 832681 9c2e7f b73779 d0416f "
             "e75263 f56b5c fc8961 fea772 fec488 fde2a3 fcfdbf",
    "coolwarm": "3b4cc0 4e68d8 6282ea 779af7 8db0fe a3c2fe b9d0f9 ccd9ed dddcdc ecd3c5 "
                "f5c4ac f7b093 f4987a eb7d62 dd5f4b ca3b37 b40426",
    "turbo": "30123b 4040a2 466be3 4294ff 28bceb 18ddc2 32f298 6dfe62 a4fc3c cdec34 "
             "eecf3a fdac34 fb7e21 eb500e d02f05 a91601 7a0403",
    "greys": "000000 ffffff",
}
#: Names accepted by :func:`colormap`.
COLORMAPS = tuple(_STOPS)

_CLAY = (0.78, 0.74, 0.70)           # default surface colour (sRGB, neutral clay)
_NAN_COLOR = (0.55, 0.55, 0.55)      # where scalars are NaN (e.g. not covered)
_BACKFACE_DIM = 0.75                 # back faces are drawn this much darker
_DEPTH_BITS = 31                     # quantised depth in the z-buffer key
_CHUNK = 1 << 22                     # candidate pixels processed at once
_EDGE_TOL = 2e-6                     # barycentric tolerance: shared edges leave no crack

# Light rig in camera space (x right, y up, z toward the viewer): key light from the
# upper left, fill from the right, rim light from behind above; intensities in linear
# light.  Ambient is hemispheric (sky above, ground below).  Colour-mapped pictures
# get more ambient and less key light, so colours stay close to the colour bar's.
_LIGHTS = np.array([[-0.45, 0.55, 0.70],
                    [0.65, 0.05, 0.75],
                    [0.00, 0.70, -0.70]])
_LIGHTS /= np.linalg.norm(_LIGHTS, axis=1, keepdims=True)
_RIGS = {   # powers of the three lights, sky, ground, specular
    "clay": (np.array([1.05, 0.18, 0.45]), 0.18, 0.06, 0.12),
    "colour": (np.array([0.70, 0.20, 0.30]), 0.42, 0.22, 0.06),
}


# -- inputs ----------------------------------------------------------------------------

def mesh_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    """``(V, T)`` of a :class:`~facewrap.mesh.Mesh` or of a ``(V, T)`` pair, checked.

    Parameters
    ----------
    mesh : Mesh or (V, T)
        ``V : (n, 3) float``, ``T : (t, 3) int``.  Polygons of a Mesh are taken as
        its fan triangulation (:attr:`~facewrap.mesh.Mesh.triangles`).

    Returns
    -------
    V : (n, 3) float64
    T : (t, 3) int64
    """
    if hasattr(mesh, "vertices") and hasattr(mesh, "triangles"):
        V = np.asarray(mesh.vertices, dtype=np.float64)
        if not np.all(np.isfinite(V)):
            raise ValueError("mesh vertices must be finite (found NaN or inf)")
        return V, np.asarray(mesh.triangles)
    if isinstance(mesh, (tuple, list)) and len(mesh) == 2:
        V = as_vertices(mesh[0], "mesh vertices")
        return V, as_triangles(mesh[1], len(V), "mesh triangles")
    raise ValueError(f"mesh must be a Mesh or a (V, T) pair, got {type(mesh).__name__}")


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
    w, h = _size(size)
    best = 0.0
    for P in points_list:
        P = np.asarray(P, dtype=np.float64)
        for v in views:
            Q = P @ view_rotation(v, frame)[:2].T
            ext = np.ptp(Q, axis=0) if len(Q) else np.zeros(2)
            best = max(best, ext[0] / (w * (1 - 2 * margin)),
                       ext[1] / (h * (1 - 2 * margin)))
    return best if best > 0 else 1.0


def _size(size) -> tuple[int, int]:
    try:
        w, h = (int(s) for s in size)
    except (TypeError, ValueError):
        raise ValueError(f"size must be (width, height), got {size!r}") from None
    if w < 1 or h < 1:
        raise ValueError(f"size must be positive, got {size!r}")
    return w, h


# -- z-buffer ----------------------------------------------------------------------------

class Raster:
    """Which triangle is visible at each pixel, and where in it.

    Attributes
    ----------
    triangle : (H, W) int64
        Visible triangle per pixel, -1 where no triangle covers the pixel centre.
    pixels : (p,) int64
        Flat indices (``row * W + col``) of the covered pixels, increasing.
    barycentric : (p, 3) float32
        Coordinates of each covered pixel centre in its triangle (sum to 1).
    """

    def __init__(self, triangle, pixels, barycentric):
        self.triangle = triangle
        self.pixels = pixels
        self.barycentric = barycentric

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool: covered pixels."""
        return self.triangle >= 0


def rasterize(xy, depth, T, size) -> Raster:
    """Z-buffer rasterisation of triangles given in pixel coordinates.

    Pixel ``(row, col)`` has its centre at ``x = col + 0.5``, ``y = row + 0.5``; a
    pixel belongs to a triangle when its centre lies inside it (within a tolerance of
    2e-6 in barycentric coordinates, so centres on shared edges are never lost).  The
    candidate with the smallest depth wins, the lower triangle index on a tie.
    Both orientations are drawn; zero-area triangles are skipped.

    Parameters
    ----------
    xy : (n, 2) float
        Vertex positions in pixels (x to the right, y down).
    depth : (n,) float
        Smaller is nearer.
    T : (t, 3) int
    size : (width, height) int

    Returns
    -------
    Raster

    Examples
    --------
    >>> r = rasterize([[0, 0], [4, 0], [0, 4.]], [0, 0, 0], [[0, 1, 2]], (4, 4))
    >>> r.mask.astype(int).tolist()
    [[1, 1, 1, 1], [1, 1, 1, 0], [1, 1, 0, 0], [1, 0, 0, 0]]
    """
    xy = np.asarray(xy, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2 or not np.all(np.isfinite(xy)):
        raise ValueError(f"xy must be a finite (n, 2) array, got shape {xy.shape}")
    depth = np.asarray(depth, dtype=np.float64)
    if depth.shape != (len(xy),) or not np.all(np.isfinite(depth)):
        raise ValueError(f"depth must be a finite ({len(xy)},) array")
    T = as_triangles(T, len(xy))
    W, H = _size(size)
    return _rasterize(xy[:, 0] - 0.5, xy[:, 1] - 0.5, depth, T, W, H)


def _rasterize(x, y, z, T, W, H) -> Raster:
    """Rasterise with pixel centres at integer ``(x, y)`` (see :func:`rasterize`)."""
    if H * W >= 2 ** 31:
        raise ValueError(f"image of {W} x {H} pixels is too large (2**31 at most)")
    empty = np.iinfo(np.int64).max
    buf = np.full(H * W, empty, dtype=np.int64)
    found = []
    if len(T):
        X, Y = x[T], y[T]
        e1x, e1y = X[:, 1] - X[:, 0], Y[:, 1] - Y[:, 0]
        e2x, e2y = X[:, 2] - X[:, 0], Y[:, 2] - Y[:, 0]
        det = e1x * e2y - e1y * e2x
        c0 = np.clip(np.ceil(X.min(axis=1) - 1e-6), 0, W).astype(np.int64)
        c1 = np.clip(np.floor(X.max(axis=1) + 1e-6), -1, W - 1).astype(np.int64)
        r0 = np.clip(np.ceil(Y.min(axis=1) - 1e-6), 0, H).astype(np.int64)
        r1 = np.clip(np.floor(Y.max(axis=1) + 1e-6), -1, H - 1).astype(np.int64)
        width = np.maximum(c1 - c0 + 1, 0)
        counts = width * np.maximum(r1 - r0 + 1, 0)
        counts[det == 0] = 0
        span = float(np.ptp(z)) if len(z) else 0.0
        zq = (z - z.min()) * ((2.0 ** _DEPTH_BITS - 1) / span) if span > 0 \
            else np.zeros_like(z)
        Zq = zq[T]
        for sel in blocks_by_budget(counts, _CHUNK):
            found.append(_scan_chunk(sel, counts[sel], X, Y, Zq, e1x, e1y, e2x, e2y,
                                     det, c0, r0, width, W, buf))
    # the winner of each pixel is the candidate whose packed key survived
    l1 = np.zeros(H * W, dtype=np.float32)
    l2 = np.zeros(H * W, dtype=np.float32)
    for key, packed, c1_, c2_ in found:
        win = buf[key] == packed
        k = key[win]
        l1[k], l2[k] = c1_[win], c2_[win]
    pixels = np.flatnonzero(buf != empty)
    tri = buf[pixels] & np.int64(0xFFFFFFFF)
    triangle = np.full(H * W, -1, dtype=np.int64)
    triangle[pixels] = tri
    b1, b2 = l1[pixels], l2[pixels]
    bary = np.clip(np.stack([1.0 - b1 - b2, b1, b2], axis=1), 0.0, 1.0)
    bary /= bary.sum(axis=1, keepdims=True)
    return Raster(triangle.reshape(H, W), pixels, bary)


def _scan_chunk(sel, cnt, X, Y, Zq, e1x, e1y, e2x, e2y, det, c0, r0, width, W, buf):
    """Candidates of triangles ``sel``: inside test, packed depth, scatter-min.

    Returns the inside candidates' ``(pixel, packed key, l1, l2)``.
    """
    inv = 1.0 / det[sel]
    x0, y0 = X[sel, 0], Y[sel, 0]
    # barycentric l1, l2 are affine in (col, row): l = a * col + b * row + k
    a1, b1 = e2y[sel] * inv, -e2x[sel] * inv
    a2, b2 = -e1y[sel] * inv, e1x[sel] * inv
    cs, rs = c0[sel], r0[sel]
    f32 = np.float32
    base1 = (a1 * (cs - x0) + b1 * (rs - y0)).astype(f32)   # at the box corner
    base2 = (a2 * (cs - x0) + b2 * (rs - y0)).astype(f32)
    a1, b1, a2, b2 = (c.astype(f32) for c in (a1, b1, a2, b2))
    n = int(cnt.sum())                                     # <= _CHUNK: int32 is enough
    i32 = np.int32
    owner = np.repeat(np.arange(len(sel), dtype=i32), cnt)
    start = (np.cumsum(cnt) - cnt).astype(i32)
    local = np.arange(n, dtype=i32) - np.repeat(start, cnt)
    w = np.repeat(width[sel].astype(i32), cnt)
    dr = local // w
    dc = local - dr * w
    dcf, drf = dc.astype(f32), dr.astype(f32)
    l1 = base1[owner] + a1[owner] * dcf + b1[owner] * drf
    l2 = base2[owner] + a2[owner] * dcf + b2[owner] * drf
    inside = (l1 >= -_EDGE_TOL) & (l2 >= -_EDGE_TOL) & (l1 + l2 <= 1.0 + _EDGE_TOL)
    idx = np.flatnonzero(inside)
    o, l1, l2 = owner[idx], l1[idx], l2[idx]
    z = Zq[sel[o]]
    zz = z[:, 0] + l1 * (z[:, 1] - z[:, 0]) + l2 * (z[:, 2] - z[:, 0])
    zz = np.clip(zz, 0.0, 2.0 ** _DEPTH_BITS - 1)
    key = (rs[o] + dr[idx]) * W + (cs[o] + dc[idx])
    packed = (zz.astype(np.int64) << 32) | sel[o]
    np.minimum.at(buf, key, packed)
    return key, packed, l1, l2


# -- colour maps -----------------------------------------------------------------------------

def colormap(cmap="viridis", n: int = 256) -> np.ndarray:
    """A colour map as a table of sRGB colours.

    Parameters
    ----------
    cmap : str or (k, 3) float array_like
        A name of :data:`COLORMAPS` (``"viridis"``, ``"inferno"``, ``"magma"``:
        perceptually uniform, lightness increasing; ``"coolwarm"``: diverging, for
        signed values; ``"turbo"``; ``"greys"``), optionally ending in ``"_r"`` for
        the reversed map, or your own stops in [0, 1] (k >= 2).
    n : int
        Entries of the table.

    Returns
    -------
    (n, 3) float64
        sRGB colours in [0, 1], from the low end to the high end.

    Examples
    --------
    >>> np.round(colormap("greys", 3), 3).tolist()
    [[0.0, 0.0, 0.0], [0.5, 0.5, 0.5], [1.0, 1.0, 1.0]]
    """
    if isinstance(cmap, str):
        name, rev = (cmap[:-2], True) if cmap.endswith("_r") else (cmap, False)
        if name not in _STOPS:
            raise ValueError(f"cmap must be one of {list(COLORMAPS)} (optionally with "
                             f"'_r') or a (k, 3) array, got {cmap!r}")
        stops = np.array([[int(h[i:i + 2], 16) for i in (0, 2, 4)]
                          for h in _STOPS[name].split()]) / 255.0
        if rev:
            stops = stops[::-1]
    else:
        stops = np.asarray(cmap, dtype=np.float64)
        if (stops.ndim != 2 or stops.shape[1] != 3 or len(stops) < 2
                or not np.all((stops >= 0) & (stops <= 1))):
            raise ValueError("a custom cmap must be a (k, 3) array of colours in [0, 1], "
                             "k >= 2")
    s = np.linspace(0.0, 1.0, len(stops))
    t = np.linspace(0.0, 1.0, int(n))
    return np.stack([np.interp(t, s, stops[:, c]) for c in range(3)], axis=1)


def _clim(values: np.ndarray, clim) -> tuple[float, float]:
    if clim is not None:
        lo, hi = (float(c) for c in clim)
        if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            raise ValueError(f"clim must be two finite numbers lo < hi, got {clim!r}")
        return lo, hi
    finite = values[np.isfinite(values)]
    if len(finite) == 0:
        return 0.0, 1.0
    lo, hi = float(finite.min()), float(finite.max())
    return (lo, hi) if hi > lo else (lo - 0.5, lo + 0.5)


def apply_colormap(values, cmap="viridis", clim=None, nan_color=_NAN_COLOR) -> np.ndarray:
    """sRGB colours of scalar values.

    Parameters
    ----------
    values : (k,) float
        NaN values get ``nan_color``.
    cmap : str or (k, 3) float
        See :func:`colormap`.
    clim : (lo, hi), optional
        Values mapped to the two ends (clipped beyond); default the finite range.
    nan_color : (3,) float

    Returns
    -------
    (k, 3) float64 in [0, 1]

    Examples
    --------
    >>> apply_colormap([0.0, 2.0, np.nan], "greys", (0, 1), nan_color=(1, 0, 0)).tolist()
    [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [1.0, 0.0, 0.0]]
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    lo, hi = _clim(v, clim)
    lut = colormap(cmap)
    out = _lookup(v, lut, lo, hi)
    out[~np.isfinite(v)] = np.asarray(nan_color, dtype=np.float64)
    return out


def _lookup(v: np.ndarray, lut: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Linear interpolation in a colour table; NaN rows come out as entry 0."""
    n = len(lut)
    s = np.nan_to_num((v - lo) / (hi - lo), nan=0.0, posinf=1.0, neginf=0.0)
    s = np.clip(s, 0.0, 1.0) * (n - 1)
    i = np.minimum(s.astype(np.int64), n - 2)
    f = (s - i)[:, None]
    return lut[i] * (1.0 - f) + lut[i + 1] * f


# -- shading ---------------------------------------------------------------------------------

def _srgb_to_linear(c):
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _linear_to_srgb(c: np.ndarray) -> np.ndarray:
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)


# linear light -> sRGB uint8 by table (faster than a power per pixel, and exact to
# within rounding: the steepest step of the curve is below 1/8 of an 8-bit level)
_LUT_SIZE = 1 << 14
_SRGB_LUT = np.clip(np.rint(_linear_to_srgb(np.linspace(0.0, 1.0, _LUT_SIZE)) * 255),
                    0, 255).astype(np.uint8)


def _linear_to_srgb8(c: np.ndarray) -> np.ndarray:
    """uint8 sRGB of linear-light values (any shape, clipped to [0, 1])."""
    i = np.rint(np.clip(c, 0.0, 1.0) * (_LUT_SIZE - 1)).astype(np.int32)
    return _SRGB_LUT[i]


def _color(c, name: str) -> np.ndarray:
    """(3,) sRGB float in [0, 1] from a name, a float triple or a uint8 triple."""
    named = {"white": (1.0, 1.0, 1.0), "black": (0.0, 0.0, 0.0),
             "clay": _CLAY, "grey": (0.5, 0.5, 0.5), "gray": (0.5, 0.5, 0.5)}
    if isinstance(c, str):
        if c in named:
            return np.array(named[c])
        if c.startswith("#") and len(c) == 7:
            return np.array([int(c[i:i + 2], 16) for i in (1, 3, 5)]) / 255.0
        raise ValueError(f"{name} must be a name in {sorted(named)}, '#rrggbb' or an "
                         f"RGB triple, got {c!r}")
    a = np.asarray(c, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be an RGB triple, got {c!r}")
    if np.issubdtype(np.asarray(c).dtype, np.integer) or a.max() > 1:
        a = a / 255.0
    return np.clip(a, 0.0, 1.0)


def _albedo(V, T, scalars, colors, cmap, clim, color, nan_color):
    """Per-vertex or per-triangle sRGB colour source and how to interpolate it.

    Returns ``(kind, data)`` with kind "uniform", "vertex_rgb", "vertex_scalar",
    "triangle_rgb"; scalars are colour-mapped per pixel (exact colours of the map,
    sharp iso-lines) rather than per vertex.
    """
    n, t = len(V), len(T)
    if scalars is not None and colors is not None:
        raise ValueError("give scalars or colors, not both")
    if scalars is not None:
        s = np.asarray(scalars, dtype=np.float64).reshape(-1)
        if len(s) == n:
            lo, hi = _clim(s, clim)
            return "vertex_scalar", (s, colormap(cmap), lo, hi, _color(nan_color,
                                                                       "nan_color"))
        if len(s) == t:
            return "triangle_rgb", apply_colormap(s, cmap, clim, _color(nan_color,
                                                                        "nan_color"))
        raise ValueError(f"scalars must have one value per vertex ({n}) or per "
                         f"triangle ({t}), got {len(s)}")
    if colors is not None:
        c = np.asarray(colors)
        scale = 255.0 if np.issubdtype(c.dtype, np.integer) else 1.0
        c = c.astype(np.float64) / scale
        if c.ndim != 2 or c.shape[1] not in (3, 4) or len(c) not in (n, t):
            raise ValueError(f"colors must have shape ({n}, 3) or ({t}, 3), got "
                             f"{c.shape}")
        c = np.clip(c[:, :3], 0.0, 1.0)
        return ("vertex_rgb" if len(c) == n else "triangle_rgb"), c
    return "uniform", _color(color, "color")


def render_mesh(mesh, *, scalars=None, cmap="viridis", clim=None, colors=None,
                color="clay", view="front", size=(640, 640), background="white",
                pixel_size=None, center=None, frame=None, smooth=True,
                supersample: int = 2, nan_color=_NAN_COLOR) -> np.ndarray:
    """Shaded picture of a mesh, optionally coloured by a scalar field.

    Parameters
    ----------
    mesh : Mesh or (V, T)
        A :class:`~facewrap.mesh.Mesh` (its triangulation is drawn, so quads work)
        or arrays ``V : (n, 3) float``, ``T : (t, 3) int``.
    scalars : (n,) or (t,) float, optional
        A value per vertex (interpolated across triangles) or per triangle (flat),
        coloured through ``cmap``; NaN values are drawn in ``nan_color``.
    cmap : str or (k, 3) float
        See :func:`colormap`.
    clim : (lo, hi), optional
        Scalar range of the colour map (values beyond are clipped); default the
        finite range of ``scalars``.
    colors : (n, 3) or (t, 3) float in [0, 1] or uint8, optional
        Per-vertex or per-triangle colours instead of scalars (e.g.
        ``mesh.vertex_colors``).
    color : str or (3,) float
        Uniform surface colour when neither ``scalars`` nor ``colors`` is given
        ("clay", "white", "#rrggbb" or an RGB triple).
    view : str or (azimuth, elevation)
        A name of :data:`VIEWS` (``"front"``, ``"three_quarter"``, ``"side"``...) or
        two angles in degrees (see the module docstring).
    size : (width, height) int
        Output size in pixels.
    background : str, (3,) float, or None
        Background colour; None gives a transparent background (RGBA output).
    pixel_size : float, optional
        Model units per output pixel; default fits the mesh with a 6 % margin
        (use :func:`fit_pixel_size` to give several pictures one scale).
    center : (3,) float, optional
        Model point at the image centre; default the centre of the mesh's
        projected bounding box.
    frame : (3, 3) float, optional
        Rotation taking the model into the frame where views are defined (front
        from +z, +y up), for meshes stored in another orientation.
    smooth : bool
        Interpolate vertex normals (smooth shading) rather than flat triangles.
    supersample : int
        Render at this many times the size and average down (anti-aliasing);
        1 turns anti-aliasing off.
    nan_color : str or (3,) float

    Returns
    -------
    image : (height, width, 3) uint8, or (height, width, 4) when ``background`` is
        None.  Row 0 is the top of the picture.

    Examples
    --------
    >>> V = np.array([[-1, -1, 0], [1, -1, 0], [0, 1, 0.]])
    >>> img = render_mesh((V, [[0, 1, 2]]), size=(32, 24))
    >>> img.shape, img.dtype.name, img[0, 0].tolist()   # corner: white background
    ((24, 32, 3), 'uint8', [255, 255, 255])
    >>> bool(img[12, 16].max() < 255)                   # centre: the triangle
    True
    """
    V, T = mesh_arrays(mesh)
    w, h = _size(size)
    ss = int(supersample)
    if ss < 1 or ss != supersample:
        raise ValueError(f"supersample must be an int >= 1, got {supersample!r}")
    kind, source = _albedo(V, T, scalars, colors, cmap, clim, color, nan_color)
    bg = None if background is None else _color(background, "background")

    R = view_rotation(view, frame)
    C = V @ R.T                                            # camera coordinates
    if pixel_size is None:
        pixel_size = fit_pixel_size(V, [view], (w, h), frame=frame)
    pixel_size = float(pixel_size)
    if not (np.isfinite(pixel_size) and pixel_size > 0):
        raise ValueError(f"pixel_size must be a positive number, got {pixel_size!r}")
    if center is None:
        c2 = (C[:, :2].min(axis=0) + C[:, :2].max(axis=0)) / 2 if len(C) else np.zeros(2)
    else:
        c2 = (R @ np.asarray(center, dtype=np.float64).reshape(3))[:2]
    W, H = w * ss, h * ss
    scale = ss / pixel_size
    x = (C[:, 0] - c2[0]) * scale + W / 2 - 0.5
    y = H / 2 - (C[:, 1] - c2[1]) * scale - 0.5
    raster = _rasterize(x, y, -C[:, 2], T, W, H)

    premult = np.zeros((H * W, 3), dtype=np.float32)
    if len(raster.pixels):
        rgb = _shade(raster, C, T, R, V, kind, source, smooth)
        premult[raster.pixels] = rgb
    cover = np.zeros(H * W, dtype=np.float32)
    cover[raster.pixels] = 1.0
    premult = _downsample(premult.reshape(H, W, 3), ss)
    alpha = _downsample(cover.reshape(H, W, 1), ss)
    if bg is None:
        rgb = np.divide(premult, alpha, out=np.zeros_like(premult), where=alpha > 0)
        a8 = np.clip(np.rint(alpha * 255.0), 0, 255).astype(np.uint8)
        return np.concatenate([_linear_to_srgb8(rgb), a8], axis=2)
    return _linear_to_srgb8(premult + _srgb_to_linear(bg).astype(np.float32)
                            * (1.0 - alpha))


def _downsample(img: np.ndarray, ss: int) -> np.ndarray:
    """Box-filter an (H, W, c) image by an integer factor (sum of ss * ss slices)."""
    if ss == 1:
        return img
    acc = np.zeros((img.shape[0] // ss, img.shape[1] // ss, img.shape[2]), img.dtype)
    for i in range(ss):
        for j in range(ss):
            acc += img[i::ss, j::ss]
    return acc / img.dtype.type(ss * ss)


def _shade(raster: Raster, C, T, R, V, kind, source, smooth) -> np.ndarray:
    """(p, 3) float32 linear RGB of the covered pixels.

    Works on float32 channel arrays of the covered pixels only (the hot path).
    """
    f32 = np.float32
    tri = raster.triangle.reshape(-1)[raster.pixels]
    bary = np.ascontiguousarray(raster.barycentric.T)      # (3, p) float32
    corners = np.ascontiguousarray(T[tri].T)               # (3, p)
    fn = np.take(np.ascontiguousarray(trusted_face_normals(C, T).T, dtype=f32), tri, axis=1)
    sign = np.where(fn[2] >= 0, f32(1), f32(-1))          # -1: back side seen
    if smooth:
        vn = np.ascontiguousarray((trusted_vertex_normals(V, T, "angle") @ R.T).T, dtype=f32)
        nrm = (bary[0] * np.take(vn, corners[0], axis=1)
               + bary[1] * np.take(vn, corners[1], axis=1)
               + bary[2] * np.take(vn, corners[2], axis=1))      # (3, p)
        length = np.sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2])
        # interpolated normals pointing to the other side than the face (silhouettes,
        # folds) or cancelling out fall back to the face normal
        agree = nrm[0] * fn[0] + nrm[1] * fn[1] + nrm[2] * fn[2]
        good = (length > 1e-6) & (agree > 0)
        inv = sign / np.where(good, length, f32(1))
        nrm = np.where(good, nrm * inv, fn * sign)
    else:
        nrm = fn * sign
    # hemispheric ambient + Lambert + Blinn-Phong highlights; the viewer is at +z
    powers, sky, ground, specular = _RIGS["clay" if kind == "uniform" else "colour"]
    light = f32(ground) + f32(0.5 * (sky - ground)) * (1.0 + nrm[1])
    spec = np.zeros(len(tri), dtype=f32)
    for L, power in zip(_LIGHTS, powers):
        d = f32(L[0]) * nrm[0] + f32(L[1]) * nrm[1] + f32(L[2]) * nrm[2]
        np.maximum(d, 0, out=d)
        light += f32(power) * d
        half = L + np.array([0.0, 0.0, 1.0])
        half /= np.linalg.norm(half)
        h = f32(half[0]) * nrm[0] + f32(half[1]) * nrm[1] + f32(half[2]) * nrm[2]
        h = np.where(d > 0, np.maximum(h, 0), f32(0))
        spec += f32(power) * _power16(h)
    light *= np.where(sign > 0, f32(1), f32(_BACKFACE_DIM))
    spec *= f32(specular)
    albedo = _pixel_albedo(kind, source, tri, corners, bary)   # (p, 3) linear
    return albedo * light[:, None] + spec[:, None]


def _power16(h: np.ndarray) -> np.ndarray:
    """``h ** 16`` by repeated squaring (much faster than ``**`` on float32)."""
    for _ in range(4):
        h = h * h
    return h


def _pixel_albedo(kind, source, tri, corners, bary) -> np.ndarray:
    """(p, 3) float32 linear-light albedo per covered pixel.

    Colours are converted to linear light once per table / vertex / triangle, not per
    pixel.
    """
    f32 = np.float32
    if kind == "uniform":
        return np.broadcast_to(_srgb_to_linear(source).astype(f32), (len(tri), 3))
    if kind == "triangle_rgb":
        return _srgb_to_linear(source).astype(f32)[tri]
    if kind == "vertex_rgb":
        lin = _srgb_to_linear(source).astype(f32)
        return (bary[0, :, None] * lin[corners[0]] + bary[1, :, None] * lin[corners[1]]
                + bary[2, :, None] * lin[corners[2]])
    s, lut, lo, hi, nan_rgb = source
    s = s.astype(f32)
    v = bary[0] * s[corners[0]] + bary[1] * s[corners[1]] + bary[2] * s[corners[2]]
    # 1024-entry table in linear light, indexed (no per-pixel interpolation)
    table = _srgb_to_linear(_lookup(np.linspace(0, 1, 1024), lut, 0.0, 1.0)).astype(f32)
    u = (v - f32(lo)) * f32(1023.0 / (hi - lo))
    finite = np.isfinite(u)
    i = np.clip(np.rint(np.where(finite, u, 0)), 0, 1023).astype(np.int32)
    out = table[i]
    out[~finite] = _srgb_to_linear(nan_rgb).astype(f32)
    return out
