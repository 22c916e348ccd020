"""A wrap job from files to files: what ``facewrap wrap``, job files and batches run.

:class:`WrapJob` names the inputs and outputs of one registration (paths only);
:func:`run_wrap_job` reads and checks the inputs, runs :func:`facewrap.wrap.wrap`
with a :class:`~facewrap.wrap.WrapSettings`, and writes the outputs atomically
(mesh, optional baked texture, optional JSON report).  Every input problem is an
:class:`~facewrap.errors.InputError` naming the file, raised before anything is
written; inputs are only read.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .errors import InputError
from .wrap import WrapSettings

__all__ = ["WrapJob", "run_wrap_job", "load_wrap_inputs"]


@dataclass
class WrapJob:
    """Files of one wrap (settings live apart, in :class:`WrapSettings`).

    Attributes
    ----------
    template, scan : path
        Meshes (OBJ/PLY).
    template_landmarks : path
        Template vertex ids (text) or facewrap landmark JSON.
    scan_landmarks : path
        Scan points: ``x y z`` text, menpo ``.ljson`` or facewrap JSON.
    output : path
        Fitted mesh (OBJ/PLY) in the template's exact topology.
    blendshapes : path, optional
        Folder of meshes in the template's topology (a shape = file − template).
    exclude : path, optional
        Template vertex ids that follow but are not pulled to the scan.
    texture : path, optional
        Scan texture image to bake into the template's UV layout
        (written next to ``output`` as PNG).
    texture_size : int
        Baked image size in pixels.
    report : path, optional
        JSON report (timings, iterations, fit distances, landmark errors).
    """
    template: str
    scan: str
    template_landmarks: str
    scan_landmarks: str
    output: str
    blendshapes: str | None = None
    exclude: str | None = None
    texture: str | None = None
    texture_size: int = 1024
    report: str | None = None


def load_wrap_inputs(job: WrapJob) -> dict:
    """Read and cross-check a job's input files.

    Returns
    -------
    dict with ``template``, ``scan`` (Mesh), ``template_landmarks``,
    ``scan_landmarks`` (Landmarks), ``exclude`` (int array or None),
    ``blendshapes`` (dict name → (n, 3) positions, or None), ``texture`` (image
    array or None).
    """
    from .io import read_mesh
    from .io.landmarks import read_landmarks, read_vertex_indices
    template = read_mesh(job.template)
    scan = read_mesh(job.scan)
    if len(scan.triangles) == 0:
        raise InputError("has no faces; a scan must be a surface", job.scan)
    tl = read_landmarks(job.template_landmarks, kind="auto")
    try:
        tl.check(template.n_vertices, len(template.triangles))
    except ValueError as exc:
        raise InputError(str(exc), job.template_landmarks) from None
    sl = read_landmarks(job.scan_landmarks, kind="points")
    try:
        sl.check(scan.n_vertices, len(scan.triangles))
    except ValueError as exc:
        raise InputError(str(exc), job.scan_landmarks) from None
    if (tl.names is None or sl.names is None) and len(tl) != len(sl):
        raise InputError(f"has {len(sl)} landmarks but the template landmarks "
                         f"({job.template_landmarks}) have {len(tl)}", job.scan_landmarks)
    exclude = None
    if job.exclude:
        exclude = read_vertex_indices(job.exclude, n_vertices=template.n_vertices).vertex
    shapes = None
    if job.blendshapes:
        from .datasets import load_shape_folder
        # a copy of the template inside the folder is skipped (it equals the neutral)
        shapes = load_shape_folder(job.blendshapes, template, exclude=())
    image = None
    if job.texture:
        from .texture import load_image
        if scan.uvs is None:
            raise InputError("the scan has no texture coordinates to bake from", job.scan)
        if template.uvs is None:
            raise InputError("the template has no UV layout to bake into", job.template)
        image = load_image(job.texture)
    return {"template": template, "scan": scan, "template_landmarks": tl,
            "scan_landmarks": sl, "exclude": exclude, "blendshapes": shapes,
            "texture": image}


def run_wrap_job(job: WrapJob, settings: WrapSettings | None = None) -> dict:
    """Run one wrap job and write its outputs; returns the report as a dict.

    The mesh, the texture and the report are each written atomically (a crash
    never leaves a half-written file).
    """
    from .io import write_mesh
    from .io.atomic import atomic_write
    from .wrap import wrap
    settings = settings or WrapSettings()
    t0 = time.perf_counter()
    inputs = load_wrap_inputs(job)
    read_seconds = time.perf_counter() - t0
    result = wrap(inputs["template"], inputs["scan"], inputs["template_landmarks"],
                  inputs["scan_landmarks"], settings, exclude=inputs["exclude"],
                  blendshapes=inputs["blendshapes"])
    write_mesh(job.output, result.mesh)
    report = {"job": {k: v for k, v in asdict(job).items() if v is not None},
              "settings": asdict(result.settings),
              "vertices": result.mesh.n_vertices,
              "read_seconds": read_seconds,
              "timings": result.timings, "metrics": result.metrics,
              "iterations": result.history,
              "transform": result.transform.matrix.tolist()}
    if result.weights is not None:
        report["blend_weights"] = dict(zip(result.shape_names,
                                           np.round(result.weights, 6).tolist()))
    if inputs["texture"] is not None:
        from .texture import bake_texture, save_png
        t = time.perf_counter()
        baked = bake_texture(result.mesh, inputs["scan"], inputs["texture"],
                             size=job.texture_size)
        png = Path(job.output).with_suffix(".png")
        save_png(png, baked.image)
        report["texture"] = {"image": str(png), "coverage": baked.filled_fraction,
                             "seconds": time.perf_counter() - t}
    if job.report:
        import json
        with atomic_write(job.report, "w") as fh:
            json.dump(report, fh, indent=1)
    return report
