"""Wavefront OBJ reading and writing, exact and vectorised.

Reading keeps the vertex count and order, polygons as they are (quads stay quads),
per-corner ``vt``/``vn`` indices (UV seams), ``usemtl`` materials, ``g``/``o`` groups
and ``mtllib`` references.  Numbers are parsed in bulk with numpy, so a
1M-triangle file loads in a few seconds; lines are looked at one by one only to
name the line of an error.

Writing prints floats with Python's shortest round-trip representation, so a mesh
read back is bit-identical, and replaces the destination atomically.
"""

from __future__ import annotations

import os
import warnings

import numpy as np

from ..errors import InputError
from ..mesh import Mesh
from .atomic import atomic_write

__all__ = ["read_obj", "write_obj"]

_NAMED = ("usemtl", "g", "o", "mtllib")


def _read_text(path) -> str:
    try:
        data = open(path, "rb").read()
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.strerror}", path) from None
    if not data.strip():
        raise InputError("empty file", path)
    if b"\0" in data:
        raise InputError("binary data, not a text OBJ file", path)
    return data.decode("utf-8", errors="replace")


def _bulk_floats(rows: list[str], width: int, what: str, path, line_no) -> np.ndarray:
    """Parse ``rows`` (text after the keyword) into an (n, width) array."""
    n = len(rows)
    if n == 0:
        return np.zeros((0, width))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        flat = np.fromstring(" ".join(rows), sep=" ")
    if flat.size == n * width:
        out = flat.reshape(n, width)
    else:
        # Slow path: per-line token counts decide (extra 'w' or colour columns) or
        # point at the bad line.
        out = np.empty((n, width))
        for k, row in enumerate(rows):
            toks = row.split()
            try:
                vals = [float(t) for t in toks]
            except ValueError:
                raise InputError(f"{what} line has a value that is not a number: "
                                 f"{row.strip()[:60]!r}", path, int(line_no[k]) + 1) from None
            if len(vals) < width:
                raise InputError(f"{what} line needs {width} numbers, found {len(vals)}",
                                 path, int(line_no[k]) + 1)
            out[k] = vals[:width]
    bad = ~np.isfinite(out).all(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(f"{what} has a NaN or infinite value", path, int(line_no[k]) + 1)
    return out


def _vertex_rows(rows, path, line_no):
    """Positions, plus colours when every line carries ``x y z r g b``."""
    n = len(rows)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        flat = np.fromstring(" ".join(rows), sep=" ")
    if n and flat.size == 6 * n and np.isfinite(flat).all():
        data = flat.reshape(n, 6)
        return data[:, :3].copy(), data[:, 3:].copy()
    return _bulk_floats(rows, 3, "vertex", path, line_no), None


def _parse_corners(rows: list[str], path, line_no):
    """Face rows -> sizes, and (c, 3) int64 [v, vt, vn] (0 where absent, 1-based)."""
    toks = [r.split() for r in rows]
    sizes = np.fromiter(map(len, toks), dtype=np.int64, count=len(toks))
    small = np.flatnonzero(sizes < 3)
    if len(small):
        k = int(small[0])
        raise InputError(f"face needs at least 3 corners, found {sizes[k]}", path,
                         int(line_no[k]) + 1)
    corners = [c for t in toks for c in t]
    n = len(corners)
    joined = " ".join(corners)
    first = corners[0]
    n_slash, double = first.count("/"), "//" in first
    uniform = (joined.count("/") == n * n_slash
               and joined.count("//") == (n if double else 0) and n_slash <= 2)
    out = np.zeros((n, 3), dtype=np.int64)
    if uniform:
        if double:
            cols = [0, 2]
            joined = joined.replace("//", " ")
        else:
            cols = list(range(n_slash + 1))
            joined = joined.replace("/", " ")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            flat = np.fromstring(joined, dtype=np.int64, sep=" ")
        if flat.size == n * len(cols):
            out[:, cols] = flat.reshape(n, len(cols))
            return sizes, out
    # Mixed corner formats or a bad token: parse corner by corner, naming the line.
    face_of_corner = np.repeat(np.arange(len(rows)), sizes)
    for c, tok in enumerate(corners):
        parts = tok.split("/")
        if len(parts) > 3 or parts[0] == "":
            raise InputError(f"bad face corner {tok!r}", path,
                             int(line_no[face_of_corner[c]]) + 1)
        for j, p in enumerate(parts):
            if p == "":
                continue
            try:
                out[c, j] = int(p)
            except ValueError:
                raise InputError(f"face index is not an integer: {tok!r}", path,
                                 int(line_no[face_of_corner[c]]) + 1) from None
    return sizes, out


def _resolve(idx, rows_no, corner_line, total, what, path):
    """1-based (or negative = relative) OBJ indices -> 0-based, checked."""
    neg = idx < 0
    if neg.any():
        before = np.searchsorted(rows_no, corner_line)  # elements defined so far
        out = np.where(neg, before + idx, idx - 1)
    else:
        out = idx - 1
    bad = (out < 0) | (out >= total)
    if bad.any():
        c = int(np.argmax(bad))
        raise InputError(f"{what} index {idx[c]} out of range (the file has {total})",
                         path, int(corner_line[c]) + 1)
    return out


def read_obj(path) -> Mesh:
    """Read a Wavefront OBJ file.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    Mesh
        Vertices in file order, polygons as written, per-corner UV and normal indices
        when the file has ``vt``/``vn``, materials from ``usemtl``, groups from
        ``g``/``o``, ``mtllib`` names.  Free-form curves, lines and points are
        ignored.

    Raises
    ------
    InputError
        Naming the file and line: empty or binary file, a non-number, NaN/inf, a
        face with fewer than 3 corners, an index out of range or 0.
    """
    text = _read_text(path)
    if "\\\n" in text:  # line continuation
        text = text.replace("\\\n", " ")
    lines = text.splitlines()
    v, vt, vn, f = [], [], [], []
    v_no, vt_no, vn_no, f_no = [], [], [], []
    named = []  # (line number, keyword, name)
    for i, line in enumerate(lines):
        if not line:
            continue
        if line[0] in " \t":
            line = line.strip()
            if not line:
                continue
        head = line[:2]
        if head == "v " or head == "v\t":
            v.append(line[2:])
            v_no.append(i)
        elif head == "vt":
            vt.append(line[3:])
            vt_no.append(i)
        elif head == "vn":
            vn.append(line[3:])
            vn_no.append(i)
        elif head == "f " or head == "f\t":
            f.append(line[2:])
            f_no.append(i)
        elif line[0] != "#":
            key, _, rest = line.partition(" ")
            if key in _NAMED:
                named.append((i, key, rest.strip()))
    if not v:
        raise InputError("no vertices ('v' lines)", path)
    if not f:
        raise InputError("no faces ('f' lines)", path)
    v_no, vt_no, vn_no, f_no = (np.asarray(a, dtype=np.int64)
                                for a in (v_no, vt_no, vn_no, f_no))

    vertices, colors = _vertex_rows(v, path, v_no)
    uvs = _bulk_floats(vt, 2, "texture coordinate", path, vt_no) if vt else None
    normals = _bulk_floats(vn, 3, "normal", path, vn_no) if vn else None

    sizes, corner = _parse_corners(f, path, f_no)
    corner_line = np.repeat(f_no, sizes)
    offsets = np.zeros(len(sizes) + 1, dtype=np.int64)
    np.cumsum(sizes, out=offsets[1:])

    def resolve(col, rows_no, total, what):
        return _resolve(corner[:, col], rows_no, corner_line, total, what, path)

    if np.any(corner[:, 0] == 0):
        c = int(np.argmax(corner[:, 0] == 0))
        raise InputError("face index 0 (OBJ indices start at 1)", path,
                         int(corner_line[c]) + 1)
    faces = resolve(0, v_no, len(vertices), "vertex")
    face_uvs = face_normals = None
    has_vt, has_vn = corner[:, 1] != 0, corner[:, 2] != 0
    if uvs is not None and has_vt.any():
        if not has_vt.all():
            c = int(np.argmax(~has_vt))
            raise InputError("some face corners have texture coordinates and some do "
                             "not", path, int(corner_line[c]) + 1)
        face_uvs = resolve(1, vt_no, len(uvs), "texture coordinate")
    elif has_vt.any():
        raise InputError("faces refer to texture coordinates but there are no 'vt' "
                         "lines", path, int(corner_line[np.argmax(has_vt)]) + 1)
    if normals is not None and has_vn.all():
        face_normals = resolve(2, vn_no, len(normals), "normal")
    elif has_vn.any() and normals is None:
        raise InputError("faces refer to normals but there are no 'vn' lines", path,
                         int(corner_line[np.argmax(has_vn)]) + 1)

    # usemtl / g / o apply to the faces that follow them.
    mtllib = [n for _, k, n in named if k == "mtllib" and n]

    def per_face(keys):
        events = [(i, n) for i, k, n in named if k in keys]
        if not events:
            return None, ()
        names = list(dict.fromkeys(n for _, n in events))
        lut = {n: j for j, n in enumerate(names)}
        ev_line = np.array([i for i, _ in events], dtype=np.int64)
        ev_id = np.array([lut[n] for _, n in events] + [-1], dtype=np.int64)
        pos = np.searchsorted(ev_line, f_no) - 1  # last event before each face
        return ev_id[pos], tuple(names)

    face_materials, materials = per_face(("usemtl",))
    face_groups, groups = per_face(("g", "o"))
    return Mesh(vertices, (offsets, faces),
                uvs=uvs if face_uvs is not None else None,
                face_uvs=(offsets, face_uvs) if face_uvs is not None else None,
                normals=normals if face_normals is not None else None,
                face_normals=(offsets, face_normals) if face_normals is not None else None,
                face_materials=face_materials, materials=materials,
                face_groups=face_groups, groups=groups, mtllib=mtllib,
                vertex_colors=colors)


def _format_rows(prefix: str, values: np.ndarray) -> str:
    if len(values) == 0:
        return ""
    width = values.shape[1]
    fmt = prefix + " %r" * width + "\n"
    return (fmt * len(values)) % tuple(values.ravel().tolist())


def _face_block(mesh: Mesh, start: int, stop: int) -> str:
    off = mesh.face_offsets
    a, b = int(off[start]), int(off[stop])
    cols = [np.asarray(mesh.face_indices[a:b]) + 1]
    if mesh.face_uvs is not None:
        cols.append(np.asarray(mesh.face_uvs[a:b]) + 1)
    if mesh.face_normals is not None:
        cols.append(np.asarray(mesh.face_normals[a:b]) + 1)
    if len(cols) == 1:
        corner = " %d"
    elif len(cols) == 2 and mesh.face_uvs is not None:
        corner = " %d/%d"
    elif len(cols) == 2:
        corner = " %d//%d"
    else:
        corner = " %d/%d/%d"
    sizes = mesh.face_sizes[start:stop]
    if np.all(sizes == sizes[0]):
        fmt = ("f" + corner * int(sizes[0]) + "\n") * (stop - start)
    else:
        per = {int(s): "f" + corner * int(s) + "\n" for s in np.unique(sizes)}
        fmt = "".join([per[s] for s in sizes.tolist()])
    return fmt % tuple(np.stack(cols, axis=1).ravel().tolist())


def write_obj(path, mesh: Mesh, *, header: str | None = "written by facewrap") -> None:
    """Write a mesh as OBJ, exactly (round-trips through :func:`read_obj`).

    Parameters
    ----------
    path : str or os.PathLike
        Destination; replaced atomically.
    mesh : Mesh
    header : str, optional
        A comment for the first line.
    """
    parts = []
    if header:
        parts.append(f"# {header}\n")
    parts += [f"mtllib {m}\n" for m in mesh.mtllib]
    if mesh.vertex_colors is not None and mesh.vertex_colors.shape[1] == 3:
        parts.append(_format_rows("v", np.hstack([mesh.vertices, mesh.vertex_colors])))
    else:
        parts.append(_format_rows("v", mesh.vertices))
    if mesh.face_uvs is not None:
        parts.append(_format_rows("vt", mesh.uvs))
    if mesh.face_normals is not None:
        parts.append(_format_rows("vn", mesh.normals))
    # Split faces into runs of constant (group, material) and announce each run.
    m = mesh.n_faces
    mat = mesh.face_materials if mesh.face_materials is not None else np.full(m, -1)
    grp = mesh.face_groups if mesh.face_groups is not None else np.full(m, -1)
    change = np.flatnonzero((np.diff(mat) != 0) | (np.diff(grp) != 0)) + 1
    bounds = [0, *change.tolist(), m]
    prev_g, prev_m = -1, -1
    for s, e in zip(bounds[:-1], bounds[1:]):
        if s == e:
            continue
        g, mt = int(grp[s]), int(mat[s])
        if g != prev_g and g >= 0:
            parts.append(f"g {mesh.groups[g]}\n")
        if mt != prev_m and mt >= 0:
            parts.append(f"usemtl {mesh.materials[mt]}\n")
        prev_g, prev_m = g, mt
        parts.append(_face_block(mesh, s, e))
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with atomic_write(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.writelines(parts)
