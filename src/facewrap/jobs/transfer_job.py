"""A transfer job from files to files: what ``facewrap transfer``, job files and batches run.

:class:`TransferJob` names the inputs, the outputs and the settings of one
deformation transfer (Sumner & Popović 2004, SPEC §3) or, with
``landmark_guided``, of avatar blendshapes (Onizuka et al. 2019, SPEC §4);
:func:`run_transfer_job` reads and checks the inputs, fits the model, transfers
every source shape and writes one OBJ per shape in the target's topology, an
optional GLB with morph targets and an optional JSON report, each atomically.
The shape OBJs name one material library, :data:`SHAPE_LIBRARY` written beside
them (the target's materials, texture paths rebased), or none when the target has
no materials.
Every input problem is an :class:`~facewrap.errors.InputError` naming the file.

The report has the shape of a wrap job's (``"job"``, ``"settings"``,
``"timings"`` with ``"total"``, ``"metrics"``, ``"warnings"``) plus what is
particular to a transfer (``"shapes"``, ``"outputs"``, ``"correspondence"``,
``"flip_repairs"``, ``"ambiguity"``).

A correspondence file (``correspondence``) is a cache: read when it exists (and
checked against the meshes and the marker pairs), else computed and written there.
It is neither an input nor an output of the job for batches: finding it or not
gives the same result up to the solver's round-off.

As for :class:`~facewrap.jobs.wrap_job.WrapJob`, each path field says in its
``metadata`` which job-file table it belongs to (:mod:`facewrap.jobs.fields`); the
settings are the ``[transfer]`` table.
"""

from __future__ import annotations

import json
import os
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from facewrap.avatar import IBUG51_PARTS, AvatarTransfer, read_parts
from facewrap.datasets import load_shape_folder
from facewrap.errors import InputError, InputWarning
from facewrap.io import read_mesh
from facewrap.io.atomic import atomic_write
from facewrap.io.files import folder_files
from facewrap.io.gltf import gltf_format, write_gltf_morphs
from facewrap.io.landmarks import read_markers
from facewrap.io.mtl import library_beside, write_mtl
from facewrap.io.obj import read_obj_vertices, write_obj
from facewrap.io.paths import check_output_paths, staged_outputs
from facewrap.texture.tiles import file_textures
from facewrap.jobs.fields import check_job_fields, input_field, output_field
from facewrap.jobs.input_checks import check_surface, oversized_shapes, survey_mesh
from facewrap.params import Flag, Interval, NoneAllowed, expect_instance, validate
from facewrap.transfer import (Correspondence, DeformationTransfer, ambiguity_summary,
                               check_markers, find_correspondence, partner_ambiguity)
from facewrap.transfer.constraints import marker_placement

__all__ = ["TransferJobSettings", "TransferJob", "run_transfer_job",
           "transfer_job_inputs", "transfer_job_outputs", "check_transfer_job_paths",
           "read_source_shapes", "SHAPE_LIBRARY"]

#: The material library the shape OBJs of ``out`` share (written inside ``out``).
SHAPE_LIBRARY = "materials.mtl"


@dataclass
class TransferJobSettings:
    """Settings of a transfer job (the ``[transfer]`` table of a job file).

    Attributes
    ----------
    landmark_guided : bool
        Avatar blendshapes (Onizuka et al. 2019: landmark motion with per-part
        frames) instead of plain deformation transfer.
    anchor : int, optional
        Target vertex kept in place (plain transfer); default: follow the markers'
        centroid.
    fix_flips : bool
        Re-solve a pose with new flipped triangles locally until none is left.
    ambiguity : bool
        Also measure where the result depends on the correspondence and name
        target vertices where more markers would help.
    gltf_scale : float
        Scale of the positions in the GLB (0.01 for cm → m), in [1e-6, 1e6].
    """
    landmark_guided: bool = False
    anchor: int | None = None
    fix_flips: bool = True
    ambiguity: bool = False
    gltf_scale: float = 1.0

    #: allowed values of every field, checked at construction (:mod:`facewrap.params`)
    constraints = {
        "landmark_guided": Flag(),
        "anchor": (NoneAllowed(), Interval(int, 0, None)),
        "fix_flips": Flag(),
        "ambiguity": Flag(),
        # a bound keeps every scaled coordinate (at most 1e15, the readers' limit)
        # inside float32, the GLB's positions: 1e308 overflowed into a JSON error;
        # below 1e-6 (micrometres to metres) a head's positions round to zero in
        # float32 and the GLB holds a point, written without a word (1e-300)
        "gltf_scale": Interval(float, 1e-6, 1e6),
    }

    def __post_init__(self):
        validate(self)


