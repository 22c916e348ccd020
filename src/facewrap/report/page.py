"""The HTML page of a finished wrap run, built from its JSON report.

Reads the JSON report that a wrap job writes (see
:func:`facewrap.jobs.run_wrap_job`), the meshes and landmark files it names
(template, scan, output) and, when the run had them, its blendshape folder and
baked texture, and writes ``DIR/index.html`` with
:func:`facewrap.report.html.write_html_report`.  The viewer and the tables agree:
both are over the same vertices (the *fitted* ones of the report's
``vertex_roles``) and in the same unit (the report's ``units``):

- layers: the template moved by the run's similarity ("template (aligned)"), the
  scan, the fitted result, and apart from it, in their own colours, the parts that
  follow (roles part, cavity, excluded, pinned); the result and its parts drawn as
  the run's glTF shows them (split at UV seams, smooth normals, the baked image of
  each UDIM tile and material), each layer counting the template's vertices of its
  role, as the "vertex roles" table does;
- landmarks of the template (aligned), the scan and the result, the worst few
  labelled with name and error; scan landmarks the run detected (no scan landmark
  file) as diamonds, their low-confidence ones, left out of the wrap, as hollow
  rings, and a picture of the scan with them marked (front and three-quarter);
- heatmaps: result → scan distance over the fitted vertices (grey where the
  closest scan point is on the scan's border, as in the fit metrics), scan →
  result distance, and with ground truth the distance to it;
- sliders: the template's blendshape offsets, turned by the run's similarity,
  added to the result (a preview, not a deformation transfer);
- the run's warnings first; tables: metrics (distances with their unit),
  timings, settings, blend weights, iterations, the transform.

Relative paths in the report are taken from the report's folder, else from the
current folder.  A report without ``vertex_roles`` (older runs) counts the job's
``exclude`` vertices as excluded and the others as fitted.
"""

from __future__ import annotations

import logging
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from facewrap.datasets import load_shape_folder
from facewrap.detection.for_wrap import confident_landmarks
from facewrap.errors import InputError, InputWarning
from facewrap.evaluate import VERTEX_ROLE_NAMES, role_codes
from facewrap.geometry import ClosestPointTree
from facewrap.io import read_mesh
from facewrap.io.files import not_a_file, read_json
from facewrap.io.images import check_image, load_image, png_bytes
from facewrap.io.landmarks import read_landmarks, read_vertex_indices
from facewrap.io.profile import read_template_profile
from facewrap.landmarks import Landmarks, pair_landmarks
from facewrap.texture.tiles import BAKED_MATERIAL
from facewrap.report.html import MeshLayer, PointSet, write_html_report
from facewrap.report.viewer_data import FLAGGED_COLOR
from facewrap.report.cameras import frame_from_axes
from facewrap.report.figures import side_by_side
from facewrap.report.landmark_figure import landmark_picture
from facewrap.report.run_tables import landmark_source, run_summary
from facewrap.units import (COORDINATE_LIMIT, UNIT_NAMES, UNKNOWN, format_distance,
                            resolve_units, units_conflict)

__all__ = ["build_report_page", "load_run_report", "run_meshes", "run_vertex_roles",
           "WORST_LANDMARKS_LABELLED"]

log = logging.getLogger(__name__)

#: How many of the worst landmarks the viewer labels with name and error.
WORST_LANDMARKS_LABELLED = 5

_FITTED = VERTEX_ROLE_NAMES.index("fitted")
# layer names of the roles that follow (the first word picks the layer's colour)
_ROLE_LAYERS = {"part": "part (follows)", "cavity": "cavity (follows)",
                "excluded": "excluded (follows)", "pinned": "pinned (held)"}


