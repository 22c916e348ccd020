"""The HTML page of a person's rig: its shapes on sliders, its example scans and
how well the rig reproduces each.

:func:`write_rig_page` writes one self-contained page with
:func:`facewrap.report.html.write_html_report`:

- the rig's neutral, drawn as its GLB draws it (UV seams, smooth normals, the baked
  texture), with one slider per shape: the viewer plays the rig as an engine would;
- the neutral scan;
- per expression scan: the scan, moved onto the neutral's head pose by the rigid
  pose that stabilised it, and the rig at that example's weights, coloured by its
  **reconstruction error**: the distance of the rig at the example's weights to the
  example's (stabilised) wrap, over the vertices that lay on that scan.  That is
  the quantity the examples table gives (:attr:`~facewrap.rig.ExampleFit.errors`),
  so heatmap and table agree;
- tables: the rig (vertices, shapes, method), each example's error against the
  neutral-only rig's and its strongest weights, timings; every distance with its
  unit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from facewrap.report.html import MeshLayer, write_html_report
from facewrap.units import UNKNOWN, format_distance

__all__ = ["write_rig_page", "reconstruction_errors"]

#: weights listed per example in the table (the strongest)
STRONGEST_WEIGHTS = 4


def reconstruction_errors(rig) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per expression scan of ``rig``: the rig at its weights, the example it
    reproduces, and the distance between them.

    Parameters
    ----------
    rig : Rig
        Built with expression scans (:func:`~facewrap.rig.build_rig`).

    Returns
    -------
    list of (reconstruction, example, distance)
        ``reconstruction`` and ``example`` (n, 3) float64 in the neutral's frame;
        ``distance`` (n,) float64, NaN off the vertices that lay on the example's
        scan (the ones :attr:`~facewrap.rig.ExampleFit.errors` counts).
    """
    fit = rig.examples
    if fit is None:
        return []
    base = rig.neutral.vertices
    names = list(rig.shapes)
    D = np.stack([rig.shapes[k] for k in names]) - base[None]          # (s, n, 3)
    out = []
    for weights, pose, wrap in zip(fit.weights, fit.poses or [None] * len(fit.weights),
                                   rig.expression_wraps):
        w = np.array([weights.get(k, 0.0) for k in names])
        rebuilt = base + np.tensordot(w, D, axes=1)
        example = wrap.vertices if pose is None else pose.apply(wrap.vertices)
        distance = np.linalg.norm(rebuilt - example, axis=1)
        if wrap.projection is not None:
            distance = np.where(wrap.projection.projected, distance, np.nan)
        out.append((rebuilt, example, distance))
    return out


def _examples_table(rig, unit: str) -> list[dict]:
    fit = rig.examples
    rows = []
    for k, (weights, error, prior) in enumerate(zip(fit.weights, fit.errors,
                                                    fit.prior_errors), start=1):
        strongest = sorted(weights.items(), key=lambda kv: -abs(kv[1]))[:STRONGEST_WEIGHTS]
        rows.append({"expression": k,
                     "rig error mean": format_distance(error["mean"], unit),
                     "rig error p95": format_distance(error["p95"], unit),
                     "neutral-only mean": format_distance(prior["mean"], unit),
                     "neutral-only p95": format_distance(prior["p95"], unit),
                     "strongest weights": ", ".join(f"{n} {v:.2f}" for n, v in strongest)})
    return rows


def write_rig_page(folder, rig, scan, *, expression_scans=(), units: str = UNKNOWN,
                   textures=None, warnings=(), title: str | None = None,
                   filename: str = "index.html") -> Path:
    """Write the page of ``rig`` into ``folder``.

    Parameters
    ----------
    folder : path
        Created if missing; only ``filename`` is written there.
    rig : Rig
        From :func:`~facewrap.rig.build_rig`.
    scan : Mesh
        The neutral scan it was built from.
    expression_scans : sequence of Mesh
        The expression scans, in the order given to ``build_rig`` (their own frames).
    units : str
        Unit of the meshes (see :mod:`facewrap.units`); every distance carries it.
    textures : optional
        The neutral's base-colour images, as :class:`MeshLayer` takes them.
    warnings : sequence of str
    title : str, optional
    filename : str

    Returns
    -------
    Path
        The page.

    Examples
    --------
    >>> import tempfile
    >>> from facewrap.rig import build_rig
    >>> from facewrap.sample import make_scan, make_template
    >>> tpl = make_template(16)
    >>> scan = make_scan(tpl, weights={})
    >>> rig = build_rig(tpl.mesh, scan.mesh, tpl.landmarks, scan.landmarks,
    ...                 tpl.blendshapes)
    >>> write_rig_page(tempfile.mkdtemp(), rig, scan.mesh, units="mm").name
    'index.html'
    """
    scans = list(expression_scans)
    if rig.examples is not None and len(scans) != len(rig.examples.weights):
        raise ValueError(f"expression_scans: the rig has {len(rig.examples.weights)} "
                         f"example(s), got {len(scans)} scan(s)")
    meshes = {"rig": MeshLayer(rig.neutral, textures=textures), "neutral scan": scan}
    scalars = {}
    T = rig.neutral.triangles
    poses = [] if rig.examples is None else (rig.examples.poses or [None] * len(scans))
    for k, ((rebuilt, _, distance), pose, expression) in enumerate(
            zip(reconstruction_errors(rig), poses, scans), start=1):
        V = expression.vertices if pose is None else pose.apply(expression.vertices)
        meshes[f"expression {k}: scan"] = (V, expression.triangles)
        meshes[f"expression {k}: rig"] = (rebuilt, T)
        scalars[f"expression {k}: rig error"] = (f"expression {k}: rig", distance, units)
    metrics = rig.wrap.metrics
    summary = {"rig": {"vertices": rig.neutral.n_vertices, "shapes": len(rig.shapes),
                       "method": rig.method, "units": units,
                       "neutral fit mean": format_distance(metrics.get("fit_mean"), units),
                       "neutral fit p95": format_distance(metrics.get("fit_p95"), units)},
               "timings (s)": {k: round(float(v), 3) for k, v in rig.timings.items()}}
    if rig.examples is not None:
        summary["examples"] = _examples_table(rig, units)
    return write_html_report(
        folder, title=title or f"Rig: {rig.neutral.n_vertices:,} vertices, "
        f"{len(rig.shapes)} shapes", summary=summary, meshes=meshes,
        scalars=scalars or None, blendshapes=("rig", rig.shapes), visible=["rig"],
        warnings=warnings, filename=filename)
