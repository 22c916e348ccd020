"""A wrap job from files to files: what ``facewrap wrap``, job files and batches run.

:class:`WrapJob` names the inputs and outputs of one registration (paths only);
:func:`run_wrap_job` reads and checks the inputs, runs :func:`facewrap.wrapping.stages.wrap`
with a :class:`~facewrap.wrapping.stages.WrapSettings`, and writes the outputs atomically
(mesh, optional baked texture, optional JSON report).  Every input problem is an
:class:`~facewrap.errors.InputError` naming the file, raised before anything is
written; inputs are only read.

Inputs that are legal but odd (duplicate vertices, degenerate or non-manifold
faces, loose pieces, landmarks beside the scan, a scan in other units...) are fitted
anyway; each oddity becomes one line in the report's ``"warnings"`` list and an
:class:`InputWarning`.  Exact duplicate scan vertices (seams split by an exporter,
triangle soups) are merged before fitting, so they do not read as holes.

Each :class:`WrapJob` field says in its ``metadata`` which job-file table it
belongs to (:mod:`facewrap.jobs.fields`), so a new field here is a new key of job
files and batch manifests.
"""

from __future__ import annotations

import json
import logging
import os
import time
import warnings
from dataclasses import KW_ONLY, asdict, dataclass, field, fields
from pathlib import Path

import numpy as np

from facewrap.datasets import load_shape_folder
from facewrap.detection.for_wrap import (confident_landmarks, detected_landmark_settings,
                                         detection_report)
from facewrap.errors import InputError, InputWarning
from facewrap.io import read_mesh, write_mesh
from facewrap.io.landmarks import read_landmarks, read_vertex_indices
from facewrap.io.atomic import atomic_write
from facewrap.io.files import memory_budget
from facewrap.io.gltf import gltf_format, write_gltf_morphs
from facewrap.io.mtl import output_library, with_library, write_mtl
from facewrap.io.paths import check_output_paths, staged_outputs
from facewrap.io.profile import find_template_profile, read_template_profile
from facewrap.jobs.fields import check_job_fields, input_field, output_field
from facewrap.jobs.input_checks import (check_model_settings, check_scan,
                                        check_template_landmarks, check_uv_layouts,
                                        nothing_to_fit, oversized_shapes, survey_mesh,
                                        unpaired_landmarks)
from facewrap.mesh import Mesh
from facewrap.parallel import in_background
from facewrap.params import expect_instance
from facewrap.texture import load_image, save_png
from facewrap.texture.tiles import (bake_memory, bake_tiles, file_layout, material_images,
                                    tile_image_paths)
from facewrap.texture.bake import MAX_SIDE
from facewrap.texture.udim import FIRST_TILE
from facewrap.units import (check_units_choice, metres_per_unit, resolve_units,
                            units_conflict)
from facewrap.wrapping import GraphCache, WrapSettings, role_ranges, wrap

log = logging.getLogger(__name__)

__all__ = ["WrapJob", "InputWarning", "run_wrap_job", "load_wrap_inputs",
           "job_inputs", "job_outputs", "check_job_paths", "OUTPUT_FRAMES",
           "write_wrap_outputs", "textureoutput_field", "detect_mesh_landmarks",
           "detected_scan_landmarks", "detection_entry"]

#: Mesh formats an output may have.
MESH_EXTENSIONS = (".obj", ".ply")

#: Frames the fitted mesh may be written in (:attr:`WrapJob.output_frame`).
OUTPUT_FRAMES = ("scan", "template")


