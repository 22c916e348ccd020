"""The viewer's JSON of a report page: mesh layers, heatmaps, point sets, labels and
blendshape sliders, checked and packed.

:func:`viewer_data` turns what :func:`facewrap.report.html.write_html_report` is given
into the JSON block its viewer (``static/viewer.js``) reads: positions and
triangles as base64 little-endian ``float32`` / ``uint32``, per-vertex heatmap
values as ``float32`` (NaN = no value) with a robust initial colour range,
blendshapes as sparse ``(vertex ids, offsets)`` pairs, a :class:`MeshLayer` as its
glTF has it (:func:`facewrap.io.gltf.gltf_layout`), and point sets (landmarks)
drawn with a marker each (:class:`PointSet`: balls, diamonds for detected points,
hollow rings for the ones flagged low-confidence).  Every malformed input is a
``ValueError`` naming it.  The page's markup is :mod:`facewrap.report.html`'s.
"""

from __future__ import annotations

import base64
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from facewrap.io.gltf import gltf_layout
from facewrap.mesh import Mesh
from facewrap.units import resolution_decimals

__all__ = ["viewer_data", "view_axes", "MeshLayer", "PointSet", "MARKERS", "POINT_COLORS",
           "FLAGGED_COLOR",
           "COLOR_RANGE_PERCENTILE", "VIEW_NAMES"]

_PALETTE = {"scan": "#b9c3cf", "result": "#d9a98c", "template": "#8fb3a0",
            # the parts that follow the skin, apart from the fitted result
            "part": "#9d8cc9", "cavity": "#c98c9b", "excluded": "#c9b86f",
            "pinned": "#6f9ec9",
            # landmarks: bright, to stand out on the meshes
            "landmarks": "#ffffff"}
#: Colours of the landmark sets, by the set (``landmarks: scan``...), in the viewer
#: and the pictures.
POINT_COLORS = {"template": "#2e9e5b", "scan": "#1f6fd1", "result": "#e8452c"}
#: Colour of landmarks flagged as doubtful (low-confidence detections).
FLAGGED_COLOR = "#c2188f"
_CYCLE = ["#d9a98c", "#b9c3cf", "#8fb3a0", "#b7a3cf", "#cfc08f", "#8fb0cf"]
#: Percentile of a heatmap's values at the top of its initial colour range.
COLOR_RANGE_PERCENTILE = 98

#: Camera views the page offers (``initial_view``).
VIEW_NAMES = ("front", "three_quarter", "left", "right")


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
    >>> quad = Mesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.]], [[0, 1, 2, 3]],
    ...             uvs=[[0, 0], [1, 0], [1, 1], [0, 1]], face_uvs=[[0, 1, 2, 3]])
    >>> data = viewer_data({"result": MeshLayer(
    ...     quad, textures=np.full((4, 4, 3), 200, np.uint8))})
    >>> len(data["textures"]), data["meshes"][0]["n_vertices"]
    (1, 4)
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


#: Markers of point sets: ``"ball"`` (given landmarks), ``"diamond"`` (detected
#: ones), ``"ring"`` (hollow: points flagged as doubtful, e.g. low-confidence).
MARKERS = ("ball", "diamond", "ring")


@dataclass(frozen=True)
class PointSet:
    """A point set of the viewer with its marker and colour.

    Attributes
    ----------
    positions : (k, 3) float
    marker : {"ball", "diamond", "ring"}
        See :data:`MARKERS`.
    color : str, optional
        ``"#rrggbb"``; default by the set's name, as a plain array's.

    Examples
    --------
    >>> entry = viewer_data({}, points={"landmarks: scan (detected)": PointSet(
    ...     np.zeros((2, 3)), marker="diamond")})["points"][0]
    >>> entry["marker"], entry["count"]
    ('diamond', 2)
    """

    positions: np.ndarray
    marker: str = "ball"
    color: str | None = None