@dataclass
class TransferJob:
    """Files and settings of one transfer.

    Attributes
    ----------
    source_neutral : path
        Source reference mesh (OBJ/PLY).
    target_neutral : path
        Target reference mesh (OBJ/PLY), whose topology the results keep.
    markers : path
        Marker pairs ``source_vid target_vid`` per line (optional count line first,
        0-based), ``.yml`` or facewrap marker JSON; landmark-guided: the landmarks in
        part order.
    source_shapes : list of path
        Folders of OBJ shapes and/or OBJ files in the source topology.
    out : path
        Output folder: one OBJ per shape, named after it.
    parts : path, optional
        Face parts JSON of a landmark-guided transfer (default: 51-point iBUG).
    correspondence : path, optional
        Correspondence cache (``.npz``): read when it exists, else written.
    gltf : path, optional
        GLB with the target neutral and one named morph target per shape.
    report : path, optional
        JSON report (timings, counts, flip repairs, ambiguity).
    settings : TransferJobSettings
        The ``[transfer]`` table.
    """
    source_neutral: str = input_field()
    target_neutral: str = input_field()
    markers: str = input_field()
    source_shapes: list[str] = input_field()
    out: str = output_field()
    parts: str | None = input_field(default=None)
    correspondence: str | None = input_field(default=None)  # a cache, see the module
    gltf: str | None = output_field(default=None)
    report: str | None = output_field(default=None)
    settings: TransferJobSettings = field(default_factory=TransferJobSettings,
                                          metadata={"table": "transfer"})


def transfer_job_inputs(job: TransferJob) -> list[str]:
    """Input paths of ``job`` that are set (files or folders; not the cache)."""
    out = [job.source_neutral, job.target_neutral, job.markers, *job.source_shapes]
    return out + ([job.parts] if job.parts else [])


def transfer_job_outputs(job: TransferJob) -> list[str]:
    """What :func:`run_transfer_job` writes: the shape folder, GLB and report."""
    return [p for p in (job.out, job.gltf, job.report) if p]


def check_transfer_job_paths(job: TransferJob, source=None) -> None:
    """Check the outputs before any work: apart from inputs, writable, none twice.

    The shape files written inside ``out`` are checked too once their names are
    known (:func:`run_transfer_job`, after reading the shapes, before the fit).

    Parameters
    ----------
    job : TransferJob
    source : path, optional
        The file the job came from (job file, manifest), named in errors.

    Raises
    ------
    InputError
    """
    check_job_fields(job, TransferJob)
    expect_instance(job.settings, TransferJobSettings, "TransferJob.settings")
    if not job.source_shapes:
        raise InputError("no source shapes given", source or job.source_neutral)
    if job.gltf:  # .glb or .gltf: refused before the fit, not after the shapes are written
        gltf_format(job.gltf)
    # the correspondence cache is read when it exists, else written
    cache = [job.correspondence] if job.correspondence else []
    cache_read = [p for p in cache if Path(p).is_file()]
    cache_written = [p for p in cache if not Path(p).is_file()]
    files = [p for p in (job.gltf, job.report) if p]
    check_output_paths(files=files + cache_written, folders=[job.out],
                       inputs=transfer_job_inputs(job) + cache_read, source=source)


def read_source_shapes(items, reference) -> dict[str, np.ndarray]:
    """Shapes ``name -> (n, 3) float64`` from folders and/or OBJ files.

    Parameters
    ----------
    items : sequence of path
        Folders (every OBJ inside, a copy of ``reference`` skipped) or OBJ files
        (named by their stem).
    reference : Mesh
        The source neutral; every shape must have its vertex count.

    Raises
    ------
    InputError
        Naming a missing or malformed file, or when no shape is found.
    """
    shapes, origin = {}, {}
    for item in items:
        p = Path(item)
        if p.is_dir():
            files = {q.stem: q for q in folder_files(p, [".obj"])}
            found = {name: (v, files.get(name, p))
                     for name, v in load_shape_folder(p, reference).items()}
        elif p.is_file():
            found = {p.stem: (read_obj_vertices(p, reference.n_vertices), p)}
        else:
            raise InputError("no such file or folder", p)
        for name, (v, path) in found.items():
            # each shape is written to NAME.obj: a second one of a name would
            # silently take the first one's place (one file given twice is one shape)
            if name in origin and not os.path.samefile(origin[name], path):
                raise InputError(f"two source shapes are named {name!r} ({origin[name]} "
                                 f"and {path}); each is written as {name}.obj: rename "
                                 "one", path)
            shapes[name], origin[name] = v, path
    if not shapes:
        raise InputError("no source shapes given", items[0] if items else None)
    return shapes


