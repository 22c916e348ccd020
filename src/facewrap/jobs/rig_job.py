"""A rig job from files to files: what ``facewrap rig``, job files and batches run.

:class:`RigJob` names the files of one person's rig (paths only): their neutral
scan, the template, the template's blendshapes and an output folder.
:func:`run_rig_job` reads and checks the inputs with the wrap job's own reader
(:func:`~facewrap.jobs.wrap_job.load_wrap_inputs`, so a rig refuses and warns
about exactly what a wrap does), builds the rig (:func:`facewrap.rig.build_rig`:
the neutral wrapped with the hybrid model, every template shape made the
person's; with expression scans, each wrapped from the neutral's result,
stabilised, and the shapes corrected so the rig reproduces them) and writes,
inside the output folder ``OUT``:

- ``OUT/neutral.obj``: the wrapped neutral in the template's topology, with
  ``neutral.mtl`` and the baked images when a texture is given, exactly as
  ``facewrap wrap`` writes them (:func:`~facewrap.jobs.wrap_job.write_wrap_outputs`);
- ``OUT/shapes/<name>.obj``: every personalised shape (naming ``../neutral.mtl``);
- ``OUT/rig.glb``: the neutral with every shape as a named morph target, normals,
  material and the baked texture (else the template's own), in metres;
- ``OUT/rig.json``: the report (units, timings, the neutral's fit metrics, the
  method, the shapes; per expression scan its blend weights, rigid pose and
  reconstruction error, and the neutral-only rig's error for comparison).

Everything is staged (:func:`facewrap.io.paths.staged_outputs`) and appears
together or not at all; every input problem is an
:class:`~facewrap.errors.InputError` naming the file, raised before anything is
written.

As for :class:`~facewrap.jobs.wrap_job.WrapJob`, each field says in its
``metadata`` which job-file table it belongs to (:mod:`facewrap.jobs.fields`);
the settings are the wrap's (:class:`~facewrap.wrapping.WrapSettings`), the
``[rig]`` table of a job file.
"""

from __future__ import annotations

import json
import os
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from facewrap.detection.for_wrap import detected_landmark_settings, detection_report
from facewrap.errors import InputError
from facewrap.io import write_obj_series
from facewrap.io.atomic import atomic_write
from facewrap.io.files import folder_files
from facewrap.io.mtl import with_library
from facewrap.io.paths import check_output_paths, staged_outputs
from facewrap.jobs.fields import check_job_fields, input_field, output_field
from facewrap.jobs.input_checks import check_not_template, check_scan_sizes, repeated_scans
from facewrap.jobs.wrap_job import (InputWarning, WrapJob, check_job_paths, job_inputs,
                                    job_outputs, load_wrap_inputs, textureoutput_field,
                                    write_wrap_outputs)
from facewrap.params import expect_instance
from facewrap.progress import progress
from facewrap.rig import PERSONALISE_METHODS, TextureFlowSettings, build_rig
from facewrap.rig.texture_flow import MIN_IMAGE_SIDE
from facewrap.texture.tiles import file_textures, material_images
from facewrap.units import metres_per_unit, resolve_units
from facewrap.wrapping import GraphCache, WrapSettings, role_ranges
from facewrap.wrapping.track import FrameError

__all__ = ["RigJob", "run_rig_job", "rig_job_inputs", "rig_job_outputs",
           "check_rig_job_paths", "neutral_wrap_job", "expression_wrap_job", "NEUTRAL",
           "SHAPES", "GLB", "REPORT", "PAGE"]

#: The files and folder written inside a rig job's output folder.
NEUTRAL, SHAPES, GLB, REPORT = "neutral.obj", "shapes", "rig.glb", "rig.json"
#: the rig's HTML page (:func:`facewrap.report.rig_page.write_rig_page`)
PAGE = "rig.html"