def _existing(path, report_path: Path, key: str) -> Path:
    """A file the run names: a relative path from the report's own folder first.

    The report's folder comes first so that a file of the same name in the current
    folder (another run's ``out.obj``) is never shown instead of the run's own; the
    current folder is still tried for reports written with paths relative to it.
    """
    if not isinstance(path, str):   # a hand-edited report: Path(5) named no file
        raise InputError(f"the run's {key} must be a path (a string), got {path!r}",
                         report_path)
    p = Path(path)
    for candidate in (report_path.parent / p, p):
        if candidate.is_file():
            return candidate
    raise InputError(f"the run's {key} {str(path)!r} is missing (looked in "
                     f"{report_path.parent} and in the current folder)", report_path)


#: Sections of a run report that are JSON objects when present.
_OBJECT_SECTIONS = ("settings", "timings", "metrics", "texture", "vertex_roles",
                    "detected_landmarks", "blend_weights", "template_profile")


def load_run_report(report_path) -> dict:
    """Read a wrap run's JSON report.

    Raises
    ------
    InputError
        When the file is missing, not JSON, has no ``job`` with template, scan
        and output paths, or a section the page reads as an object is not one.
    """
    report_path = Path(report_path)
    if not report_path.exists():
        raise InputError("no such file", report_path)
    try:
        run = read_json(report_path)
    except InputError as exc:
        raise InputError(f"not a JSON report ({exc.problem})", report_path,
                         exc.line) from None
    job = run.get("job") if isinstance(run, dict) else None
    if isinstance(job, dict) and "expression_scans" in job and "blendshapes" in job:
        # its output is a folder: the wrap's page would look for a mesh there
        raise InputError("a rig's report, not a wrap run's: its page is rig.html beside "
                         "it ('facewrap rig' writes it)", report_path)
    if not isinstance(job, dict) or not all(k in job for k in ("template", "scan",
                                                               "output")):
        raise InputError("not a facewrap wrap report: 'job' with template, scan and "
                         "output paths expected", report_path)
    for key in _OBJECT_SECTIONS:   # read with .get(...) by the page's tables
        if key in run and not isinstance(run[key], dict):
            raise InputError(f"'{key}' must be an object, got "
                             f"{type(run[key]).__name__}", report_path)
    return run


def _similarity(run: dict, report_path: Path) -> np.ndarray:
    """The run's (4, 4) template → scan similarity."""
    try:
        M = np.asarray(run.get("transform", np.eye(4)), dtype=np.float64)
    except (TypeError, ValueError):   # text or ragged rows: numpy's words named no file
        M = None
    if M is None or M.shape != (4, 4):
        raise InputError("'transform' must be a 4x4 matrix of numbers, got "
                         f"{str(run.get('transform'))[:60]}", report_path)
    bad = ~(np.abs(M) <= COORDINATE_LIMIT)   # NaN too
    if bad.any():
        i, j = divmod(int(np.argmax(bad)), 4)
        raise InputError(f"'transform' entry [{i}][{j}] is {float(M[i, j])!r}: a finite "
                         f"number no larger than {COORDINATE_LIMIT:g} expected",
                         report_path)
    return M


def run_meshes(job: dict, report_path: Path):
    """Template, scan and result meshes of the run (the result in template topology)."""
    paths = {k: _existing(job[k], report_path, k) for k in ("template", "scan", "output")}
    log.info("reading %s", ", ".join(str(p) for p in paths.values()))
    template, scan, result = (read_mesh(paths[k]) for k in ("template", "scan", "output"))
    if result.n_vertices != template.n_vertices:
        raise InputError(f"has {result.n_vertices} vertices but the template "
                         f"{paths['template']} has {template.n_vertices}", paths["output"])
    return template, scan, result


