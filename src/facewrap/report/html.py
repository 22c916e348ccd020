"""One self-contained HTML page per run: numbers, pictures and a 3D viewer.

:func:`write_html_report` writes ``index.html`` into a folder.  Everything the page
needs is inside it, so it opens offline from ``file://`` and can be mailed or
archived as one file:

- pictures (PNG or JPEG, from paths or bytes) as base64 ``data:`` URIs;
- meshes as base64 little-endian ``float32`` positions and ``uint32`` triangles,
  per-vertex heatmap values as ``float32`` (NaN = no value), blendshapes as sparse
  ``(vertex ids, offsets)`` pairs, all in one JSON block; a :class:`MeshLayer` as its
  glTF has it (:func:`facewrap.io.gltf.gltf_layout`: split at UV seams, the smooth
  normals of the whole mesh, UVs, one PNG per UDIM tile or material, once per page);
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
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from facewrap.io.atomic import atomic_write
from facewrap.io.gltf import gltf_layout
from facewrap.mesh import Mesh
from facewrap.report.tables import summary_html
from facewrap.units import resolution_decimals
from facewrap.version import __version__

__all__ = ["write_html_report", "MeshLayer", "STATIC", "THREE_VERSION", "VIEW_NAMES",
           "COLOR_RANGE_PERCENTILE"]

STATIC = Path(__file__).resolve().parent / "static"
"""Folder of the vendored three.js bundle, the viewer script and the page style."""

_PALETTE = {"scan": "#b9c3cf", "result": "#d9a98c", "template": "#8fb3a0",
            # the parts that follow the skin, apart from the fitted result
            "part": "#9d8cc9", "cavity": "#c98c9b", "excluded": "#c9b86f",
            "pinned": "#6f9ec9",
            # landmarks: bright, to stand out on the meshes
            "landmarks": "#ffffff"}
_POINT_COLORS = {"template": "#2e9e5b", "scan": "#1f6fd1", "result": "#e8452c"}
_CYCLE = ["#d9a98c", "#b9c3cf", "#8fb3a0", "#b7a3cf", "#cfc08f", "#8fb0cf"]
#: Percentile of a heatmap's values at the top of its initial colour range.
COLOR_RANGE_PERCENTILE = 98

THREE_VERSION = "0.187.0"
"""Version of the vendored three.js (npm package ``three``)."""

#: Camera views the page offers (``initial_view``).
VIEW_NAMES = ("front", "three_quarter", "left", "right")

_IMAGE_TYPES = {b"\x89PNG\r\n\x1a\n": "image/png", b"\xff\xd8\xff": "image/jpeg"}


# ---------------------------------------------------------------------------------
# Inputs
# ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class MeshLayer:
    """A viewer layer drawn as the mesh's glTF (``write_gltf_morphs``) shows it.

    Attributes
    ----------
    mesh : Mesh
        The whole mesh: normals are its own, smooth across UV seams; heatmaps and
        blendshapes give one value or position per vertex of it.
    triangles : (t,) bool, optional
        Which of ``mesh.triangles`` the layer draws (default all).
    textures : as :func:`facewrap.io.gltf.write_gltf_morphs` takes them, optional
        Base-colour images per UDIM tile or ``(tile, material ids)``.
    vertices : (n,) bool, optional
        The vertices the layer stands for, counted on the page (default those of
        its triangles), e.g. the template's vertices of one role.

    Examples
    --------
    >>> import tempfile
    >>> quad = Mesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.]], [[0, 1, 2, 3]],
    ...             uvs=[[0, 0], [1, 0], [1, 1], [0, 1]], face_uvs=[[0, 1, 2, 3]])
    >>> page = write_html_report(tempfile.mkdtemp(), meshes={"result": MeshLayer(
    ...     quad, textures=np.full((4, 4, 3), 200, np.uint8))})
    >>> page.read_text().count("data:image/png;base64,")
    1
    """

    mesh: Mesh
    triangles: np.ndarray | None = None
    textures: object = None
    vertices: np.ndarray | None = None


def _layer_entry(name: str, layer: MeshLayer, k: int, images: dict,
                 layouts: dict) -> tuple[dict, np.ndarray]:
    """The JSON of a :class:`MeshLayer` and (n,) bool of the vertices it draws.

    ``images`` (PNG bytes → index into the page's textures) and ``layouts`` (one
    glTF layout per mesh and textures) are shared by the layers of one page."""
    mesh, n = layer.mesh, layer.mesh.n_vertices
    key = (id(mesh), id(layer.textures))
    if key not in layouts:
        layouts[key] = gltf_layout(mesh, layer.textures)
    lay = layouts[key]
    # written triangles are the mesh's, in its order
    pick = (np.ones(len(lay.triangles), bool) if layer.triangles is None else
            np.asarray(layer.triangles, bool))
    if pick.shape != (len(lay.triangles),):
        raise ValueError(f"meshes[{name!r}].triangles must be ({len(lay.triangles)},) "
                         "bool")
    order = np.argsort(lay.image_of[pick], kind="stable")     # one group per image
    T, image_of = lay.triangles[pick][order], lay.image_of[pick][order]
    written, inverse = np.unique(T, return_inverse=True)
    vid = lay.vertex_ids[written]
    drawn = np.bincount(vid, minlength=n) > 0
    counted = drawn if layer.vertices is None else np.asarray(layer.vertices, bool)
    if counted.shape != (n,):
        raise ValueError(f"meshes[{name!r}].vertices must be ({n},) bool")
    entry = _mesh_entry(name, layer.mesh.vertices[vid], inverse.reshape(-1, 3), k, True)
    entry.update(n_vertices=int(counted.sum()), n_original=n,
                 vertex_ids=_b64(vid, np.uint32), normals=_b64(lay.normals[written], "f4"))
    if lay.uvs is not None and lay.images:
        keys = list(lay.images)
        entry["uvs"] = _b64(lay.uvs[written], np.float32)
        cuts = np.flatnonzero(np.diff(image_of)) + 1
        entry["groups"] = [[int(a), int(b - a), images.setdefault(
            lay.images[keys[image_of[a]]], len(images)) if image_of[a] >= 0 else -1]
            for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(T)]) if b > a]
    return entry, drawn


def _triangles_of(mesh, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(V, T)`` of a :class:`~facewrap.mesh.Mesh` or a ``(V, T)`` pair, checked."""
    if hasattr(mesh, "vertices") and hasattr(mesh, "triangles"):
        V, T = mesh.vertices, mesh.triangles
    else:
        try:
            V, T = mesh
        except (TypeError, ValueError):
            raise ValueError(f"meshes[{name!r}] must be a Mesh or a (V, T) pair, "
                             f"not {type(mesh).__name__}") from None
    V = np.asarray(V, dtype=np.float64)
    T = np.asarray(T)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0:
        raise ValueError(f"meshes[{name!r}] vertices must be (n, 3) with n > 0, "
                         f"got {V.shape}")
    if not np.isfinite(V).all():
        raise ValueError(f"meshes[{name!r}] has non-finite vertex coordinates")
    if T.ndim != 2 or T.shape[1] != 3 or not np.issubdtype(T.dtype, np.integer):
        raise ValueError(f"meshes[{name!r}] triangles must be (m, 3) int, got "
                         f"{T.shape} {T.dtype}")
    if T.size and (T.min() < 0 or T.max() >= len(V)):
        raise ValueError(f"meshes[{name!r}] triangles index outside 0..{len(V) - 1}")
    return V, T


