"""The ``facewrap`` command: parsing arguments and calling the library, nothing else.

Each subcommand is a small function ``cmd_<name>(args)`` registered in
:func:`build_parser`.  Errors in user input (:class:`~facewrap.errors.InputError`,
missing files) print one line ``facewrap: error: <file>:<line>: <problem>`` and
exit with status 2; nothing is written in that case.
"""

from __future__ import annotations

import argparse
from importlib import import_module
import json
import sys
from pathlib import Path

import numpy as np

from facewrap.version import __version__
from facewrap.errors import InputError
from facewrap.wrapping import MODELS, WrapSettings

__all__ = ["main", "build_parser"]

#: subcommands that live in their own module here, each with ``register(subparsers)``
_COMMAND_MODULES = ("track", "transfer", "evaluate", "report", "run", "batch")


def cmd_info(args) -> int:
    """Print a summary of a mesh (and its landmarks)."""
    from facewrap.geometry import boundary_loops, connected_components
    from facewrap.io import read_mesh
    mesh = read_mesh(args.mesh)
    sizes, counts = np.unique(mesh.face_sizes, return_counts=True)
    lo, hi = mesh.bounding_box()
    info = {
        "file": str(args.mesh),
        "vertices": mesh.n_vertices,
        "faces": mesh.n_faces,
        "polygon_sizes": {int(s): int(c) for s, c in zip(sizes, counts)},
        "triangles": len(mesh.triangles),
        "uvs": None if mesh.uvs is None else len(mesh.uvs),
        "normals": None if mesh.normals is None else len(mesh.normals),
        "materials": list(mesh.materials),
        "groups": list(mesh.groups),
        "components": int(connected_components(mesh.triangles, mesh.n_vertices).max() + 1),
        "boundary_loops": len(boundary_loops(mesh.triangles)),
        "bounding_box": [lo.tolist(), hi.tolist()],
        "diagonal": mesh.scale(),
    }
    if args.json:
        print(json.dumps(info, indent=1))
    else:
        for k, v in info.items():
            print(f"{k:>15}: {v}")
    return 0


def cmd_convert(args) -> int:
    """Convert between OBJ and PLY, keeping vertex order, polygons and UVs."""
    from facewrap.io import read_mesh, write_mesh
    write_mesh(args.output, read_mesh(args.input))
    print(args.output)
    return 0


def cmd_sample(args) -> int:
    """Write the built-in synthetic template and scan to a folder."""
    from facewrap.sample import make_scan, make_template, write_sample
    template = make_template()
    scan = make_scan(template)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    paths = write_sample(out, template, scan)
    for name, p in paths.items():
        print(f"{name:>20}: {p}")
    return 0


def wrap_settings_from_args(args) -> WrapSettings:
    """The :class:`WrapSettings` of ``facewrap wrap``'s options."""
    return WrapSettings(model=args.model, kernel=args.kernel, smoothing=args.smoothing,
                        project=not args.no_project, max_distance=args.max_distance,
                        rigid_refine=args.rigid_refine, node_spacing=args.node_spacing,
                        robust=args.robust, pca_components=args.pca_components,
                        weight_range=(None if args.no_weight_range
                                      else tuple(args.weight_range)),
                        landmark_pull=not args.no_landmark_pull,
                        landmark_tolerance=args.landmark_tolerance)


def cmd_wrap(args) -> int:
    """Fit the template to the scan and write the template-topology result."""
    from facewrap.jobs import WrapJob
    job = WrapJob(template=args.template, scan=args.scan,
                  template_landmarks=args.template_landmarks,
                  scan_landmarks=args.scan_landmarks, output=args.output,
                  blendshapes=args.blendshapes, exclude=args.exclude,
                  texture=args.texture, texture_size=args.texture_size,
                  report=args.report)
    run_wrap_job_verbosely(job, wrap_settings_from_args(args), quiet=args.quiet)
    return 0


def run_wrap_job_verbosely(job, settings, quiet: bool = False) -> dict:
    """Run a wrap job for the command line: input warnings as one
    ``facewrap: warning:`` line each, then a one-line summary unless ``quiet``."""
    import warnings
    from facewrap.jobs import InputWarning, run_wrap_job
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", InputWarning)
        report = run_wrap_job(job, settings)
    for w in caught:
        if issubclass(w.category, InputWarning):
            print(f"facewrap: warning: {w.message}", file=sys.stderr)
    if not quiet:
        m, t = report["metrics"], report["timings"]
        print(f"wrote {job.output}: {report['vertices']} vertices, model "
              f"{report['settings']['model']}, fit mean {m['fit_mean']:.4g} p95 "
              f"{m['fit_p95']:.4g}, landmarks mean {m['landmark_mean']:.4g}, "
              f"{t['total']:.2f} s")
    return report


def cmd_animate(args) -> int:
    """Frames between two fitted meshes of one topology, as an OBJ sequence."""
    from facewrap.animation import interpolate_textures, interpolate_vertices, write_obj_sequence
    from facewrap.io import read_mesh
    start, end = read_mesh(args.start), read_mesh(args.end)
    if (start.n_vertices != end.n_vertices
            or not np.array_equal(start.face_indices, end.face_indices)):
        raise InputError(f"is not in the topology of {args.start} (vertex count or "
                         "faces differ)", args.end)
    frames = interpolate_vertices(start.vertices, end.vertices, args.frames)
    textures = None
    if args.textures:
        from facewrap.texture import load_image
        a, b = (load_image(p) for p in args.textures)
        if a.shape != b.shape:
            raise InputError(f"image size {b.shape[:2]} differs from "
                             f"{args.textures[0]} {a.shape[:2]}", args.textures[1])
        textures = interpolate_textures(a, b, args.frames)
    paths = write_obj_sequence(args.out, start, frames, textures=textures)
    print(f"wrote {len(paths)} frames to {args.out}")
    return 0


