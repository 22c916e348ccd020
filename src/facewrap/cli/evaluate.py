"""``facewrap evaluate RESULT SCAN``: the numbers (and a heatmap) of a fitted mesh.

Parses arguments, reads files, calls :func:`facewrap.evaluate.evaluate` and, when
asked, :func:`facewrap.report.heatmap_figure`; prints a short summary, writes the
full summary as JSON.  Input problems raise :class:`~facewrap.errors.InputError`
(one line, exit status 2, nothing written).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from facewrap.errors import InputError
from facewrap.io import read_mesh
from facewrap.io.atomic import atomic_write
from facewrap.io.files import not_a_file, read_json
from facewrap.io.landmarks import read_landmarks, read_vertex_indices
from facewrap.io.paths import check_output_paths, staged_outputs
from facewrap.units import (COORDINATE_LIMIT, UNIT_NAMES, UNKNOWN, add_units_argument,
                            first_too_large, format_distance, infer_units, resolve_units,
                            units_conflict, units_note)

__all__ = ["view_axes", "implausible_pair", "landmarks_off_scan", "landmarks_mispaired",
           "ground_truth_unlike", "TRUTH_SIZE_LIMIT", "TRUTH_SHIFT_LIMIT", "TRUTH_TURN_LIMIT",
           "register", "cmd_evaluate", "read_ground_truth"]

# --heatmap-of choice -> (vertex_values key, colour-bar label, picture title)
_HEATMAPS = {
    "fit": ("fit", "distance", "Result to scan distance"),
    "fit_signed": ("fit_signed", "signed distance", "Result to scan signed distance"),
    "correspondence": ("correspondence", "error", "Correspondence error (vs ground truth)"),
    "area_ratio": ("area_ratio", "area ratio", "Triangle area change (vs reference)"),
    "stretch": ("stretch", "anisotropy", "Triangle stretch (vs reference)"),
}


def _same_topology(mesh, other, path, what):
    if other.n_vertices != mesh.n_vertices or not np.array_equal(other.face_indices,
                                                                 mesh.face_indices):
        raise InputError(f"{what} is not in the result's topology (vertex count or "
                         "faces differ)", path)


def read_ground_truth(path, result):
    """(n, 3) positions from a mesh in the result's topology or an .npy array.

    Raises
    ------
    InputError
        Naming ``path``: unreadable, not one row per vertex of ``result``, or
        without a single known (non-NaN) row.
    """
    if str(path).lower().endswith(".npy"):
        if not Path(path).is_file():   # np.load would wait on a fifo forever
            raise not_a_file(path)
        try:
            G = np.load(path, allow_pickle=False)
        except FileNotFoundError:
            raise InputError("no such file", path) from None
        except (OSError, ValueError) as exc:
            raise InputError(f"cannot read a NumPy array ({exc})", path) from None
        if G.shape != (result.n_vertices, 3) or G.dtype.kind not in "fiu":
            # complex or boolean "positions" would be cast silently (imaginary parts lost)
            raise InputError(f"ground truth must be a ({result.n_vertices}, 3) array of "
                             "real numbers (NaN rows for vertices without truth), got "
                             f"{G.shape} {G.dtype}", path)
        G = G.astype(np.float64)
        known = G[~np.isnan(G).any(axis=1)]
        if not np.isfinite(known).all() or first_too_large(known) is not None:
            raise InputError(f"ground truth holds an infinite or too large value (more "
                             f"than {COORDINATE_LIMIT:g} in magnitude)", path)
        if len(known) == 0:   # measured as "correspondence mean n/a", without a word
            raise InputError("ground truth has no known position (every row is NaN): "
                             "there is nothing to measure against", path)
        return G
    gt = read_mesh(path)
    _same_topology(result, gt, path, "the ground truth")
    return gt.vertices


def _read_mask(path, n):
    ids = read_vertex_indices(path, n_vertices=n).vertex
    return ids


def implausible_pair(result, scan, result_path, scan_path) -> list[str]:
    """Warnings for a result and a scan that cannot be one fit: sizes a unit apart
    (a scan in metres against a result in millimetres), or boxes that do not meet.

    Returns
    -------
    list of str
        One line each, naming the scan.
    """
    notes = []
    a, b = result.scale(), scan.scale()
    if a > 0 and b > 0 and not 0.25 <= a / b <= 4.0:
        # each size in the unit its own head's size suggests: the mismatch, in words
        size_b = format_distance(b, infer_units(scan.vertices))
        size_a = format_distance(a, infer_units(result.vertices))
        notes.append(f"{scan_path}: its diagonal ({size_b}) and the result's ({size_a}, "
                     f"{result_path}) differ {max(a / b, b / a):.3g}-fold: in other units? "
                     "the distances below compare unlike things")
    (lo_a, hi_a), (lo_b, hi_b) = result.bounding_box(), scan.bounding_box()
    if np.any(lo_a > hi_b) or np.any(lo_b > hi_a):
        notes.append(f"{scan_path}: does not overlap the result {result_path} (their "
                     "bounding boxes are apart): not the scan it was fitted to?")
    return notes


#: a ground truth this many times larger or smaller than the result is in other units
TRUTH_SIZE_LIMIT = 1.25
#: a ground truth whose centroid lies farther than this fraction of the result's
#: diagonal from the result's, or turned more than TRUTH_TURN_LIMIT degrees, is in
#: another frame (a wrap's --output-frame template, a truth in the template's frame)
TRUTH_SHIFT_LIMIT, TRUTH_TURN_LIMIT = 0.1, 8.0


def ground_truth_unlike(result, truth, path, result_path) -> list[str]:
    """A warning when the ground truth cannot be the true place of the result's
    vertices as given: a mirror image of it, in other units, or in another frame.
    Its errors would measure that, not the fit.

    Parameters
    ----------
    result : Mesh
    truth : (n, 3) float
        NaN rows for vertices without truth.
    path, result_path : path
        The ground truth's and the result's files, for the message.

    Returns
    -------
    list of str
        One line naming ``path``, or none.
    """
    # deferred: `facewrap evaluate --help` loads no geometry
    from facewrap.geometry.similarity import pose_change
    change = pose_change(result.vertices, truth)
    unit = infer_units(result.surface_points())
    tail = "its errors measure that, not the fit"
    if change.mirrored:
        return [f"{path}: is a mirror image of the result ({result_path}; left and right "
                f"swapped): {tail}"]
    if not 1 / TRUTH_SIZE_LIMIT <= change.scale <= TRUTH_SIZE_LIMIT:
        return [f"{path}: is {change.scale:.3g} times the size of the result "
                f"({result_path}): in other units? {tail}"]
    if change.shift > TRUTH_SHIFT_LIMIT * result.scale() or change.angle > TRUTH_TURN_LIMIT:
        moved = format_distance(change.shift, unit)
        return [f"{path}: lies {moved} from the result ({result_path}) and is turned "
                f"{change.angle:.0f} degrees: in another frame (a wrap's --output-frame), "
                f"or a fit that failed? {tail}"]
    return []


def landmarks_off_scan(scan, landmarks, path) -> list[str]:
    """A warning when the scan's landmarks lie mostly off it (another scan's file,
    or other units): their errors would be measured against nothing."""
    from facewrap.geometry import ClosestPointTree
    try:
        points = landmarks.positions(scan)
    except (ValueError, IndexError):
        return []               # vertex ids beyond the scan: evaluate names them
    d = ClosestPointTree(scan.vertices, scan.triangles).query(points).distances
    size = scan.scale()
    if size > 0 and np.median(d) > 0.1 * size:
        unit = infer_units(scan.vertices)
        return [f"{path}: the landmarks lie off the scan (median "
                f"{format_distance(float(np.median(d)), unit)} from it, scan diagonal "
                f"{format_distance(size, unit)}): another scan's file, or other units?"]
    return []


def landmarks_mispaired(landmarks, path, result_path, show: int = 3) -> list[str]:
    """A warning when the scan's landmarks pair with the result's only in a mirror
    image, or some pair wrongly: their errors would read as a bad fit.

    The wrap's own checks decide (:func:`~facewrap.wrapping.plausibility.check_reflection`,
    then :func:`~facewrap.wrapping.plausibility.mispaired_landmarks`): a mirrored
    scan or landmark file (left and right swapped) matches only a mirror image;
    a wrong order or numbering leaves landmarks far off after the best similarity,
    or fitting far better swapped.

    Parameters
    ----------
    landmarks : LandmarkErrors
        The evaluation's pairs (``positions`` on the result, ``targets`` on the scan).
    path, result_path : path
        The scan's and the result's landmark files, for the message.
    show : int
        How many flagged landmarks to name.

    Returns
    -------
    list of str
        One line naming ``path``, or empty (also when fewer than four pairs or
        landmarks all at one point leave nothing to compare).
    """
    # deferred: the wrap's package is not loaded by evaluate without landmarks
    from facewrap.wrapping.plausibility import (check_reflection, landmark_spread,
                                                mispaired_landmarks)
    X, Y = landmarks.positions, landmarks.targets
    if X is None or len(X) < 4 or not min(landmark_spread(X), landmark_spread(Y)) > 0:
        return []
    if check_reflection(X, Y, allow_mirrored=True):
        return [f"{path}: the landmarks match the result's ({result_path}) only in a "
                "mirror image: is the scan or a landmark file mirrored (left and right "
                "swapped)? The landmark errors measure that, not the fit"]
    _, residuals, flagged = mispaired_landmarks(X, Y)
    bad = np.flatnonzero(flagged)
    if not len(bad):
        return []
    worst = bad[np.argsort(-residuals[bad], kind="stable")[:show]]
    named = "; ".join(f"landmark {landmarks.names[i]} off by {100 * residuals[i]:.0f} %"
                      for i in worst)
    return [f"{path}: {len(bad)} of {len(X)} landmarks are far from the result's "
            f"({result_path}) after the best similarity, or fit far better swapped "
            f"({named}{'; ...' if len(bad) > show else ''}, of the landmarks' spread): "
            "mis-paired (wrong order or numbering)? The landmark errors measure that, "
            "not the fit"]


def view_axes(up, front, options: str = "--up/--front"):
    """The ``up`` and ``front`` directions of the options, checked and scaled.

    Each vector is divided by its largest component (the direction is kept; a
    1e308 component no longer overflows the norm), and the pair must make a
    frame (:func:`~facewrap.report.frame_from_axes`).

    Returns
    -------
    up, front : (3,) float64

    Raises
    ------
    InputError
        Naming ``options``: not finite, zero, or parallel.
    """
    from facewrap.report import frame_from_axes
    pair = []
    for v in (up, front):
        v = np.asarray(v, dtype=np.float64)
        top = np.abs(v).max() if v.size and np.isfinite(v).all() else 0.0
        pair.append(v / top if top > 0 else v)
    try:
        frame_from_axes(*pair)
    except ValueError as exc:
        raise InputError(f"{options}: {exc}") from None
    return tuple(pair)


def _frame(args, result, reference):
    """Rotation that turns the result to face +z with +y up, for pictures."""
    # deferred: the other commands (and `facewrap --help`) do not pay for this import
    from facewrap.geometry.similarity import similarity_transform
    from facewrap.report import frame_from_axes
    F = frame_from_axes(*view_axes(args.up, args.front))
    if reference is not None:
        # the result sits in scan coordinates: undo the template -> scan rotation
        R = similarity_transform(reference.vertices, result.vertices).rotation
        return F @ R.T
    return F


def _format_line(s: dict, unit: str) -> str:
    def f(key):
        return format_distance(s.get(key), unit)
    parts = [f"fit mean {f('fit_mean')} p95 {f('fit_p95')} max {f('fit_max')}, "
             f"coverage {100 * s['fit_coverage']:.1f} % of "
             f"{s['fit_vertices']:,} vertices",
             f"scan->result mean {f('scan_to_result_mean')} p95 "
             f"{f('scan_to_result_p95')}"]
    if "landmark_mean" in s:
        parts.append(f"landmarks mean {f('landmark_mean')} max {f('landmark_max')} "
                     f"(worst {s.get('landmark_worst')})")
    if "correspondence_mean" in s:
        parts.append(f"correspondence mean {f('correspondence_mean')} p95 "
                     f"{f('correspondence_p95')}")
    tri = f"triangles: min angle {_ratio(s.get('triangles_min_angle_min'))} deg"
    if "triangles_flipped" in s:
        tri += (f", {s['triangles_flipped']} flipped, area ratio p5-p95 "
                f"{_ratio(s.get('triangles_area_ratio_p5'))}-"
                f"{_ratio(s.get('triangles_area_ratio_p95'))}, stretch p95 "
                f"{_ratio(s.get('triangles_stretch_p95'))}")
    parts.append(tri)
    if s.get("units_source") == "inferred":
        parts.append(units_note(unit, "inferred"))
    return "\n".join(parts)


def _ratio(v) -> str:
    """A unitless number (angle, ratio) to three significant digits."""
    return "n/a" if v is None else f"{round(v, 4):.3g}"


def _run_roles(path, n: int):
    """Fitted vertices (n,) bool and the unit ``(unit, source)`` of a run's report."""
    from facewrap.evaluate import VERTEX_ROLE_NAMES, role_codes
    # the shared reader, as `facewrap report` reads a run: a folder, FIFO or device is
    # named instead of opened (a FIFO hung, /dev/zero filled the memory), a sparse or
    # binary file is refused from its ends, and the errors name the file
    try:
        run = read_json(path)
    except InputError as exc:
        raise InputError(f"not a JSON report ({exc.problem})", path, exc.line) from None
    if not isinstance(run, dict) or "vertex_roles" not in run:
        raise InputError("not a wrap report with 'vertex_roles' (which vertices were "
                         "fitted)", path)
    try:
        fitted = role_codes(run["vertex_roles"], n) == VERTEX_ROLE_NAMES.index("fitted")
    except ValueError as exc:
        raise InputError(f"{exc} (the result has {n} vertices)", path) from None
    unit = run.get("units")
    if unit not in UNIT_NAMES + (UNKNOWN,):
        return fitted, None
    return fitted, (unit, run.get("units_source", "given"))


