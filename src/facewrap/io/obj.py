"""Wavefront OBJ reading and writing, exact and vectorised.

Reading keeps the vertex count and order, polygons as they are (quads stay quads),
per-corner ``vt``/``vn`` indices (UV seams), ``usemtl`` materials, ``g``/``o`` groups
and ``mtllib`` references.  Lines are classified with numpy on the raw bytes and all
rows of one keyword are parsed in one C call; lines are looked at one by one only to
name the line of an error.

Writing prints floats in their shortest round-trip form, so a mesh read back is
bit-identical, and replaces the destination atomically.

Two maintained C libraries do the text <-> float64 steps when installed, both exact:
``fastnumbers`` (fast_float, correctly rounded: ~3x numpy's ``fromstring``) and
``orjson`` (shortest round trip: ~6x ``repr``); without them numpy's parser and
``repr`` give the same values.  Face indices are parsed and laid out by numpy.
"""

from __future__ import annotations

import contextlib
import functools
import importlib
import os
import warnings

import numpy as np

from facewrap.errors import InputError
from facewrap.mesh import Mesh
from facewrap.io.atomic import atomic_write
from facewrap.io.files import check_coordinates, read_file_bytes
from facewrap.io.paths import new_folders_removed_on_failure
from facewrap.parallel import thread_map

__all__ = ["read_obj", "write_obj", "write_obj_series", "read_obj_vertices"]

_NAMED = ("usemtl", "g", "o", "mtllib")


def _read_lines(path, data: bytes | None = None) -> "_Lines":
    """The file's bytes (``data`` when already read) indexed by line, its rare forms
    made plain first.

    The checks for those forms read the line index (first byte of each line, byte
    before each newline) instead of searching the whole file once per form.
    """
    if data is None:
        data = read_file_bytes(path, text=True)
    if b"\r" in data and b"\n" not in data:  # classic Mac line ends (CR only)
        data = data.replace(b"\r", b"\n")
    elif b"\r" in data and data.count(b"\r") != data.count(b"\r\n"):
        # mixed line ends (files pasted together): a lone CR ends a line too
        data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    lines = _Lines(data)
    if np.any(lines.last_byte() == 92):
        # line continuation (rare): join, keeping byte offsets
        data = data.replace(b"\\\n", b"  ")
        lines = _Lines(data)
    if np.any((lines.c[0] == 32) | (lines.c[0] == 9)):
        # indented lines (rare): strip them so keywords start each line
        lines = _Lines(b"\n".join(line.strip() for line in data.split(b"\n")))
    return lines