def run_vertex_roles(run: dict, report_path, n: int) -> np.ndarray:
    """(n,) int8 role codes (:data:`facewrap.evaluate.VERTEX_ROLE_NAMES`) of a run.

    From the report's ``vertex_roles``; a report without them (older runs) gives
    the job's ``exclude`` vertices "excluded" and the others "fitted".

    Raises
    ------
    InputError
        When ``vertex_roles`` is malformed or the exclude file unreadable.
    """
    report_path = Path(report_path)
    if "vertex_roles" in run:
        try:
            return role_codes(run["vertex_roles"], n)
        except ValueError as exc:
            raise InputError(f"{exc} (the result has {n} vertices)", report_path) from None
    codes = np.full(n, _FITTED, dtype=np.int8)
    exclude = run["job"].get("exclude")
    if exclude:
        path = _existing(exclude, report_path, "exclude")
        codes[read_vertex_indices(path, n_vertices=n).vertex] = \
            VERTEX_ROLE_NAMES.index("excluded")
    return codes


def _fitted_triangles(T: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """(m,) bool: triangles whose three vertices are all fitted."""
    return (codes[T] == _FITTED).all(axis=1)


def _distances(scan, result, codes) -> tuple[np.ndarray, np.ndarray]:
    """Result → scan distance of the fitted vertices (NaN for the others and where
    the closest point is on the scan's border, as :func:`~facewrap.wrapping.stages.
    fit_metrics` leaves them out) and scan → fitted-result distance, per vertex."""
    log.info("measuring distances")
    scan_tree = ClosestPointTree(scan.vertices, scan.triangles)
    cp = scan_tree.query(result.vertices)
    off = scan_tree.boundary_triangles[cp.triangles] | (codes != _FITTED)
    to_scan = np.where(off, np.nan, cp.distances)
    T = result.triangles
    fitted_T = T[_fitted_triangles(T, codes)]
    to_result = ClosestPointTree(result.vertices, fitted_T if len(fitted_T) else T).query(
        scan.vertices).distances
    return to_scan, to_result


def _result_layers(result, codes, textures=None) -> dict:
    """The fitted result (its fitted triangles) and one layer per role that follows,
    so the heatmap never paints them and each has a toggle; each as the run's glTF
    draws it, standing for the template's vertices of its role."""
    T = result.triangles
    fitted = _fitted_triangles(T, codes)
    layers = {"result": MeshLayer(result, fitted, textures, codes == _FITTED)}
    # a triangle that touches a following vertex goes with the highest such role
    tri_role = codes[T].max(axis=1)
    for role, name in _ROLE_LAYERS.items():
        code = VERTEX_ROLE_NAMES.index(role)
        sel = ~fitted & (tri_role == code)
        if sel.any():
            layers[name] = MeshLayer(result, sel, textures, codes == code)
    return layers


def _baked_textures(run: dict, report_path: Path, result) -> dict | None:
    """The run's baked images keyed as its glTF holds them: ``(tile, material ids of
    the result)``; faces the template left without a material (named
    :data:`~facewrap.texture.tiles.BAKED_MATERIAL` in the output) go with the first
    image of their tile.  None when the run baked nothing or the result has no UVs."""
    texture = run.get("texture")
    if not isinstance(texture, dict) or result.triangle_uvs is None:
        return None
    entries = texture.get("images") or [{"image": texture.get("image"), "tile": 1001,
                                         "materials": None}]
    out, tiles_seen = {}, set()
    for k, entry in enumerate(entries):
        if not isinstance(entry, dict) or not entry.get("image"):
            continue
        path = _existing(entry["image"], report_path, "texture image")
        image = path.read_bytes()   # a PNG is embedded as it is, not encoded again
        if not image.startswith(b"\x89PNG\r\n\x1a\n"):
            image = load_image(path)
        tile = int(entry.get("tile", 1001))
        if entry.get("materials") is None:   # an older run: one image, tile 1001
            out[tile] = image
            continue
        ids = [m for m, name in enumerate(result.materials) if name in entry["materials"]]
        if tile not in tiles_seen:
            ids += [-1] + [m for m, name in enumerate(result.materials)
                           if name in (BAKED_MATERIAL, f"{BAKED_MATERIAL}_{tile}")]
            tiles_seen.add(tile)
        out[(tile, tuple(ids))] = image
    if len({isinstance(key, tuple) for key in out}) > 1:
        raise InputError("'texture' mixes images with and without materials", report_path)
    return out or None


def _detected(run: dict, which: str, report_path: Path):
    """``(Landmarks, (k,) bool low-confidence)`` of the run's detection on ``which``
    ("scan" or "template"), from the report's surface landmarks; None without one."""
    entry = (run.get("detected_landmarks") or {}).get(which)
    if not isinstance(entry, dict):
        return None
    try:
        names = list(entry["names"])
        lm = Landmarks.from_barycentric(entry["triangles"], entry["barycentric"], names)
        low = np.isin(names, list(entry.get("low_confidence", ())))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"'detected_landmarks' › {which} is malformed ({exc})",
                         report_path) from None
    return lm, low


