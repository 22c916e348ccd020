"""Figures: rendered meshes composed with text, colour bars and grids.

This module owns layout: a colour bar with ticks and units (:func:`colorbar`), an
error heatmap from several views with its colour bar and title
(:func:`heatmap_figure`), several meshes from one view at one scale
(:func:`render_views`), labelled images side by side (:func:`side_by_side`), image
grids (:func:`image_grid`) and a sheet of blendshapes (:func:`blendshape_sheet`).
Rendering itself is :mod:`facewrap.report.render`'s job; text is drawn with
Pillow's built-in FreeType font (no font file, no system package).

All figures are ``(H, W, 3)`` uint8 RGB arrays; write them with
:func:`facewrap.texture.bake.save_png`.
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from facewrap.geometry.checks import mesh_arrays
from facewrap.report.cameras import fit_pixel_size, image_size, view_rotation
from facewrap.report.colors import apply_colormap, as_rgb, color_limits, colormap
from facewrap.report.render import render_mesh

__all__ = ["nice_ticks", "robust_clim", "colorbar", "render_views", "heatmap_figure",
           "side_by_side", "image_grid", "blendshape_sheet"]

_TEXT = (40, 40, 40)
_SUBTLE = (110, 110, 110)
_DEFAULT_VIEWS = ("front", "three_quarter", "side")


# -- text ----------------------------------------------------------------------------------

def _font(size: int):
    """Pillow's built-in scalable font at ``size`` px (bitmap font without FreeType)."""
    try:
        return ImageFont.load_default(size=max(int(size), 6))
    except (TypeError, OSError, ImportError, AttributeError):   # Pillow < 10.1 or no FreeType
        return ImageFont.load_default()


def _text_size(draw, text: str, font) -> tuple[int, int]:
    left, top, right, bottom = draw.textbbox((0, 0), text, font=font)
    return right - left, bottom - top


def _draw_text(draw, xy, text: str, font, fill=_TEXT, align: str = "left",
               valign: str = "top") -> None:
    """Draw ``text`` with its box's left/centre/right and top/middle edge at ``xy``."""
    left, top, right, bottom = draw.textbbox((0, 0), text, font=font)
    x, y = xy
    w, h = right - left, bottom - top
    x -= {"left": 0, "center": w / 2, "right": w}[align] + left
    y -= {"top": 0, "middle": h / 2, "bottom": h}[valign] + top
    draw.text((round(x), round(y)), text, font=font, fill=fill)


def _canvas(width: int, height: int, background):
    bg = tuple(int(round(c * 255)) for c in as_rgb(background, "background"))
    return Image.new("RGB", (int(width), int(height)), bg), bg


def _to_pil(image):
    a = np.asarray(image)
    if a.dtype != np.uint8 or a.ndim not in (2, 3):
        raise ValueError(f"images must be uint8 (H, W[, C]) arrays, got {a.dtype} "
                         f"{a.shape}")
    img = Image.fromarray(np.ascontiguousarray(a))
    return img


def _paste(canvas, image, xy, bg) -> None:
    img = _to_pil(image)
    if img.mode == "RGBA":
        canvas.paste(img.convert("RGB"), xy, img)
    else:
        canvas.paste(img.convert("RGB"), xy)


# -- scales ----------------------------------------------------------------------------------

def nice_ticks(lo: float, hi: float, count: int = 5) -> np.ndarray:
    """Round tick values (1, 2, 2.5 or 5 times a power of ten) inside ``[lo, hi]``.

    Parameters
    ----------
    lo, hi : float
        The range, ``lo < hi``.
    count : int
        About how many ticks.

    Returns
    -------
    (k,) float64

    Examples
    --------
    >>> nice_ticks(0, 1.9).tolist()
    [0.0, 0.5, 1.0, 1.5]
    >>> nice_ticks(-3, 3, count=6).tolist()
    [-3.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0]
    """
    step = _nice_step((hi - lo) / max(count, 1))
    first = math.ceil(lo / step - 1e-9)
    last = math.floor(hi / step + 1e-9)
    ticks = np.arange(first, last + 1) * step
    return np.where(np.abs(ticks) < step * 1e-9, 0.0, ticks)