@dataclass
class RigJob:
    """Files of one person's rig (settings live apart, in :class:`WrapSettings`).

    Attributes
    ----------
    template : path
        Template mesh (OBJ/PLY) whose topology the rig keeps.
    scan : path
        The person's neutral scan (OBJ/PLY).
    blendshapes : path
        Folder of the template's shapes (meshes in its topology): the hybrid model
        fits with them, and each becomes one of the person's.
    output : path
        Output folder: neutral.obj (+ .mtl, baked images), shapes/<name>.obj,
        rig.glb and rig.json.
    expression_scans : list of path
        Scans of the person's expressions (OBJ/PLY; any head pose): each corrects
        the shapes (example-based rigging).  Empty: the neutral only.
    scan_landmarks : path, optional
        The neutral scan's points: 'x y z' text, menpo .ljson or facewrap JSON;
        unset: the 68 iBUG points are detected on the scan.
    expression_landmarks : list of path
        One landmark file per expression scan, in their order (as
        ``scan_landmarks``); empty: detected on each scan.
    template_landmarks : path, optional
        Template vertex ids (text) or facewrap landmark JSON; default: the
        template profile's landmarks.
    template_profile : path, optional
        The template's profile (ICT-FaceKit's vertex_indices.json or facewrap's
        own): landmarks, fitting vertices and the skull-rigid vertices that hold
        the personalised shapes in place.  Default: the one found beside the
        template, if any; "none" uses none.
    exclude : path, optional
        Template vertex ids that follow but are not pulled to the scan.
    fit_mask : path, optional
        The only template vertex ids pulled onto the scan.
    pin : path, optional
        Template vertex ids kept exactly where the landmark similarity puts them.
    texture : path, optional
        The neutral scan's texture image, baked into the template's UV layout.
    expression_textures : list of path
        One texture image per expression scan, in their order; with ``texture``,
        each expression's wrap is refined by matching the textures (optical flow,
        :func:`facewrap.rig.refine_by_texture`).  Empty: geometry only.
    texture_size : int
        Baked image size in pixels.
    method : {"deformation", "delta"}
        How the template's shapes are carried onto the person: deformation
        transfer, or the displacements as they are.
    texture_flow : bool
        Refine the expression wraps by texture where the textures are given (needs
        OpenCV, the extra ``facewrap[flow]``; without it, a warning).
    units : str
        Unit of the scan's coordinates: auto (inferred from the head's size), mm,
        cm, m or in.
    """
    template: str = input_field()
    scan: str = input_field()
    blendshapes: str = input_field()
    output: str = output_field()
    expression_scans: list[str] = input_field(default_factory=list)
    scan_landmarks: str | None = input_field(default=None)
    expression_landmarks: list[str] = input_field(default_factory=list)
    template_landmarks: str | None = input_field(default=None)
    template_profile: str | None = input_field(default=None)
    exclude: str | None = input_field(default=None)
    fit_mask: str | None = input_field(default=None)
    pin: str | None = input_field(default=None)
    texture: str | None = input_field(default=None)
    expression_textures: list[str] = input_field(default_factory=list)
    texture_size: int = output_field(path=False, default=1024)
    # how the outputs are made, not a file: the [outputs] table, never resolved
    method: str = output_field(path=False, default="deformation")
    texture_flow: bool = output_field(path=False, default=True)
    units: str = field(default="auto", metadata={"table": "inputs", "path": False})


def neutral_wrap_job(job: RigJob, folder=None) -> WrapJob:
    """The wrap of the neutral scan, writing ``neutral.obj`` (and its material and
    images) into ``folder`` (default: the rig's output folder)."""
    return WrapJob(template=job.template, scan=job.scan, scan_landmarks=job.scan_landmarks,
                   output=os.path.join(os.fspath(folder or job.output), NEUTRAL),
                   template_landmarks=job.template_landmarks,
                   template_profile=job.template_profile, blendshapes=job.blendshapes,
                   exclude=job.exclude, fit_mask=job.fit_mask, pin=job.pin,
                   texture=job.texture, texture_size=job.texture_size, units=job.units)


def expression_wrap_job(job: RigJob, k: int) -> WrapJob:
    """The wrap of expression scan ``k``, for reading and checking its files (it
    writes nothing; the template's shapes and texture are the neutral's)."""
    landmarks = job.expression_landmarks[k] if job.expression_landmarks else None
    texture = job.expression_textures[k] if job.expression_textures else None
    return WrapJob(template=job.template, scan=job.expression_scans[k],
                   scan_landmarks=landmarks, texture=texture,
                   output=os.path.join(job.output, NEUTRAL),
                   template_landmarks=job.template_landmarks,
                   template_profile=job.template_profile, units=job.units)


def rig_job_inputs(job: RigJob) -> list[str]:
    """Input paths of ``job`` (files or folders): the neutral wrap's, then the
    expression scans and their landmarks."""
    return (job_inputs(neutral_wrap_job(job)) + list(job.expression_scans)
            + list(job.expression_landmarks) + list(job.expression_textures))


