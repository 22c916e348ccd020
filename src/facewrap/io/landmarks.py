"""Landmark and marker files.

Formats read (and, where it makes sense, written):

* **vertex-index lists** — whitespace separated 0-based vertex ids, on one line or
  many (ICT, Onizuka ``landmarks_*.txt``): :func:`read_vertex_indices`;
* **point lists** — one ``x y z`` (or ``x,y,z``) per line, optional ``name`` as a
  fourth column: :func:`read_points`;
* **iBUG ``.pts``** — ``version: 1`` / ``n_points: N`` / ``{`` one ``x y z`` row per
  point ``}``: :func:`read_pts` (2-D rows, the usual image landmarks, are refused:
  a wrap needs points in space);
* **menpo LJSON** v1–v3 (``.ljson``) — points named ``<label>_<k>`` by their label
  group: :func:`read_ljson`;
* **marker pairs** — ``src tgt`` (or ``src, tgt``) per line with an optional count
  first line (Sumner's ``.cons``), or YAML with ``markers: ["src:tgt", ...]``:
  :func:`read_markers`;
* **facewrap JSON** — our own documented format, any landmark kind, names kept
  (:func:`read_landmarks_json`, :func:`write_landmarks_json`)::

      {"format": "facewrap.landmarks", "version": 1,
       "landmarks": [
         {"name": "nose_tip", "vertex": 20},
         {"name": "mouth_left", "triangle": 511, "barycentric": [0.2, 0.3, 0.5]},
         {"name": "pupil_r", "point": [31.2, 10.5, 88.0]}]}

  Detected landmarks may add ``"confidence"`` and ``"low_confidence"`` per landmark
  and top-level ``"source"`` and ``"views"`` (:func:`read_landmark_details`).
  A marker-pair JSON uses ``{"format": "facewrap.markers", "version": 1,
  "pairs": [[src, tgt], ...]}``.

:func:`read_landmarks` picks a reader from the extension and, for plain text,
from the content: integer text is a vertex-index list unless every line holds
exactly three numbers (then, like anything else, it is read as points).
Every reader raises one :class:`~facewrap.errors.InputError` naming the file and
line for malformed content.
"""

from __future__ import annotations

import json
import os
import re

import numpy as np

from facewrap.errors import InputError
from facewrap.landmarks import IBUG68_NAMES, Landmarks
from facewrap.io.atomic import atomic_write
from facewrap.io.files import check_coordinates, not_a_file, read_file_bytes, read_json
from facewrap.io.landmarks_json import (read_landmark_details, read_landmarks_json,
                                         write_landmarks_json)

__all__ = ["read_landmarks", "read_vertex_indices", "read_points", "read_pts", "read_ljson",
           "read_landmarks_json", "write_landmarks_json", "read_landmark_details",
           "write_points",
           "write_vertex_indices", "read_markers", "write_markers"]

_INT = re.compile(r"^[+-]?\d+$")


#: Largest index a file may hold (int64); larger ones are errors, not overflows.
_MAX_INDEX = 2**63 - 1


def _bounded(value: int, path, line=None) -> int:
    """An integer read from a file, checked to fit an int64 index."""
    if abs(value) > _MAX_INDEX:
        raise InputError(f"index {str(value)[:30]} is too large", path, line)
    return value


def _text(path) -> str:
    # a byte-order mark (Windows editors write one) is not part of the first line
    return read_file_bytes(path, text=True).decode("utf-8-sig", errors="replace")


def _content_lines(text: str):
    """(line number, stripped line) for lines that are not blank or comments."""
    for i, line in enumerate(text.splitlines(), start=1):
        s = line.split("#", 1)[0].strip()
        if s:
            yield i, s


def read_vertex_indices(path, n_vertices: int | None = None) -> Landmarks:
    """Read 0-based vertex ids separated by white space (or commas).

    Parameters
    ----------
    path : str or os.PathLike
    n_vertices : int, optional
        When given, ids must be below it.

    Returns
    -------
    Landmarks
        Vertex landmarks, in file order, unnamed.
    """
    ids, lines = [], []
    for no, s in _content_lines(_text(path)):
        for tok in s.replace(",", " ").split():
            if not _INT.match(tok):
                raise InputError(f"vertex index is not an integer: {tok!r}", path, no)
            ids.append(_bounded(int(tok), path, no))
            lines.append(no)
    if not ids:
        raise InputError("no vertex indices", path)
    arr = np.asarray(ids, dtype=np.int64)
    if (arr < 0).any():
        k = int(np.argmax(arr < 0))
        raise InputError(f"negative vertex index {arr[k]}", path, lines[k])
    if n_vertices is not None and (arr >= n_vertices).any():
        k = int(np.argmax(arr >= n_vertices))
        raise InputError(f"vertex index {arr[k]} out of range (mesh has {n_vertices} "
                         "vertices)", path, lines[k])
    return Landmarks.from_vertices(arr)