def _fromstring(text, dtype=np.float64) -> np.ndarray | None:
    """Parse white-space separated numbers in C; None when a token is not a number."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        try:
            return np.fromstring(text, dtype=dtype, sep=" ")
        except ValueError:
            return None


@functools.lru_cache(maxsize=None)
def _accelerator(name: str):
    """The optional C module ``name`` (fastnumbers, orjson), or None when absent;
    imported on first use, so commands that never touch an OBJ do not pay for it."""
    try:
        return importlib.import_module(name)
    except ImportError:
        return None


def _row_floats(rows: "_Rows") -> np.ndarray | None:
    """All numbers of the rows (keywords dropped) as float64, correctly rounded (by
    fastnumbers or numpy: the same values); None when a token is not a number."""
    fast = _accelerator("fastnumbers")
    if fast is None:
        return _fromstring(rows.numbers_text())
    tokens = rows.joined().split()
    n, keyword = len(rows), rows.keyword
    step = len(tokens) // n if n else 0
    if (step > 1 and len(tokens) == n * step and tokens[::step].count(keyword) == n
            and tokens.count(keyword) == n):
        del tokens[::step]   # every row has `step` tokens, the keyword first
    else:
        tokens = rows.numbers_text().split()
    try:
        return fast.try_array(tokens, dtype=np.float64)
    except (ValueError, TypeError, OverflowError):
        return None


class _Lines:
    """Byte-level index of an OBJ file: where each line starts and ends.

    Classifying millions of lines with numpy on the raw bytes, and parsing all rows
    of one keyword with a single C call, is what makes reading fast; Python looks at
    single lines only to name the line of an error.
    """

    def __init__(self, data: bytes):
        buf = np.frombuffer(data, dtype=np.uint8)
        newline = np.flatnonzero(buf == 10)
        self.data = data
        self.starts = np.concatenate([[0], newline + 1]).astype(np.int64)
        self.ends = np.concatenate([newline, [len(buf)]]).astype(np.int64)
        # first three bytes of each line (0 past the end), no padded copy of the file
        last = len(buf) - 1
        self.c = [np.where(self.starts + k <= last, buf[np.minimum(self.starts + k, last)],
                           0).astype(np.uint8) if len(buf) else
                  np.zeros(len(self.starts), np.uint8) for k in range(3)]

    def last_byte(self) -> np.ndarray:
        """The byte before each newline (0 for an empty line)."""
        before = self.ends[:-1] - 1
        buf = np.frombuffer(self.data, dtype=np.uint8)
        return np.where(before >= self.starts[:-1], buf[np.maximum(before, 0)], 0)

    @staticmethod
    def _space(c):
        return (c == 32) | (c == 9) | (c == 13)

    def rows(self, keyword: bytes) -> "_Rows":
        c0, c1, c2 = self.c
        if len(keyword) == 1:
            mask = (c0 == keyword[0]) & self._space(c1)
        else:
            mask = (c0 == keyword[0]) & (c1 == keyword[1]) & self._space(c2)
        return _Rows(self, np.flatnonzero(mask), keyword)

    def text(self, i: int) -> str:
        return self.data[self.starts[i]:self.ends[i]].decode("utf-8", "replace")


class _Rows:
    """The lines of one OBJ keyword, in file order."""

    def __init__(self, lines: _Lines, idx: np.ndarray, keyword: bytes):
        self.lines, self.numbers, self.keyword = lines, idx, keyword
        self.skip = len(keyword) + 1
        # contiguous runs of rows -> few large byte slices
        cut = np.flatnonzero(np.diff(idx) != 1) + 1
        first = np.concatenate([[0], cut]) if len(idx) else np.zeros(0, np.int64)
        last = np.concatenate([cut - 1, [len(idx) - 1]]) if len(idx) else first
        self._spans = [(int(lines.starts[idx[a]]), int(lines.ends[idx[b]]))
                       for a, b in zip(first, last)]

    def __len__(self) -> int:
        return len(self.numbers)

    def joined(self) -> bytes:
        """All rows as one byte string, newline separated, keywords kept."""
        data = self.lines.data
        if len(self._spans) == 1:
            a, b = self._spans[0]
            return data[a:b]
        return b"\n".join([data[a:b] for a, b in self._spans])

    def numbers_text(self) -> bytes:
        """All rows with the keyword that starts each blanked (offsets kept)."""
        joined, k = self.joined(), len(self.keyword)
        return joined and b" " * k + joined[k:].replace(b"\n" + self.keyword,
                                                       b"\n" + b" " * k)

    def eol(self) -> np.ndarray:
        """Offsets of each row's end in :meth:`joined` (rows are one line each)."""
        lines = self.lines
        return np.cumsum(lines.ends[self.numbers] - lines.starts[self.numbers] + 1) - 1

    def row(self, k: int) -> str:
        """Text of row ``k`` after the keyword."""
        return self.lines.text(self.numbers[k])[self.skip:]

    @property
    def text(self) -> list[str]:
        return [self.row(k) for k in range(len(self))]

    def line(self, k) -> int:
        """1-based line number of row ``k``."""
        return int(self.numbers[int(k)]) + 1


def _refuse_bare_keywords(lines: _Lines, path) -> None:
    """A ``v`` or ``f`` line with nothing after it (which the rows of a keyword,
    a keyword and a space, do not hold) named, not skipped."""
    length = lines.ends - lines.starts
    bare = (length == 1) | ((length == 2) & (lines.c[1] == 13))     # (a CR before LF)
    for keyword, what in ((b"f", "face needs at least 3 corners, found 0"),
                          (b"v", "vertex line needs 3 numbers, found 0")):
        hit = np.flatnonzero(bare & (lines.c[0] == keyword[0]))
        if len(hit):
            raise InputError(what, path, int(hit[0]) + 1)