def _rig_files(job: RigJob) -> list[str]:
    """The GLB, the report and a shape file per OBJ of the blendshapes folder (the
    shapes are named after their files), known before anything is read."""
    folder = Path(job.blendshapes)
    names = [p.stem for p in folder_files(folder, [".obj"])] if folder.is_dir() else []
    return ([os.path.join(job.output, name) for name in (GLB, REPORT, PAGE)]
            + [os.path.join(job.output, SHAPES, f"{name}.obj") for name in names])


def rig_job_outputs(job: RigJob) -> list[str]:
    """What :func:`run_rig_job` writes: the neutral (and its material library and
    images), the shapes folder and its files, the GLB and the report."""
    return (job_outputs(neutral_wrap_job(job)) + [os.path.join(job.output, SHAPES)]
            + _rig_files(job))


def check_rig_job_paths(job: RigJob, source=None) -> None:
    """Check the outputs and choices before any work.

    The neutral's checks are a wrap job's (:func:`~facewrap.jobs.wrap_job.check_job_paths`:
    texture size, units, writable, apart from the inputs); the output folder, its
    shapes folder, GLB and report must be apart from every input too.

    Parameters
    ----------
    job : RigJob
    source : path, optional
        The file the job came from (job file, manifest), named in errors.

    Raises
    ------
    InputError
    """
    check_job_fields(job, RigJob)
    if job.method not in PERSONALISE_METHODS:
        raise InputError(f"method must be one of {', '.join(PERSONALISE_METHODS)}; got "
                         f"{job.method!r}", source)
    for files, what, flag, none in (
            (job.expression_landmarks, "expression landmark file(s)",
             "--expression-landmarks", "none to detect them"),
            (job.expression_textures, "expression texture(s)", "--expression-textures",
             "none")):
        if files and len(files) != len(job.expression_scans):
            raise InputError(f"{len(files)} {what} ({flag}) for "
                             f"{len(job.expression_scans)} expression scan(s); give one "
                             f"per scan, or {none}", source or files[0])
    if not isinstance(job.texture_flow, bool):
        raise InputError(f"texture_flow must be true or false, got {job.texture_flow!r}",
                         source)
    check_job_paths(neutral_wrap_job(job), source)
    check_output_paths(files=_rig_files(job),
                       folders=[job.output, os.path.join(job.output, SHAPES)],
                       inputs=rig_job_inputs(job), source=source)


def _files(scan: str, landmarks: str | None, job: RigJob) -> dict:
    """The file each of a wrap's refusals and warnings is about (they start
    ``"scan landmarks: ..."``)."""
    return {"scan": scan, "scan landmarks": landmarks or scan,
            "template landmarks": (job.template_landmarks or job.template_profile
                                   or job.template), "template": job.template}


def _named(notes, files: dict) -> list[str]:
    """A wrap's warnings, each naming the file it is about."""
    return [f"{files[about]}: {text}" if about in files else f"{about}: {text}"
            for about, _, text in (note.partition(": ") for note in notes)]