def cmd_demo(args) -> int:
    """Run the main job on the built-in sample and say where the outputs are."""
    from facewrap.cli.demo import run_demo
    return run_demo(Path(args.out), verbose=not args.quiet)


def add_fit_options(p) -> None:
    """The fitting options shared by ``wrap`` and ``track`` (see WrapSettings)."""
    p.add_argument("--blendshapes", metavar="DIR",
                   help="folder of meshes in the template's topology (shape = file - "
                        "template)")
    p.add_argument("--model", default="auto", choices=list(MODELS),
                   help="deformation model (default: hybrid with --blendshapes, "
                        "else graph)")
    p.add_argument("--exclude", help="template vertex ids not to fit (they follow)")
    p.add_argument("--node-spacing", type=float, default=WrapSettings.node_spacing,
                   help="graph node spacing, fraction of template size (default "
                        "%(default)s)")
    p.add_argument("--robust", default=WrapSettings.robust,
                   choices=["welsch", "huber", "geman_mcclure", "none"],
                   help="robust norm of the data term (default %(default)s)")
    p.add_argument("--pca-components", type=int, default=None,
                   help="fit this many PCA components of the blendshapes")
    p.add_argument("--weight-range", type=float, nargs=2, metavar=("LO", "HI"),
                   default=WrapSettings.weight_range,
                   help="range of the blend weights (default 0 1, an expression "
                        "rig's); see --no-weight-range")
    p.add_argument("--no-weight-range", action="store_true",
                   help="let blend weights take any value (identity or corrective "
                        "shapes used with negative or > 1 weights)")
    p.add_argument("--landmark-tolerance", type=float,
                   default=WrapSettings.landmark_tolerance, metavar="F",
                   help="landmarks left farther than this from their targets after "
                        "the fit (fraction of template size) are pulled to it; 0 keeps "
                        "them exactly (default %(default)s)")
    p.add_argument("--no-landmark-pull", action="store_true",
                   help="leave the landmarks where the fit puts them")
    p.add_argument("--kernel", default="biharmonic",
                   choices=["biharmonic", "thin_plate", "exponential", "gaussian"],
                   help="RBF kernel of the landmark warp")
    p.add_argument("--smoothing", type=float, default=0.0,
                   help="RBF smoothing for noisy landmarks (default 0)")
    p.add_argument("--max-distance", type=float, default=None,
                   help="longest projection move (default 5%% of template size)")
    p.add_argument("--no-project", action="store_true", help="skip the projection")
    p.add_argument("--rigid-refine", action="store_true",
                   help="refine the alignment with rigid ICP")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="facewrap",
        description="Wrap a template head onto face scans, transfer deformations, "
                    "make avatar blendshapes.")
    parser.add_argument("--version", action="version", version=f"facewrap {__version__}")
    parser.add_argument("-v", "--verbose", dest="log_verbose", action="count", default=0,
                        help="more log lines (-v info, -vv debug) on standard error")
    parser.add_argument("--silent", dest="log_quiet", action="count", default=0,
                        help="only errors in the log, no progress bars")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("info", help="summary of a mesh file")
    p.add_argument("mesh", help="OBJ or PLY file")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("convert", help="convert a mesh between OBJ and PLY")
    p.add_argument("input")
    p.add_argument("output")
    p.set_defaults(func=cmd_convert)

    p = sub.add_parser("sample", help="write the built-in synthetic template and scan")
    p.add_argument("out", help="output folder")
    p.set_defaults(func=cmd_sample)

    p = sub.add_parser("wrap", help="fit a template onto a scan (template topology kept)")
    p.add_argument("template", help="template mesh (OBJ/PLY)")
    p.add_argument("scan", help="scan mesh (OBJ/PLY)")
    p.add_argument("-o", "--output", required=True, help="output mesh (OBJ/PLY)")
    p.add_argument("--template-landmarks", required=True,
                   help="template vertex ids (text) or facewrap landmark JSON")
    p.add_argument("--scan-landmarks", required=True,
                   help="scan points: 'x y z' text, menpo .ljson or facewrap JSON")
    add_fit_options(p)
    p.add_argument("--texture", help="scan texture image to bake into the template UVs")
    p.add_argument("--texture-size", type=int, default=1024)
    p.add_argument("--report", help="write metrics and timings as JSON")
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_wrap)

    p = sub.add_parser("animate", help="interpolate two fitted meshes into a sequence")
    p.add_argument("start", help="first mesh (e.g. fitted neutral)")
    p.add_argument("end", help="last mesh, same topology")
    p.add_argument("--frames", type=int, default=10, help="frames including both ends")
    p.add_argument("--textures", nargs=2, metavar=("START_PNG", "END_PNG"),
                   help="textures to blend along")
    p.add_argument("-o", "--out", required=True, help="output folder")
    p.set_defaults(func=cmd_animate)

    for name in _COMMAND_MODULES:
        import_module(f"{__name__}.{name}").register(sub)

    p = sub.add_parser("demo", help="run the main job on the built-in sample")
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_demo)
    return parser


def main(argv=None) -> int:
    """Entry point of the ``facewrap`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    from facewrap.progress import configure_logging
    # progress bars draw only on a terminal; logs go to standard error
    configure_logging(args.log_verbose - args.log_quiet
                      - (1 if getattr(args, "quiet", False) else 0))
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"facewrap: error: {exc}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"facewrap: error: {exc.filename}: no such file", file=sys.stderr)
        return 2
    except ValueError as exc:  # inconsistent inputs found past the readers
        print(f"facewrap: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