@dataclass
class WrapJob:
    """Files of one wrap (settings live apart, in :class:`WrapSettings`).

    ``template`` and ``scan`` may be given by position, every other field by name
    (``WrapJob("t.obj", "s.obj", output="out.obj")``).

    Attributes
    ----------
    template : path
        Template mesh (OBJ/PLY) whose topology the result keeps.
    scan : path
        Scan mesh (OBJ/PLY).
    scan_landmarks : path, optional
        Scan points: ``x y z`` text, menpo ``.ljson`` or facewrap JSON; left out
        (None), the 68 iBUG points are detected on the scan (:mod:`facewrap.detection`,
        the extra ``facewrap[landmarks]``), the low-confidence ones left out, and on
        the template too when it has no landmarks of its own.
    output : path
        Fitted mesh (OBJ/PLY) in the template's exact topology.
    template_landmarks : path, optional
        Template vertex ids (text) or facewrap landmark JSON; default: the
        template profile's landmarks.
    template_profile : path, optional
        The template's profile (:mod:`facewrap.io.profile`: ICT-FaceKit's
        ``vertex_indices.json`` or facewrap's own): landmarks, and the vertices
        meant to be fitted (pulled as a ``fit_mask`` is; the others follow).  Default: the one found
        beside the template (:func:`~facewrap.io.profile.find_template_profile`),
        if any; ``"none"`` uses none.
    blendshapes : path, optional
        Folder of meshes in the template's topology (a shape = file − template).
    exclude : path, optional
        Template vertex ids that follow but are not pulled to the scan.
    fit_mask : path, optional
        The only template vertex ids pulled onto the scan, cavities among them
        too (replaces the profile's fitting vertices); the template's parts and
        cavities outside it follow as such unless ``fit_hidden``.
    pin : path, optional
        Template vertex ids kept exactly where the landmark similarity puts them.
    texture : path, optional
        Scan texture image to bake into the template's UV layout
        (written next to ``output`` as PNG).
    texture_size : int
        Baked image size in pixels.
    report : path, optional
        JSON report (timings, iterations, fit distances, landmark errors).
    gltf : path, optional
        The fitted mesh as glTF (``.glb`` binary, ``.gltf`` JSON, by extension):
        smooth normals, a PBR material, the baked images embedded; in metres.
    output_frame : {"scan", "template"}
        Where the written mesh lies: on the scan (default), or mapped back through
        the inverse of the template → scan landmark similarity, so it overlays the
        template (a texture is baked before, on the scan).  The report's
        ``"output_frame"`` records it.
    units : str
        Unit of the scan's coordinates (and so of every distance): auto (inferred
        from the head's size), mm, cm, m or in.
    """
    template: str = input_field()
    scan: str = input_field()
    _: KW_ONLY   # by name from here: scan_landmarks may be left out, output may not
    scan_landmarks: str | None = input_field(default=None)
    output: str = output_field()
    template_landmarks: str | None = input_field(default=None)
    template_profile: str | None = input_field(default=None)
    blendshapes: str | None = input_field(default=None)
    exclude: str | None = input_field(default=None)
    fit_mask: str | None = input_field(default=None)
    pin: str | None = input_field(default=None)
    texture: str | None = input_field(default=None)
    texture_size: int = output_field(path=False, default=1024)
    report: str | None = output_field(default=None)
    gltf: str | None = output_field(default=None)
    output_frame: str = output_field(path=False, default="scan")
    # a property of the input data, not a path: the [inputs] table, never resolved
    units: str = field(default="auto", metadata={"table": "inputs", "path": False})


def _path_fields(table: str) -> list[str]:
    return [f.name for f in fields(WrapJob)
            if f.metadata.get("table", "inputs") == table and f.metadata.get("path")]


#: ``template_profile`` value that turns the search for a profile off
NO_PROFILE = "none"


def profile_path(job: WrapJob) -> str | None:
    """The template profile ``job`` uses: its own, else the one beside the template."""
    if job.template_profile == NO_PROFILE:
        return None
    if job.template_profile:
        return job.template_profile
    found = find_template_profile(job.template)
    return None if found is None else str(found)


def job_inputs(job: WrapJob) -> list[str]:
    """Input paths of ``job`` that are set, in field order (files or folders), and
    the template profile found beside the template."""
    out = [getattr(job, n) for n in _path_fields("inputs")
           if getattr(job, n) and n != "template_profile"]
    profile = profile_path(job)
    return out + ([profile] if profile else [])


def textureoutput_field(job: WrapJob) -> dict:
    """Where the baked images go: texture set → path beside ``output`` (empty when
    nothing is baked).

    One ``OUT.png`` for a 0–1 layout, else ``OUT.<tile>.png`` per used UDIM tile and
    ``OUT.<material>.<tile>.png`` for materials whose UVs overlap inside a tile
    (:mod:`facewrap.texture.tiles`).  The template is read for its layout (once per
    file version); when it cannot be read, the error comes when the inputs are.
    """
    if not job.texture:
        return {}
    try:
        sets = file_layout(job.template)[0]
    except InputError:
        sets = ()
    return tile_image_paths(job.output, sets or (FIRST_TILE,))