def _build(job: RigJob, settings: WrapSettings, inputs: dict, expressions: list,
           graph_cache):
    """:func:`~facewrap.rig.build_rig` on the read inputs; the wrap's refusals name
    the file they are about (the neutral's, when there are no expression scans to
    tell it from)."""
    profile = inputs["profile"]
    # every scan's tree is the one its reading built (for its landmark checks)
    options = {"exclude": inputs["exclude"], "fit_mask": inputs["fit_mask"],
               "pinned": inputs["pinned"], "graph_cache": graph_cache,
               "scan_tree": inputs["scan_tree"],
               "expression_scan_trees": [e["scan_tree"] for e in expressions]}
    if job.texture_flow:       # the refinement's images, checked at the door
        for path, image in [(p, e["texture"])
                            for p, e in zip(job.expression_textures, expressions)]:
            if image is not None and min(np.shape(image)[:2]) < MIN_IMAGE_SIDE:
                raise InputError(f"a {np.shape(image)[1]} x {np.shape(image)[0]} px image "
                                 f"is too small for the texture refinement (at least "
                                 f"{MIN_IMAGE_SIDE} px a side; --no-texture-flow skips it)",
                                 path)
    template_landmarks = inputs["template_landmarks"]
    named = [e["template_landmarks"] for e in expressions if "scan" in e["detections"]]
    if template_landmarks.names is None and named:
        # detected landmarks are named: pair them with the same template landmarks
        # named as the detection read them (68 unnamed ones in iBUG order)
        template_landmarks = named[0]
    try:
        return build_rig(inputs["template"], inputs["scan"], template_landmarks,
                         inputs["scan_landmarks"], inputs["blendshapes"],
                         settings=settings, method=job.method,
                         rigid_vertices=None if profile is None else profile.rigid,
                         expression_scans=[e["scan"] for e in expressions],
                         expression_landmarks=[e["scan_landmarks"] for e in expressions],
                         texture=inputs["texture"],
                         expression_textures=[e["texture"] for e in expressions],
                         texture_flow=TextureFlowSettings(enabled=job.texture_flow,
                                                          texture_size=job.texture_size),
                         **options)
    except ValueError as exc:
        # an expression's wrap says which it is (FrameError); else it is the neutral's
        about, _, text = str(exc).partition(": ")
        files = _files(job.scan, job.scan_landmarks, job)
        if isinstance(exc, FrameError):
            own = expression_wrap_job(job, exc.frame)
            files = _files(own.scan, own.scan_landmarks, job)
            if about not in files:   # a refusal about no file of its own: the scan's
                about, text = "scan", str(exc)
        if about in files:
            raise InputError(text, files[about]) from None
        raise


def _examples_report(job: RigJob, rig, expressions: list) -> list[dict]:
    """Per expression scan: its files, weights, rigid pose and the rig's error."""
    fit = rig.examples
    return [{"scan": scan,
             "scan_landmarks_source": "detected" if "scan" in e["detections"] else "file",
             "weights": {k: round(float(v), 6) for k, v in weights.items()},
             "error": dict(error), "neutral_only_error": dict(prior),
             "pose": None if pose is None else pose.matrix.tolist(),
             "fit": {k: w.metrics[k] for k in ("fit_mean", "fit_p95", "landmark_mean")
                     if k in w.metrics},
             "texture_flow": _flow_report(flow)}
            for scan, e, weights, error, prior, pose, w, flow in zip(
                job.expression_scans, expressions, fit.weights, fit.errors,
                fit.prior_errors, fit.poses or [None] * len(expressions),
                rig.expression_wraps,
                rig.texture_refinements or [None] * len(expressions))]


def _flow_report(refinement) -> dict | None:
    """How the texture refined an expression's wrap (distances in the report's
    units); None where it did not run."""
    if refinement is None:
        return None
    return {"rounds_kept": sum(r["kept"] for r in refinement.rounds),
            "matches": refinement.rounds[0]["matches"] if refinement.rounds else 0,
            "moved_mean": refinement.moved, "seconds": refinement.seconds}


def _write_shapes(folder: Path, rig, images: dict, library: bool) -> None:
    """One OBJ per shape, with the neutral's UVs and materials (``../neutral.mtl``)."""
    face_materials, materials, _ = material_images(rig.neutral, images)
    # every shape is the neutral's topology with its own vertices
    topology = with_library(rig.neutral, "../" + Path(NEUTRAL).with_suffix(".mtl").name
                            if library else None, face_materials, materials)
    write_obj_series([folder / f"{name}.obj" for name in rig.shapes], topology,
                     list(rig.shapes.values()))


def _final(path, staged: Path, output: str) -> str:
    """Where a file written under the staged folder ends up."""
    return os.path.join(output, os.path.relpath(os.fspath(path), staged))