def _read_inputs(job: TransferJob) -> dict:
    """Meshes, marker ids, shapes and the cached correspondence (or None), checked."""
    source = read_mesh(job.source_neutral)
    target = read_mesh(job.target_neutral)
    notes = []
    for mesh, path, what in ((source, job.source_neutral, "source neutral"),
                             (target, job.target_neutral, "target neutral")):
        # a point cloud, or triangles of zero area: no surface to deform (the
        # latter solved silently into garbage, their gradients undefined)
        areas = check_surface(mesh, path, what, "deformation transfer needs a surface")
        # some such triangles, repeated or non-manifold ones: said, as a wrap's
        # template (a third of a target's triangles flat moved the shapes by mm)
        notes += survey_mesh(mesh, path, what, pieces=False, areas=areas)
    src_ids, tgt_ids = check_markers(read_markers(job.markers), source.n_vertices,
                                     target.n_vertices, job.markers)
    # a mirrored pairing, other units, too few pairs: said, with the file
    notes += [f"{job.markers}: {w}" for w in marker_placement(source.vertices[src_ids],
                                                               target.vertices[tgt_ids])]
    anchor = job.settings.anchor
    if anchor is not None and not job.settings.landmark_guided \
            and anchor >= target.n_vertices:
        raise InputError(f"anchor {anchor} out of range (target has "
                         f"{target.n_vertices} vertices)", job.target_neutral)
    shapes = read_source_shapes(job.source_shapes, source)
    for item in job.source_shapes:   # a pose in other units, mirrored or moved: said
        names = ({q.stem for q in folder_files(item, [".obj"])} if Path(item).is_dir()
                 else {Path(item).stem})
        notes += oversized_shapes({k: v for k, v in shapes.items() if k in names},
                                  source, item, what="source neutral")
    corr = None
    if job.correspondence and Path(job.correspondence).is_file():
        corr = Correspondence.load(job.correspondence)
        # made with other markers (the file edited since), it answered for the old
        # ones: the new markers were ignored without a word
        corr.check(source, target, job.correspondence,
                   markers=np.column_stack([src_ids, tgt_ids]))
    return {"source": source, "target": target, "markers": (src_ids, tgt_ids),
            "shapes": shapes, "correspondence": corr, "warnings": notes}


def _fit(job: TransferJob, inputs: dict):
    """The fitted transfer model (its ``correspondence_`` found or reused)."""
    s = job.settings
    source, target = inputs["source"], inputs["target"]
    src_ids, tgt_ids = inputs["markers"]
    corr = inputs["correspondence"]
    if s.landmark_guided:
        parts = read_parts(job.parts) if job.parts else IBUG51_PARTS
        return AvatarTransfer(parts=parts, fix_flips=s.fix_flips).fit(
            source, src_ids, target, tgt_ids, correspondence=corr,
            landmarks_path=job.markers)
    if corr is None:
        corr = find_correspondence(source, target, (src_ids, tgt_ids),
                                   markers_path=job.markers)
    anchor = "markers" if s.anchor is None else s.anchor
    return DeformationTransfer(anchor=anchor, fix_flips=s.fix_flips).fit(source, target,
                                                                         corr)


def _shape_files(job: TransferJob, names) -> list[Path]:
    """The OBJ that each shape is written to, inside ``job.out``, and the material
    library they share (checked whether or not the target has materials)."""
    return [Path(job.out) / f"{name}.obj" for name in names] + [
        Path(job.out) / SHAPE_LIBRARY]


