"""``facewrap track``: register a 4D sequence of scans (parsing and calling only).

Outputs in ``OUT``: ``frame_0000.obj``… in the template's exact topology,
``weights.csv`` (blend weights per frame) and ``track.json`` (fit and landmark
errors over time, iterations, seconds).  See :mod:`facewrap.wrapping.track`.

Landmarks: ``--scan-landmarks`` for the first frame (or every frame); left out, the
68 iBUG points are detected on the first frame (the extra ``facewrap[landmarks]``;
its low-confidence points left out) and every later frame follows the fit, as a
frame without landmarks of its own does (the fitted landmarks of the frames before,
moved on and onto its scan).  That is chosen over a detection per frame: a second
or more each, and each with its own jitter, where the previous fit is already
within a frame's motion.  The line ``frame 0 (FILE): 68 landmarks detected...``
and ``track.json`` (``scan_landmarks_source``, ``detected_landmarks``) say so.
``--template-landmarks`` left out: the template profile's (found beside the
template), else detected on the template.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from facewrap.cli.fit_options import add_fit_options, wrap_settings_from_args
from facewrap.datasets import load_shape_folder
from facewrap.errors import InputError
from facewrap.detection.for_wrap import detected_landmark_settings
from facewrap.io import read_mesh
from facewrap.io.files import folder_files
from facewrap.io.paths import check_output_paths
from facewrap.io.landmarks import read_vertex_indices
from facewrap.io.profile import find_template_profile, read_template_profile
from facewrap.jobs.input_checks import (check_not_template, check_scan, check_scan_sizes,
                                        check_template_landmarks, frames_of_another_head,
                                        repeated_scans)
from facewrap.jobs.wrap_job import (detect_mesh_landmarks, detected_scan_landmarks,
                                    detection_entry, read_mesh_landmarks)
from facewrap.progress import progress
from facewrap.units import (add_units_argument, format_distance, resolve_units,
                            units_conflict, units_note)
from facewrap.wrapping import track, write_track_outputs
from facewrap.wrapping.track import FrameError, track_output_files

__all__ = ["register", "cmd_track", "frame_warnings"]

_MESH_SUFFIXES = (".obj", ".ply")


def _scan_paths(items) -> list[Path]:
    """Scans from files and/or folders (a folder gives its meshes in name order,
    numbers by value, hidden files left out)."""
    paths = []
    for item in items:
        p = Path(item)
        if p.is_dir():
            # frames numbered without leading zeros (f_2, f_10) in their numbers' order
            found = folder_files(p, _MESH_SUFFIXES, natural=True)
            if not found:
                raise InputError("holds no OBJ or PLY scans", p)
            paths += found
        else:
            paths.append(p)
    return paths


def frame_warnings(result, scans) -> list[str]:
    """Each frame's input warnings as ``frame N (FILE): ...`` lines, in frame order."""
    return [f"frame {i} ({path}): {note}"
            for i, (path, frame) in enumerate(zip(scans, result.frames))
            for note in frame.warnings]


def _scan_landmarks(args, template, meshes, scans):
    """Template landmarks and one entry per frame (None: carried on from the fit of
    the frames before), with the detections made (``{"template"|"frame 0": ...}``).

    With no ``--scan-landmarks``, the first frame's are detected and every later
    frame's are the fitted landmarks of the frames before it, moved on and put onto
    its scan (:func:`facewrap.wrapping.track.track`): the face moves little between
    frames, so this is smoother than a detection per frame (about a second each,
    and a jitter of its own) and follows the fit."""
    template_path = args.template
    detections = {}
    if args.template_landmarks:
        tl, tl_source = read_mesh_landmarks(args.template_landmarks, template,
                                            kind="auto"), args.template_landmarks
    else:
        tl, tl_source = _profile_landmarks(template_path)
        if tl is None:
            detections["template"] = detect_mesh_landmarks(template, template_path)
            tl, tl_source = detections["template"].landmarks, template_path
    # as wrap checks them: a vertex id listed twice failed deep in the landmark warp
    # with a line naming the scan
    check_template_landmarks(template, tl, tl_source)
    if not args.scan_landmarks:
        tl, first, detections["frame 0"] = detected_scan_landmarks(
            tl, tl_source, meshes[0], scans[0])
        return tl, [first] + [None] * (len(meshes) - 1), detections
    if len(args.scan_landmarks) not in (1, len(scans)):
        raise InputError(f"give scan landmarks for the first frame or for all "
                         f"{len(scans)} frames, not {len(args.scan_landmarks)}",
                         args.scan_landmarks[0])
    lms = [read_mesh_landmarks(p, m, kind="points")
           for p, m in zip(args.scan_landmarks, meshes)]
    for path, lm in zip(args.scan_landmarks, lms):
        if (tl.names is None or lm.names is None) and len(lm) != len(tl):
            raise InputError(f"has {len(lm)} landmarks but the template landmarks "
                             f"({tl_source}) have {len(tl)}", path)
    return tl, lms + [None] * (len(meshes) - len(lms)), detections


def _profile_landmarks(template_path):
    """The landmarks of the template profile found beside the template and its
    path, or ``(None, None)``."""
    profile = find_template_profile(template_path)
    if profile is None:
        return None, None
    landmarks = read_template_profile(profile).landmarks
    return (None, None) if landmarks is None else (landmarks, str(profile))