def _caption(key: str, s: dict, unit: str):
    """The heatmap picture's caption line, distances with their unit."""
    if key in ("fit", "fit_signed"):
        return (f"mean {format_distance(s['fit_mean'], unit)} · p95 "
                f"{format_distance(s['fit_p95'], unit)} · coverage "
                f"{100 * s['fit_coverage']:.0f} % (grey: not covered by the scan)")
    if key == "correspondence":
        return (f"mean {format_distance(s['correspondence_mean'], unit)} · p95 "
                f"{format_distance(s['correspondence_p95'], unit)} over "
                f"{s['correspondence_count']} vertices")
    return None


def cmd_evaluate(args) -> int:
    """Evaluate a fitted mesh against its scan (and truth, landmarks, reference)."""
    # deferred: `facewrap evaluate --help` (and the other commands) do not pay for these
    from facewrap.evaluate import evaluate
    from facewrap.jobs.input_checks import check_surface
    from facewrap.report import heatmap_figure, save_png

    if (args.result_landmarks is None) != (args.scan_landmarks is None):
        raise InputError("--result-landmarks and --scan-landmarks go together")
    if args.heatmap_of in ("correspondence",) and args.ground_truth is None:
        raise InputError("--heatmap-of correspondence needs --ground-truth")
    if args.heatmap_of in ("area_ratio", "stretch") and args.reference is None:
        raise InputError(f"--heatmap-of {args.heatmap_of} needs --reference")
    inputs = [args.result, args.scan, args.ground_truth, args.reference,
              args.result_landmarks, args.scan_landmarks, args.mask, args.run]
    check_output_paths(files=[p for p in (args.json, args.heatmap) if p],
                       inputs=[p for p in inputs if p])
    result = read_mesh(args.result)
    scan = read_mesh(args.scan)
    # distances are measured to surfaces both ways: a point cloud (a PLY of vertices
    # alone) or a mesh of zero-area triangles has none, and is named, not measured
    check_surface(result, args.result, "result", "a fitted mesh is a surface")
    check_surface(scan, args.scan, "scan", "distances are measured to its surface")
    odd = implausible_pair(result, scan, args.result, args.scan)
    gt = ref = None
    if args.ground_truth:
        gt = read_ground_truth(args.ground_truth, result)
        odd += ground_truth_unlike(result, gt, args.ground_truth, args.result)
    if args.reference:
        ref = read_mesh(args.reference)
        _same_topology(result, ref, args.reference, "the reference")
    lm_r = lm_s = None
    if args.result_landmarks:
        lm_r = read_landmarks(args.result_landmarks)
        lm_s = read_landmarks(args.scan_landmarks)
        if (lm_r.names is None or lm_s.names is None) and len(lm_r) != len(lm_s):
            raise InputError(f"has {len(lm_s)} landmarks but the result's "
                             f"({args.result_landmarks}) has {len(lm_r)}",
                             args.scan_landmarks)
        odd += landmarks_off_scan(scan, lm_s, args.scan_landmarks)
    if args.mask and args.run:
        raise InputError("give --mask or --run (its fitted vertices), not both")
    mask, run_units = None, None
    if args.mask:
        mask = _read_mask(args.mask, result.n_vertices)
    elif args.run:
        mask, run_units = _run_roles(args.run, result.n_vertices)

    ev = evaluate(result, scan, ground_truth=gt, result_landmarks=lm_r,
                  scan_landmarks=lm_s, reference=ref, mask=mask,
                  exclude_border=not args.keep_border)
    if ev.landmarks is not None:
        odd += landmarks_mispaired(ev.landmarks, args.scan_landmarks, args.result_landmarks)
    if args.units == "auto" and run_units is not None:
        unit, source = run_units
    else:
        unit, source = resolve_units(args.units, result.surface_points())
        conflict = units_conflict(args.units, result.surface_points())
        odd += [f"{args.result}: {conflict}"] if conflict else []
    summary = {"result": str(args.result), "scan": str(args.scan), "units": unit,
               "units_source": source, **ev.summary(),
               "fit_vertices": int(np.count_nonzero(ev.result_to_scan.eligible)),
               **({"warnings": odd} if odd else {})}

    image = None
    if args.heatmap:
        key, label, title = _HEATMAPS[args.heatmap_of]
        values = ev.vertex_values()[key]
        units = unit if key in ("fit", "fit_signed", "correspondence") else ""
        image = heatmap_figure(result, values, units=units, label=label, title=title,
                               caption=_caption(key, summary, unit),
                               frame=_frame(args, result, ref))

    with staged_outputs() as stage:
        if args.json:
            with atomic_write(stage.file(args.json), "w") as fh:
                json.dump(summary, fh, indent=1)
        if image is not None:
            save_png(stage.file(args.heatmap), image)
    for note in odd:   # measured all the same, but never as if it were fine
        print(f"facewrap: warning: {note}", file=sys.stderr)
    if not args.quiet:
        print(_format_line(summary, unit))
        for p in (args.json, args.heatmap):
            if p:
                print(f"wrote {p}")
    return 0