def _write_rig_outputs(job: RigJob, rig, inputs: dict, report: dict,
                       expression_scans=()) -> None:
    """Neutral, shapes, GLB, report and page, staged in one folder moved into place
    whole."""
    t0 = time.perf_counter()
    with staged_outputs() as stage:
        staged = stage.folder(job.output)
        wrap_job = neutral_wrap_job(job, staged)
        neutral = {"timings": {}, "read_seconds": 0.0, "units": report["units"]}
        images = textureoutput_field(wrap_job)
        # the texture the refinement baked is the neutral's: written, not baked again
        reuse = rig.texture is not None and tuple(rig.texture.images) == tuple(images)
        write_wrap_outputs(wrap_job, rig.wrap, inputs, neutral,
                           baked=rig.texture if reuse else None)
        shapes = staged / SHAPES
        shapes.mkdir()
        _write_shapes(shapes, rig, images, "material_library" in neutral)
        if images:   # the baked PNGs as they are, by texture set (as facewrap wrap)
            textures = {(s.tile, s.materials): Path(p).read_bytes()
                        for s, p in images.items()}
        else:        # the template's own base colour, where its files name one
            textures = file_textures(job.template, inputs["template"])
        metres = metres_per_unit(report["units"])
        rig.write_gltf(staged / GLB, scale=metres or 1.0, textures=textures)
        if "texture" in neutral:
            texture = neutral["texture"]
            texture["image"] = _final(texture["image"], staged, job.output)
            for item in texture["images"]:
                item["image"] = _final(item["image"], staged, job.output)
            report["texture"] = texture
        report["outputs"] = {
            "neutral": os.path.join(job.output, NEUTRAL),
            "material_library": (_final(neutral["material_library"], staged, job.output)
                                 if "material_library" in neutral else None),
            "shapes": {k: os.path.join(job.output, SHAPES, f"{k}.obj") for k in rig.shapes},
            "gltf": {"path": os.path.join(job.output, GLB), "scale": metres or 1.0,
                     "units": "m" if metres else report["units"]},
            "report": os.path.join(job.output, REPORT),
            "page": os.path.join(job.output, PAGE)}
        from facewrap.report.rig_page import write_rig_page   # only a rig needs it
        write_rig_page(staged, rig, inputs["scan"], expression_scans=expression_scans,
                       units=report["units"], textures=textures,
                       warnings=report["warnings"], filename=PAGE)
        timings = report["timings"]
        # the neutral's bake: the rig's (for its refinement; writing it is writing),
        # else the writing's
        bake = 0.0 if reuse else neutral["timings"].get("bake", 0.0)
        timings["texture"] = timings.get("texture", 0.0) + bake
        timings["writing"] = time.perf_counter() - t0 - bake
        # not a sum of them all: the rig's bake and refinements ran beside its wraps
        timings["total"] = timings["read"] + rig.timings["total"] + bake + timings["writing"]
        with atomic_write(staged / REPORT, "w") as fh:
            json.dump(report, fh, indent=1)


def _report(job: RigJob, rig, inputs: dict, expressions: list, read_seconds: float,
            notes: list) -> dict:
    """The rig's report before its outputs are written (they add paths and times)."""
    result = rig.wrap
    units, source = resolve_units(job.units, rig.neutral.surface_points())
    report = {"job": {k: v for k, v in asdict(job).items() if v is not None},
              "settings": asdict(result.settings), "method": rig.method,
              "units": units, "units_source": source,
              "vertices": rig.neutral.n_vertices,
              # distances in the report's units, as a wrap job's
              "metrics": result.metrics, "iterations": result.history,
              "transform": result.transform.matrix.tolist(),
              "vertex_roles": role_ranges(result.roles),
              "shapes": list(rig.shapes),
              "timings": {"read": read_seconds,
                          **{k: v for k, v in rig.timings.items() if k != "total"}},
              "warnings": notes,
              "scan_landmarks_source": "detected" if "scan" in inputs["detections"]
              else "file"}
    detected = {k: detection_report(v) for k, v in inputs["detections"].items()}
    detected.update({f"expression scan {k + 1}": detection_report(e["detections"]["scan"])
                     for k, e in enumerate(expressions) if "scan" in e["detections"]})
    if detected:   # the neutral's ("scan", "template"), then each expression scan's
        report["detected_landmarks"] = detected
    if inputs["profile"] is not None:
        report["template_profile"] = {"path": inputs["profile"].path,
                                      "gives": inputs["profile"].summary()}
    if result.weights is not None:
        report["blend_weights"] = dict(zip(result.shape_names,
                                           np.round(result.weights, 6).tolist()))
    if rig.examples is not None:
        report["examples"] = _examples_report(job, rig, expressions)
    return report


def _check_expression_scans(job: RigJob, inputs: dict, expressions: list) -> None:
    """The expression scans against the template and the neutral, before any fit:
    the template itself among them, or one in another unit, is refused (its wrap would fit a head ten times the size, or fail naming
    no file); one given twice, or the neutral given again, is a warning line."""
    scans = [inputs["scan"]] + [e["scan"] for e in expressions]
    # (the neutral may be: a rig of the template itself is a smoke test)
    check_not_template(inputs["template"], scans[1:], job.expression_scans)
    check_scan_sizes(scans, [job.scan, *job.expression_scans], "the neutral scan")
    inputs["warnings"] += repeated_scans(
        scans, [f"the neutral scan ({job.scan})"] + [
            f"expression scan {k + 1} ({p})" for k, p in enumerate(job.expression_scans)])


