"""``facewrap info MESH``: a summary of a mesh file (counts, pieces, borders, size)."""

from __future__ import annotations

import json
import sys

import numpy as np

from facewrap.io import read_mesh
from facewrap.units import (add_units_argument, format_distance, resolve_units,
                            units_conflict, units_note)

__all__ = ["register", "cmd_info"]


def cmd_info(args) -> int:
    """Print a summary of a mesh (as text, or JSON with ``--json``)."""
    # deferred: `facewrap info --help` does not load the geometry
    from facewrap.geometry.adjacency import boundary_loops, connected_components
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
    unit, source = resolve_units(args.units, mesh.surface_points())
    conflict = units_conflict(args.units, mesh.surface_points())
    if conflict:   # shown as given, but never as if it were fine
        print(f"facewrap: warning: {args.mesh}: {conflict}", file=sys.stderr)
    if args.json:
        print(json.dumps({**info, "units": unit, "units_source": source}, indent=1))
        return 0
    # every length shown carries its unit (inferred from the head's size, and said so)
    info["bounding_box"] = " to ".join(
        "(" + ", ".join(format_distance(x, unit, with_unit=False) for x in corner) + ")"
        for corner in (lo, hi)) + " " + format_distance(1.0, unit).split()[-1]
    info["diagonal"] = format_distance(mesh.scale(), unit)
    for k, v in info.items():
        print(f"{k:>15}: {v}")
    print(units_note(unit, source))
    return 0


def register(subparsers, summary: str) -> None:
    """Add ``info`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser("info", help=summary)
    p.add_argument("mesh", help="OBJ or PLY file")
    p.add_argument("--json", action="store_true", help="print JSON")
    add_units_argument(p)
    p.set_defaults(func=cmd_info)