def job_outputs(job: WrapJob) -> list[str]:
    """Files that :func:`run_wrap_job` writes for ``job``: mesh, report, baked images
    and, for an OBJ with materials or a baked texture, its material library
    ``OUT.mtl``.  An unknown glTF extension is an InputError, before any work."""
    if job.gltf:
        gltf_format(job.gltf)
    out = [getattr(job, n) for n in _path_fields("outputs") if getattr(job, n)]
    images = list(textureoutput_field(job).values())
    mtl = []
    if Path(job.output).suffix.lower() == ".obj":
        try:
            materials = file_layout(job.template, sets=False)[1]
        except InputError:
            materials = ()
        if images or materials:
            mtl = [str(Path(job.output).with_suffix(".mtl"))]
    return out + images + mtl


def check_job_paths(job: WrapJob, source=None) -> None:
    """Check outputs before any work: formats known, apart from inputs, writable.

    Parameters
    ----------
    job : WrapJob
    source : path, optional
        The file the job came from (job file, manifest), named in errors; default
        the offending output.

    Raises
    ------
    InputError
    """
    check_job_fields(job, WrapJob)
    ext = os.path.splitext(job.output)[1].lower()
    if ext not in MESH_EXTENSIONS:
        # named as the job file's entry, or as the output path itself (said once)
        where = f"output {job.output!r}: " if source else "output: "
        raise InputError(f"{where}unknown mesh format {ext or '(no extension)'!r}; "
                         "use .obj or .ply", source or job.output)
    check_output_paths(files=job_outputs(job), inputs=job_inputs(job), source=source)
    # a setting's problem: named with the job file, or alone (not as the output's)
    # a Python int, not True (an int to Python: it baked a 1 x 1 texture without a
    # word) nor a numpy integer (which the job's JSON report cannot hold)
    size = job.texture_size
    if isinstance(size, bool) or not isinstance(size, int) or not 1 <= size <= MAX_SIDE:
        raise InputError(f"texture_size (--texture-size) must be an integer in [1, "
                         f"{MAX_SIDE}], got {job.texture_size!r}", source)
    need = bake_memory(job.texture_size)
    if job.texture and need > memory_budget():
        raise InputError(f"texture_size (--texture-size) {job.texture_size}: baking needs "
                         f"about {need / 2 ** 30:.1f} GiB of memory, more than the "
                         f"{memory_budget() / 2 ** 30:.1f} GiB budget (half the memory, "
                         "or of ulimit -v)", source)
    if job.output_frame not in OUTPUT_FRAMES:
        raise InputError(f"output_frame must be one of {', '.join(map(repr, OUTPUT_FRAMES))},"
                         f" got {job.output_frame!r}", source)
    try:
        check_units_choice(job.units)
    except ValueError as exc:
        raise InputError(str(exc), source) from None


def read_mesh_landmarks(path, mesh, kind: str = "auto"):
    """Read landmarks and check them against the mesh they belong to.

    Returns
    -------
    Landmarks

    Raises
    ------
    InputError
        Naming ``path`` when a vertex or triangle id is outside ``mesh``.
    """
    landmarks = read_landmarks(path, kind=kind)
    try:
        landmarks.check(mesh.n_vertices, len(mesh.triangles))
    except ValueError as exc:
        raise InputError(str(exc), path) from None
    return landmarks