def write_vertex_indices(path, landmarks: Landmarks) -> None:
    """Write vertex landmarks as one 0-based id per line."""
    if np.any(landmarks.vertex < 0):
        raise ValueError("only vertex landmarks can be written as an index list")
    with atomic_write(path, "w") as fh:
        fh.write("".join(f"{i}\n" for i in landmarks.vertex.tolist()))


def read_points(path) -> Landmarks:
    """Read ``x y z`` points, one per line (commas allowed, optional 4th-column name).

    Returns
    -------
    Landmarks
        Free points; named when every line carries a name.
    """
    pts, names = [], []
    for no, s in _content_lines(_text(path)):
        toks = s.replace(",", " ").split()
        if len(toks) not in (3, 4):
            raise InputError(f"expected 'x y z' (and an optional name), found "
                             f"{len(toks)} values", path, no)
        try:
            xyz = [float(t) for t in toks[:3]]
        except ValueError:
            raise InputError(f"not a number in {s[:60]!r}", path, no) from None
        if not np.isfinite(xyz).all():
            raise InputError("NaN or infinite coordinate", path, no)
        pts.append(xyz)
        names.append(toks[3] if len(toks) == 4 else None)
    if not pts:
        raise InputError("no points", path)
    named = all(n is not None for n in names)
    if any(n is not None for n in names) and not named:
        raise InputError("some points have names and some do not", path)
    try:
        return Landmarks.from_points(np.asarray(pts), names if named else None)
    except ValueError as exc:
        raise InputError(str(exc), path) from None


def write_points(path, points_or_landmarks, names=None) -> None:
    """Write ``x y z [name]`` lines (full float precision)."""
    if isinstance(points_or_landmarks, Landmarks):
        names = points_or_landmarks.names if names is None else names
        if not np.isfinite(points_or_landmarks.points).all():
            raise ValueError("only free-point landmarks can be written as points; "
                             "resolve them with Landmarks.positions first")
        pts = points_or_landmarks.points
    else:
        pts = np.asarray(points_or_landmarks, dtype=np.float64)
    rows = [f"{x!r} {y!r} {z!r}" for x, y, z in pts.tolist()]
    if names is not None:
        rows = [f"{r} {n}" for r, n in zip(rows, names)]
    with atomic_write(path, "w") as fh:
        fh.write("\n".join(rows) + "\n")


def _pts_header(rows, path) -> tuple[int, int]:
    """(number of points the header promises, index of the row after ``{``)."""
    n_points = None
    for k, (no, s) in enumerate(rows):
        if s == "{":
            if n_points is None:
                raise InputError("no 'n_points:' line before '{'", path, no)
            return n_points, k + 1
        key, colon, value = s.partition(":")
        key = key.strip().lower()
        if not colon or key not in ("version", "n_points", "image_size_x",
                                    "image_size_y"):
            raise InputError(f"not an iBUG .pts header line: {s[:60]!r}", path, no)
        if key == "n_points":
            if not _INT.match(value.strip()) or int(value) < 1:
                raise InputError(f"n_points must be a positive integer, got "
                                 f"{value.strip()[:30]!r}", path, no)
            n_points = _bounded(int(value), path, no)
    raise InputError("no '{' opening the points", path)


