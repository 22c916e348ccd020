"""One self-contained HTML page per run: numbers, pictures and a 3D viewer.

:func:`write_html_report` writes ``index.html`` into a folder.  Everything the page
needs is inside it, so it opens offline from ``file://`` and can be mailed or
archived as one file:

- pictures (PNG or JPEG, from paths or bytes) as base64 ``data:`` URIs;
- meshes, heatmaps, point sets and blendshapes in one JSON block, packed and
  checked by :mod:`facewrap.report.viewer_data` (a :class:`MeshLayer` as its glTF
  has it; a :class:`PointSet` with its marker);
- the viewer: three.js (vendored in ``static/three-viewer.min.js``, see its
  README for version and source) and facewrap's ``static/viewer.js`` inlined as
  classic scripts, so no module loading and no network.

The viewer orbits and zooms (OrbitControls), toggles each mesh and its opacity,
colours a mesh by one of the ``scalars`` with a viridis colour bar (a robust
initial range, editable; the statistics of the values given and their unit; the
value under the pointer), draws point sets such as landmarks with labels, and
deforms a mesh with one slider per blendshape.  The run's warnings open the page.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import json
import os
from pathlib import Path
from typing import Mapping, Sequence

from facewrap.io.atomic import atomic_write
from facewrap.report.tables import summary_html
from facewrap.report.viewer_data import (COLOR_RANGE_PERCENTILE, VIEW_NAMES, MeshLayer,
                                         PointSet, viewer_data)
from facewrap.version import __version__

__all__ = ["write_html_report", "MeshLayer", "PointSet", "STATIC", "THREE_VERSION",
           "VIEW_NAMES", "COLOR_RANGE_PERCENTILE"]

STATIC = Path(__file__).resolve().parent / "static"
"""Folder of the vendored three.js bundle, the viewer script and the page style."""

THREE_VERSION = "0.187.0"
"""Version of the vendored three.js (npm package ``three``)."""


_IMAGE_TYPES = {b"\x89PNG\r\n\x1a\n": "image/png", b"\xff\xd8\xff": "image/jpeg"}


def _image_uri(item, k: int) -> tuple[str, str]:
    """``(caption, data URI)`` of one ``(caption, path or bytes)`` pair."""
    try:
        caption, src = item
    except (TypeError, ValueError):
        raise ValueError(f"images[{k}] must be a (caption, path or bytes) pair") from None
    if isinstance(src, (bytes, bytearray, memoryview)):
        data, where = bytes(src), f"images[{k}]"
    else:
        data, where = Path(os.fspath(src)).read_bytes(), os.fspath(src)
    for magic, mime in _IMAGE_TYPES.items():
        if data.startswith(magic):
            return str(caption), f"data:{mime};base64," + base64.b64encode(data).decode()
    raise ValueError(f"{where} is not a PNG or JPEG image")


# ---------------------------------------------------------------------------------
# Page
# ---------------------------------------------------------------------------------
def _static_text(name: str) -> str:
    text = (STATIC / name).read_text(encoding="utf-8")
    if "</script" in text.lower():  # would end the inline <script> early
        raise RuntimeError(f"{STATIC / name} contains '</script' and cannot be inlined")
    return text


def _json_for_script(obj) -> str:
    # inside <script type="application/json"> only "</" (and "<!--") need care
    return (json.dumps(obj, separators=(",", ":"), allow_nan=False)
            .replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026"))


def _viewer_html(data: dict) -> str:
    e = html.escape
    layers = "".join(
        f'<div class="layer"><label><input type="checkbox" data-fw-layer="{e(m["name"])}"'
        f'{" checked" if m["visible"] else ""}><span class="swatch" style="background:'
        f'{e(m["color"])}"></span><span class="name" title="{e(m["name"])}: '
        f'{m["n_vertices"]:,} vertices">{e(m["name"])}</span><span class="count" '
        f'data-fw-count="{e(m["name"])}">{m["n_vertices"]:,}</span></label>'
        f'<input type="range" min="0.1" max="1" step="0.05" value="1" '
        f'title="opacity" aria-label="{e(m["name"])} opacity" '
        f'data-fw-opacity="{e(m["name"])}"></div>' for m in data["meshes"])
    layers += "".join(
        f'<div class="layer"><label><input type="checkbox" data-fw-points="{k}"'
        f'{" checked" if p["visible"] else ""}><span class="swatch dot {e(p["marker"])}" '
        f'style="--c:{e(p["color"])}"></span><span class="name" title="{e(p["name"])}">'
        f'{e(p["name"])} ({p["count"]})</span></label></div>'
        for k, p in enumerate(data["points"]))
    heat = ""
    if data["scalars"]:
        options = "".join(f'<option value="{k}"{" selected" if k == 0 else ""}>'
                          f'{e(s["name"])} — {e(s["mesh"])}</option>'
                          for k, s in enumerate(data["scalars"]))
        heat = (f'<h3>Heatmap</h3><select id="fw-heatmap" aria-label="heatmap">'
                f'<option value="-1">none ({"textures, " if data["textures"] else ""}'
                f'plain colours)</option>{options}</select>'
                '<div id="fw-colorbar"><div id="fw-colorbar-title"></div>'
                '<div class="bar"></div><div id="fw-colorbar-ticks"></div>'
                '<div class="range-row"><label>from<input type="text" id="fw-range-lo">'
                '</label><label>to<input type="text" id="fw-range-hi"></label></div>'
                '<div id="fw-colorbar-stats"></div></div>')
    else:
        heat = ('<div id="fw-colorbar" hidden><div id="fw-colorbar-title"></div>'
                '<div id="fw-colorbar-ticks"></div><div id="fw-colorbar-stats"></div>'
                '<input type="hidden" id="fw-range-lo"><input type="hidden" '
                'id="fw-range-hi"></div>')
    shapes = ""
    if data["blendshapes"]:
        bs = data["blendshapes"]
        rows = "".join(
            f'<div class="shape"><span title="{e(s["name"])}">{e(s["name"])}</span>'
            f'<input type="range" min="0" max="1" step="0.01" value="0" '
            f'aria-label="{e(s["name"])}" data-fw-shape="{k}"><output>0.00</output></div>'
            for k, s in enumerate(bs["shapes"]))
        shapes = (f'<h3>Blendshapes on {e(bs["mesh"])}</h3>{rows}'
                  '<div style="margin-top:6px"><button id="fw-shapes-reset">'
                  'Reset weights</button></div>')
    views = "".join(f'<button data-fw-view="{v}">{t}</button>' for v, t in
                    (("front", "Front"), ("three_quarter", "¾"), ("left", "Left"),
                     ("right", "Right")))
    return (
        '<section class="card viewer"><div class="stage"><div id="fw-canvas-host"></div>'
        f'<div class="views">{views}</div>'
        '<div id="fw-labels"></div>'
        '<div id="fw-viewer-message" hidden></div><div id="fw-probe" hidden></div>'
        '<div class="hint">drag: orbit · right-drag: pan · wheel: zoom</div></div>'
        f'<aside class="panel"><h3>Layers</h3>{layers}{heat}{shapes}</aside></section>')


def write_html_report(folder, *, title: str = "facewrap report",
                      summary: Mapping | None = None,
                      images: Sequence = (),
                      meshes: Mapping | None = None,
                      scalars: Mapping | None = None,
                      blendshapes=None,
                      points: Mapping | None = None,
                      labels: Sequence = (),
                      warnings: Sequence[str] = (),
                      subtitle: str | None = None,
                      visible: Sequence[str] | None = None,
                      view_up=(0.0, 1.0, 0.0), view_front=(0.0, 0.0, 1.0),
                      initial_view: str = "front",
                      filename: str = "index.html") -> Path:
    """Write one self-contained HTML page (numbers, pictures, 3D viewer).

    Parameters
    ----------
    folder : str or os.PathLike
        Output folder, created if missing.  Only ``filename`` is written there.
    title : str
        Page title and heading.
    summary : dict, optional
        Numbers shown as tables.  Top-level scalars go in an "Overview" table; a
        nested dict becomes its own table (deeper dicts flattened as ``a › b``);
        a list of dicts (e.g. per-iteration records) becomes a wide scrolling
        table; a list of equal-length number lists (e.g. a 4×4 transform) a matrix;
        a list of strings (e.g. warnings) a bulleted list.
        Ints, floats (4 significant digits), bools, strings and None are shown.
    images : sequence of (str, path or bytes)
        Captions and pictures (PNG or JPEG files or bytes), embedded in base64.
    meshes : dict of str to Mesh, (V, T) or MeshLayer, optional
        Meshes for the viewer, in drawing order, e.g. ``"scan"``, ``"result"``,
        ``"template"``.  ``V`` is (n, 3) float, ``T`` (m, 3) int triangles; a
        :class:`~facewrap.mesh.Mesh` contributes its fan triangulation; a
        :class:`MeshLayer` is drawn as its glTF shows it (seams, smooth normals,
        textures) and counted by its ``vertices``.
    scalars : dict of str to (str, (n,) float, str), optional
        Heatmaps: ``name -> (mesh name, per-vertex values, units)``.  NaN or inf
        mark vertices without a value (drawn grey).  The first is shown at
        start; its statistics (mean, p95, max) are over the values given; the
        colour range is 0 (or the 2nd percentile for signed values) to the 98th
        percentile (:data:`COLOR_RANGE_PERCENTILE`), editable on the page.
    blendshapes : (neutral, dict of str to (n, 3) float), optional
        Sliders: ``neutral`` is the name of one of ``meshes`` or a Mesh / (V, T)
        pair (then shown as a layer named ``"blendshapes"``); each shape is the
        vertex positions at weight 1.  The viewer shows ``neutral + sum w (shape -
        neutral)``.
    points : dict of str to (k, 3) float or PointSet, optional
        Point sets drawn over the meshes (landmarks), each with its own toggle;
        a name ``"landmarks: scan"`` takes the scan's landmark colour.  A
        :class:`PointSet` says its marker (``"ball"``, ``"diamond"`` for detected
        points, ``"ring"`` for flagged ones) and colour.
    labels : sequence of (str, (3,) float, str)
        Text labels: ``(points name, position, text)``, shown with that set
        (e.g. the worst landmarks with their error).
    warnings : sequence of str
        Shown in a box at the top of the page, before anything else.
    subtitle : str, optional
        Line under the title (default: the creation time).
    visible : sequence of str, optional
        Meshes shown at start (default: the first heatmap's mesh if any, else all).
    view_up, view_front : (3,) float
        Up direction and the direction from the model toward the front camera.
    initial_view : {"front", "three_quarter", "left", "right"}
    filename : str
        Name of the page inside ``folder``.

    Returns
    -------
    Path
        The written page.

    Raises
    ------
    ValueError
        If a mesh, heatmap, blendshape or image is malformed (the message names it).

    Examples
    --------
    >>> import tempfile
    >>> import numpy as np
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]]); T = np.array([[0, 1, 2]])
    >>> page = write_html_report(tempfile.mkdtemp(), title="one triangle",
    ...                          summary={"fit_mean": 0.25, "vertices": 3},
    ...                          meshes={"result": (V, T)},
    ...                          scalars={"error": ("result", [0, 1, 2], "mm")})
    >>> page.name, "one triangle" in page.read_text()
    ('index.html', True)
    """
    figures = [_image_uri(item, k) for k, item in enumerate(images)]
    data = viewer_data(meshes, scalars, blendshapes, visible, points=points,
                       labels=labels, view_up=view_up, view_front=view_front,
                       initial_view=initial_view)
    notes = [str(w) for w in warnings]
    page = _page_html(title, subtitle, summary, figures, data, notes)
    out = Path(os.fspath(folder))
    out.mkdir(parents=True, exist_ok=True)
    path = out / filename
    with atomic_write(path, "w", encoding="utf-8") as fh:
        fh.write(page)
    return path


def _warnings_html(notes: list[str]) -> str:
    """The box of the run's warnings, first on the page (issue 16)."""
    if not notes:
        return ""
    items = "".join(f"<li>{html.escape(n)}</li>" for n in notes)
    return (f'<section class="card warnings" id="fw-warnings" role="alert"><h2>'
            f'{len(notes)} warning{"s" if len(notes) != 1 else ""}: check the inputs '
            f'before trusting the numbers</h2><ul class="notes">{items}</ul></section>')