def _b64(a: np.ndarray, dtype) -> str:
    return base64.b64encode(np.ascontiguousarray(a, dtype=np.dtype(dtype).newbyteorder("<"))
                            .tobytes()).decode("ascii")


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


def _scalar_entry(name: str, spec, sizes: Mapping[str, int],
                  used: Mapping[str, np.ndarray]) -> dict:
    try:
        mesh_name, values, units = spec
    except (TypeError, ValueError):
        raise ValueError(f"scalars[{name!r}] must be (mesh name, values, units)") from None
    if mesh_name not in sizes:
        raise ValueError(f"scalars[{name!r}] names mesh {mesh_name!r}, not one of "
                         f"{sorted(sizes)}")
    v = np.asarray(values, dtype=np.float64)
    if v.shape != (sizes[mesh_name],):
        raise ValueError(f"scalars[{name!r}] must have one value per vertex of "
                         f"{mesh_name!r}: shape ({sizes[mesh_name]},), got {v.shape}")
    v = np.where(np.isfinite(v), v, np.nan)
    ok = v[~np.isnan(v)]
    if len(ok):
        stats = {"min": float(ok.min()), "mean": float(ok.mean()),
                 "p95": float(np.percentile(ok, 95)), "max": float(ok.max()),
                 "count": int(len(ok))}
        # a robust range: non-negative values (distances) from 0, signed ones from
        # the 2nd percentile, to the 98th, so a few outliers (a lip corner, a rim)
        # do not wash out the map; the page lets the reader widen it
        lo = 0.0 if stats["min"] >= 0 else float(np.percentile(ok, 2))
        hi = float(np.percentile(ok, COLOR_RANGE_PERCENTILE))
        # never narrower than ten steps of the unit's resolution: values that are
        # all rounding noise (vertices projected onto the scan) show as one colour
        hi = max(hi, lo + 10.0 ** (1 - resolution_decimals(str(units or ""))))
    else:
        stats = {"min": None, "mean": None, "p95": None, "max": None, "count": 0}
        lo, hi = 0.0, 1.0
    # drawn vertices without a value (grey); values off the drawn triangles are
    # neither drawn nor missing
    stats["missing"] = int(np.isnan(v[used[mesh_name]]).sum())
    unit = str(units or "")
    return {"name": str(name), "mesh": mesh_name, "units": unit,
            "decimals": resolution_decimals(unit), "values": _b64(v, np.float32),
            "range": [lo, hi], "stats": stats}