def read_pts(path) -> Landmarks:
    """Read iBUG ``.pts`` landmarks with 3-D rows.

    The format: ``version: 1``, ``n_points: N``, then ``{``, N rows of coordinates
    and ``}``.  Rows of three numbers are points in space (3-D landmarks of a scan);
    rows of two are image landmarks, which a wrap cannot use.

    Returns
    -------
    Landmarks
        ``N`` free points, in file order, unnamed.

    Raises
    ------
    InputError
        Naming the file (and line): 2-D rows ("2-D landmarks; facewrap needs 3-D
        points"), a count that differs from ``n_points``, rows of mixed sizes, a
        missing ``{`` or ``}``, values that are not finite numbers.
    """
    rows = list(_content_lines(_text(path)))
    n_points, start = _pts_header(rows, path)
    body = rows[start:]
    if not body or body[-1][1] != "}":
        raise InputError("no '}' closing the points", path)
    body = body[:-1]
    if len(body) != n_points:
        raise InputError(f"n_points says {n_points} but {len(body)} rows follow", path)
    widths = {len(s.replace(",", " ").split()) for _, s in body}
    if widths == {2}:
        raise InputError("2-D landmarks; facewrap needs 3-D points", path)
    for no, s in body:
        if len(s.replace(",", " ").split()) != 3:
            raise InputError(f"expected 'x y z', found {s[:60]!r}", path, no)
    try:
        pts = np.array([s.replace(",", " ").split() for _, s in body], dtype=np.float64)
    except ValueError:
        raise InputError("a coordinate is not a number", path) from None
    if not np.isfinite(pts).all():
        line = body[int(np.argmax(~np.isfinite(pts).all(axis=1)))][0]
        raise InputError("NaN or infinite coordinate", path, line)
    return Landmarks.from_points(pts)


def read_ljson(path, ibug68: bool = True) -> Landmarks:
    """Read menpo LJSON (v1, v2, v3) landmarks.

    Points are named ``<label>_<k>`` (k-th point of the label's mask) when the file
    labels them, e.g. ``chin_0``.  When the labels are menpo's 68-point face groups
    (chin, leye, reye, leyebrow, nose, reyebrow, mouth — ordered by group, not in
    iBUG order) and ``ibug68`` is true, the points are reordered into the standard
    iBUG-68 order and named :data:`~facewrap.landmarks.IBUG68_NAMES`, so they pair
    with any iBUG-68 landmark set.  A point that menpo marks missing (``null``) is
    an error: this reader never invents positions.
    """
    d = read_json(path)
    if not isinstance(d, dict):
        raise InputError("LJSON must be an object", path)
    version = d.get("version", 1)
    if version in (1, 2) and "landmarks" in d and "groups" not in d:
        block = d["landmarks"]
        raw = block.get("points") if isinstance(block, dict) else None
        labels = d.get("labels", [])
    else:
        groups = d.get("groups")
        if not isinstance(groups, dict) or not groups:
            raise InputError("LJSON has no 'groups'", path)
        group = groups.get("LJSON") or next(iter(groups.values()))
        if not isinstance(group, dict) or not isinstance(group.get("landmarks", {}), dict):
            raise InputError("LJSON group must be an object with 'landmarks'", path)
        raw = group.get("landmarks", {}).get("points")
        labels = group.get("labels", [])
    if not isinstance(labels, list) or not all(isinstance(lab, dict) for lab in labels):
        raise InputError("LJSON 'labels' must be a list of objects", path)
    if not isinstance(raw, list) or not raw:
        raise InputError("LJSON has no landmark points", path)
    if version in (1, 2) and raw and isinstance(raw[0], dict):
        raw = [p.get("point") for p in raw]
    for k, p in enumerate(raw):
        if (not isinstance(p, list) or len(p) != 3
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                           for x in p)):
            raise InputError(f"landmark {k} is missing or not an [x, y, z] point", path)
    try:
        pts = np.asarray(raw, dtype=np.float64)
    except OverflowError:
        raise InputError("landmark coordinate too large", path) from None
    if not np.isfinite(pts).all():
        raise InputError("NaN or infinite landmark coordinate", path)
    names = None
    if labels:
        names = [None] * len(pts)
        for lab in labels:
            mask = lab.get("mask", [])
            if not isinstance(mask, list):
                raise InputError(f"label {lab.get('label')!r}: 'mask' must be a list",
                                 path)
            for k, i in enumerate(mask):
                if not isinstance(i, int) or not 0 <= i < len(pts):
                    raise InputError(f"label {lab.get('label')!r} has a mask index "
                                     f"out of range: {i}", path)
                names[i] = f"{lab.get('label')}_{k}"
        if any(n is None for n in names) or len(set(names)) != len(names):
            names = None  # partial or overlapping labels: fall back to order only
    lm = Landmarks.from_points(pts, names)
    return _menpo_face_to_ibug68(lm) if ibug68 else lm


