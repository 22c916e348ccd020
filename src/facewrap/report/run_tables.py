"""The tables of a wrap run's page: the run's numbers, each with its unit.

:func:`run_summary` orders a run report's sections for the page
(:data:`RUN_SECTIONS` first, any other key after) and turns every distance into
text with the run's unit (:func:`facewrap.units.format_distance`) and every
duration into seconds, so a table never shows a bare number that is a length.
The run's warnings are not among the tables: the page shows them first, apart.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Mapping

import numpy as np

from facewrap.units import describe_units, format_distance

__all__ = ["run_summary", "landmark_source", "RUN_SECTIONS", "DISTANCE_SECTIONS",
           "is_distance_key"]

#: Order of the tables on the page; any other key of the report follows.
RUN_SECTIONS = ("metrics", "ground_truth_error_mm", "worst_landmarks", "detected_landmarks",
                "vertex_roles",
                "timings", "blend_weights", "texture", "settings", "job", "iterations",
                "transform")

#: Sections whose statistics keys are distances (``mean``, ``fit_p95``, ...).
DISTANCE_SECTIONS = ("metrics", "ground_truth_error_mm", "iterations", "landmark_pull")

# statistics of a distance: fit_mean, p95, max_move, landmark_rms, tolerance, ...
_DISTANCE_KEY = re.compile(r"(^|_)(mean|median|p\d\d?|max|min|rms|move|tolerance)$")
# sections shown under another title (the unit is in the values now)
_TITLES = {"ground_truth_error_mm": "ground truth error",
           "detected_landmarks": "landmarks detected"}


def is_distance_key(key: str) -> bool:
    """Whether a statistic named ``key`` in :data:`DISTANCE_SECTIONS` is a length.

    >>> [is_distance_key(k) for k in ("fit_p95", "max_move", "fit_coverage", "energy")]
    [True, True, False, False]
    """
    return bool(_DISTANCE_KEY.search(str(key)))


def _is_float(v) -> bool:
    return isinstance(v, float)


def _with_units(value, unit: str, key: str = ""):
    """``value`` with its distances as text in ``unit`` and seconds as ``"… s"``."""
    if isinstance(value, Mapping):
        return {k: _with_units(v, unit, k) for k, v in value.items()}
    if isinstance(value, list) and value and all(isinstance(r, Mapping) for r in value):
        return [_with_units(r, unit) for r in value]
    if _is_float(value) and (key == "seconds" or key.endswith("_seconds")):
        return f"{value:.3g} s"
    if _is_float(value) and key.endswith("coverage"):
        return f"{100 * value:.1f} %"
    if _is_float(value) and is_distance_key(key):
        return format_distance(value, unit)
    return value


def _seconds(d: Mapping) -> dict:
    return {k: (f"{v:.3g} s" if _is_float(v) else v) for k, v in d.items()}


def landmark_source(run: dict) -> str | None:
    """What the run's scan landmarks were, for the overview table.

    >>> landmark_source({"job": {"scan_landmarks": "in/scan_lm.txt"}})
    'file scan_lm.txt'
    >>> landmark_source({"job": {}, "scan_landmarks_source": "detected",
    ...                  "detected_landmarks": {"scan": {"names": ["a"] * 68,
    ...                                                  "low_confidence": ["a"] * 17}}})
    'detected (51 confident of 68)'
    """
    found = (run.get("detected_landmarks") or {}).get("scan")
    if run.get("scan_landmarks_source") == "detected" and isinstance(found, dict):
        total = len(found.get("names") or found.get("confidence") or ())
        low = len(found.get("low_confidence") or ())
        return f"detected ({total - low} confident of {total})"
    path = run["job"].get("scan_landmarks")
    return f"file {Path(path).name}" if path else None


def _detection_tables(found: Mapping, unit: str) -> dict:
    """One row set per detection (scan, template): what a reader checks, not the
    points themselves (the viewer draws those)."""
    out = {}
    for which, entry in found.items():
        if not isinstance(entry, Mapping):
            continue
        low = list(entry.get("low_confidence") or ())
        total = len(entry.get("names") or entry.get("confidence") or ())
        seconds = (entry.get("timings") or {}).get("total")
        out[which] = {"confident": f"{total - len(low)} of {total}",
                      "low confidence (left out)": ", ".join(low) or "none",
                      "views": len(entry.get("views") or ()),
                      "eye distance": format_distance(entry.get("eye_distance"), unit),
                      "seconds": f"{seconds:.3g} s" if _is_float(seconds) else seconds}
    return out


def run_summary(run: dict, unit: str, unit_source: str, *, roles: Mapping | None = None,
                worst_landmarks=(), ground_truth=None) -> dict:
    """The page's tables of a run report: an overview, then the sections.

    Parameters
    ----------
    run : dict
        The run's JSON report.
    unit : str
        Unit of its distances (:data:`facewrap.units.UNIT_NAMES` or "units").
    unit_source : {"given", "inferred"}
        How the unit was settled (:func:`facewrap.units.resolve_units`).
    roles : dict of str to int, optional
        Vertices per role (fitted, part, cavity, excluded, pinned).
    worst_landmarks : sequence of (str, float)
        The worst landmarks' names and result → scan errors, worst first.
    ground_truth : (n,) float, optional
        Per-vertex distance to ground truth shown in the viewer (NaN: not
        counted): a table of the same statistics the viewer's colour bar shows.

    Returns
    -------
    dict
        For :func:`facewrap.report.html.write_html_report`'s ``summary``.
    """
    job, settings = run["job"], run.get("settings", {})
    overview = {"scan": Path(job["scan"]).name, "template": Path(job["template"]).name,
                "model": settings.get("model"), "vertices": run.get("vertices"),
                "units": describe_units(unit, unit_source),
                "scan landmarks": landmark_source(run),
                "total_seconds": run.get("timings", {}).get("total")}
    summary = {k: _with_units(v, unit, k) for k, v in overview.items() if v is not None}
    extra = {"vertex_roles": {k: v for k, v in (roles or {}).items() if v},
             "worst_landmarks": [{"landmark": name, "error": format_distance(e, unit)}
                                 for name, e in worst_landmarks]}
    source = {**run, **extra}
    skip = ("vertices", "warnings", "units", "units_source", "scan_landmarks_source")
    for key in RUN_SECTIONS + tuple(k for k in run if k not in RUN_SECTIONS):
        if key in skip or key not in source or source[key] in (None, {}, []):
            continue
        value = source[key]
        if key in DISTANCE_SECTIONS or key == "texture":
            value = _with_units(value, unit)
        elif key == "timings" and isinstance(value, Mapping):
            value = _seconds(value)
        elif key == "detected_landmarks" and isinstance(value, Mapping):
            value = _detection_tables(value, unit)
        else:
            value = _with_units(value, unit, key) if _is_float(value) else value
        summary[_TITLES.get(key, key)] = value
    if ground_truth is not None:
        e = np.asarray(ground_truth, dtype=np.float64)
        e = e[np.isfinite(e)]
        stats = {"vertices": int(len(e))}
        if len(e):
            stats.update(mean=float(e.mean()), p95=float(np.percentile(e, 95)),
                         max=float(e.max()))
        summary["distance to ground truth (fitted vertices)"] = _with_units(stats, unit)
    return summary