def _points_entries(points: Mapping, k0: int) -> list[dict]:
    """Point sets (landmarks) of the viewer, each a layer with its own toggle."""
    out = []
    for k, (name, item) in enumerate(points.items()):
        spec = item if isinstance(item, PointSet) else PointSet(item)
        P = np.asarray(spec.positions, dtype=np.float64)
        if P.ndim != 2 or P.shape[1] != 3 or not np.isfinite(P).all():
            raise ValueError(f"points[{name!r}] must be (k, 3) finite positions, "
                             f"got {P.shape}")
        if spec.marker not in MARKERS:
            raise ValueError(f"points[{name!r}] marker must be one of "
                             f"{', '.join(MARKERS)}, not {spec.marker!r}")
        color = spec.color or _color(str(name), k0 + k)
        if not (isinstance(color, str) and len(color) == 7 and color[0] == "#"
                and all(c in "0123456789abcdefABCDEF" for c in color[1:])):
            raise ValueError(f"points[{name!r}] color must be '#rrggbb', not {color!r}")
        out.append({"name": str(name), "positions": _b64(P, np.float32),
                    "count": int(len(P)), "color": color, "marker": spec.marker,
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
    landmarks by their second (``landmarks: scan``, ``landmarks: scan (detected)``),
    else cycled."""
    words = name.lower().replace("_", " ").replace(":", " ").split()
    if words and words[0] == "landmarks":
        return POINT_COLORS.get(words[1] if len(words) > 1 else "",
                                 _CYCLE[k % len(_CYCLE)])
    return _PALETTE.get(words[0] if words else "", _CYCLE[k % len(_CYCLE)])


def _unit(v, name) -> list:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.isfinite(a).all() or np.linalg.norm(a) == 0:
        raise ValueError(f"{name} must be a non-zero 3-vector, got {v!r}")
    return (a / np.linalg.norm(a)).tolist()


def view_axes(view_up, view_front, initial_view: str) -> tuple[list, list]:
    """The unit up and front vectors of a view, checked.

    >>> view_axes((0, 2, 0), (0, 0, 1), "front")
    ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0])
    """
    if initial_view not in VIEW_NAMES:
        raise ValueError(f"initial_view must be front, three_quarter, left or right, "
                         f"not {initial_view!r}")
    up, front = _unit(view_up, "view_up"), _unit(view_front, "view_front")
    if abs(float(np.dot(up, front))) > 0.999:
        raise ValueError("view_up and view_front must not be parallel")
    return up, front


def viewer_data(meshes: Mapping | None, scalars: Mapping | None = None, blendshapes=None,
                visible=None, *, points: Mapping | None = None, labels: Sequence = (),
                view_up=(0.0, 1.0, 0.0), view_front=(0.0, 0.0, 1.0),
                initial_view: str = "front") -> dict:
    """The viewer's JSON: mesh layers, heatmaps, blendshape sliders, the textures of
    the :class:`MeshLayer` s, point sets, labels and the view, checked.

    Parameters are :func:`facewrap.report.html.write_html_report`'s of the same names.

    Returns
    -------
    dict
        ``meshes``, ``scalars``, ``blendshapes``, ``textures`` (data URIs),
        ``points``, ``labels`` and ``view`` (unit ``up`` and ``front``, ``initial``).

    Raises
    ------
    ValueError
        Naming the malformed input.
    """
    up, front = view_axes(view_up, view_front, initial_view)
    data = _layers_data(dict(meshes or {}), dict(scalars or {}), blendshapes, visible)
    data["points"] = _points_entries(dict(points or {}), len(data["meshes"]))
    data["labels"] = _label_entries(labels, {p["name"] for p in data["points"]})
    data["view"] = {"up": up, "front": front, "initial": initial_view}
    return data


def _layers_data(meshes: dict, scalars: dict, blendshapes, visible) -> dict:
    """Mesh layers, heatmaps, blendshape sliders and the textures of the
    :class:`MeshLayer` s, checked."""
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