def load_wrap_inputs(job: WrapJob, settings: WrapSettings | None = None) -> dict:
    """Read and cross-check a job's input files.

    ``settings`` (optional) are checked against what the files hold: no more
    ``pca_components`` than blendshapes.

    Returns
    -------
    dict with ``template``, ``scan`` (Mesh, duplicate vertices merged),
    ``template_landmarks``, ``scan_landmarks`` (Landmarks), ``exclude`` (int array
    or None), ``blendshapes`` (dict name → (n, 3) positions, or None),
    ``texture`` (image array or None), ``scan_tree`` (ClosestPointTree of the
    scan) and ``warnings`` (list of str, one line per legal-but-odd input).

    Raises
    ------
    InputError
        Naming the file: unreadable or malformed files, a scan without faces or
        with zero area, landmark counts that differ, landmarks in a line or off the
        scan, indices out of range.
    """
    notes: list[str] = []
    # the texture decodes beside the meshes' reading and checks (Pillow frees the GIL)
    decoding = in_background(load_image, job.texture) if job.texture else None
    template = read_mesh(job.template)
    scan = read_mesh(job.scan)
    if len(scan.triangles) == 0:
        raise InputError("has no faces; a scan must be a surface", job.scan)
    profile = _template_profile(job, template)
    detections = {}
    if not job.template_landmarks and (profile is None or profile.landmarks is None) \
            and not job.scan_landmarks:
        detections["template"] = detect_mesh_landmarks(template, job.template)
    tl, tl_source = _template_landmarks(job, template, profile, detections)
    if job.scan_landmarks:
        sl = read_mesh_landmarks(job.scan_landmarks, scan, kind="points")
    else:
        tl, sl, detections["scan"] = detected_scan_landmarks(tl, tl_source, scan,
                                                             job.scan, job.texture)
    if (tl.names is None or sl.names is None) and len(tl) != len(sl):
        raise InputError(f"has {len(sl)} landmarks but the template landmarks "
                         f"({tl_source}) have {len(tl)}", job.scan_landmarks)

    template_size = template.scale()
    if not np.isfinite(template_size):
        raise InputError("coordinates are too large (the bounding box overflows)",
                         job.template)
    if template_size == 0:
        raise InputError("template is degenerate: all vertices at one point",
                         job.template)
    notes += survey_mesh(template, job.template, "template", pieces=False)
    check_template_landmarks(template, tl, job.template_landmarks or tl_source)
    if job.scan_landmarks:   # detected ones are a confident subset by design
        notes += unpaired_landmarks(tl, sl, tl_source, job.scan_landmarks)
    scan, sl, tree, scan_notes = check_scan(scan, sl, job.scan, job.scan_landmarks,
                                            units=job.units)
    notes += scan_notes
    # a given unit off by a decade or more would mislabel every distance reported
    conflict = units_conflict(job.units, scan.surface_points())
    notes += [f"{job.scan}: {conflict}"] if conflict else []

    n = template.n_vertices
    exclude, fit_mask, pinned = (
        None if not path else read_vertex_indices(path, n_vertices=n).vertex
        for path in (job.exclude, job.fit_mask, job.pin))
    notes += nothing_to_fit(n, {p: ids for p, ids in ((job.exclude, exclude),
                                                      (job.pin, pinned)) if p})
    if profile is not None and profile.fitting is not None and fit_mask is None:
        # the profile's fitting vertices are the template author's word on what a
        # scanner sees: pulled, even where the template's shape looks hidden (ICT's
        # lips meet along a seam that the shape test calls a cavity)
        fit_mask = profile.fitting
    shapes = None
    if job.blendshapes:
        # a copy of the template inside the folder is skipped (it equals the neutral)
        shapes = load_shape_folder(job.blendshapes, template, exclude=())
        notes += oversized_shapes(shapes, template, job.blendshapes)
    check_model_settings(settings, shapes, job.blendshapes)
    image = None
    if job.texture:
        notes += check_uv_layouts(template, scan, job.template, job.scan)
        image = decoding.result()
    return {"template": template, "scan": scan, "template_landmarks": tl,
            "scan_landmarks": sl, "exclude": exclude, "fit_mask": fit_mask,
            "pinned": pinned, "profile": profile, "blendshapes": shapes,
            "texture": image, "scan_tree": tree, "warnings": notes,
            "detections": detections}


def detect_mesh_landmarks(mesh: Mesh, path, texture_path=None):
    """The 68 landmarks detected on a job's mesh, logged.

    Drawn textured with ``texture_path`` (when the mesh has texture coordinates),
    else with the image its material names, else shaded.

    Returns
    -------
    DetectedLandmarks

    Raises
    ------
    InputError
        No face on the mesh (naming ``path``), or the extra ``facewrap[landmarks]``
        missing.
    """
    from facewrap.detection import detect_landmarks, mesh_texture  # dlib loads on use

    image = load_image(texture_path) if texture_path and mesh.uvs is not None \
        else mesh_texture(path, mesh)
    found = detect_landmarks(mesh, image, source=path)
    log.info("%s: 68 landmarks detected (%d low-confidence, left out)", path,
             int(found.low_confidence.sum()))
    return found


def detection_entry(found) -> dict:
    """The report's account of one detection, with the points themselves: surface
    landmarks (triangle of the mesh file's triangulation + barycentric) and
    positions, so a report page draws them without detecting again."""
    lm = found.landmarks
    return {**detection_report(found), "names": list(lm.names),
            "triangles": lm.triangle.tolist(), "barycentric": lm.barycentric.tolist(),
            "positions": np.asarray(found.positions).tolist()}


