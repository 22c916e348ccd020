"""``facewrap demo``: the main job on the built-in sample, end to end.

Writes the synthetic template, its blendshapes and a scan (another identity in
an extreme expression: jaw open, eyes shut, smile; noise, holes) to
``OUT/input``, runs the wrap job ``facewrap wrap`` would run on them with its
default settings (alignment, hybrid non-rigid ICP, projection, texture baking,
JSON report), measures the result against the sample's known ground truth, draws
a heatmap of that error and before/after pictures, and builds the HTML report
(as ``facewrap report`` does), whose path it prints last.

Then it wraps the same scan once more with no scan landmarks, as ``facewrap wrap``
does without ``--scan-landmarks`` (the 68 points detected on the textured scan,
issue 18), into ``OUT/landmark_free``, and prints that wrap's ground-truth error
beside the landmarked one's and the detected landmarks' distance to the sample's
true ones.  Without the optional extra ``facewrap[landmarks]`` (dlib) this section
is skipped with one line saying so; the exit status stays 0.
"""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path

import numpy as np

from facewrap.cli.wrap import run_wrap_job_verbosely
from facewrap.geometry import ClosestPointTree
from facewrap.io import read_mesh
from facewrap.io.atomic import atomic_write
from facewrap.io.landmarks import write_vertex_indices
from facewrap.errors import InputError
from facewrap.io.files import read_json
from facewrap.io.paths import check_writable, real_path
from facewrap.jobs import WrapJob
from facewrap.landmarks import Landmarks
from facewrap.units import format_distance
from facewrap.wrapping import WrapSettings

__all__ = ["register", "cmd_demo", "run_demo", "check_demo_folder", "DEMO_NAMES",
           "LANDMARK_FREE"]

#: Sub-folder of the demo's output with the wrap from detected landmarks.
LANDMARK_FREE = "landmark_free"


def _ground_truth_error(template, scan, fitted):
    """Per face vertex: error to its true position, and whether the scan sees it."""
    face = template.parts["face"]
    err = np.linalg.norm(fitted[face] - scan.ground_truth[face], axis=1)
    # "seen": vertices whose true position is on the scan away from its borders
    # (the template head is larger than the cropped, holed scan)
    gt_tree = ClosestPointTree(scan.mesh.vertices, scan.mesh.triangles)
    on_scan = gt_tree.query(scan.ground_truth[face])
    seen = ~gt_tree.boundary_triangles[on_scan.triangles] & (on_scan.distances < 1.0)
    return face, err, seen


def _error_stats(err, seen) -> dict:
    stats = {}
    for name, e in (("face_seen_by_scan", err[seen]), ("whole_head", err)):
        stats[name] = {"vertices": int(len(e)), "mean": float(e.mean()),
                       "p95": float(np.percentile(e, 95)), "max": float(e.max())}
    return stats


def _distance_stats(d) -> dict:
    """Count, mean, p95 and max of the (n,) distances ``d``."""
    return {"count": int(len(d)), "mean": float(d.mean()),
            "p95": float(np.percentile(d, 95)), "max": float(d.max())}


#: What the demo writes at the top of its folder (files and folders).
DEMO_NAMES = ("input", "wrapped.obj", "wrapped.mtl", "wrapped.png", "report.json",
              "report", "error_heatmap.png", "scan_and_result.png", LANDMARK_FREE)


def check_demo_folder(out: Path) -> None:
    """Refuse a folder that holds a file or folder of a name the demo writes,
    unless a demo wrote it (its ``report.json`` names its ``input/template.obj``):
    ``facewrap demo --out .`` in a project must not replace its ``input/scan.obj``
    or ``report.json``; a re-run of the demo into its own folder replaces its own.

    Raises
    ------
    InputError
        Naming the folder and the first name in the way.
    """
    taken = [n for n in DEMO_NAMES if os.path.lexists(out / n)]
    if not taken:
        return
    try:
        template = Path(read_json(out / "report.json")["job"]["template"])
        # written relative to where the demo ran: its last two parts, or all of it
        if (template.parts[-2:] == ("input", "template.obj")
                and (out / "input" / "template.obj").is_file()) \
                or real_path(template) == real_path(out / "input" / "template.obj"):
            return   # the demo's own folder: a re-run
    except (InputError, KeyError, TypeError, OSError):
        pass
    raise InputError(f"holds {taken[0]!r}, a name the demo writes, and no demo wrote "
                     "it: give a new or empty folder (--out)", out)


