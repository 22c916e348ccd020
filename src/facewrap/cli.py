"""The ``facewrap`` command: parsing arguments and calling the library, nothing else.

Each subcommand is a small function ``cmd_<name>(args)`` registered in
:func:`build_parser`.  Errors in user input (:class:`~facewrap.errors.InputError`,
missing files) print one line ``facewrap: error: <file>:<line>: <problem>`` and
exit with status 2; nothing is written in that case.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from . import __version__
from .errors import InputError

__all__ = ["main", "build_parser"]


def cmd_info(args) -> int:
    """Print a summary of a mesh (and its landmarks)."""
    import numpy as np
    from .geometry import boundary_loops, connected_components
    from .io import read_mesh
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
    from .io import read_mesh, write_mesh
    write_mesh(args.output, read_mesh(args.input))
    print(args.output)
    return 0


def cmd_sample(args) -> int:
    """Write the built-in synthetic template and scan to a folder."""
    from .sample import make_scan, make_template, write_sample
    template = make_template()
    scan = make_scan(template)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    paths = write_sample(out, template, scan)
    for name, p in paths.items():
        print(f"{name:>20}: {p}")
    return 0


def cmd_demo(args) -> int:
    """Run the main job on the built-in sample and say where the outputs are."""
    from .demo import run_demo
    return run_demo(Path(args.out), verbose=not args.quiet)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="facewrap",
        description="Wrap a template head onto face scans, transfer deformations, "
                    "make avatar blendshapes.")
    parser.add_argument("--version", action="version", version=f"facewrap {__version__}")
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

    p = sub.add_parser("demo", help="run the main job on the built-in sample")
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_demo)
    return parser


def main(argv=None) -> int:
    """Entry point of the ``facewrap`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"facewrap: error: {exc}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"facewrap: error: {exc.filename}: no such file", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
