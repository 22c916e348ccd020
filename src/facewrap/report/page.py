"""The HTML page of a finished wrap run, built from its JSON report.

Reads the JSON report that a wrap job writes (see
:func:`facewrap.jobs.run_wrap_job`), the meshes it names (template, scan, output)
and, when the run had them, its blendshape folder and baked texture, and writes
``DIR/index.html`` with :func:`facewrap.report.html.write_html_report`:

- layers: the template moved by the run's similarity ("template (aligned)"), the
  scan and the result;
- heatmaps: result → scan distance (grey where the closest scan point is on the
  scan's border, i.e. the scan does not cover that vertex, as in the fit metrics)
  and scan → result distance;
- sliders: the template's blendshape offsets, turned by the run's similarity,
  added to the result (a preview, not a deformation transfer);
- tables: warnings, metrics, timings, settings, blend weights, iterations, the
  transform.

Relative paths in the report are taken from the current folder, else from the
report's folder.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from facewrap.datasets import load_shape_folder
from facewrap.errors import InputError
from facewrap.geometry import ClosestPointTree
from facewrap.io import read_mesh
from facewrap.report.html import write_html_report

__all__ = ["build_report_page", "load_run_report", "RUN_SECTIONS"]

log = logging.getLogger(__name__)

#: Order of the tables on the page; any other key of the report follows.
RUN_SECTIONS = ("warnings", "metrics", "ground_truth_error_mm", "timings",
                "blend_weights", "texture", "settings", "job", "iterations", "transform")


def _existing(path, report_path: Path, key: str) -> Path:
    """A file the run names: a relative path from the report's own folder first.

    The report's folder comes first so that a file of the same name in the current
    folder (another run's ``out.obj``) is never shown instead of the run's own; the
    current folder is still tried for reports written with paths relative to it.
    """
    p = Path(path)
    for candidate in (report_path.parent / p, p):
        if candidate.is_file():
            return candidate
    raise InputError(f"the run's {key} {str(path)!r} is missing (looked in "
                     f"{report_path.parent} and in the current folder)", report_path)


def load_run_report(report_path) -> dict:
    """Read a wrap run's JSON report.

    Raises
    ------
    InputError
        When the file is missing, not JSON, or has no ``job`` with template, scan
        and output paths.
    """
    report_path = Path(report_path)
    try:
        run = json.loads(report_path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("no such file", report_path) from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not a JSON report ({exc})", report_path) from None
    job = run.get("job") if isinstance(run, dict) else None
    if not isinstance(job, dict) or not all(k in job for k in ("template", "scan",
                                                               "output")):
        raise InputError("not a facewrap wrap report: 'job' with template, scan and "
                         "output paths expected", report_path)
    return run


def _similarity(run: dict, report_path: Path) -> np.ndarray:
    """The run's (4, 4) template → scan similarity."""
    M = np.asarray(run.get("transform", np.eye(4)), dtype=np.float64)
    if M.shape != (4, 4) or not np.isfinite(M).all():
        raise InputError(f"'transform' must be a 4x4 matrix, got shape {M.shape}",
                         report_path)
    return M


def _run_meshes(job: dict, report_path: Path):
    """Template, scan and result meshes of the run (the result in template topology)."""
    paths = {k: _existing(job[k], report_path, k) for k in ("template", "scan", "output")}
    log.info("reading %s", ", ".join(str(p) for p in paths.values()))
    template, scan, result = (read_mesh(paths[k]) for k in ("template", "scan", "output"))
    if result.n_vertices != template.n_vertices:
        raise InputError(f"has {result.n_vertices} vertices but the template "
                         f"{paths['template']} has {template.n_vertices}", paths["output"])
    return template, scan, result


def _distances(scan, result) -> tuple[np.ndarray, np.ndarray]:
    """Result → scan distance (NaN where the closest point is on the scan's border)
    and scan → result distance, per vertex."""
    log.info("measuring distances")
    scan_tree = ClosestPointTree(scan.vertices, scan.triangles)
    cp = scan_tree.query(result.vertices)
    to_scan = np.where(scan_tree.boundary_triangles[cp.triangles], np.nan, cp.distances)
    to_result = ClosestPointTree(result.vertices, result.triangles).query(
        scan.vertices).distances
    return to_scan, to_result


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
    """The baked texture (when the run made one) and the extra images, checked."""
    pictures = []
    texture = run.get("texture")
    if isinstance(texture, dict) and texture.get("image"):
        pictures.append(("baked texture (template UV layout)",
                         _existing(texture["image"], report_path, "texture image")))
    for p in images:
        pictures.append((Path(p).name, Path(p)))
    for _, p in pictures:
        if not Path(p).is_file():
            raise InputError("no such file", p)
    return pictures


def _summary(run: dict) -> dict:
    """The page's tables: an overview, then :data:`RUN_SECTIONS`, then the rest."""
    job, settings = run["job"], run.get("settings", {})
    overview = {"scan": Path(job["scan"]).name, "template": Path(job["template"]).name,
                "model": settings.get("model"), "vertices": run.get("vertices"),
                "total seconds": run.get("timings", {}).get("total")}
    summary = {k: v for k, v in overview.items() if v is not None}
    for key in RUN_SECTIONS + tuple(k for k in run if k not in RUN_SECTIONS):
        if key in run and key not in ("vertices",) and run[key] not in (None, {}, []):
            summary[key] = run[key]
    return summary


def build_report_page(report_path, out_dir, *, images=(), units: str = "mm",
                      template_up=(0.0, 1.0, 0.0), template_front=(0.0, 0.0, 1.0),
                      title: str | None = None) -> Path:
    """Write the HTML page of a wrap run's JSON report.

    Parameters
    ----------
    report_path : path
        JSON written by a wrap job (:func:`~facewrap.jobs.run_wrap_job`).
    out_dir : path
        Folder for ``index.html`` (created).
    images : sequence of path
        Extra pictures (PNG/JPEG), captioned by file name.
    units : str
        Label of the distance units in the heatmaps.
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
    """
    report_path = Path(report_path)
    run = load_run_report(report_path)
    job = run["job"]
    M = _similarity(run, report_path)
    A, t = M[:3, :3], M[:3, 3]
    template, scan, result = _run_meshes(job, report_path)
    to_scan, to_result = _distances(scan, result)
    return write_html_report(
        out_dir, title=title or f"Wrap of {Path(job['scan']).name}",
        subtitle=f"report {report_path}",
        summary=_summary(run), images=_pictures(run, report_path, images),
        meshes={"template (aligned)": (template.vertices @ A.T + t, template.triangles),
                "scan": scan, "result": result},
        scalars={"distance to scan": ("result", to_scan, units),
                 "distance to result": ("scan", to_result, units)},
        blendshapes=_blendshape_preview(job, report_path, template, result, A),
        view_up=A @ np.asarray(template_up, float),
        view_front=A @ np.asarray(template_front, float))