def _nice_step(raw: float) -> float:
    if not raw > 0:
        return 1.0
    p = 10.0 ** math.floor(math.log10(raw))
    for m in (1.0, 2.0, 2.5, 5.0, 10.0):
        if raw <= m * p * (1 + 1e-9):
            return m * p
    return 10.0 * p


def _tick_label(v: float, step: float) -> str:
    decimals = max(0, -math.floor(math.log10(step) + 1e-9)) if step > 0 else 0
    if abs(step * 10 ** decimals - round(step * 10 ** decimals)) > 1e-6:
        decimals += 1                                      # steps of 2.5
    text = f"{v:.{decimals}f}"
    return "0" if float(text) == 0 else text.replace("-", "\u2212")


def robust_clim(values, percentile: float = 99.0) -> tuple[float, float]:
    """A colour range that ignores rare outliers and ends on a round number.

    Non-negative data get ``(0, hi)``, signed data ``(-hi, hi)``, where ``hi`` is the
    ``percentile`` of ``|values|`` rounded up to a round step.

    Parameters
    ----------
    values : array_like float
        NaN values are ignored.
    percentile : float

    Returns
    -------
    (lo, hi) : tuple of float

    Examples
    --------
    >>> robust_clim(np.linspace(0, 0.87, 100), 100)
    (0.0, 0.9)
    >>> robust_clim([-2.0, 1.0])
    (-2.0, 2.0)
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    v = v[np.isfinite(v)]
    if len(v) == 0:
        return 0.0, 1.0
    signed = v.min() < 0
    top = float(np.percentile(np.abs(v) if signed else v, percentile))
    if not top > 0:
        top = float(np.abs(v).max()) or 1.0
    step = _nice_step(top / 10)
    hi = math.ceil(top / step - 1e-9) * step
    hi = float(f"{hi:.12g}")
    return (-hi, hi) if signed else (0.0, hi)


# -- colour bar ---------------------------------------------------------------------------------

def colorbar(cmap="viridis", clim=(0.0, 1.0), *, height: int = 360, units: str = "",
             label: str = "", font_size: int = 16, bar_width: int = 18,
             extend: str = "neither", background="white") -> np.ndarray:
    """A vertical colour bar with round ticks, a label and units.

    Parameters
    ----------
    cmap : str or (k, 3) float
        See :func:`~facewrap.report.render.colormap`.
    clim : (lo, hi)
    height : int
        Height of the whole image, pixels.
    units : str
        Shown after the label in brackets (or alone), e.g. ``"mm"``.
    label : str
        What the colours mean, shown above the bar.
    font_size : int
    bar_width : int
    extend : {"neither", "max", "min", "both"}
        Draw a pointed end where values go beyond ``clim`` (as matplotlib does).
    background : colour

    Returns
    -------
    (height, w, 3) uint8
        ``w`` fits the bar, the tick labels and the title.

    Examples
    --------
    >>> img = colorbar("viridis", (0, 2), height=200, units="mm")
    >>> img.shape[0], img.dtype.name
    (200, 'uint8')
    """
    lo, hi = color_limits(np.zeros(0), clim)
    if extend not in ("neither", "max", "min", "both"):
        raise ValueError(f"extend must be 'neither', 'max', 'min' or 'both', got "
                         f"{extend!r}")
    font = _font(font_size)
    small = _font(round(font_size * 0.9))
    ticks = nice_ticks(lo, hi, count=max(2, min(6, int(height / (3.2 * font_size)))))
    step = ticks[1] - ticks[0] if len(ticks) > 1 else (hi - lo)
    labels = [_tick_label(t, step) for t in ticks]
    title = f"{label} ({units})" if label and units else (label or units)

    probe, _ = _canvas(1, 1, background)
    d = ImageDraw.Draw(probe)
    label_w = max((_text_size(d, s, small)[0] for s in labels), default=0)
    title_w, title_h = _text_size(d, title, font) if title else (0, 0)
    pad = max(4, font_size // 2)
    cap = bar_width if extend != "neither" else 0          # height of a pointed end
    top = pad + (title_h + pad if title else 0) + font_size // 2
    bottom = height - pad - font_size // 2
    bar_x = pad
    width = max(bar_x + bar_width + 6 + 4 + label_w + pad, title_w + 2 * pad)
    canvas, _ = _canvas(width, height, background)
    draw = ImageDraw.Draw(canvas)
    y0 = top + (cap if extend in ("max", "both") else 0)
    y1 = bottom - (cap if extend in ("min", "both") else 0)
    if y1 - y0 < 8:
        raise ValueError(f"height {height} is too small for a colour bar")
    # the gradient, top = hi
    rows = np.linspace(hi, lo, y1 - y0)
    strip = (apply_colormap(rows, cmap, (lo, hi)) * 255).round().astype(np.uint8)
    strip = np.repeat(strip[:, None, :], bar_width, axis=1)
    _paste(canvas, strip, (bar_x, y0), None)
    lut = colormap(cmap)
    hi_col = tuple(int(round(c * 255)) for c in lut[-1])
    lo_col = tuple(int(round(c * 255)) for c in lut[0])
    outline = (150, 150, 150)
    if extend in ("max", "both"):
        draw.polygon([(bar_x, y0), (bar_x + bar_width - 1, y0),
                      (bar_x + (bar_width - 1) / 2, y0 - cap)], fill=hi_col,
                     outline=outline)
    if extend in ("min", "both"):
        draw.polygon([(bar_x, y1 - 1), (bar_x + bar_width - 1, y1 - 1),
                      (bar_x + (bar_width - 1) / 2, y1 - 1 + cap)], fill=lo_col,
                     outline=outline)
    draw.rectangle([bar_x, y0, bar_x + bar_width - 1, y1 - 1], outline=outline)
    for t, text in zip(ticks, labels):
        y = y0 + (hi - t) / (hi - lo) * (y1 - 1 - y0)
        draw.line([(bar_x + bar_width, y), (bar_x + bar_width + 5, y)], fill=outline,
                  width=1)
        _draw_text(draw, (bar_x + bar_width + 9, y), text, small, fill=_TEXT,
                   valign="middle")
    if title:
        _draw_text(draw, (pad, pad), title, font, fill=_TEXT)
    return np.asarray(canvas)


# -- composing ------------------------------------------------------------------------------------

def render_views(meshes, views=_DEFAULT_VIEWS, *, size=(400, 480), margin=0.06,
                 frame=None, **render_kw) -> list[np.ndarray]:
    """Render meshes from views, all at one scale (so they compare).

    Parameters
    ----------
    meshes : Mesh, (V, T), or a sequence of them
        With one view, one picture per mesh; with one mesh, one per view; with
        several of both, every mesh in every view (mesh-major order).
    views : view or sequence of views
        Names of :data:`~facewrap.report.render.VIEWS` or (azimuth, elevation).
    size : (width, height) int
        Size of each picture.
    margin : float
        Blank border as a fraction of the size, for the mesh that needs most room.
    frame : (3, 3) float, optional
    **render_kw
        Passed to :func:`~facewrap.report.render.render_mesh` (``scalars``, ``cmap``,
        ``clim``, ``color``, ``background``...); ``scalars`` and ``colors`` apply to
        every mesh, so they only make sense for meshes of one topology.

    Returns
    -------
    list of (height, width, 3) uint8
    """
    if hasattr(meshes, "vertices") or (isinstance(meshes, tuple) and len(meshes) == 2
                                       and np.ndim(meshes[0]) == 2):
        meshes = [meshes]
    if isinstance(views, str) or (len(views) == 2 and not isinstance(views[0], str)):
        views = [views]
    arrays = [mesh_arrays(m) for m in meshes]
    w, h = image_size(size)
    pixel_size = fit_pixel_size([V for V, _ in arrays], views, (w, h), margin, frame)
    # one centre per view for all meshes: the middle of their joint projected box
    out = []
    for V, T in arrays:
        for v in views:
            out.append(render_mesh((V, T), view=v, size=(w, h), pixel_size=pixel_size,
                                   center=_joint_center(arrays, v, frame), frame=frame,
                                   **render_kw))
    return out


def _joint_center(arrays, view, frame) -> np.ndarray:
    R = view_rotation(view, frame)
    lo = np.min([(V @ R.T).min(axis=0) for V, _ in arrays], axis=0)
    hi = np.max([(V @ R.T).max(axis=0) for V, _ in arrays], axis=0)
    return R.T @ ((lo + hi) / 2)


def heatmap_figure(mesh, values, *, units: str = "mm", title: str | None = None,
                   label: str = "", caption: str | None = None, cmap=None, clim=None,
                   views=_DEFAULT_VIEWS, size=(400, 480), frame=None,
                   background="white", nan_color=(0.55, 0.55, 0.55)) -> np.ndarray:
    """A scalar field on a mesh from several views, with a colour bar and a title.

    Parameters
    ----------
    mesh : Mesh or (V, T)
    values : (n,) or (t,) float
        One value per vertex (or per triangle); NaN values are drawn grey (e.g.
        vertices the scan does not cover).
    units : str
        Units of ``values``, shown on the colour bar.
    title : str, optional
        Line of text above the pictures.
    label : str
        What the values are, on the colour bar (e.g. ``"distance"``).
    caption : str, optional
        Line of smaller text below the title (e.g. summary statistics).
    cmap : str or (k, 3) float, optional
        Default ``"viridis"`` for non-negative values, ``"coolwarm"`` when values
        change sign.
    clim : (lo, hi), optional
        Default :func:`robust_clim` (99th percentile, round number); values beyond
        are shown with the end colours and a pointed end on the colour bar.
    views : sequence of views
    size : (width, height) int
        Size of each view.
    frame : (3, 3) float, optional
        See :func:`~facewrap.report.render.render_mesh`.
    background : colour
    nan_color : colour

    Returns
    -------
    (H, W, 3) uint8
    """
    V, T = mesh_arrays(mesh)
    vals = np.asarray(values, dtype=np.float64).reshape(-1)
    finite = vals[np.isfinite(vals)]
    if cmap is None:
        cmap = "coolwarm" if len(finite) and finite.min() < 0 < finite.max() else "viridis"
    lo, hi = robust_clim(vals) if clim is None else color_limits(vals, clim)
    extend = {(False, False): "neither", (False, True): "max", (True, False): "min",
              (True, True): "both"}[(bool(len(finite) and finite.min() < lo),
                                     bool(len(finite) and finite.max() > hi))]
    if isinstance(views, str) or (len(views) == 2 and not isinstance(views[0], str)):
        views = [views]
    w, h = image_size(size)
    pictures = render_views((V, T), views, size=(w, h), frame=frame, scalars=vals,
                            cmap=cmap, clim=(lo, hi), background=background,
                            nan_color=nan_color)
    fs = max(12, round(h / 26))
    bar = colorbar(cmap, (lo, hi), height=round(h * 0.8), units=units, label=label,
                   font_size=fs, bar_width=max(12, fs), extend=extend,
                   background=background)
    title_font, caption_font = _font(round(fs * 1.35)), _font(fs)
    pad = fs
    probe, _ = _canvas(1, 1, background)
    d = ImageDraw.Draw(probe)
    title_h = _text_size(d, "Ag", title_font)[1] + pad // 2 if title else 0
    caption_h = _text_size(d, "Ag", caption_font)[1] + pad // 2 if caption else 0
    head = pad + title_h + caption_h
    width = len(pictures) * w + bar.shape[1] + 2 * pad
    canvas, bg = _canvas(width, head + h + pad // 2, background)
    draw = ImageDraw.Draw(canvas)
    if title:
        _draw_text(draw, (pad, pad), title, title_font, fill=_TEXT)
    if caption:
        _draw_text(draw, (pad, pad + title_h), caption, caption_font, fill=_SUBTLE)
    for i, pic in enumerate(pictures):
        _paste(canvas, pic, (i * w, head), bg)
    _paste(canvas, bar, (len(pictures) * w + pad, head + (h - bar.shape[0]) // 2), bg)
    return np.asarray(canvas)


def side_by_side(images: Sequence, labels: Sequence[str] | None = None, *,
                 gap: int = 12, font_size: int = 18, background="white") -> np.ndarray:
    """Images in a row, each with a centred label above it (before / after...).

    Parameters
    ----------
    images : sequence of (h, w, 3) or (h, w, 4) uint8
        Of any sizes; shorter ones are centred vertically.
    labels : sequence of str, optional
        One per image.
    gap : int
        Pixels between images and around the row.
    font_size : int
    background : colour

    Returns
    -------
    (H, W, 3) uint8
        The row of images with their labels on top.

    Examples
    --------
    >>> a = np.zeros((10, 20, 3), np.uint8)
    >>> side_by_side([a, a], ["before", "after"], gap=4).shape[1]
    52
    """
    images = list(images)
    if not images:
        raise ValueError("images must not be empty")
    if labels is not None and len(labels) != len(images):
        raise ValueError(f"{len(labels)} labels for {len(images)} images")
    return image_grid(images, labels, columns=len(images), gap=gap,
                      font_size=font_size, background=background, label_side="top")


def image_grid(images: Sequence, labels: Sequence[str] | None = None, *,
               columns: int = 4, gap: int = 12, font_size: int = 16,
               background="white", label_side: str = "bottom",
               title: str | None = None) -> np.ndarray:
    """Images in a grid of cells, each with an optional centred label.

    Parameters
    ----------
    images : sequence of uint8 images
        Cells are as large as the largest image; images are centred in them.
    labels : sequence of str, optional
    columns : int
    gap : int
    font_size : int
    background : colour
    label_side : {"bottom", "top"}
    title : str, optional
        A line of larger text above the grid.

    Returns
    -------
    (H, W, 3) uint8
    """
    images = [np.asarray(im) for im in images]
    if not images:
        raise ValueError("images must not be empty")
    if labels is not None and len(labels) != len(images):
        raise ValueError(f"{len(labels)} labels for {len(images)} images")
    if label_side not in ("bottom", "top"):
        raise ValueError(f"label_side must be 'bottom' or 'top', got {label_side!r}")
    columns = max(1, min(int(columns), len(images)))
    rows = -(-len(images) // columns)
    cw = max(im.shape[1] for im in images)
    ch = max(im.shape[0] for im in images)
    font = _font(font_size)
    title_font = _font(round(font_size * 1.4))
    probe, _ = _canvas(1, 1, background)
    d = ImageDraw.Draw(probe)
    lab_h = (_text_size(d, "Ag", font)[1] + gap // 2) if labels else 0
    title_h = (_text_size(d, "Ag", title_font)[1] + gap) if title else 0
    W = columns * cw + (columns + 1) * gap
    H = title_h + rows * (ch + lab_h) + (rows + 1) * gap
    canvas, bg = _canvas(W, H, background)
    draw = ImageDraw.Draw(canvas)
    if title:
        _draw_text(draw, (gap, gap), title, title_font, fill=_TEXT)
    for k, im in enumerate(images):
        r, c = divmod(k, columns)
        x = gap + c * (cw + gap)
        y = title_h + gap + r * (ch + lab_h + gap)
        iy = y + (lab_h if label_side == "top" else 0)
        _paste(canvas, im, (x + (cw - im.shape[1]) // 2, iy + (ch - im.shape[0]) // 2), bg)
        if labels:
            ly = y if label_side == "top" else y + ch + gap // 4
            _draw_text(draw, (x + cw / 2, ly), str(labels[k]), font, fill=_TEXT,
                       align="center")
    return np.asarray(canvas)


def blendshape_sheet(neutral, shapes: Mapping[str, np.ndarray], *, columns: int = 4,
                     view="three_quarter", cell_size=(260, 300), offsets: bool = False,
                     include_neutral: bool = True, color_by_offset: bool = False,
                     units: str = "mm", cmap="viridis", title: str | None = None,
                     frame=None, background="white") -> np.ndarray:
    """A labelled grid of blendshapes, all from one view at one scale.

    Parameters
    ----------
    neutral : Mesh or (V, T)
        The neutral face; every shape shares its topology.
    shapes : mapping of str to (n, 3) float
        Shape name to vertex positions (or to offsets from the neutral with
        ``offsets=True``), in display order.
    columns : int
    view : view
        See :func:`~facewrap.report.render.render_mesh`.
    cell_size : (width, height) int
        Size of each picture.
    offsets : bool
        ``shapes`` hold offsets from the neutral rather than positions.
    include_neutral : bool
        Show the neutral first.
    color_by_offset : bool
        Colour each shape by how far its vertices moved from the neutral (one colour
        range for all, with a colour bar in ``units``), showing where each shape acts.
    units : str
    cmap : str or (k, 3) float
        Colour map of ``color_by_offset``.
    title : str, optional
    frame : (3, 3) float, optional
    background : colour

    Returns
    -------
    (H, W, 3) uint8
    """
    V, T = mesh_arrays(neutral)
    names = list(shapes)
    positions = []
    for name in names:
        S = np.asarray(shapes[name], dtype=np.float64)
        if S.shape != V.shape or not np.all(np.isfinite(S)):
            raise ValueError(f"shape {name!r} must be a finite {V.shape} array, got "
                             f"{S.shape}")
        positions.append(V + S if offsets else S)
    if include_neutral:
        names, positions = ["neutral"] + names, [V] + positions
    if not positions:
        raise ValueError("shapes is empty and include_neutral is False")
    w, h = image_size(cell_size)
    pixel_size = fit_pixel_size(positions, [view], (w, h), 0.05, frame)
    arrays = [(P, T) for P in positions]
    center = _joint_center(arrays, view, frame)
    moved = [np.linalg.norm(P - V, axis=1) for P in positions]
    clim = robust_clim(np.concatenate(moved), 99.5) if color_by_offset else None
    cells = []
    for P, m in zip(positions, moved):
        kw = dict(scalars=m, cmap=cmap, clim=clim) if color_by_offset else {}
        cells.append(render_mesh((P, T), view=view, size=(w, h), pixel_size=pixel_size,
                                 center=center, frame=frame, background=background, **kw))
    grid = image_grid(cells, names, columns=columns, font_size=max(12, round(h / 17)),
                      background=background, title=title)
    if not color_by_offset:
        return grid
    top = float(np.concatenate(moved).max())
    bar = colorbar(cmap, clim, height=min(grid.shape[0] - 20, round(1.6 * h)),
                   units=units, label="offset", font_size=max(12, round(h / 18)),
                   extend="max" if top > clim[1] else "neither", background=background)
    canvas, bg = _canvas(grid.shape[1] + bar.shape[1] + 12, grid.shape[0], background)
    _paste(canvas, grid, (0, 0), bg)
    _paste(canvas, bar, (grid.shape[1], (grid.shape[0] - bar.shape[0]) // 2), bg)
    return np.asarray(canvas)