def _write_shapes(job: TransferJob, stage, target, names, results) -> list[str]:
    """One OBJ per shape in ``job.out``, their material library (when the target
    has materials) and the GLB, staged; returns the OBJ paths."""
    folder = stage.folder(job.out)
    # the library's texture paths are rebased onto job.out, where it will lie
    shaped, library = library_beside(target, job.target_neutral,
                                     Path(job.out) / SHAPE_LIBRARY, SHAPE_LIBRARY)
    if library is not None:
        write_mtl(folder / SHAPE_LIBRARY, library)
    for name, X in zip(names, results):
        write_obj(folder / f"{name}.obj", shaped.with_vertices(X))
    if job.gltf:
        # the target's own base-colour images, when its file says which they are
        write_gltf_morphs(stage.file(job.gltf), target, dict(zip(names, results)),
                          scale=job.settings.gltf_scale,
                          textures=file_textures(job.target_neutral, target))
    return [str(p) for p in _shape_files(job, names)[:len(names)]]


def _repairs(repairs, names) -> dict:
    """Per shape with new flipped triangles: found / repaired / remaining / rounds."""
    if not repairs:
        return {}
    return {name: {k: int(v[i]) for k, v in repairs.items()}
            for i, name in enumerate(names) if repairs["found"][i]}


def _report(job: TransferJob, model, names, written, ambiguity, times) -> dict:
    """The job's report; ``times``: clock at read, fit, transfer, write, ambiguity, end."""
    t0, t1, t2, t3, t4, t5 = times
    corr = model.correspondence_
    return {
        "job": {k: v for k, v in asdict(job).items() if v is not None and k != "settings"},
        "settings": asdict(job.settings),
        "source": str(job.source_neutral), "target": str(job.target_neutral),
        "method": ("landmark-guided" if job.settings.landmark_guided
                   else "deformation transfer"),
        "shapes": len(names), "outputs": written, "gltf": job.gltf,
        "correspondence": {"file": job.correspondence, "pairs": len(corr), **corr.stats},
        "flip_repairs": _repairs(getattr(model, "repairs_", None), names),
        "ambiguity": ambiguity,
        "metrics": {"shapes": len(names), "triangle_pairs": len(corr)},
        "timings": {"read": t1 - t0, "fit": t2 - t1, "transfer": t3 - t2,
                    "write": t4 - t3, "ambiguity": t5 - t4, "total": t5 - t0},
        "warnings": [],
    }


def run_transfer_job(job: TransferJob) -> dict:
    """Run one transfer job and write its outputs; returns the report as a dict.

    Parameters
    ----------
    job : TransferJob

    Returns
    -------
    dict
        The report (also written to ``job.report`` when set): ``job``,
        ``settings``, ``method``, ``shapes``, ``outputs``, ``gltf``,
        ``correspondence`` (file, pairs, statistics), ``flip_repairs``,
        ``ambiguity`` (None unless asked for), ``metrics``, ``timings`` (seconds:
        read, fit, transfer, write, ambiguity, total) and ``warnings``.

    Raises
    ------
    InputError
        Naming the file, before anything is written.
    """
    check_transfer_job_paths(job)
    t0 = time.perf_counter()
    inputs = _read_inputs(job)
    for note in inputs["warnings"]:
        warnings.warn(note, InputWarning, stacklevel=2)
    # the files written inside the output folder, now that the shapes' names are known
    check_output_paths(files=_shape_files(job, inputs["shapes"]),
                       inputs=transfer_job_inputs(job))
    t1 = time.perf_counter()
    model = _fit(job, inputs)
    corr = model.correspondence_
    if job.correspondence and not Path(job.correspondence).is_file():
        Path(job.correspondence).parent.mkdir(parents=True, exist_ok=True)
        corr.save(job.correspondence)
    t2 = time.perf_counter()
    names = list(inputs["shapes"])
    poses = np.stack([inputs["shapes"][k] for k in names])
    results = model.transfer(poses)
    t3 = time.perf_counter()
    with staged_outputs() as stage:
        written = _write_shapes(job, stage, inputs["target"], names, results)
        t4 = time.perf_counter()
        ambiguity = None
        if job.settings.ambiguity:
            ambiguity = ambiguity_summary(partner_ambiguity(
                corr, inputs["source"], inputs["target"], poses), inputs["target"])
        t5 = time.perf_counter()
        report = _report(job, model, names, written, ambiguity,
                         (t0, t1, t2, t3, t4, t5))
        report["warnings"] = list(inputs["warnings"])
        if job.report:
            with atomic_write(stage.file(job.report), "w") as fh:
                json.dump(report, fh, indent=1)
    return report