def run_demo(out: Path, verbose: bool = True) -> int:
    """Run the demo into folder ``out``; returns the exit status (0)."""
    # deferred: the other commands (and `facewrap --help`) do not pay for this import
    from facewrap.report.page import build_report_page
    from facewrap.sample import make_scan, make_template, write_sample
    out = Path(out)
    check_writable(folders=[out, out / "input", out / "report", out / LANDMARK_FREE])
    check_demo_folder(out)
    out.mkdir(parents=True, exist_ok=True)
    template = make_template()
    scan = make_scan(template)
    paths = write_sample(out / "input", template, scan)
    # the eyeballs are not on a scan (closed lids cover them): they follow the face
    exclude = out / "input" / "exclude_eyeballs.txt"
    write_vertex_indices(exclude, Landmarks.from_vertices(np.concatenate(
        [template.parts["eyeball_left"], template.parts["eyeball_right"]])))
    wrapped = out / "wrapped.obj"
    report = out / "report.json"
    inputs = dict(template=str(paths["template"]), scan=str(paths["scan"]),
                  template_landmarks=str(paths["template_landmarks"]),
                  blendshapes=str(paths["blendshapes/blink"].parent),
                  exclude=str(exclude), texture=str(paths["scan_texture"]),
                  texture_size=512)
    job = WrapJob(**inputs, scan_landmarks=str(paths["scan_landmarks"]),
                  output=str(wrapped), report=str(report))
    run_wrap_job_verbosely(job, WrapSettings(), quiet=not verbose)
    # ground truth is known for the sample: how far is each vertex from where it
    # truly belongs on the scan?
    fitted = read_mesh(wrapped).vertices
    face, err, seen = _ground_truth_error(template, scan, fitted)
    data = json.loads(report.read_text())
    stats = _error_stats(err, seen)
    data["ground_truth_error_mm"] = stats
    with atomic_write(report, "w") as fh:
        json.dump(data, fh, indent=1)
    pictures = _pictures(out, template, scan, fitted, face, seen, err)
    page_dir = out / "report"
    print(build_report_page(report, page_dir, images=pictures,
                            ground_truth=scan.ground_truth,
                            title="facewrap demo: hybrid wrap of the built-in sample"))
    if verbose:
        for name, st in stats.items():
            print(f"ground-truth vertex error, {name.replace('_', ' ')} "
                  f"({st['vertices']} vertices): mean "
                  f"{format_distance(st['mean'], data['units'])}, p95 "
                  f"{format_distance(st['p95'], data['units'])}")
    line = _landmark_free(out / LANDMARK_FREE, inputs, template, scan, stats)
    if verbose:
        print(line)
        print(f"outputs in {out.resolve()}:")
        for p in sorted(out.iterdir()):
            print(f"  {p.name}")
        print(f"HTML report: {(page_dir / 'index.html').resolve()}")
    return 0