#: menpo's 68-point face groups (as in ``james.ljson``) in the order that gives the
#: standard iBUG-68 order: the "l" groups are on the same side as chin_0, i.e. the
#: subject's right, which iBUG numbers first (checked on james and ICT geometry).
_MENPO_TO_IBUG = (("chin", 17), ("leyebrow", 5), ("reyebrow", 5), ("nose", 9),
                  ("leye", 6), ("reye", 6), ("mouth", 20))


def _menpo_face_to_ibug68(lm: Landmarks) -> Landmarks:
    """Reorder menpo face-group landmarks into iBUG-68 order and names (or return
    them unchanged when they are not menpo's 68-point face layout)."""
    if lm.names is None or len(lm) != 68:
        return lm
    pos = {n: i for i, n in enumerate(lm.names)}
    order = []
    for group, count in _MENPO_TO_IBUG:
        keys = [f"{group}_{k}" for k in range(count)]
        if not all(k in pos for k in keys):
            return lm
        order += [pos[k] for k in keys]
    return Landmarks.from_points(lm.points[order], IBUG68_NAMES)


def read_landmarks(path, kind: str = "auto") -> Landmarks:
    """Read landmarks, choosing the reader from extension and content.

    Parameters
    ----------
    path : str or os.PathLike
    kind : {"auto", "vertices", "points"}
        For plain text: ``"auto"`` reads integer text as vertex ids unless every
        line has exactly three values, and one value a line as vertex ids (a
        value that is not an id is then named with its line); anything else is
        read as ``x y z`` points.
    """
    landmarks = _read_any_landmarks(path, kind)
    # free points no head could hold (a 1e308 passed the NaN check and
    # overflowed the alignment into "landmarks on one line")
    free = landmarks.points[np.isfinite(landmarks.points).all(axis=1)]
    check_coordinates(free, path, "landmark")
    return landmarks