def _bulk_floats(rows: _Rows, width: int, what: str, path, flat=None) -> np.ndarray:
    """Parse the rows into an (n, width) float array, or name the bad line.

    ``flat``: the rows' numbers when already parsed (None when a token was not).
    """
    n = len(rows)
    if n == 0:
        return np.zeros((0, width))
    if flat is None:
        flat = _row_floats(rows)
    if flat is not None and flat.size == n * width:
        out = flat.reshape(n, width)
    else:
        # Slow path: per-line token counts decide (extra 'w' or colour columns) or
        # point at the bad line.
        out = np.empty((n, width))
        for k, row in enumerate(rows.text):
            try:
                vals = [float(t) for t in row.split()]
            except ValueError:
                raise InputError(f"{what} line has a value that is not a number: "
                                 f"{row.strip()[:60]!r}", path, rows.line(k)) from None
            if len(vals) < width:
                raise InputError(f"{what} line needs {width} numbers, found {len(vals)}",
                                 path, rows.line(k))
            out[k] = vals[:width]
    finite = np.isfinite(out)
    if not finite.all():    # (a flat test first: the per-row one costs 7 ms a million)
        raise InputError(f"{what} has a NaN or infinite value", path,
                         rows.line(np.argmax(~finite.all(axis=1))))
    return out


def _vertex_rows(rows: _Rows, path):
    """Positions, plus colours when every line carries ``x y z r g b``."""
    n = len(rows)
    flat = _row_floats(rows)
    if n and flat is not None and flat.size == 6 * n and np.isfinite(flat).all():
        data = flat.reshape(n, 6)
        return data[:, :3].copy(), data[:, 3:].copy()
    return _bulk_floats(rows, 3, "vertex", path, flat), None


# corner slashes -> spaces: what is left is the indices
_SLASHES = bytes.maketrans(b"/", b" ")
# and the face keyword, when it is the only "f" of each row
_F_AND_SLASHES = bytes.maketrans(b"f/", b"  ")


def _parse_corners(rows: _Rows, path):
    """Face rows -> sizes (m,), and (c, 3) int64 [v, vt, vn] (0 where absent)."""
    original = rows.joined()
    raw = np.frombuffer(original, dtype=np.uint8)
    # single spaces between corners and no control characters but the newlines
    # joining the rows (str.split and numpy's parser treat those differently)
    fast = not (b"  " in original or b" \n" in original or original.endswith(b" ")
                or np.count_nonzero(raw < 32) != len(rows) - 1)
    if fast:  # single spaces only: corners per face = spaces on the line
        spaces = np.flatnonzero(raw == 32)
        sizes = np.diff(np.concatenate([[0], np.searchsorted(spaces, rows.eol())]))
        text = original
        first = original[2:original.find(b" ", 2)] if len(rows) else b""
        corners = None
    else:
        toks = [r.split() for r in rows.text]
        sizes = np.fromiter(map(len, toks), dtype=np.int64, count=len(toks))
        corners = [c for t in toks for c in t]
        text = " ".join(corners).encode("utf-8", "replace")
        first = text.split(None, 1)[0] if corners else b""
    small = np.flatnonzero(sizes < 3)
    if len(small):
        raise InputError(f"face needs at least 3 corners, found {sizes[small[0]]}",
                         path, rows.line(small[0]))
    n = int(sizes.sum())
    n_slash, double = first.count(b"/"), b"//" in first
    uniform = (text.count(b"/") == n * n_slash
               and text.count(b"//") == (n if double else 0) and n_slash <= 2)
    out = np.zeros((n, 3), dtype=np.int64)
    if uniform:
        cols = [0, 2] if double else list(range(n_slash + 1))
        if corners is None and original.count(b"f") == len(rows):
            numbers = original.translate(_F_AND_SLASHES)   # one pass, keywords too
        elif corners is None:
            numbers = rows.numbers_text().translate(_SLASHES)
        else:
            numbers = text.translate(_SLASHES)
        flat = _fromstring(numbers, np.int64)
        if flat is not None and flat.size == n * len(cols):
            out[:, cols] = flat.reshape(n, len(cols))
            return sizes, out
    # Mixed corner formats or a bad token: parse corner by corner, naming the line.
    if corners is None:
        corners = [c for r in rows.text for c in r.split()]
    face_of_corner = np.repeat(np.arange(len(rows)), sizes)
    for c, tok in enumerate(corners):
        parts = tok.split("/")
        if len(parts) > 3 or parts[0] == "":
            raise InputError(f"bad face corner {tok!r}", path,
                             rows.line(face_of_corner[c]))
        for j, p in enumerate(parts):
            if p == "":
                continue
            try:
                out[c, j] = int(p)
            except ValueError:
                raise InputError(f"face index is not an integer: {tok!r}", path,
                                 rows.line(face_of_corner[c])) from None
            except OverflowError:   # beyond int64: no mesh has that many vertices
                raise InputError(f"face index out of range: {tok!r}", path,
                                 rows.line(face_of_corner[c])) from None
    return sizes, out