def _landmark_free(folder: Path, inputs: dict, template, scan, landmarked: dict) -> str:
    """The sample wrapped from detected landmarks into ``folder``; the line to print.

    The job is the landmarked one with no scan landmarks: the wrap job detects them
    on the textured scan and weighs them as detected ones.  Its report gains the
    ground-truth error and the detected landmarks' distances to the sample's true
    landmarks (all 68, and the confident ones the wrap used).  Without the extra
    ``facewrap[landmarks]`` nothing is written and the line says why.
    """
    from facewrap.detection.backend import face_model   # dlib loads on use
    from facewrap.errors import InputError
    wrapped, report = folder / "wrapped.obj", folder / "report.json"
    try:
        face_model()    # the one failure that skips: the extra is not installed
    except InputError as exc:
        # an earlier demo's section must not pass for this one's: its files go
        for old in (wrapped, wrapped.with_suffix(".png"), wrapped.with_suffix(".mtl"),
                    report):
            old.unlink(missing_ok=True)
        with contextlib.suppress(OSError):      # (kept when something else is in it)
            folder.rmdir()
        return f"landmark-free wrap skipped: {exc}"
    job = WrapJob(**inputs, output=str(wrapped), report=str(report))
    data = run_wrap_job_verbosely(job, WrapSettings(), quiet=True)
    fitted = read_mesh(wrapped).vertices
    _, err, seen = _ground_truth_error(template, scan, fitted)
    stats = _error_stats(err, seen)
    found = data["detected_landmarks"]["scan"]
    # the sample's landmarks are the true positions of the template's, by name
    true = dict(zip(scan.landmarks.names, scan.landmarks.points))
    lm_err = np.linalg.norm(np.asarray(found["positions"])
                            - np.array([true[n] for n in found["names"]]), axis=1)
    confident = ~np.isin(found["names"], found["low_confidence"])
    data["ground_truth_error_mm"] = stats
    data["detected_landmark_error_mm"] = {
        "all": _distance_stats(lm_err), "confident": _distance_stats(lm_err[confident])}
    with atomic_write(report, "w") as fh:
        json.dump(data, fh, indent=1)
    unit = data["units"]
    mine, theirs = stats["face_seen_by_scan"], landmarked["face_seen_by_scan"]
    return (f"landmark-free wrap ({int(confident.sum())} of {len(lm_err)} detected "
            f"landmarks confident, used): ground-truth vertex error, face seen by scan: "
            f"mean {format_distance(mine['mean'], unit)}, p95 "
            f"{format_distance(mine['p95'], unit)} (landmarked: mean "
            f"{format_distance(theirs['mean'], unit)}, p95 "
            f"{format_distance(theirs['p95'], unit)}); detected landmarks to the true "
            f"ones: mean {format_distance(lm_err.mean(), unit)} (confident ones "
            f"{format_distance(lm_err[confident].mean(), unit)}, at most "
            f"{format_distance(lm_err[confident].max(), unit)})")


def _pictures(out: Path, template, scan, fitted, face, seen, err) -> list[Path]:
    """Ground-truth error heatmap and scan / result side by side (PNG files)."""
    # deferred: the other commands (and `facewrap --help`) do not pay for this import
    from facewrap.report import (frame_from_axes, heatmap_figure, render_views, save_png,
                                 side_by_side)
    # the scan was moved by a random similarity: look at both from the face's
    # front, i.e. the template's +z and +y turned by that similarity
    A = np.asarray(scan.transform)[:3, :3]
    frame = frame_from_axes(up=A @ [0.0, 1.0, 0.0], front=A @ [0.0, 0.0, 1.0])
    values = np.full(len(fitted), np.nan)
    values[face[seen]] = err[seen]
    heat = out / "error_heatmap.png"
    save_png(heat, heatmap_figure((fitted, template.mesh.triangles), values, units="mm",
                                  title="distance to ground truth", clim=(0.0, 2.0),
                                  frame=frame))
    views = render_views([scan.mesh, (fitted, template.mesh.triangles)],
                         views=("front",), size=(420, 480), frame=frame)
    both = out / "scan_and_result.png"
    save_png(both, side_by_side(views, [f"scan ({len(scan.mesh.triangles):,} triangles, "
                                        "holes, noise)",
                                        "fitted template (quads, UVs kept)"]))
    return [heat, both]


def cmd_demo(args) -> int:
    """Run the main job on the built-in sample and say where the outputs are."""
    return run_demo(Path(args.out), verbose=not args.quiet)


def register(subparsers, summary: str) -> None:
    """Add ``demo`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser("demo", help=summary)
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_demo)