def _read_any_landmarks(path, kind: str) -> Landmarks:
    """The reader of :func:`read_landmarks`, by extension and ``kind``."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if not os.path.isfile(path):
        raise not_a_file(path)
    if ext == ".ljson":
        return read_ljson(path)
    if ext == ".pts":
        return read_pts(path)
    if ext == ".json":
        return read_landmarks_json(path)
    if kind == "vertices":
        return read_vertex_indices(path)
    if kind == "points":
        return read_points(path)
    if kind != "auto":
        raise ValueError(f"kind must be 'auto', 'vertices' or 'points', got {kind!r}")
    rows = [s.replace(",", " ").split() for _, s in _content_lines(_text(path))]
    all_int = all(_INT.match(t) for r in rows for t in r)
    # one value a line is an id list even with a bad id in it ("12.0" on line 3),
    # so the error names that line, not "expected 'x y z'" on line 1
    one_column = all(len(r) == 1 for r in rows)
    if one_column or (all_int and not all(len(r) == 3 for r in rows)):
        return read_vertex_indices(path)
    return read_points(path)


def read_markers(path) -> tuple[np.ndarray, np.ndarray]:
    """Read marker pairs (source vertex id, target vertex id), 0-based.

    Accepts Sumner's ``.cons`` (optional count line, then ``src, tgt`` or ``src tgt``
    per line), YAML with ``markers: ["src:tgt", ...]`` (``.yml``/``.yaml``), and the
    facewrap marker JSON.  A pair given twice is kept; a vertex paired with two
    different partners is refused (the two pairs contradict each other).

    Returns
    -------
    source : (k,) int64
    target : (k,) int64

    Raises
    ------
    InputError
        Naming the file: malformed, or the first pair that contradicts another.
    """
    source, target = _read_marker_pairs(path)
    _check_one_partner(source, target, path)
    return source, target


def _check_one_partner(source: np.ndarray, target: np.ndarray, path) -> None:
    """Refuse a vertex on either side that two markers give different partners."""
    pairs = np.stack([source, target], axis=1)
    _, first = np.unique(pairs, axis=0, return_index=True)
    first = np.sort(first)   # one marker per distinct pair, in file order
    for side, other, what, whose in ((0, 1, "source", "target"),
                                     (1, 0, "target", "source")):
        ids = pairs[first, side]
        _, seen, counts = np.unique(ids, return_index=True, return_counts=True)
        if not np.any(counts > 1):
            continue
        vertex = ids[seen[counts > 1]]
        rows = first[np.isin(ids, vertex)]
        a = rows[0]                                   # the first pair in conflict
        b = rows[(pairs[rows, side] == pairs[a, side])][1]
        raise InputError(f"markers {a} and {b} pair {what} vertex {pairs[a, side]} with "
                         f"two {whose} vertices ({pairs[a, other]} and "
                         f"{pairs[b, other]}): each vertex can have one partner only",
                         path)


def _read_marker_pairs(path) -> tuple[np.ndarray, np.ndarray]:
    """Marker pairs as the file gives them (see :func:`read_markers`)."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext in (".yml", ".yaml"):
        return _read_markers_yaml(path)
    if ext == ".json":
        d = read_json(path)
        if not isinstance(d, dict) or d.get("format") != "facewrap.markers":
            raise InputError("not a facewrap marker file (\"format\": "
                             "\"facewrap.markers\" missing)", path)
        pairs = d.get("pairs")
        if not isinstance(pairs, list) or not all(
                isinstance(p, list) and all(isinstance(x, int) and not isinstance(x, bool)
                                            for x in p) for p in pairs):
            raise InputError("'pairs' must be a list of [source, target] integers",
                             path)
        try:
            arr = np.asarray(pairs, dtype=np.int64)
        except (TypeError, ValueError, OverflowError):
            raise InputError("'pairs' must be a list of [source, target] integers "
                             "(int64)", path) from None
        if arr.ndim != 2 or arr.shape[1] != 2 or len(arr) == 0:
            raise InputError("'pairs' must be a non-empty list of [source, target]", path)
        if (arr < 0).any():
            raise InputError("negative vertex id in 'pairs'", path)
        return arr[:, 0].copy(), arr[:, 1].copy()
    rows = list(_content_lines(_text(path)))
    expected = None
    first_toks = rows[0][1].replace(",", " ").split() if rows else []
    if len(first_toks) == 1:
        if not _INT.match(first_toks[0]):
            raise InputError(f"not a marker count: {first_toks[0]!r}", path, rows[0][0])
        expected = _bounded(int(first_toks[0]), path, rows[0][0])
        rows = rows[1:]
    src, tgt = [], []
    for no, s in rows:
        toks = s.replace(",", " ").split()
        if len(toks) != 2 or not all(_INT.match(t) for t in toks):
            raise InputError(f"expected 'source_vertex target_vertex', found {s[:60]!r}",
                             path, no)
        a, b = _bounded(int(toks[0]), path, no), _bounded(int(toks[1]), path, no)
        if a < 0 or b < 0:
            raise InputError("negative vertex id", path, no)
        src.append(a)
        tgt.append(b)
    if not src:
        raise InputError("no marker pairs", path)
    if expected is not None and expected != len(src):
        raise InputError(f"the count line says {expected} markers but {len(src)} "
                         "pairs follow", path)
    return np.asarray(src, dtype=np.int64), np.asarray(tgt, dtype=np.int64)


def _read_markers_yaml(path):
    # deferred: only YAML files need PyYAML (start-up of every other command)
    import yaml
    try:
        d = yaml.safe_load(_text(path))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = " ".join(str(getattr(exc, "problem", None) or exc).split())
        raise InputError(f"invalid YAML: {problem}", path,
                         None if mark is None else mark.line + 1) from None
    items = d.get("markers") if isinstance(d, dict) else None
    if not isinstance(items, list) or not items:
        raise InputError("YAML has no 'markers' list", path)
    src, tgt = [], []
    for k, it in enumerate(items):
        m = re.match(r"^\s*(\d+)\s*[:,\s]\s*(\d+)\s*$", str(it))
        if not m:
            raise InputError(f"marker {k} is not 'source:target': {it!r}", path)
        src.append(_bounded(int(m.group(1)), path))
        tgt.append(_bounded(int(m.group(2)), path))
    return np.asarray(src, dtype=np.int64), np.asarray(tgt, dtype=np.int64)


def write_markers(path, source, target) -> None:
    """Write marker pairs as a count line and ``src tgt`` lines (``.cons`` style)."""
    s = np.asarray(source, dtype=np.int64)
    t = np.asarray(target, dtype=np.int64)
    if s.shape != t.shape or s.ndim != 1:
        raise ValueError("source and target must be 1-D arrays of the same length")
    with atomic_write(path, "w") as fh:
        fh.write(f"{len(s)}\n" + "".join(f"{a} {b}\n" for a, b in zip(s.tolist(),
                                                                    t.tolist())))