def read_obj(path) -> Mesh:
    """Read a Wavefront OBJ file.

    Parameters
    ----------
    path : str or os.PathLike
        A text file of ``v``, ``vt``, ``vn``, ``f`` (and ``usemtl``, ``g``, ``o``,
        ``mtllib``) lines; relative (negative) indices are resolved.

    Returns
    -------
    mesh : Mesh
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
    lines = _read_lines(path)
    v, vt, vn, f = (lines.rows(k) for k in (b"v", b"vt", b"vn", b"f"))
    _refuse_bare_keywords(lines, path)
    if not len(v):
        raise InputError("no vertices ('v' lines)", path)
    if not len(f):
        raise InputError("no faces ('f' lines)", path)

    vertices, colors = _vertex_rows(v, path)
    uvs = _bulk_floats(vt, 2, "texture coordinate", path) if len(vt) else None
    normals = _bulk_floats(vn, 3, "normal", path) if len(vn) else None

    sizes, corner = _parse_corners(f, path)
    offsets = np.zeros(len(sizes) + 1, dtype=np.int64)
    np.cumsum(sizes, out=offsets[1:])
    corners = _Corners(corner, sizes, f, path)
    if np.any(corner[:, 0] == 0):
        raise InputError("face index 0 (OBJ indices start at 1)", path,
                         corners.line(np.argmax(corner[:, 0] == 0)))
    faces = corners.resolve(0, v, len(vertices), "vertex")
    face_uvs, face_normals = _corner_attributes(corners, vt, uvs, vn, normals)

    named = _named_statements(lines)
    # usemtl / g / o apply to the faces that follow them.
    mtllib = [n for _, k, n in named if k == "mtllib" and n]
    face_materials, materials = _per_face(named, ("usemtl",), f)
    face_groups, groups = _per_face(named, ("g", "o"), f)
    return Mesh(vertices, (offsets, faces),
                uvs=uvs if face_uvs is not None else None,
                face_uvs=(offsets, face_uvs) if face_uvs is not None else None,
                normals=normals if face_normals is not None else None,
                face_normals=(offsets, face_normals) if face_normals is not None else None,
                face_materials=face_materials, materials=materials,
                face_groups=face_groups, groups=groups, mtllib=mtllib,
                vertex_colors=colors, copy=False)   # made here, held by no one else


class _Corners:
    """The face corners of an OBJ file: ``(c, 3)`` raw v/vt/vn indices and their lines."""

    def __init__(self, corner: np.ndarray, sizes: np.ndarray, f: "_Rows", path):
        self.corner, self.f, self.path, self.sizes = corner, f, path, sizes

    @functools.cached_property
    def face_of_corner(self) -> np.ndarray:
        """Face of each corner (only errors and relative indices need it)."""
        return np.repeat(np.arange(len(self.sizes)), self.sizes)

    def line(self, c) -> int:
        """File line of corner ``c`` (for error messages)."""
        return self.f.line(self.face_of_corner[c])

    def resolve(self, col: int, rows: "_Rows", total: int, what: str) -> np.ndarray:
        """0-based indices of column ``col`` (0 v, 1 vt, 2 vn), relative ones resolved.

        A negative index counts the ``rows`` defined before the face's line.
        """
        idx = self.corner[:, col]
        neg = idx < 0
        if neg.any():
            line0 = self.f.numbers[self.face_of_corner]
            out = np.where(neg, np.searchsorted(rows.numbers, line0) + idx, idx - 1)
        else:
            out = idx - 1
        bad = (out < 0) | (out >= total)
        if bad.any():
            c = int(np.argmax(bad))
            shown = (f"{idx[c]} out of range" if abs(int(idx[c])) < np.iinfo(np.int64).max
                     else "beyond the int64 range")
            raise InputError(f"{what} index {shown} (the file has {total})", self.path,
                             self.line(c))
        return out


def _corner_attributes(corners: _Corners, vt, uvs, vn, normals):
    """Per-corner UV and normal indices (or None), checked against the vt/vn lines."""
    path, corner = corners.path, corners.corner
    face_uvs = face_normals = None
    has_vt, has_vn = corner[:, 1] != 0, corner[:, 2] != 0
    if uvs is not None and has_vt.any():
        if not has_vt.all():
            raise InputError("some face corners have texture coordinates and some do "
                             "not", path, corners.line(np.argmax(~has_vt)))
        face_uvs = corners.resolve(1, vt, len(uvs), "texture coordinate")
    elif has_vt.any():
        raise InputError("faces refer to texture coordinates but there are no 'vt' "
                         "lines", path, corners.line(np.argmax(has_vt)))
    if normals is not None and has_vn.all():
        face_normals = corners.resolve(2, vn, len(normals), "normal")
    elif has_vn.any() and normals is None:
        raise InputError("faces refer to normals but there are no 'vn' lines", path,
                         corners.line(np.argmax(has_vn)))
    return face_uvs, face_normals


def _named_statements(lines: "_Lines") -> list[tuple[int, str, str]]:
    """``(line index, keyword, name)`` of every usemtl / g / o / mtllib statement."""
    first = lines.c[0]
    maybe = np.flatnonzero((first == 117) | (first == 103) | (first == 111)
                           | (first == 109))  # u g o m
    return [(int(i), key, rest.strip()) for i, (key, _, rest) in
            ((i, lines.text(i).strip().partition(" ")) for i in maybe)
            if key in _NAMED]


def _per_face(named, keys, f: "_Rows"):
    """Per-face ids of the last ``keys`` statement before each face, and the names."""
    events = [(i, n) for i, k, n in named if k in keys]
    if not events:
        return None, ()
    names = list(dict.fromkeys(n for _, n in events))
    lut = {n: j for j, n in enumerate(names)}
    ev_line = np.array([i for i, _ in events], dtype=np.int64)
    ev_id = np.array([lut[n] for _, n in events] + [-1], dtype=np.int64)
    pos = np.searchsorted(ev_line, f.numbers) - 1  # last event before each face
    return ev_id[pos], tuple(names)


def _float_rows(keyword: bytes, values: np.ndarray) -> bytes:
    """``keyword x y ...`` lines of (n, w) floats, each in its shortest round-trip form.

    orjson (when installed) formats whole arrays about 6x faster than Python's
    ``repr`` and is as exact; a non-finite value (which JSON cannot hold) keeps the
    ``repr`` route, so it is written as ``nan``/``inf`` as always.
    """
    if len(values) == 0:
        return b""
    values = np.ascontiguousarray(values, dtype=np.float64)
    fast = _accelerator("orjson")
    if fast is not None and np.isfinite(values).all():
        text = fast.dumps(values, option=fast.OPT_SERIALIZE_NUMPY)   # [[x,y],[x,y]]
        body = text[2:-2].replace(b"],[", b"\n" + keyword + b" ").replace(b",", b" ")
        return keyword + b" " + body + b"\n"
    fmt = keyword.decode() + " %r" * values.shape[1] + "\n"
    return ((fmt * len(values)) % tuple(values.ravel().tolist())).encode()


def _digit_table(largest: int) -> np.ndarray:
    """(largest + 1, w) uint8: the decimal digits of 0..largest, right-aligned,
    padded on the left with NUL bytes (removed once the text is laid out)."""
    value = np.arange(largest + 1, dtype=np.int64)
    width = len(str(largest))
    table = np.zeros((largest + 1, width), dtype=np.uint8)
    for d in range(width):
        table[:, width - 1 - d] = np.where((value >= 10 ** d) | (d == 0),
                                           48 + value // 10 ** d % 10, 0)
    return table


def _face_rows(columns: np.ndarray, within: bytes, offsets: np.ndarray) -> bytes:
    """``f a/b c/d ...`` lines: one polygon per line, written with numpy.

    Parameters
    ----------
    columns : (c, k) int64
        Per corner, the k 1-based indices (v, then vt and/or vn), none negative.
    within : bytes
        What separates a corner's indices: ``b"/"`` or ``b"//"``.
    offsets : (m + 1,) int64
        Corners of polygon ``i`` are ``offsets[i]:offsets[i + 1]``.

    Each corner is one fixed-width row of bytes (``f`` if it opens its polygon, a
    space, its indices from a table of digit strings, ``\\n`` if it closes it), NUL
    padding deleted from the whole text in one pass: no per-face Python.
    """
    c, k = columns.shape
    if c == 0:
        return b""
    table = _digit_table(int(columns.max()))
    w, sep = table.shape[1], np.frombuffer(within, dtype=np.uint8)
    row = np.zeros((c, 3 + k * w + (k - 1) * len(sep)), dtype=np.uint8)
    row[offsets[:-1], 0] = ord("f")
    row[:, 1] = ord(" ")
    row[offsets[1:] - 1, -1] = ord("\n")
    at = 2
    for j in range(k):
        row[:, at:at + w] = table[columns[:, j]]
        at += w
        if j < k - 1:
            row[:, at:at + len(sep)] = sep
            at += len(sep)
    return row.tobytes().translate(None, b"\0")


def _face_block(mesh: Mesh, start: int, stop: int) -> bytes:
    off = mesh.face_offsets
    a, b = int(off[start]), int(off[stop])
    cols = [np.asarray(mesh.face_indices[a:b]) + 1]
    if mesh.face_uvs is not None:
        cols.append(np.asarray(mesh.face_uvs[a:b]) + 1)
    if mesh.face_normals is not None:
        cols.append(np.asarray(mesh.face_normals[a:b]) + 1)
    within = b"//" if len(cols) == 2 and mesh.face_uvs is None else b"/"
    return _face_rows(np.stack(cols, axis=1).astype(np.int64), within, off[start:stop + 1] - a)


def _vertex_text(mesh: Mesh) -> bytes:
    """``v`` lines of ``mesh`` (with its colours where it has three channels)."""
    if mesh.vertex_colors is not None and mesh.vertex_colors.shape[1] == 3:
        return _float_rows(b"v", np.hstack([mesh.vertices, mesh.vertex_colors]))
    return _float_rows(b"v", mesh.vertices)


def _text_around_vertices(mesh: Mesh, header: str | None) -> tuple[list, list]:
    """The parts of ``mesh``'s OBJ before its ``v`` lines and after them (``vt``,
    ``vn`` and the faces, announced by group and material run)."""
    head = [f"# {header}\n".encode()] if header else []
    head += [f"mtllib {m}\n".encode() for m in mesh.mtllib]
    tail = []
    if mesh.face_uvs is not None:
        tail.append(_float_rows(b"vt", mesh.uvs))
    if mesh.face_normals is not None:
        tail.append(_float_rows(b"vn", mesh.normals))
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
            tail.append(f"g {mesh.groups[g]}\n".encode())
        if mt != prev_m and mt >= 0:
            tail.append(f"usemtl {mesh.materials[mt]}\n".encode())
        prev_g, prev_m = g, mt
        tail.append(_face_block(mesh, s, e))
    return head, tail


def _write_text(path, parts: list) -> None:
    """``parts`` (bytes) into ``path``, atomically; its folder made if missing."""
    folder = os.path.dirname(os.path.abspath(path))
    with new_folders_removed_on_failure(folder):
        os.makedirs(folder, exist_ok=True)
        with atomic_write(path, "wb") as fh:
            fh.writelines(parts)


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
    head, tail = _text_around_vertices(mesh, header)
    _write_text(path, [*head, _vertex_text(mesh), *tail])


def write_obj_series(paths, mesh: Mesh, positions, *,
                     header: str | None = "written by facewrap") -> None:
    """One OBJ per vertex set, all in ``mesh``'s topology: file ``k`` is exactly what
    :func:`write_obj` writes of ``mesh.with_vertices(positions[k])``.

    A rig's shapes, a sequence's frames: only the ``v`` lines differ between the
    files, so the rest (UVs, faces, groups, materials: over half the text of a
    textured head) is laid out once, and the files are written on two threads (a
    file's write and ``fsync`` release the GIL while the next one's vertices are
    formatted).  53 shapes of a 9,409-vertex textured head: half the time of
    :func:`write_obj` file by file (0.63-0.87 -> 0.35-0.42 s on a loaded machine).

    Parameters
    ----------
    paths : sequence of str or os.PathLike
        Destinations, each replaced atomically.
    mesh : Mesh
        The topology (its stored normals are dropped, as ``with_vertices`` drops
        them: they belong to its own positions).
    positions : sequence of (n, 3) float array_like
        One vertex set per path.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from facewrap.mesh import Mesh
    >>> tri = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> write_obj_series([d / "a.obj", d / "b.obj"], tri,
    ...                  [tri.vertices, tri.vertices * 2], header=None)
    >>> (d / "b.obj").read_text().splitlines()[1]
    'v 2.0 0.0 0.0'
    """
    paths, positions = list(paths), list(positions)
    if len(paths) != len(positions):
        raise ValueError(f"{len(paths)} paths but {len(positions)} vertex sets")
    meshes = [mesh.with_vertices(P) for P in positions]   # each checked here
    if not meshes:
        return
    head, tail = _text_around_vertices(meshes[0], header)
    # every folder made before the threads start, removed (when new) if any write fails
    with contextlib.ExitStack() as stack:
        for folder in dict.fromkeys(os.path.dirname(os.path.abspath(p)) for p in paths):
            stack.enter_context(new_folders_removed_on_failure(folder))
            os.makedirs(folder, exist_ok=True)
        thread_map(lambda k: _write_text(paths[k], [*head, _vertex_text(meshes[k]), *tail]),
                   range(len(paths)))


def read_obj_vertices(path, n_vertices: int | None = None, *,
                      data: bytes | None = None) -> np.ndarray:
    """Read only the ``v`` lines of an OBJ: fast loading of shapes in one topology.

    Parameters
    ----------
    path : str or os.PathLike
        The file (named in errors).
    n_vertices : int, optional
        Expected vertex count (a blendshape must match its neutral).
    data : bytes, optional
        The file's bytes when the caller has read them already (to hash them, say,
        with :func:`facewrap.io.files.read_file_bytes`); the file is then not read
        again.

    Returns
    -------
    (n, 3) float64

    Examples
    --------
    >>> read_obj_vertices("shape.obj", 2, data=b"v 0 0 0\\nv 1 2 3.5\\n").tolist()
    [[0.0, 0.0, 0.0], [1.0, 2.0, 3.5]]
    """
    rows = _read_lines(path, data).rows(b"v")
    if not len(rows):
        raise InputError("no vertices ('v' lines)", path)
    vertices, _ = _vertex_rows(rows, path)
    check_coordinates(vertices, path)    # a shape, never 1e30 across
    if n_vertices is not None and len(vertices) != n_vertices:
        raise InputError(f"has {len(vertices)} vertices, expected {n_vertices} (the "
                         "shape must be in the same topology)", path)
    return vertices