def _template_landmarks(job: dict, report_path: Path, profile, run: dict):
    """The run's template landmarks: from their file, else from the template profile
    the run used (``profile``: its path, from the report), else detected."""
    found = _detected(run, "template", report_path)
    if "template_landmarks" not in job and not profile and found is not None:
        return found[0]
    if "template_landmarks" in job or not profile:
        return read_landmarks(_existing(job["template_landmarks"], report_path,
                                        "template landmarks"), kind="auto")
    landmarks = read_template_profile(_existing(profile, report_path,
                                                "template profile")).landmarks
    if landmarks is None:
        raise InputError("has no landmarks", profile)
    return landmarks


def _scan_landmarks(run: dict, report_path: Path, template_landmarks):
    """``(template, scan, low)``: the run's scan landmarks from their file (``low``
    None), else the detected ones paired as the wrap paired them (the confident
    points; ``low``: the positions of the others, drawn apart)."""
    job = run["job"]
    found = _detected(run, "scan", report_path)
    if job.get("scan_landmarks") or found is None:
        return template_landmarks, read_landmarks(_existing(
            job["scan_landmarks"], report_path, "scan landmarks"), kind="points"), None
    lm, low = found
    tl, sl = confident_landmarks(template_landmarks,
                                 SimpleNamespace(landmarks=lm, low_confidence=low))
    return tl, sl, lm.subset(np.flatnonzero(low))


def _landmark_points(run: dict, report_path: Path, template, scan, result, M,
                     profile=None):
    """Landmark sets for the viewer, labels of the worst, and the paired errors.

    Returns ``(points, labels, errors)``: ``points`` maps "landmarks: template"
    (aligned), "landmarks: scan" and "landmarks: result" to (k, 3) positions —
    detected scan landmarks as "landmarks: scan (detected)" diamonds and their
    low-confidence ones, left out of the wrap, as "landmarks: scan (low
    confidence)" rings; ``labels`` names the :data:`WORST_LANDMARKS_LABELLED`
    largest result → scan errors; ``errors`` is (l,) float over the pairs.  Empty
    when the files are gone.
    """
    job = run["job"]
    try:
        tl = _template_landmarks(job, report_path, profile, run)
        tl.check(template.n_vertices, len(template.triangles))
        tl, sl, low = _scan_landmarks(run, report_path, tl)
        sl.check(scan.n_vertices, len(scan.triangles))
        ia, ib = pair_landmarks(tl, sl, ("template", "scan"))
    except (KeyError, InputError, ValueError) as exc:
        log.warning("landmarks not shown: %s", exc)
        return {}, [], np.zeros(0)
    A, t = M[:3, :3], M[:3, 3]
    on_result = tl.positions(result.vertices, result.triangles)[ia]
    on_scan = sl.positions(scan.vertices, scan.triangles)[ib]
    aligned = (tl.positions(template.vertices, template.triangles) @ A.T + t)[ia]
    points = {"landmarks: template": aligned}
    if low is None:
        points["landmarks: scan"] = on_scan
    else:
        points["landmarks: scan (detected)"] = PointSet(on_scan, marker="diamond")
        if len(low):
            points["landmarks: scan (low confidence)"] = PointSet(
                low.positions(scan.vertices, scan.triangles), marker="ring",
                color=FLAGGED_COLOR)
    points["landmarks: result"] = on_result
    errors = np.linalg.norm(on_result - on_scan, axis=1)
    worst = np.argsort(-errors, kind="stable")[:WORST_LANDMARKS_LABELLED]
    # names from the template's file, else the scan's (a menpo .ljson names them)
    name = ((lambda j: tl.label(int(ia[j]))) if tl.names is not None or sl.names is None
            else (lambda j: sl.label(int(ib[j]))))
    labels = [(int(j), on_result[j], name(j)) for j in worst]
    return points, labels, errors