def _checked_frames(args, meshes, scans, lms) -> list[str]:
    """The frames' checks before any fit: refusals raised, warnings returned as
    ``frame N (FILE): ...`` lines."""
    # each frame through the wrap's refusals of a scan: a sphere, a scan in other
    # units or landmarks off the surface are refused here as `facewrap wrap` does
    # (the mesh's oddities are the frames' own warnings, from the fit)
    given = list(args.scan_landmarks or ())
    checked = []
    for i, mesh in enumerate(meshes):
        own = lms[i] if i < len(given) else None     # the frame's landmark file's
        found = check_scan(mesh, own, scans[i], given[i] if own is not None else None,
                           survey=False, units=args.units)[3]
        checked += [f"frame {i} ({scans[i]}): {note}" for note in found]
    # one sequence, one head, one unit: a frame in another is refused, a frame
    # written twice said (the fit would show the face frozen for a frame)
    labels = [f"frame {i} ({path})" for i, path in enumerate(scans)]
    check_scan_sizes(meshes, scans, f"frame 0 ({scans[0]})")
    checked += repeated_scans(meshes, labels)
    # a given unit its first frame's size contradicts, once
    conflict = units_conflict(args.units, meshes[0].surface_points())
    return checked + ([f"frame 0 ({scans[0]}): {conflict}"] if conflict else [])


def cmd_track(args) -> int:
    """Track the template through the scans and write the sequence."""
    scans = _scan_paths(args.scans)
    inputs = [args.template, *args.scans, *scans, args.template_landmarks,
              *(args.scan_landmarks or ()), args.blendshapes, args.exclude]
    # weights.csv is checked whether or not blend weights will be written
    check_output_paths(files=track_output_files(args.out, len(scans)), folders=[args.out],
                       inputs=[p for p in inputs if p])
    template = read_mesh(args.template)
    meshes = [read_mesh(p) for p in scans]
    check_not_template(template, meshes, scans)   # kept in the scans' folder?
    tl, lms, detections = _scan_landmarks(args, template, meshes, scans)
    checked = _checked_frames(args, meshes, scans, lms)
    if detections and not args.quiet:
        for what, found in detections.items():
            where = args.template if what == "template" else f"frame 0 ({scans[0]})"
            print(f"{where}: 68 landmarks detected, {int(found.low_confidence.sum())} "
                  "low-confidence left out"
                  + ("; later frames follow the fit" if what != "template" else ""))
    shapes = None
    if args.blendshapes:
        shapes = load_shape_folder(args.blendshapes, template, exclude=())
    exclude = None
    if args.exclude:
        exclude = read_vertex_indices(args.exclude, n_vertices=template.n_vertices).vertex
    log = logging.getLogger("facewrap.wrapping.track")

    units: list = []  # (unit, source), settled on the first frame's result

    with progress(len(meshes), "tracking") as bar:
        def say(i, result):
            if not units:
                units.append(resolve_units(args.units, result.mesh.surface_points()))
            m, unit = result.metrics, units[0][0]
            log.info("frame %d: fit mean %s, landmarks mean %s, %.2f s", i,
                     format_distance(m["fit_mean"], unit),
                     format_distance(m.get("landmark_mean"), unit),
                     result.timings["total"])
            bar.advance()

        settings = wrap_settings_from_args(args)
        first = (detected_landmark_settings(settings) if "frame 0" in detections
                 else None)                    # millimetres off: the surface leads
        try:
            result = track(template, meshes, tl, lms, settings, blendshapes=shapes,
                           exclude=exclude, progress=say, first_settings=first)
        except FrameError as exc:   # the file the wrap's refusal is about
            about, _, text = str(exc).partition(": ")
            given = args.scan_landmarks or []
            landmarks = (given[exc.frame] if exc.frame < len(given)
                         else scans[exc.frame])          # detected, or the fit's
            files = {"scan": scans[exc.frame], "scan landmarks": landmarks}
            raise InputError(text if about in files else str(exc),
                             files.get(about, scans[exc.frame])) from None
    # after the run, as wrap does: a failed track is its one error line
    notes = checked + frame_warnings(result, scans) + [
        f"frame {i} ({scans[i]}): {note.partition(': ')[2]}"
        for i, note in frames_of_another_head(result.frames, template, shapes)]
    for note in notes:
        print(f"facewrap: warning: {note}", file=sys.stderr)
    unit, source = units[0] if units else resolve_units(args.units, template.surface_points())
    paths = write_track_outputs(
        args.out, result, output_frame=args.output_frame,
        extra_report={"template": str(args.template), "scans": [str(p) for p in scans],
                      "shape_names": result.shape_names, "warnings": notes,
                      "units": unit, "units_source": source,
                      "scan_landmarks_source": "detected" if "frame 0" in detections
                      else "file",
                      **({"detected_landmarks": {k: detection_entry(v) for k, v in
                                                 detections.items()}}
                         if detections else {})})
    if not args.quiet:
        print(f"wrote {len(paths['meshes'])} frames to {args.out}")
        if source == "inferred":
            print(units_note(unit, source))
    return 0


def register(subparsers, summary: str) -> None:
    """Add ``track`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser("track", help=summary)
    p.add_argument("template", help="template mesh (OBJ/PLY)")
    p.add_argument("scans", nargs="+", help="scan files in frame order, or a folder")
    p.add_argument("-o", "--out", required=True, help="output folder")
    p.add_argument("--template-landmarks",
                   help="template vertex ids (text) or facewrap landmark JSON (default: "
                        "the template profile's, else detected on the template)")
    p.add_argument("--scan-landmarks", nargs="+", metavar="F",
                   help="landmarks of the first frame, or one file per frame (default: "
                        "the 68 iBUG points detected on the first frame, the later "
                        "frames following the fit; needs facewrap[landmarks])")
    add_fit_options(p)
    add_units_argument(p)
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_track)
