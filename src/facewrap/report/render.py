"""Headless mesh pictures: a vectorised numpy software rasteriser.

This module owns turning a triangle mesh into an image (:func:`render_mesh`):
shading, lights and anti-aliasing.  Cameras are :mod:`facewrap.report.cameras`'
(:data:`~facewrap.report.cameras.VIEWS`), the z-buffer
:mod:`facewrap.report.raster`'s, colour maps :mod:`facewrap.report.colors`'.
Composing several images with text (colour bars, titles, sheets) is
:mod:`facewrap.report.figures`' job.

Why a software rasteriser: it needs nothing but numpy (no OpenGL, no display, no
GPU, no system library), so pictures render the same on a laptop, a headless
server and a CI machine with only pip wheels, byte for byte.  The z-buffer
(:func:`~facewrap.report.raster.trusted_rasterize`) finds the visible triangle of
every pixel deterministically; shading runs per pixel on the winners only: interpolated vertex normals (Phong normals), a soft three-light
studio rig plus hemispheric ambient, in linear light; the image is rendered at
``supersample`` times the size and box-filtered down (anti-aliasing).  Timings
are in ``docs/benchmarks.md``.

Conventions: the camera is orthographic (views: :mod:`facewrap.report.cameras`).
Images are ``(H, W, 3)`` or ``(H, W, 4)`` uint8 with row 0 at the top.  Triangles
are two-sided: back faces are lit with their normal flipped toward the viewer and
drawn a little darker.
"""

from __future__ import annotations

import numpy as np

from facewrap.geometry.checks import mesh_arrays
from facewrap.geometry.normals import trusted_face_normals, trusted_vertex_normals
from facewrap.report.cameras import camera_pixels, fit_pixel_size, image_size, view_rotation
from facewrap.report.colors import (NAN_COLOR, apply_colormap, as_rgb, color_limits, colormap,
                                    colormap_lookup, linear_to_srgb8, srgb_to_linear)
from facewrap.report.raster import Raster, trusted_rasterize

__all__ = ["render_mesh"]

_BACKFACE_DIM = 0.75                 # back faces are drawn this much darker


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
            lo, hi = color_limits(s, clim)
            return "vertex_scalar", (s, colormap(cmap), lo, hi, as_rgb(nan_color,
                                                                       "nan_color"))
        if len(s) == t:
            return "triangle_rgb", apply_colormap(s, cmap, clim, as_rgb(nan_color,
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
    return "uniform", as_rgb(color, "color")


def render_mesh(mesh, *, scalars=None, cmap="viridis", clim=None, colors=None,
                color="clay", view="front", size=(640, 640), background="white",
                pixel_size=None, center=None, frame=None, smooth=True,
                supersample: int = 2, nan_color=NAN_COLOR) -> np.ndarray:
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
    w, h = image_size(size)
    ss = int(supersample)
    if ss < 1 or ss != supersample:
        raise ValueError(f"supersample must be an int >= 1, got {supersample!r}")
    kind, source = _albedo(V, T, scalars, colors, cmap, clim, color, nan_color)
    bg = None if background is None else as_rgb(background, "background")

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
    x, y, depth = camera_pixels(C, c2, ss / pixel_size, (W, H))
    raster = trusted_rasterize(x, y, depth, T, W, H)

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
        return np.concatenate([linear_to_srgb8(rgb), a8], axis=2)
    return linear_to_srgb8(premult + srgb_to_linear(bg).astype(np.float32)
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
        return np.broadcast_to(srgb_to_linear(source).astype(f32), (len(tri), 3))
    if kind == "triangle_rgb":
        return srgb_to_linear(source).astype(f32)[tri]
    if kind == "vertex_rgb":
        lin = srgb_to_linear(source).astype(f32)
        return (bary[0, :, None] * lin[corners[0]] + bary[1, :, None] * lin[corners[1]]
                + bary[2, :, None] * lin[corners[2]])
    s, lut, lo, hi, nan_rgb = source
    s = s.astype(f32)
    v = bary[0] * s[corners[0]] + bary[1] * s[corners[1]] + bary[2] * s[corners[2]]
    # 1024-entry table in linear light, indexed (no per-pixel interpolation)
    table = srgb_to_linear(colormap_lookup(np.linspace(0, 1, 1024), lut, 0.0, 1.0)).astype(f32)
    u = (v - f32(lo)) * f32(1023.0 / (hi - lo))
    finite = np.isfinite(u)
    i = np.clip(np.rint(np.where(finite, u, 0)), 0, 1023).astype(np.int32)
    out = table[i]
    out[~finite] = srgb_to_linear(nan_rgb).astype(f32)
    return out