def _blendshape_preview(job: dict, report_path: Path, template, result, A):
    """("result", shapes): the template's shape offsets turned by ``A``, on the result."""
    if not job.get("blendshapes"):
        return None
    folder = Path(job["blendshapes"])
    if not folder.is_dir() and (report_path.parent / folder).is_dir():
        folder = report_path.parent / folder
    shapes = load_shape_folder(folder, template, exclude=())
    return ("result", {name: result.vertices + (P - template.vertices) @ A.T
                       for name, P in shapes.items()})


def _pictures(run: dict, report_path: Path, images) -> list[tuple[str, Path]]:
    """The baked texture (when the run made one) and the extra images, checked, and
    with them every baked image the viewer shows."""
    pictures = []
    texture = run.get("texture")
    if isinstance(texture, dict) and texture.get("image"):
        pictures.append(("baked texture (template UV layout)",
                         _existing(texture["image"], report_path, "texture image")))
        for entry in texture.get("images") or ():
            if isinstance(entry, dict) and entry.get("image"):
                check_image(_existing(entry["image"], report_path, "texture image"))
    for p in images:
        pictures.append((Path(p).name, Path(p)))
    for _, p in pictures:
        if not Path(p).is_file():
            raise not_a_file(p)   # says what it is: missing, a folder, a fifo ...
        check_image(p)
    return pictures


def _detection_pictures(run: dict, report_path: Path, scan, up, front) -> list:
    """The scan from the front and three-quarter with its detected landmarks marked
    (diamonds: confident; rings: low-confidence, left out of the wrap), when the
    run detected them; ``(caption, PNG bytes)``."""
    found = _detected(run, "scan", report_path)
    if found is None or run["job"].get("scan_landmarks"):
        return []
    lm, low = found
    try:
        points = lm.positions(scan.vertices, scan.triangles)
    except (IndexError, ValueError) as exc:
        log.warning("detected landmarks not drawn: %s", exc)
        return []
    frame = frame_from_axes(up=up, front=front)
    views = [landmark_picture(scan, points, low, view=v, frame=frame)
             for v in ("front", "three_quarter")]
    caption = (f"scan landmarks: {landmark_source(run)}; diamonds confident, rings "
               "low-confidence (left out of the wrap)")
    return [(caption, png_bytes(side_by_side(views, ["front", "three-quarter"])))]


def _run_units(run: dict, units: str, result) -> tuple[str, str]:
    """``(unit, source)``: ``units`` when given, else the run's own, else inferred."""
    if units == "auto" and run.get("units") in UNIT_NAMES + (UNKNOWN,):
        return run["units"], run.get("units_source", "given")
    return resolve_units(units, result.surface_points())


def _ground_truth_values(ground_truth, result, codes) -> np.ndarray | None:
    """(n,) distance of each fitted vertex to its true position (NaN elsewhere)."""
    if ground_truth is None:
        return None
    G = np.asarray(ground_truth, dtype=np.float64)
    if G.shape != result.vertices.shape:
        raise ValueError(f"ground_truth must have shape {result.vertices.shape} (one "
                         f"true position per result vertex), got {G.shape}")
    err = np.linalg.norm(result.vertices - G, axis=1)  # NaN where the truth is NaN
    return np.where(codes == _FITTED, err, np.nan)


