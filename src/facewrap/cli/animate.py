"""``facewrap animate START END -o DIR``: frames between two fitted meshes."""

from __future__ import annotations

import contextlib
import os
import sys

import numpy as np

from facewrap.errors import InputError
from facewrap.io import read_mesh
from facewrap.io.paths import check_output_paths

__all__ = ["register", "cmd_animate", "unlike_ends", "TURN_LIMIT", "SIZE_LIMIT"]


def cmd_animate(args) -> int:
    """Frames between two fitted meshes of one topology, as an OBJ sequence."""
    # deferred: the other commands (and `facewrap --help`) do not pay for this import
    from facewrap.animation import (check_sequence_budget, interpolate_textures,
                                    interpolate_vertices, obj_sequence_files,
                                    write_obj_sequence)
    from facewrap.io.images import load_image
    with _naming_frames():
        obj_sequence_files(args.out, args.frames)   # the count, before reading anything
    start, end = read_mesh(args.start), read_mesh(args.end)
    if (start.n_vertices != end.n_vertices
            or not np.array_equal(start.face_indices, end.face_indices)):
        raise InputError(f"is not in the topology of {args.start} (vertex count or "
                         "faces differ)", args.end)
    # an OBJ frame is about as large as the start mesh's file (and at least a
    # vertex line per vertex)
    frame_bytes = max(os.path.getsize(args.start), 40 * start.n_vertices)
    with _naming_frames():   # the frames alone first: checking 10^5 output paths is slow
        check_sequence_budget(args.out, args.frames, start.n_vertices, frame_bytes)
    check_output_paths(files=obj_sequence_files(args.out, args.frames,
                                                textures=bool(args.textures)),
                       folders=[args.out],
                       inputs=[args.start, args.end, *(args.textures or ())])
    a = b = None
    if args.textures:
        a, b = (load_image(p) for p in args.textures)
        if a.shape != b.shape:
            raise InputError(f"image size {b.shape[:2]} differs from "
                             f"{args.textures[0]} {a.shape[:2]}", args.textures[1])
    if a is not None:
        with _naming_frames():   # and their textures
            check_sequence_budget(args.out, args.frames, start.n_vertices, frame_bytes,
                                  image_shape=a.shape)
    notes = unlike_ends(start.vertices, end.vertices, args.start, args.end)
    frames = interpolate_vertices(start.vertices, end.vertices, args.frames)
    textures = None if a is None else interpolate_textures(a, b, args.frames)
    paths = write_obj_sequence(args.out, start, frames, textures=textures)
    for note in notes:   # written all the same, but never as if they were fine
        print(f"facewrap: warning: {note}", file=sys.stderr)
    print(f"wrote {len(paths)} frames to {args.out}")
    return 0


#: in-between frames of ends turned farther apart than this (degrees) shrink: the
#: halfway frame by 1 - cos(angle / 2), 8 % at 45 degrees
TURN_LIMIT = 45.0
#: ends whose sizes differ by more than this factor either way are not one head
SIZE_LIMIT = 1.25


def unlike_ends(start, end, start_path, end_path) -> list[str]:
    """Warnings for two meshes that cannot be two poses of one head: one a mirror
    image of the other, one in other units, or turned so far that the straight
    in-between frames shrink the head; and for one mesh given as both ends.

    Parameters
    ----------
    start, end : (n, 3) float
        Vertex positions in one topology.
    start_path, end_path : path
        For the messages (they name the end).

    Returns
    -------
    list of str
        One line each.
    """
    if np.array_equal(start, end):   # a mesh given twice: a still, not an animation
        return [f"{end_path}: is {start_path} again (every vertex alike): every frame "
                "is the same"]
    # deferred: `facewrap animate --help` loads no geometry
    from facewrap.geometry.similarity import pose_change
    change = pose_change(start, end)
    if change.mirrored:   # then the best proper turn and scale say nothing more
        return [f"{end_path}: is a mirror image of {start_path} (left and right "
                "swapped): the in-between frames pass through a flattened head"]
    notes = []
    if not 1 / SIZE_LIMIT <= change.scale <= SIZE_LIMIT:
        notes.append(f"{end_path}: is {change.scale:.3g} times the size of {start_path}: "
                     "in other units?")
    if change.angle > TURN_LIMIT:
        shrink = 1 - np.cos(np.radians(change.angle) / 2)
        notes.append(f"{end_path}: is turned {change.angle:.0f} degrees from "
                     f"{start_path}: the straight in-between frames shrink the head (the "
                     f"middle one by {100 * shrink:.0f} %)")
    return notes


@contextlib.contextmanager
def _naming_frames():
    """A refused frame count as one line naming ``--frames``."""
    try:
        yield
    except ValueError as exc:
        raise InputError(str(exc).removeprefix("frames "), "--frames") from None


def register(subparsers, summary: str) -> None:
    """Add ``animate`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser("animate", help=summary)
    p.add_argument("start", help="first mesh (e.g. fitted neutral)")
    p.add_argument("end", help="last mesh, same topology")
    p.add_argument("--frames", type=int, default=10, help="frames including both ends")
    p.add_argument("--textures", nargs=2, metavar=("START_PNG", "END_PNG"),
                   help="textures to blend along")
    p.add_argument("-o", "--out", required=True, help="output folder")
    p.set_defaults(func=cmd_animate)