def detected_scan_landmarks(template_landmarks, template_source, scan: Mesh, path,
                            texture_path=None):
    """Scan landmarks detected and paired with the template's as a wrap uses them.

    Returns
    -------
    (Landmarks, Landmarks, DetectedLandmarks)
        Template and scan landmarks, named, the low-confidence scan points left out
        (:func:`~facewrap.detection.for_wrap.confident_landmarks`), and the
        detection itself (for the report, :func:`detection_entry`).

    Raises
    ------
    InputError
        As :func:`detect_mesh_landmarks`; naming ``template_source`` when its
        landmarks cannot be paired with the iBUG-68 points.
    """
    found = detect_mesh_landmarks(scan, path, texture_path)
    try:
        tl, sl = confident_landmarks(template_landmarks, found)
    except ValueError as exc:
        raise InputError(str(exc).partition(": ")[2], template_source) from None
    return tl, sl, found


def _template_profile(job: WrapJob, template: Mesh):
    """The job's template profile, read and checked against the template (None
    without one)."""
    path = profile_path(job)
    if path is None:
        return None
    profile = read_template_profile(path)
    profile.check(template.n_vertices)
    return profile


def _template_landmarks(job: WrapJob, template: Mesh, profile, detections):
    """The template landmarks (from their file, else the profile, else detected) and
    where they came from."""
    if job.template_landmarks:
        return (read_mesh_landmarks(job.template_landmarks, template, kind="auto"),
                job.template_landmarks)
    if profile is not None and profile.landmarks is not None:
        return profile.landmarks, profile.path
    if "template" in detections:
        return detections["template"].landmarks, job.template
    raise InputError("no template landmarks: give --template-landmarks (template_"
                     "landmarks in a job file) or a template profile with landmarks "
                     "(see facewrap.io.profile)", job.template)


def write_wrap_outputs(job: WrapJob, result, inputs: dict, report: dict, *,
                       baked=None) -> None:
    """Mesh, baked images, material library, glTF and report, staged and moved into
    place together.

    The texture is baked inside the stage, so a failure there leaves none of the
    job's outputs behind (and an earlier run's outputs untouched); ``baked`` (a rig's
    TiledBake of ``result``, the job's sets and size) is written instead.  An OBJ
    output names its own library ``OUT.mtl`` (written beside it: the template's
    materials by name, ``map_Kd`` of each baked material at its image) or none.  The
    report's ``timings`` gain ``read``, ``bake`` and ``write``; ``total`` is then
    reading + fitting + baking + writing, and ``fit`` keeps the wrap's own total.
    """
    t_write = time.perf_counter()
    mesh, images, bake_seconds, baked_images = result.mesh, {}, 0.0, {}
    with staged_outputs() as stage:
        if inputs["texture"] is not None:
            t = time.perf_counter()
            paths = textureoutput_field(job)
            if baked is None:
                baked = bake_tiles(mesh, inputs["scan"], inputs["texture"],
                                   size=job.texture_size, tree=inputs["scan_tree"],
                                   sets=list(paths))
            for s, r in baked.images.items():
                save_png(stage.file(paths[s]), r.image)
            bake_seconds = time.perf_counter() - t
            report["texture"] = {
                "image": next(iter(paths.values())), "coverage": baked.filled_fraction,
                "seconds": bake_seconds,
                "images": [{"image": paths[s], "tile": s.tile,
                            "materials": [mesh.materials[m] for m in s.materials if m >= 0],
                            "coverage": r.filled_fraction,
                            "laid_out_texels": int(r.layout.sum()),
                            "seconds": baked.seconds[s]}
                           for s, r in baked.images.items()]}
            images = paths
            baked_images = {(s.tile, s.materials): r.image for s, r in baked.images.items()}
        if Path(job.output).suffix.lower() == ".obj":
            face_materials, materials, shown = material_images(mesh, images)
            mtl = Path(job.output).with_suffix(".mtl")
            if materials:
                write_mtl(stage.file(mtl), output_library(
                    materials, job.template, mesh.mtllib, job.output, shown))
                report["material_library"] = str(mtl)
            mesh = with_library(mesh, mtl.name if materials else None, face_materials,
                                materials)
        if job.output_frame == "template":  # baked above in the scan's frame
            mesh = mesh.with_vertices(result.transform.inverse().apply(mesh.vertices))
        write_mesh(stage.file(job.output), mesh)
        if job.gltf:  # in metres, glTF's unit (as it is when unknown); by texture set
            metres = metres_per_unit(report["units"])
            write_gltf_morphs(stage.file(job.gltf), result.mesh.with_vertices(
                mesh.vertices), {}, scale=metres or 1.0, textures=baked_images)
            report["gltf"] = {"path": job.gltf, "scale": metres or 1.0,
                              "units": "m" if metres else report["units"]}
        timings = dict(report["timings"])
        timings.update(fit=timings.get("total", 0.0), read=report["read_seconds"],
                       bake=bake_seconds,
                       write=time.perf_counter() - t_write - bake_seconds)
        timings["total"] = timings["read"] + timings["fit"] + timings["bake"] + \
            timings["write"]
        report["timings"] = timings
        if job.report:
            with atomic_write(stage.file(job.report), "w") as fh:
                json.dump(report, fh, indent=1)