def build_report_page(report_path, out_dir, *, images=(), units: str = "auto",
                      ground_truth=None, template_up=(0.0, 1.0, 0.0),
                      template_front=(0.0, 0.0, 1.0), title: str | None = None) -> Path:
    """Write the HTML page of a wrap run's JSON report.

    Parameters
    ----------
    report_path : path
        JSON written by a wrap job (:func:`~facewrap.jobs.run_wrap_job`).
    out_dir : path
        Folder for ``index.html`` (created).
    images : sequence of path
        Extra pictures (PNG/JPEG), captioned by file name.
    units : {"auto", "mm", "cm", "m", "in"}
        Unit of the run's distances; "auto": the report's ``units``, else
        inferred from the result's size (:mod:`facewrap.units`).
    ground_truth : (n, 3) float, optional
        True positions of the result's vertices (NaN rows: unknown): adds a
        heatmap of the distance to them over the fitted vertices.
    template_up, template_front : (3,) float
        Up and front directions of the template; the view turns them with the
        run's similarity.
    title : str, optional
        Page title (default names the scan).

    Returns
    -------
    Path
        The page.

    Raises
    ------
    InputError
        If the report or a file it names is missing or malformed.
    ValueError
        If ``ground_truth`` is not one row per result vertex.
    """
    report_path = Path(report_path)
    run = load_run_report(report_path)
    job = run["job"]
    pictures = _pictures(run, report_path, images)   # checked before any work
    for which in ("scan", "template"):               # so are the run's detections
        _detected(run, which, report_path)
    M = _similarity(run, report_path)
    A, t = M[:3, :3], M[:3, 3]
    template, scan, result = run_meshes(job, report_path)
    codes = run_vertex_roles(run, report_path, result.n_vertices)
    unit, source = _run_units(run, units, result)
    conflict = units_conflict(units, result.surface_points())
    odd = [f"{job.get('output', report_path)}: {conflict}"] if conflict else []
    for note in odd:   # the page shows every distance in it all the same
        warnings.warn(note, InputWarning, stacklevel=2)
    truth = _ground_truth_values(ground_truth, result, codes)
    to_scan, to_result = _distances(scan, result, codes)
    profile = run.get("template_profile", {}).get("path")
    points, worst, errors = _landmark_points(run, report_path, template, scan, result, M,
                                             profile)
    labelled = [(name, float(errors[j])) for j, _, name in worst]
    scalars = {"distance to scan": ("result", to_scan, unit),
               "distance to result": ("scan", to_result, unit)}
    if truth is not None:  # the truest measure comes first, shown at start
        scalars = {"distance to ground truth": ("result", truth, unit), **scalars}
    counts = np.bincount(codes, minlength=len(VERTEX_ROLE_NAMES))
    summary = run_summary(run, unit, source,
                          roles=dict(zip(VERTEX_ROLE_NAMES, counts.tolist())),
                          worst_landmarks=labelled, ground_truth=truth)
    layers = _result_layers(result, codes, _baked_textures(run, report_path, result))
    up, front = A @ np.asarray(template_up, float), A @ np.asarray(template_front, float)
    pictures += _detection_pictures(run, report_path, scan, up, front)
    return write_html_report(
        out_dir, title=title or f"Wrap of {Path(job['scan']).name}",
        subtitle=f"report {report_path}", summary=summary,
        warnings=odd + (run["warnings"] if isinstance(run.get("warnings"), list) else []),
        images=pictures,
        meshes={"template (aligned)": (template.vertices @ A.T + t, template.triangles),
                "scan": scan, **layers},
        visible=list(layers), scalars=scalars, points=points,
        labels=[("landmarks: result", at, f"{name}: {format_distance(errors[j], unit)}")
                for j, at, name in worst],
        blendshapes=_blendshape_preview(job, report_path, template, result, A),
        view_up=up, view_front=front)