def _points_entries(points: Mapping, k0: int) -> list[dict]:
    """Point sets (landmarks) of the viewer, each a layer with its own toggle."""
    out = []
    for k, (name, P) in enumerate(points.items()):
        P = np.asarray(P, dtype=np.float64)
        if P.ndim != 2 or P.shape[1] != 3 or not np.isfinite(P).all():
            raise ValueError(f"points[{name!r}] must be (k, 3) finite positions, "
                             f"got {P.shape}")
        out.append({"name": str(name), "positions": _b64(P, np.float32),
                    "count": int(len(P)), "color": _color(str(name), k0 + k),
                    "visible": True})
    return out


def _label_entries(labels: Sequence, point_names: set) -> list[dict]:
    """Text labels at 3D positions, each shown with its point set."""
    out = []
    for k, item in enumerate(labels):
        try:
            layer, xyz, text = item
        except (TypeError, ValueError):
            raise ValueError(f"labels[{k}] must be (points name, (3,) position, "
                             "text)") from None
        xyz = np.asarray(xyz, dtype=np.float64).reshape(-1)
        if xyz.shape != (3,) or not np.isfinite(xyz).all():
            raise ValueError(f"labels[{k}] position must be 3 finite numbers")
        if str(layer) not in point_names:
            raise ValueError(f"labels[{k}] names points {layer!r}, not one of "
                             f"{sorted(point_names)}")
        out.append({"layer": str(layer), "position": xyz.tolist(), "text": str(text)})
    return out


def _blendshape_entry(blendshapes, meshes_out: list, positions: dict) -> dict:
    """Sparse shape offsets; adds the neutral as a layer unless it names one."""
    try:
        neutral, shapes = blendshapes
    except (TypeError, ValueError):
        raise ValueError("blendshapes must be (neutral mesh or mesh name, "
                         "dict name -> (n, 3) positions)") from None
    if isinstance(neutral, str):
        if neutral not in positions:
            raise ValueError(f"blendshapes names mesh {neutral!r}, not one of "
                             f"{sorted(positions)}")
        name, base = neutral, positions[neutral]
    else:
        name = "blendshapes"
        while name in positions:
            name += "_"
        base, T = _triangles_of(neutral, "blendshapes neutral")
        meshes_out.append(_mesh_entry(name, base, T, len(meshes_out), True))
        positions[name] = base
    out = []
    tol = 1e-7 * max(float(np.ptp(base)), 1e-12)
    for shape_name, P in dict(shapes).items():
        P = np.asarray(P, dtype=np.float64)
        if P.shape != base.shape or not np.isfinite(P).all():
            raise ValueError(f"blendshapes[{shape_name!r}] must be {base.shape} finite "
                             f"positions, got {P.shape}")
        D = P - base
        moved = np.flatnonzero(np.abs(D).max(axis=1) > tol)
        out.append({"name": str(shape_name), "indices": _b64(moved, np.uint32),
                    "deltas": _b64(D[moved], np.float32)})
    return {"mesh": name, "shapes": out}


def _mesh_entry(name, V, T, k, visible) -> dict:
    return {"name": str(name), "positions": _b64(V, np.float32),
            "indices": _b64(T, np.uint32), "n_vertices": int(len(V)),
            "n_triangles": int(len(T)), "visible": bool(visible),
            "color": _color(str(name), k)}


def _color(name: str, k: int) -> str:
    """Colour of a layer: by its first word (scan, result, template, part, ...),
    landmarks by their last (``landmarks: scan``), else cycled."""
    words = name.lower().replace("_", " ").replace(":", " ").split()
    if words and words[0] == "landmarks":
        return _POINT_COLORS.get(words[-1], _CYCLE[k % len(_CYCLE)])
    return _PALETTE.get(words[0] if words else "", _CYCLE[k % len(_CYCLE)])


