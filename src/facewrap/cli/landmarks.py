"""``facewrap landmarks MESH -o landmarks.json``: the 68 iBUG points found on a mesh.

Parsing and one call: :func:`facewrap.detection.detect_landmarks` on the mesh (drawn
textured with ``--texture`` or the image its material names, shaded otherwise),
written as facewrap landmark JSON with a confidence and a low-confidence flag per
point and the views used (:func:`facewrap.io.landmarks.write_landmarks_json`).
The output is checked against the inputs before any work and staged.
"""

from __future__ import annotations

import sys

from facewrap.errors import InputError
from facewrap.io import read_mesh
from facewrap.io.images import load_image
from facewrap.io.landmarks import write_landmarks_json
from facewrap.io.paths import check_output_paths, staged_outputs
from facewrap.units import (add_units_argument, format_distance, resolve_units,
                            units_conflict, units_note)

__all__ = ["register", "cmd_landmarks", "detection_summary"]


def detection_summary(found, unit: str) -> str:
    """One line about detected landmarks: flagged points, eye distance with its unit,
    views, seconds."""
    low = [found.landmarks.names[i] for i in found.low_confidence.nonzero()[0]]
    shown = ", ".join(low[:4]) + (", ..." if len(low) > 4 else "")
    views = sum(v["found"] for v in found.views)
    return (f"68 landmarks, {len(low)} low-confidence{f' ({shown})' if low else ''}, "
            f"mean confidence {found.confidence.mean():.2f}, eye distance "
            f"{format_distance(found.eye_distance, unit)}, face in {views} of "
            f"{len(found.views)} views, {found.timings['total']:.2f} s")


def cmd_landmarks(args) -> int:
    """Detect the landmarks of a face mesh and write them as JSON."""
    from facewrap.detection import detect_landmarks, mesh_texture  # dlib loads on use

    inputs = [args.mesh] + ([args.texture] if args.texture else [])
    check_output_paths(files=[args.output], inputs=inputs)
    if not args.output.lower().endswith(".json"):
        raise InputError("landmarks are written as facewrap JSON: give a .json output",
                         args.output)
    mesh = read_mesh(args.mesh)
    if len(mesh.triangles) == 0:
        raise InputError("has no faces; landmarks are found on a surface", args.mesh)
    conflict = units_conflict(args.units, mesh.surface_points())
    if conflict:   # the eye distance is said in it all the same
        print(f"facewrap: warning: {args.mesh}: {conflict}", file=sys.stderr)
    if args.shaded:
        image = None
    elif args.texture:
        if mesh.uvs is None:
            raise InputError("--texture given but the mesh has no texture coordinates",
                             args.mesh)
        image = load_image(args.texture)
    else:
        image = mesh_texture(args.mesh, mesh)
    found = detect_landmarks(mesh, image, source=args.mesh)
    with staged_outputs() as stage:
        write_landmarks_json(stage.file(args.output), found.landmarks,
                             confidence=found.confidence,
                             low_confidence=found.low_confidence,
                             views=found.views, source="detected")
    unit, source = resolve_units(args.units, mesh.surface_points())
    lines = [f"wrote {args.output}: {detection_summary(found, unit)}"]
    lines += [units_note(unit, source)] if source == "inferred" else []
    print("\n".join([] if args.quiet else lines), end="" if args.quiet else "\n")
    return 0


def register(subparsers, summary: str) -> None:
    """Add ``landmarks`` to the ``facewrap`` subcommands."""
    p = subparsers.add_parser("landmarks", help=summary)
    p.add_argument("mesh", help="face scan or template (OBJ/PLY/glTF/STL/OFF)")
    p.add_argument("-o", "--output", required=True, help="landmark JSON to write")
    p.add_argument("--texture", metavar="IMG",
                   help="texture image of the mesh (default: the one its material "
                        "names, if any)")
    p.add_argument("--shaded", action="store_true",
                   help="draw the mesh shaded even when it has a texture")
    add_units_argument(p)
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_landmarks)