def run_rig_job(job: RigJob, settings: WrapSettings | None = None, *,
                graph_cache: GraphCache | None = None) -> dict:
    """Build one person's rig and write it; returns the report as a dict.

    Parameters
    ----------
    job : RigJob
    settings : WrapSettings, optional
        The neutral's wrap (default: the defaults, which with blendshapes is the
        hybrid model).
    graph_cache : GraphCache, optional
        The template's deformation graphs between jobs (a batch of people).

    Returns
    -------
    dict
        What ``OUT/rig.json`` holds: ``units``, ``timings`` (``read``, ``wrap``,
        ``shapes``, ``texture``, ``writing``, ``total`` and, with expression scans,
        ``expressions``, ``stabilise``, ``examples``, ``texture_flow``; seconds;
        ``texture``, the neutral's bake, ran beside the shapes (and the expression
        wraps), ``stabilise`` and ``texture_flow`` beside the wraps: part of those,
        not added to them, see :class:`~facewrap.rig.Rig`),
        ``metrics`` (the neutral's fit, in ``units``), ``method``, ``shapes``
        (names), ``outputs``,
        ``warnings`` (each also issued as an :class:`InputWarning`) and, with
        expression scans, ``examples``: per scan its ``weights`` (name → [0, 1]),
        ``error`` (``mean``, ``p95``: the rig at those weights against the scan's
        wrap, in ``units``), ``neutral_only_error`` (the same for the shapes
        before the examples corrected them), ``pose`` (the 4 x 4 rigid motion
        that stabilised it) and ``fit`` (its wrap's distances).

    Raises
    ------
    InputError
        Naming the file, before anything is written.
    """
    settings = expect_instance(settings, WrapSettings, "settings", optional=True) or WrapSettings()
    check_rig_job_paths(job)
    # on a terminal, one line that says which step runs (the wraps draw their own)
    with progress(3, "rig: reading the scans") as bar:
        t0 = time.perf_counter()
        inputs = load_wrap_inputs(neutral_wrap_job(job), settings)
        expressions = [load_wrap_inputs(expression_wrap_job(job, k), settings)
                       for k in range(len(job.expression_scans))]
        _check_expression_scans(job, inputs, expressions)
        read_seconds = time.perf_counter() - t0
        if "scan" in inputs["detections"]:   # millimetres off: the surface leads
            settings = detected_landmark_settings(settings)
        bar.update(completed=1, description="rig: wrapping, making the shapes")
        rig = _build(job, settings, inputs, expressions, graph_cache)
        bar.update(completed=2, description="rig: writing")
        report = _finish(job, rig, inputs, expressions, read_seconds)
        bar.advance()
    return report


def _finish(job: RigJob, rig, inputs: dict, expressions: list, read_seconds: float
            ) -> dict:
    """Refuse a rig that is not finite, issue the warnings, write the outputs."""
    if not np.isfinite(rig.neutral.vertices).all() or not all(
            np.isfinite(v).all() for v in rig.shapes.values()):
        raise InputError("the rig has non-finite positions (degenerate input?)", job.scan)
    notes = list(inputs["warnings"]) + _named(
        rig.wrap.warnings, _files(job.scan, job.scan_landmarks, job))
    for k, (e, w) in enumerate(zip(expressions, rig.expression_wraps)):
        wrap_job = expression_wrap_job(job, k)
        notes += e["warnings"] + _named(w.warnings, _files(
            wrap_job.scan, wrap_job.scan_landmarks, job))
    for note in notes:
        warnings.warn(note, InputWarning, stacklevel=3)
    report = _report(job, rig, inputs, expressions, read_seconds, notes)
    if metres_per_unit(report["units"]) is None:
        # glTF's unit is the metre: a head of unknown unit is written as it is
        note = (f"{os.path.join(job.output, GLB)}: the data's unit is unknown, so the "
                "GLB (in metres, by glTF's rule) holds the coordinates unscaled: "
                "--units (the job key units) to set it")
        warnings.warn(note, InputWarning, stacklevel=3)
        report["warnings"].append(note)
    _write_rig_outputs(job, rig, inputs, report, [e["scan"] for e in expressions])
    return report