def run_wrap_job(job: WrapJob, settings: WrapSettings | None = None, *,
                 graph_cache: GraphCache | None = None) -> dict:
    """Run one wrap job and write its outputs; returns the report as a dict.

    The mesh, the texture and the report are staged and moved into place together
    (:func:`facewrap.io.paths.staged_outputs`): a failed or killed run leaves none
    of them half-written or partial.  The report's ``"warnings"`` lists the
    legal-but-odd inputs met (each is also issued as an :class:`InputWarning`).
    ``graph_cache`` holds the template's deformation graphs between jobs (see
    :class:`~facewrap.wrapping.GraphCache`; default: the process-wide one), so the
    jobs of a batch that share a template build its graphs once per worker.
    """
    settings = expect_instance(settings, WrapSettings, "settings", optional=True) or WrapSettings()
    check_job_paths(job)
    t0 = time.perf_counter()
    inputs = load_wrap_inputs(job, settings)
    read_seconds = time.perf_counter() - t0
    if "scan" in inputs["detections"]:   # millimetres off: the surface leads
        settings = detected_landmark_settings(settings)
    # the wrap's plausibility checks say what they are about ("scan landmarks: ...");
    # here that becomes the file, in its warnings and in a refusal alike
    files = {"scan": job.scan, "scan landmarks": job.scan_landmarks or job.scan,
             "template landmarks": (job.template_landmarks or job.template_profile
                                    or job.template), "template": job.template}
    try:
        result = wrap(inputs["template"], inputs["scan"], inputs["template_landmarks"],
                      inputs["scan_landmarks"], settings, exclude=inputs["exclude"],
                      fit_mask=inputs["fit_mask"], pinned=inputs["pinned"],
                      blendshapes=inputs["blendshapes"], scan_tree=inputs["scan_tree"],
                      graph_cache=graph_cache)
    except ValueError as exc:
        about, _, text = str(exc).partition(": ")
        if about in files:
            raise InputError(text, files[about]) from None
        raise
    notes = list(inputs["warnings"]) + [
        f"{files[about]}: {text}" if about in files else f"{about}: {text}"
        for about, _, text in (note.partition(": ") for note in result.warnings)]
    if not np.isfinite(result.mesh.vertices).all():
        raise InputError("the fit produced non-finite positions (degenerate input?)",
                         job.scan)
    for note in notes:
        warnings.warn(note, InputWarning, stacklevel=2)
    report = {"job": {k: v for k, v in asdict(job).items() if v is not None},
              "settings": asdict(result.settings),
              "vertices": result.mesh.n_vertices,
              "read_seconds": read_seconds,
              "timings": result.timings, "metrics": result.metrics,
              "iterations": result.history,
              "transform": result.transform.matrix.tolist(),
              "vertex_roles": role_ranges(result.roles),
              "output_frame": job.output_frame,
              "warnings": notes}
    if inputs["profile"] is not None:
        report["template_profile"] = {"path": inputs["profile"].path,
                                      "gives": inputs["profile"].summary()}
    report["scan_landmarks_source"] = "detected" if "scan" in inputs["detections"] \
        else "file"
    if inputs["detections"]:
        report["detected_landmarks"] = {k: detection_entry(v)
                                        for k, v in inputs["detections"].items()}
    report["units"], report["units_source"] = resolve_units(job.units,
                                                            result.mesh.surface_points())
    if job.gltf and metres_per_unit(report["units"]) is None:   # glTF's unit: metres
        notes.append(f"{job.gltf}: the data's unit is unknown, so the glTF (in metres) "
                     "holds the coordinates unscaled: --units (the job key units) to set it")
        warnings.warn(notes[-1], InputWarning, stacklevel=2)
    if result.weights is not None:
        report["blend_weights"] = dict(zip(result.shape_names,
                                           np.round(result.weights, 6).tolist()))
    write_wrap_outputs(job, result, inputs, report)
    return report