def register(subparsers, summary: str) -> None:
    """Add ``evaluate`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser(
        "evaluate", help=summary,
        description="Measure a fitted mesh against its scan: distances both ways "
                    "(statistics over points the other mesh covers), landmark errors, "
                    "correspondence error against a ground truth in the same "
                    "topology, and triangle quality against the template.")
    p.add_argument("result", help="fitted mesh (OBJ/PLY)")
    p.add_argument("scan", help="scan mesh (OBJ/PLY)")
    p.add_argument("--ground-truth", metavar="MESH|NPY",
                   help="true positions of the result's vertices: a mesh in the same "
                        "topology, or an (n, 3) .npy array with NaN rows to skip")
    p.add_argument("--result-landmarks", metavar="FILE",
                   help="landmarks on the result: vertex ids or facewrap JSON")
    p.add_argument("--scan-landmarks", metavar="FILE",
                   help="landmarks on the scan: 'x y z' text, .ljson or facewrap JSON")
    p.add_argument("--reference", metavar="TEMPLATE",
                   help="the template before fitting (same topology): flipped "
                        "triangles, area change, stretch")
    p.add_argument("--mask", metavar="FILE",
                   help="result vertex ids to evaluate (text, one per line)")
    p.add_argument("--run", metavar="RUN.json",
                   help="the wrap's JSON report: evaluate its fitted vertices only "
                        "(not the parts and cavities that follow, nor the excluded "
                        "or pinned ones) in its units")
    p.add_argument("--keep-border", action="store_true",
                   help="count points whose closest point is on the other mesh's border")
    p.add_argument("--json", metavar="OUT", help="write every number as JSON")
    p.add_argument("--heatmap", metavar="OUT.png", help="write a heatmap picture")
    p.add_argument("--heatmap-of", default="fit", choices=list(_HEATMAPS),
                   help="what the heatmap shows (default %(default)s)")
    add_units_argument(p)
    p.add_argument("--up", type=float, nargs=3, default=(0.0, 1.0, 0.0),
                   metavar=("X", "Y", "Z"),
                   help="up axis of the template for pictures (default 0 1 0)")
    p.add_argument("--front", type=float, nargs=3, default=(0.0, 0.0, 1.0),
                   metavar=("X", "Y", "Z"),
                   help="facing direction of the template for pictures (default 0 0 1)")
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_evaluate)