def _unit(v, name) -> list:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.isfinite(a).all() or np.linalg.norm(a) == 0:
        raise ValueError(f"{name} must be a non-zero 3-vector, got {v!r}")
    return (a / np.linalg.norm(a)).tolist()


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
        f'{" checked" if p["visible"] else ""}><span class="swatch dot" style="background:'
        f'{e(p["color"])}"></span><span class="name" title="{e(p["name"])}">'
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
    points : dict of str to (k, 3) float, optional
        Point sets drawn over the meshes (landmarks), each with its own toggle;
        a name ``"landmarks: scan"`` takes the scan's landmark colour.
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
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]]); T = np.array([[0, 1, 2]])
    >>> page = write_html_report(tempfile.mkdtemp(), title="one triangle",
    ...                          summary={"fit_mean": 0.25, "vertices": 3},
    ...                          meshes={"result": (V, T)},
    ...                          scalars={"error": ("result", [0, 1, 2], "mm")})
    >>> page.name, "one triangle" in page.read_text()
    ('index.html', True)
    """
    up, front = _view_axes(view_up, view_front, initial_view)
    figures = [_image_uri(item, k) for k, item in enumerate(images)]
    data = _viewer_data(dict(meshes or {}), dict(scalars or {}), blendshapes, visible)
    data["points"] = _points_entries(dict(points or {}), len(data["meshes"]))
    data["labels"] = _label_entries(labels, {p["name"] for p in data["points"]})
    data["view"] = {"up": up, "front": front, "initial": initial_view}
    notes = [str(w) for w in warnings]
    page = _page_html(title, subtitle, summary, figures, data, notes)
    out = Path(os.fspath(folder))
    out.mkdir(parents=True, exist_ok=True)
    path = out / filename
    with atomic_write(path, "w", encoding="utf-8") as fh:
        fh.write(page)
    return path


def _view_axes(view_up, view_front, initial_view: str) -> tuple[list, list]:
    """The unit up and front vectors of the view, checked."""
    if initial_view not in VIEW_NAMES:
        raise ValueError(f"initial_view must be front, three_quarter, left or right, "
                         f"not {initial_view!r}")
    up, front = _unit(view_up, "view_up"), _unit(view_front, "view_front")
    if abs(float(np.dot(up, front))) > 0.999:
        raise ValueError("view_up and view_front must not be parallel")
    return up, front


def _viewer_data(meshes: dict, scalars: dict, blendshapes, visible) -> dict:
    """The viewer's JSON: mesh layers, heatmaps, blendshape sliders and the
    textures of the :class:`MeshLayer` s, checked."""
    mesh_entries, positions, used, images, layouts = [], {}, {}, {}, {}
    for k, (name, mesh) in enumerate(meshes.items()):
        name = str(name)
        if isinstance(mesh, MeshLayer):
            entry, used[name] = _layer_entry(name, mesh, k, images, layouts)
            mesh_entries.append(entry)
            positions[name] = mesh.mesh.vertices
            continue
        V, T = _triangles_of(mesh, name)
        mesh_entries.append(_mesh_entry(name, V, T, k, True))
        positions[name] = V
        used[name] = np.bincount(np.asarray(T, np.int64).ravel(), minlength=len(V)) > 0
    bs_entry = (_blendshape_entry(blendshapes, mesh_entries, positions)
                if blendshapes is not None else None)
    if bs_entry is not None and bs_entry["mesh"] not in used:  # the neutral's layer
        used[bs_entry["mesh"]] = np.ones(len(positions[bs_entry["mesh"]]), bool)
    sizes = {name: len(V) for name, V in positions.items()}
    scalar_entries = [_scalar_entry(str(n), s, sizes, used) for n, s in scalars.items()]
    if visible is None:
        shown = {scalar_entries[0]["mesh"]} if scalar_entries else set(sizes)
    else:
        shown = {str(v) for v in visible}
        unknown = shown - set(sizes)
        if unknown:
            raise ValueError(f"visible names unknown meshes {sorted(unknown)}; "
                             f"meshes are {sorted(sizes)}")
    for m in mesh_entries:
        m["visible"] = m["name"] in shown
    return {"meshes": mesh_entries, "scalars": scalar_entries, "blendshapes": bs_entry,
            "textures": ["data:image/png;base64," + base64.b64encode(png).decode()
                         for png in images]}


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