def _body_parts(title, subtitle, summary, figures, data, created: str,
                notes: list[str]) -> list[str]:
    """Header, warnings, 3D view, tables, pictures and footer of the page."""
    e = html.escape
    parts = [f'<header class="top"><div><h1>{e(title)}</h1><div class="sub">'
             f'{e(subtitle if subtitle is not None else "created " + created)}</div></div>'
             f'<div class="brand"><b>facewrap</b> {e(__version__)}</div></header>',
             _warnings_html(notes)]
    if data["meshes"]:
        counts = " · ".join(f'{e(m["name"])} {m["n_vertices"]:,} vertices'
                            for m in data["meshes"])
        parts.append(f'<h2>3D view <span class="sub" style="font-weight:400;'
                     f'color:var(--muted);font-size:12.5px">— {counts}</span></h2>')
        parts.append(_viewer_html(data))
    if summary:
        parts.append(f'<h2>Numbers</h2><div class="tables">{summary_html(summary)}</div>')
    if figures:
        figs = "".join(f'<figure class="card"><img src="{uri}" alt="{e(cap)}">'
                       f'<figcaption>{e(cap)}</figcaption></figure>'
                       for cap, uri in figures)
        parts.append(f'<h2>Pictures</h2><div class="figures">{figs}</div>')
    parts.append(f'<footer>Made by facewrap {e(__version__)} on {e(created)}. '
                 'Self-contained page: works offline. 3D view: three.js '
                 f'{THREE_VERSION} (MIT).</footer>')
    return parts


def _page_html(title, subtitle, summary, figures, data, notes) -> str:
    """The whole page: styles, body and (with meshes) the inlined viewer scripts."""
    e = html.escape
    created = _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z").strip()
    parts = _body_parts(title, subtitle, summary, figures, data, created, notes)
    scripts = ""
    if data["meshes"]:
        scripts = (f'<script type="application/json" id="facewrap-data">'
                   f'{_json_for_script(data)}</script>\n'
                   f'<script>{_static_text("three-viewer.min.js")}</script>\n'
                   f'<script>{_static_text("viewer.js")}</script>')
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<meta name=\"generator\" content=\"facewrap {e(__version__)}\">"
            f"<title>{e(title)}</title><style>{_static_text('report.css')}</style>"
            f"</head><body><main class=\"page\">{''.join(parts)}</main>\n{scripts}"
            "</body></html>\n")
