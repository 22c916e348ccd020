"""Stanford PLY reading and writing, exact and vectorised.

Reading understands ``format ascii 1.0``, ``binary_little_endian 1.0`` and
``binary_big_endian 1.0`` with any elements in any order.  Elements and properties
that a mesh has no place for are skipped; in binary files their rows are measured
from the header's types, list properties of any count and item type included.

From the ``vertex`` element the reader keeps positions ``x y z`` (required), normals
``nx ny nz``, per-vertex texture coordinates (``u v``, ``s t``, ``texture_u
texture_v`` or ``texture_s texture_t``) and colours ``red green blue [alpha]``
(integer types scaled to [0, 1], floats kept).  From the ``face`` element it keeps
the polygons (list ``vertex_indices`` or ``vertex_index``; any sizes, mixed sizes
allowed, quads stay quads) and per-corner texture coordinates (list ``texcoord``,
two numbers per corner, as MeshLab writes them), turned into a table of distinct
``(u, v)`` pairs in order of first use plus per-corner indices, so UV seams are
kept; they win over per-vertex UVs when a file has both.  The first ``comment
TextureFile <name>`` becomes :attr:`Mesh.texture`.  ASCII numbers are parsed as
float64, so ``float`` values keep the digits written in the file.

Numbers are parsed in bulk with numpy.  Binary elements whose lists all have one
length (all triangles, all quads) are read with a single structured dtype; when list
lengths vary (mixed polygons), one pass in Python finds where each row starts
(0.2-1 µs per row) and all values are then gathered in bulk.
ASCII rows must be one per line, as every common writer makes them; lines are
looked at one by one only to name the line of an error.

Writing produces binary little-endian (or ASCII) files with positions, normals and
texture coordinates as ``double``, so a mesh read back is exact, and replaces the
destination atomically.
"""

from __future__ import annotations

import mmap
import os
import re
import struct
import sys
import warnings
from dataclasses import dataclass, field

import numpy as np

from facewrap.errors import InputError
from facewrap.io.files import file_size, nul_at_ends, read_file_bytes, read_file_head
from facewrap.mesh import Mesh
from facewrap.io.atomic import atomic_write

__all__ = ["read_ply", "write_ply"]

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_BYTE_ORDER = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_END_HEADER = re.compile(rb"(?:^|\n)end_header[ \t\r]*(?:\n|\Z)")

_UV_NAMES = (("u", "v"), ("s", "t"), ("texture_u", "texture_v"),
             ("texture_s", "texture_t"))
_COLOR_NAMES = ("red", "green", "blue", "alpha")
_FACE_INDEX_NAMES = ("vertex_indices", "vertex_index")
_WANTED = {
    "vertex": frozenset({"x", "y", "z", "nx", "ny", "nz", *_COLOR_NAMES,
                         *(name for pair in _UV_NAMES for name in pair)}),
    "face": frozenset({*_FACE_INDEX_NAMES, "texcoord"}),
}


# -- header -------------------------------------------------------------------------
@dataclass(frozen=True)
class _Property:
    name: str
    dtype: np.dtype              # item type (byte order of the file for binary)
    count: np.dtype | None       # list count type, None for a scalar property
    line: int


@dataclass
class _Element:
    name: str
    count: int
    line: int
    props: list[_Property] = field(default_factory=list)

    def prop(self, name: str) -> _Property | None:
        return next((p for p in self.props if p.name == name), None)


@dataclass
class _Header:
    byte_order: str | None       # None for ascii
    elements: list[_Element]
    texture: str | None
    data_start: int              # byte offset of the first data byte
    n_lines: int                 # header lines, 'end_header' included


# The header is read from the file's first bytes before the rest: a header longer
# than this is refused (real ones are a few hundred bytes, a few KiB with comments).
_HEADER_LIMIT = 1 << 20
_HEADER_LIMIT_TEXT = "1 MiB"


def _read_bytes(path) -> bytes:
    return read_file_bytes(path)


def _map_file(path) -> mmap.mmap | bytes:
    """The file mapped read-only: a binary body is read only where rows are.

    Every array taken from it is a copy, so the map closes when the reader drops it
    (not explicitly: an error's traceback may still hold a view of it).  Where a
    file cannot be mapped (a pipe, an address-space limit) it is read whole.
    """
    try:
        with open(path, "rb") as fh:
            return mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    except (OSError, ValueError):
        return _read_bytes(path)


def _read_header(path) -> tuple[_Header, int]:
    """The header and the file size, from the first bytes of the file only."""
    size = file_size(path)
    head = read_file_head(path, min(size, _HEADER_LIMIT))
    if not head.strip():
        read_file_bytes(path)  # the one "empty file" / "cannot read" error
    if (len(head) < size and head.split(b"\n", 1)[0].strip() == b"ply"
            and _END_HEADER.search(head) is None):
        raise InputError(f"no 'end_header' line in the first {_HEADER_LIMIT_TEXT} (a "
                         "header that long is not a PLY header)", path)
    header = _parse_header(head, path)
    _check_size(header, size, path)
    return header, size


def _check_size(header: _Header, size: int, path) -> None:
    """Refuse counts the file is too small to hold, before anything is allocated.

    A binary row takes at least the bytes of its scalars and list counts.  An ASCII
    value takes at least two bytes (a digit and a separator); ASCII files that fit
    in the first read are left to the reader, which names the line where they end.
    A sparse or binary file posing as ASCII (NUL bytes at either end) is refused
    here too, as reading it would cost several times its size in memory.
    """
    off = header.data_start
    if header.byte_order is None:
        if size <= _HEADER_LIMIT:
            return
        if nul_at_ends(path, size):
            raise InputError("NUL bytes in an ASCII PLY (a binary or sparse file with "
                             "an ASCII header?)", path)
        values = sum(e.count * len(e.props) for e in header.elements)
        if 2 * values - 1 > size - off:
            raise InputError(f"file is truncated: the header's elements need {values} "
                             f"values (at least {2 * values - 1} bytes) from byte "
                             f"{off}, the file has {size - off}", path)
        return
    for element in header.elements:
        least = element.count * sum(p.dtype.itemsize if p.count is None
                                    else p.count.itemsize for p in element.props)
        if least > size - off:
            raise InputError(f"file is truncated: element '{element.name}' needs at "
                             f"least {least} bytes from byte {off}, the file has "
                             f"{size - off}", path)
        off += least


def _ply_type(name: str, path, line: int) -> np.dtype:
    if name not in _TYPES:
        raise InputError(f"unknown property type {name!r} (expected one of "
                         f"{', '.join(sorted(set(_TYPES)))})", path, line)
    return np.dtype(_TYPES[name])


def _parse_header(data: bytes, path) -> _Header:
    if data.split(b"\n", 1)[0].strip() != b"ply":
        raise InputError("not a PLY file: the first line must be 'ply'", path, 1)
    end = _END_HEADER.search(data)
    if end is None:
        raise InputError("header has no 'end_header' line (missing, or the file is "
                         "cut short)", path)
    lines = data[:end.start()].decode("ascii", errors="replace").split("\n")
    byte_order, fmt_seen, texture = None, False, None
    elements: list[_Element] = []
    for no, raw in enumerate(lines[1:], start=2):
        toks = raw.split()
        if not toks or toks[0] == "obj_info":
            continue
        if any(ord(c) < 32 and c not in "\t\r" for c in raw):
            raise InputError("header line has control characters (binary data in the "
                             "header?)", path, no)
        key = toks[0]
        if key == "comment":
            if len(toks) > 2 and toks[1].lower() == "texturefile" and texture is None:
                texture = raw.strip().split(None, 2)[2]
        elif key == "format":
            if fmt_seen:
                raise InputError("second 'format' line", path, no)
            if len(toks) != 3:
                raise InputError("format line must read 'format <type> 1.0'", path, no)
            if toks[1] not in _BYTE_ORDER:
                raise InputError(f"unknown format {toks[1]!r} (expected ascii, "
                                 "binary_little_endian or binary_big_endian)", path, no)
            byte_order, fmt_seen = _BYTE_ORDER[toks[1]], True
        elif key == "element":
            if len(toks) != 3 or not toks[2].isdigit():
                raise InputError("element line must read 'element <name> <count>' with "
                                 "a non-negative integer count", path, no)
            if toks[1] in _WANTED and any(e.name == toks[1] for e in elements):
                raise InputError(f"second '{toks[1]}' element: which one is the mesh "
                                 "is ambiguous", path, no)
            elements.append(_Element(toks[1], int(toks[2]), no))
        elif key == "property":
            if not elements:
                raise InputError("property line before any element line", path, no)
            if len(toks) >= 2 and toks[1] == "list":
                if len(toks) != 5:
                    raise InputError("list property must read 'property list <count "
                                     "type> <item type> <name>'", path, no)
                count = _ply_type(toks[2], path, no)
                if count.kind not in "iu":
                    raise InputError(f"list count type must be an integer type, not "
                                     f"{toks[2]!r}", path, no)
                prop = _Property(toks[4], _ply_type(toks[3], path, no), count, no)
            else:
                if len(toks) != 3:
                    raise InputError("property must read 'property <type> <name>'",
                                     path, no)
                prop = _Property(toks[2], _ply_type(toks[1], path, no), None, no)
            if elements[-1].name in _WANTED and elements[-1].prop(prop.name):
                raise InputError(f"{elements[-1].name} property {prop.name!r} given "
                                 "twice: which one to read is ambiguous", path, no)
            elements[-1].props.append(prop)
        else:
            raise InputError(f"unknown header line {raw.strip()[:60]!r}", path, no)
    if not fmt_seen:
        raise InputError("header has no 'format' line", path)
    if byte_order is not None:
        elements = [_Element(e.name, e.count, e.line, [
            _Property(p.name, p.dtype.newbyteorder(byte_order),
                      None if p.count is None else p.count.newbyteorder(byte_order),
                      p.line) for p in e.props]) for e in elements]
    return _Header(byte_order, elements, texture, end.end(), len(lines) + 1)


# -- element data -------------------------------------------------------------------
class _Table:
    """Values of the properties a mesh uses from one element, and where rows are.

    ``scalars`` maps a property name to an (n,) array; ``lists`` maps it to
    ``(offsets (n + 1,), values)``.  :meth:`error` builds the InputError for a row.
    """

    def __init__(self, element: _Element, path, scalars, lists, *, lines=None,
                 row_byte=None):
        self.element, self.path = element, path
        self.scalars, self.lists = scalars, lists
        self._lines, self._row_byte = lines, row_byte

    def error(self, row, problem: str) -> InputError:
        row = int(row)
        what = f"{self.element.name} {row}: {problem}"
        if self._lines is not None:
            return InputError(what, self.path, int(self._lines[row]))
        return InputError(f"{what} (row starts at byte {self._row_byte(row)})",
                          self.path)


def _excl_cumsum(sizes: np.ndarray) -> np.ndarray:
    out = np.zeros(len(sizes) + 1, dtype=np.int64)
    np.cumsum(sizes, out=out[1:])
    return out


def _wanted_props(element: _Element) -> list[bool]:
    """Whether each property is one the mesh uses (first of each name only)."""
    names = _WANTED.get(element.name, frozenset())
    out, seen = [], set()
    for p in element.props:
        out.append(p.name in names and p.name not in seen)
        seen.add(p.name)
    return out


def _ascii_numbers(body: bytes, starts, ends, tokens, lines, name: str,
                   path) -> np.ndarray:
    """The numbers of lines ``body[starts[k]:ends[k]]`` (``tokens[k]`` each), float64."""
    expected = int(tokens.sum())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        try:
            flat = np.fromstring(body[int(starts[0]):int(ends[-1])], sep=" ")
        except ValueError:
            flat = None
    if flat is not None and flat.size == expected:
        return flat
    # Slow path: name the line of the bad token.
    values = []
    for a, b, count, line in zip(starts.tolist(), ends.tolist(), tokens.tolist(),
                                 lines.tolist()):
        toks = body[a:b].split()
        for tok in toks:
            try:
                values.append(float(tok))
            except ValueError:
                text = tok[:40].decode("latin-1")
                raise InputError(f"{name} value {text!r} is not a number", path,
                                 line) from None
        if len(toks) != count:
            raise InputError(f"{name} line has control characters between its values",
                             path, line)
    return np.asarray(values, dtype=np.float64)


def _ascii_walk(flat, tokens, element: _Element, wanted, lines, path):
    """Positions of each property in each row; checks rows against the header."""
    n = len(tokens)
    end = np.cumsum(tokens)
    pos = end - tokens
    bad = np.zeros(n, dtype=bool)
    last = max(len(flat) - 1, 0)
    scalars, lists = {}, {}
    for prop, want in zip(element.props, wanted):
        bad |= pos >= end
        if prop.count is None:
            if want:
                scalars[prop.name] = pos
            pos = pos + 1
            continue
        count = flat[np.minimum(pos, last)] if len(flat) else np.zeros(n)
        ok = (count >= 0) & (count == np.floor(count)) & (count < end - pos)
        bad |= ~ok
        count = np.where(ok, count, 0).astype(np.int64)
        if want:
            lists[prop.name] = (pos + 1, count)
        pos = pos + 1 + count
    bad |= pos != end
    if bad.any():
        r = int(np.argmax(bad))
        raise InputError(f"{element.name} {r}: line has {tokens[r]} values, which does "
                         "not match the element's properties in the header", path,
                         int(lines[r]))
    out_scalars = {k: flat[v] for k, v in scalars.items()}
    out_lists = {}
    for name, (first, count) in lists.items():
        offsets = _excl_cumsum(count)
        idx = np.repeat(first - offsets[:-1], count) + np.arange(offsets[-1])
        out_lists[name] = (offsets, flat[idx])
    return out_scalars, out_lists


def _ascii_tables(data: bytes, header: _Header, path) -> dict[str, _Table]:
    body = data[header.data_start:]
    arr = np.frombuffer(body, dtype=np.uint8)
    # Tokens per line without splitting: a token starts at a byte above ' ' that
    # follows a byte at or below it (control bytes count as separators here; a
    # token holding one fails the number parser and is named by the slow path).
    space = arr <= 32
    newline = np.flatnonzero(arr == 10)
    line_start = np.concatenate([[0], newline + 1])
    line_end = np.concatenate([newline, [len(arr)]])
    token_start = ~space
    token_start[1:] &= space[:-1]
    del space
    before = np.searchsorted(np.flatnonzero(token_start), line_start)  # tokens before
    tokens_per_line = np.diff(np.append(before, int(token_start.sum())))
    del token_start
    rows_all = np.flatnonzero(tokens_per_line)  # blank lines are skipped
    tables: dict[str, _Table] = {}
    cursor = 0
    for element in header.elements:
        n, left = element.count, len(rows_all) - cursor
        if n > left:
            last = header.n_lines + (int(rows_all[-1]) + 1 if len(rows_all) else 0)
            raise InputError(f"file is truncated: element '{element.name}' needs {n} "
                             f"lines but only {left} are left", path, last)
        rows = rows_all[cursor:cursor + n]
        cursor += n
        if element.name not in _WANTED or element.name in tables:
            continue
        lines = header.n_lines + rows + 1
        tokens = tokens_per_line[rows]
        flat = np.zeros(0)
        if n:
            flat = _ascii_numbers(body, line_start[rows], line_end[rows], tokens,
                                  lines, element.name, path)
        scalars, lists = _ascii_walk(flat, tokens, element,
                                     _wanted_props(element), lines, path)
        tables[element.name] = _Table(element, path, scalars, lists, lines=lines)
    if cursor < len(rows_all):   # counts that leave rows out: part of the scan unread
        raise InputError(f"{len(rows_all) - cursor} more lines than the header's element "
                         "counts take", path, header.n_lines + int(rows_all[cursor]) + 1)
    return tables


def _gather(data: bytes, pos: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """Values of ``dtype`` starting at byte positions ``pos`` of ``data``.

    A strided view whose element ``p`` is the value starting at byte ``p`` turns the
    gather into one fancy index (positions are checked by the caller).
    """
    size = dtype.itemsize
    every_byte = np.ndarray((max(len(data) - size + 1, 0),), dtype=dtype, buffer=data,
                            strides=(1,))
    return every_byte[pos]


def _struct_format(dtype: np.dtype) -> str:
    """The :mod:`struct` format of one integer of ``dtype`` (byte order included)."""
    native = "<" if sys.byteorder == "little" else ">"
    return {"<": "<", ">": ">", "=": native, "|": "<"}[dtype.byteorder] + dtype.char


def _first_row_counts(data: bytes, off: int, element: _Element, path) -> list[int]:
    """List lengths of the first row of ``element`` (starting at byte ``off``)."""
    counts = []
    pos = off
    for p in element.props:
        if p.count is None:
            pos += p.dtype.itemsize
            continue
        try:
            (c,) = struct.unpack_from(_struct_format(p.count), data, pos)
        except struct.error:
            raise InputError(f"file is truncated: element '{element.name}' row 0 "
                             f"runs past the end (byte {pos})", path) from None
        if c < 0:
            raise InputError(f"{element.name} 0: negative list length {c} for "
                             f"'{p.name}' (row starts at byte {off})", path)
        counts.append(int(c))
        pos += p.count.itemsize + c * p.dtype.itemsize
    return counts


def _row_starts(data: bytes, off: int, element: _Element, path):
    """Byte offset of every row of an element whose list lengths vary, and the end.

    Rows must be walked one after another (each list length says where the next row
    starts), so this is a plain loop, specialised for the common layouts: about
    0.2 µs a row for one list with a ``uchar`` count, up to ~1 µs otherwise.
    """
    segments, fixed = [], 0  # per list: (bytes before its count, count type, item size)
    for p in element.props:
        if p.count is None:
            fixed += p.dtype.itemsize
        else:
            segments.append((fixed, p.count, p.dtype.itemsize))
            fixed = 0
    tail, n = fixed, element.count
    starts = [0] * n
    pos, r, c = off, 0, 0
    byte_counts = all(cnt == np.dtype("u1") for _, cnt, _ in segments)
    try:
        if byte_counts and len(segments) == 1:  # e.g. list uchar int vertex_indices
            ((pre, _, isize),) = segments
            step = pre + 1 + tail
            for r in range(n):
                starts[r] = pos
                pos += step + data[pos + pre] * isize
        elif byte_counts and len(segments) == 2:  # ... plus list uchar float texcoord
            (pre1, _, isize1), (pre2, _, isize2) = segments
            step1, step2 = pre1 + 1, pre2 + 1 + tail
            for r in range(n):
                starts[r] = pos
                pos += step1 + data[pos + pre1] * isize1
                pos += step2 + data[pos + pre2] * isize2
        else:
            steps = [(pre, struct.Struct(_struct_format(cnt)).unpack_from,
                      pre + cnt.itemsize, isize) for pre, cnt, isize in segments]
            for r in range(n):
                starts[r] = pos
                for pre, unpack, step, isize in steps:
                    (c,) = unpack(data, pos + pre)
                    if c < 0:
                        break
                    pos += step + c * isize
                if c < 0:
                    break
                pos += tail
    except (IndexError, struct.error):
        raise InputError(f"file is truncated: element '{element.name}' row {r} runs "
                         f"past the end (byte {pos})", path) from None
    if c < 0:
        raise InputError(f"{element.name} {r}: negative list length {c} (row starts "
                         f"at byte {starts[r]})", path)
    if pos > len(data):
        raise InputError(f"file is truncated: element '{element.name}' needs bytes up "
                         f"to {pos}, the file has {len(data)}", path)
    return np.asarray(starts, dtype=np.int64), pos


def _binary_element(data: bytes, off: int, element: _Element, wanted, path):
    """Read one binary element at byte ``off``: (scalars, lists, row_byte, end)."""
    n, props = element.count, element.props
    has_list = any(p.count is not None for p in props)
    counts = (_first_row_counts(data, off, element, path) if has_list and n
              else [0] * sum(p.count is not None for p in props))
    # Row size if every row had the first row's list lengths.
    size = (sum(p.dtype.itemsize if p.count is None else p.count.itemsize
                for p in props)
            + sum(c * p.dtype.itemsize for c, p in zip(
                counts, [p for p in props if p.count is not None])))
    if n * size <= len(data) - off:
        fields, lengths = [], iter(counts)
        for i, p in enumerate(props):
            if p.count is None:
                fields.append((f"p{i}", p.dtype))
            else:
                fields += [(f"c{i}", p.count), (f"p{i}", p.dtype, (next(lengths),))]
        dtype = np.dtype(fields)
        rec = np.frombuffer(data, dtype=dtype, count=n, offset=off) if n else \
            np.zeros(0, dtype=dtype)
        uniform = all(np.all(rec[f"c{i}"] == dtype[f"p{i}"].shape[0])
                      for i, p in enumerate(props) if p.count is not None)
        if uniform:
            scalars, lists = {}, {}
            for i, (p, want) in enumerate(zip(props, wanted)):
                if not want:
                    continue
                values = rec[f"p{i}"]
                if p.count is None:
                    scalars[p.name] = values.astype(p.dtype.newbyteorder("="))
                else:
                    k = values.shape[1]
                    lists[p.name] = (np.arange(n + 1, dtype=np.int64) * k,
                                     values.reshape(-1).astype(p.dtype.newbyteorder("=")))
            return scalars, lists, (lambda r: off + r * size), off + n * size
    if not has_list:
        raise InputError(f"file is truncated: element '{element.name}' needs {n * size} "
                         f"bytes from byte {off}, the file has {len(data) - off}", path)
    starts, end = _row_starts(data, off, element, path)
    pos = starts.copy()
    scalars, lists = {}, {}
    for p, want in zip(props, wanted):
        if p.count is None:
            if want:
                scalars[p.name] = _gather(data, pos, p.dtype).astype(
                    p.dtype.newbyteorder("="))
            pos += p.dtype.itemsize
            continue
        count = _gather(data, pos, p.count).astype(np.int64)
        first = pos + p.count.itemsize
        if want:
            offsets = _excl_cumsum(count)
            isize = p.dtype.itemsize
            item_pos = (np.repeat(first - offsets[:-1] * isize, count)
                        + np.arange(offsets[-1], dtype=np.int64) * isize)
            lists[p.name] = (offsets, _gather(data, item_pos, p.dtype).astype(
                p.dtype.newbyteorder("=")))
        pos = first + count * p.dtype.itemsize
    return scalars, lists, (lambda r: int(starts[r])), end


def _binary_tables(data: bytes, header: _Header, path) -> dict[str, _Table]:
    off = header.data_start
    tables: dict[str, _Table] = {}
    for element in header.elements:
        least = element.count * sum(p.dtype.itemsize if p.count is None
                                    else p.count.itemsize for p in element.props)
        if least > len(data) - off:
            raise InputError(f"file is truncated: element '{element.name}' needs at "
                             f"least {least} bytes from byte {off}, the file has "
                             f"{len(data) - off}", path)
        if not element.props:  # rows of nothing
            if element.name in _WANTED:
                tables.setdefault(element.name, _Table(element, path, {}, {}))
            continue
        wanted = (_wanted_props(element) if element.name in _WANTED
                  and element.name not in tables else [False] * len(element.props))
        scalars, lists, row_byte, off = _binary_element(data, off, element, wanted,
                                                        path)
        if element.name in _WANTED and element.name not in tables:
            tables[element.name] = _Table(element, path, scalars, lists,
                                          row_byte=row_byte)
    return tables


# -- mesh ---------------------------------------------------------------------------
def _finite(table: _Table, values: np.ndarray, what: str) -> np.ndarray:
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.argmax(bad.reshape(len(values), -1).any(axis=1)))
        raise table.error(row, f"{what} is NaN or infinite")
    return values


def _show(value) -> str:
    """A number from the file as a user would write it (4, not 4.0 or np.int32(4))."""
    value = value.item()
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    return repr(value)


def _scalar(table: _Table, name: str) -> np.ndarray:
    if name in table.lists:
        raise InputError(f"{table.element.name} property '{name}' must not be a list",
                         table.path, table.element.prop(name).line)
    return table.scalars[name]


def _has(table: _Table, names) -> bool:
    return all(n in table.scalars or n in table.lists for n in names)


def _colors(table: _Table) -> np.ndarray | None:
    names = _COLOR_NAMES if _has(table, _COLOR_NAMES) else _COLOR_NAMES[:3]
    if not _has(table, names):
        return None
    columns = []
    for name in names:
        values = _finite(table, _scalar(table, name).astype(np.float64), "colour")
        dtype = table.element.prop(name).dtype
        if dtype.kind in "iu":
            top = float(np.iinfo(dtype).max)
            bad = (values < 0) | (values > top) | (values != np.floor(values))
            if bad.any():
                raise table.error(np.argmax(bad), f"colour {_show(values[np.argmax(bad)])} "
                                  f"is not an integer in [0, {top:.0f}]")
            values = values / top
        columns.append(values)
    return np.column_stack(columns)


def _faces(table: _Table, n: int) -> tuple[np.ndarray, np.ndarray]:
    name = next((k for k in _FACE_INDEX_NAMES if _has(table, [k])), None)
    if name is None or name not in table.lists:
        raise InputError("face element has no list property 'vertex_indices' (or "
                         "'vertex_index')", table.path, table.element.line)
    offsets, values = table.lists[name]
    sizes = np.diff(offsets)
    small = sizes < 3
    if small.any():
        r = int(np.argmax(small))
        raise table.error(r, f"face has {sizes[r]} corners, at least 3 are needed")
    bad = (values < 0) | (values >= n)
    if values.dtype.kind == "f":
        bad |= values != np.floor(values)
    if bad.any():
        c = int(np.argmax(bad))
        r = int(np.searchsorted(offsets, c, side="right")) - 1
        raise table.error(r, f"face index {_show(values[c])} is not a vertex index in "
                          f"[0, {n}) (out of range)")
    return offsets, values.astype(np.int64)


def _corner_uvs(table: _Table, offsets: np.ndarray):
    """Per-corner ``texcoord`` lists -> (uv table, per-corner indices) or None."""
    if "texcoord" not in table.lists:
        return None
    t_offsets, values = table.lists["texcoord"]
    t_sizes = np.diff(t_offsets)
    if not t_sizes.any():  # written empty by some exporters: no texture coordinates
        return None
    bad = t_sizes != 2 * np.diff(offsets)
    if bad.any():
        r = int(np.argmax(bad))
        raise table.error(r, f"texcoord has {t_sizes[r]} values, expected 2 per corner "
                          f"({2 * (offsets[r + 1] - offsets[r])})")
    with np.errstate(invalid="ignore"):   # a garbled value: refused just below
        corner_uv = values.astype(np.float64).reshape(-1, 2)
    bad = ~np.isfinite(corner_uv).all(axis=1)
    if bad.any():
        r = int(np.searchsorted(offsets, int(np.argmax(bad)), side="right")) - 1
        raise table.error(r, "texcoord is NaN or infinite")
    return _distinct_rows(corner_uv)


def _group(key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First index of each distinct value of a 1-D array, and each item's group."""
    order = np.argsort(key)
    sorted_key = key[order]
    new = np.ones(len(key), dtype=bool)
    new[1:] = sorted_key[1:] != sorted_key[:-1]
    first = np.minimum.reduceat(order, np.flatnonzero(new)) if len(key) else order
    inverse = np.empty(len(key), dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    return first, inverse


def _distinct_rows(pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct rows of a (c, 2) float64 array in order of first use, and the inverse.

    The same table as ``np.unique(pairs, axis=0, return_inverse=True)`` up to its
    order, several times faster: pairs exact in float32 (as MeshLab writes them)
    become one 64-bit key; others are first reduced to integer ids per column.

    Examples
    --------
    >>> table, idx = _distinct_rows(np.array([[.5, 0], [0, 1], [.5, -0.]]))
    >>> table.tolist(), idx.tolist()
    ([[0.5, 0.0], [0.0, 1.0]], [0, 1, 0])
    """
    single = pairs.astype(np.float32) + np.float32(0)  # + 0 turns -0.0 into 0.0
    if np.array_equal(single, pairs):
        bits = single.view(np.uint32).astype(np.uint64)
        key = (bits[:, 0] << np.uint64(32)) | bits[:, 1]
    else:
        _, iu = _group(pairs[:, 0])
        _, iv = _group(pairs[:, 1])
        key = iu * (int(iv.max()) + 1 if len(iv) else 1) + iv
    first, inverse = _group(key)
    order = np.argsort(first)  # table in order of first use
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return pairs[first[order]], rank[inverse]


def _build_mesh(tables: dict[str, _Table], header: _Header, path) -> Mesh:
    vt = tables.get("vertex")
    if vt is None:
        raise InputError("header has no 'vertex' element", path)
    for name in "xyz":
        if not _has(vt, name):
            raise InputError(f"vertex element has no property '{name}'", path,
                             vt.element.line)
    vertices = _finite(vt, np.column_stack([_scalar(vt, c).astype(np.float64)
                                            for c in "xyz"]), "vertex coordinate")
    n = len(vertices)
    ft = tables.get("face")
    if ft is None:
        offsets, indices = np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64)
    else:
        offsets, indices = _faces(ft, n)
    kw = {}
    if _has(vt, ("nx", "ny", "nz")):
        kw["normals"] = _finite(vt, np.column_stack(
            [_scalar(vt, c).astype(np.float64) for c in ("nx", "ny", "nz")]), "normal")
        kw["face_normals"] = (offsets, indices)
    corner = None if ft is None else _corner_uvs(ft, offsets)
    if corner is not None:
        kw["uvs"], kw["face_uvs"] = corner[0], (offsets, corner[1])
    else:
        pair = next((p for p in _UV_NAMES if _has(vt, p)), None)
        if pair is not None:
            kw["uvs"] = _finite(vt, np.column_stack(
                [_scalar(vt, c).astype(np.float64) for c in pair]), "texture coordinate")
            kw["face_uvs"] = (offsets, indices)
    kw["vertex_colors"] = _colors(vt)
    try:
        return Mesh(vertices, (offsets, indices), texture=header.texture, **kw)
    except ValueError as exc:  # validated above; kept so nothing but InputError leaks
        raise InputError(f"inconsistent mesh data: {exc}", path) from None


def read_ply(path) -> Mesh:
    """Read a PLY file (ASCII or binary, either byte order).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    Mesh
        Vertices in file order, polygons as written (any sizes), and when the file
        has them: per-vertex normals (``face_normals`` equal to the face indices),
        per-vertex UVs (``len(uvs) == n``) or per-corner UVs from ``texcoord``
        (distinct pairs in order of first use, ``face_uvs`` per corner),
        ``vertex_colors`` (n, 3|4) in [0, 1] for integer types, and ``texture`` from
        the first ``comment TextureFile``.  A file without a face element gives a
        mesh with no faces.

    Raises
    ------
    InputError
        Naming the file, and the line for ASCII content or the row and byte offset
        for binary content: missing or empty file, not a PLY file, missing
        ``format`` or ``end_header``, unknown format or property type, truncated
        data or element counts the file's size cannot hold (found from the header,
        before the body is read), a value that is not a number, NaN/inf
        coordinates, a face with fewer than 3 corners or an index out of range, no
        vertex element or no x/y/z.

    Examples
    --------
    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "quad.ply")
    >>> quad = Mesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.]], [[0, 1, 2, 3]])
    >>> write_ply(path, quad)
    >>> back = read_ply(path)
    >>> back.face_sizes.tolist(), bool((back.vertices == quad.vertices).all())
    ([4], True)
    """
    header, size = _read_header(path)
    data = _read_bytes(path) if header.byte_order is None else _map_file(path)
    if len(data) != size:  # changed since the header was read: take what is there
        header = _parse_header(data[:_HEADER_LIMIT], path)
    if header.byte_order is None:
        tables = _ascii_tables(data, header, path)
    else:
        tables = _binary_tables(data, header, path)
    return _build_mesh(tables, header, path)


# -- writing ------------------------------------------------------------------------
@dataclass
class _Column:
    """One property to write: scalar (``sizes`` None) or list (per-row ``sizes``)."""
    declaration: str
    values: np.ndarray           # (n,) for scalars, flat for lists
    dtype: str                   # numpy type of the values
    text: str                    # %-format of one value in ASCII
    sizes: np.ndarray | None = None
    count_dtype: str = "u1"


def _count_type(max_count: int) -> tuple[str, str]:
    if max_count <= 255:
        return "uchar", "u1"
    if max_count <= 65535:
        return "ushort", "u2"
    return "int", "i4"


def _list_column(name, item_ply, item_dtype, text, sizes, values) -> _Column:
    ply, dtype = _count_type(int(sizes.max()) if len(sizes) else 0)
    return _Column(f"property list {ply} {item_ply} {name}", values, item_dtype, text,
                   sizes, dtype)


def _vertex_normals(mesh: Mesh) -> np.ndarray | None:
    """Normals as one per vertex, when the mesh's normals can be put that way."""
    if mesh.normals is None:
        return None
    n, corners = mesh.n_vertices, np.asarray(mesh.face_indices)
    if len(mesh.normals) == n and np.array_equal(mesh.face_normals, corners):
        return np.asarray(mesh.normals)
    per_corner = np.asarray(mesh.normals)[mesh.face_normals]
    per_vertex = np.full((n, 3), np.nan)
    per_vertex[corners] = per_corner
    if np.isnan(per_vertex).any() or not np.array_equal(per_vertex[corners], per_corner):
        return None  # some vertex has no normal, or different normals on its corners
    return per_vertex


def _pack_binary(columns: list[_Column], n: int) -> bytes:
    """Rows of little-endian bytes, vectorised (a scatter when list sizes vary)."""
    parts = []  # (items per row: (n,) int64, values in their little-endian dtype)
    for col in columns:
        if col.sizes is None:
            parts.append((np.ones(n, np.int64), col.values.astype(
                np.dtype(col.dtype).newbyteorder("<"))))
            continue
        parts.append((np.ones(n, np.int64), col.sizes.astype(
            np.dtype(col.count_dtype).newbyteorder("<"))))
        parts.append((np.asarray(col.sizes, np.int64), col.values.astype(
            np.dtype(col.dtype).newbyteorder("<"))))
    if n == 0:
        return b""
    if all(np.all(counts == counts[0]) for counts, _ in parts):  # one row layout
        return np.hstack([np.ascontiguousarray(values).view(np.uint8).reshape(n, -1)
                          for _, values in parts]).tobytes()
    row_bytes = sum(counts * values.dtype.itemsize for counts, values in parts)
    out = np.zeros(int(row_bytes.sum()), dtype=np.uint8)
    cursor = _excl_cumsum(row_bytes)[:-1]
    for counts, values in parts:
        size = values.dtype.itemsize
        dest = (np.repeat(cursor - _excl_cumsum(counts)[:-1] * size, counts)
                + np.arange(len(values), dtype=np.int64) * size)
        # element p of this view is the value starting at byte p of out
        np.ndarray((len(out) - size + 1,), dtype=values.dtype, buffer=out,
                   strides=(1,))[dest] = values
        cursor = cursor + counts * size
    return out.tobytes()


def _format_ascii(columns: list[_Column], n: int) -> str:
    """Rows of text: values scattered into row order, formatted with one % call.

    Integers go to ``%d`` as Python ints and floats to ``%r`` as Python floats
    (shortest exact form); a mixed row is built in an object array.
    """
    if n == 0:
        return ""
    parts = []  # (values per row: (n,) int64, flat values, %-format)
    for col in columns:
        if col.sizes is None:
            parts.append((np.ones(n, np.int64), col.values, col.text))
        else:
            parts.append((np.ones(n, np.int64), col.sizes, "%d"))
            parts.append((np.asarray(col.sizes, np.int64), col.values, col.text))
    integer = all(p[2] == "%d" for p in parts)
    per_row = np.stack([p[0] for p in parts], axis=1)
    out = np.empty(int(per_row.sum()), dtype=np.int64 if integer else object)
    cursor = _excl_cumsum(per_row.sum(axis=1))[:-1]
    for counts, flat, text in parts:
        dest = np.repeat(cursor - _excl_cumsum(counts)[:-1], counts) + np.arange(len(flat))
        flat = np.asarray(flat)
        out[dest] = flat.astype(np.int64) if text == "%d" else flat.astype(np.float64)
        cursor = cursor + counts

    def row_format(kind) -> str:
        return " ".join(" ".join([p[2]] * int(c)) for p, c in zip(parts, kind) if c) + "\n"

    if np.all(per_row == per_row[0]):
        fmt = row_format(per_row[0]) * n
    else:
        key = np.zeros(n, dtype=np.int64)  # one int per distinct row layout
        for column in per_row.T:
            key = key * (int(column.max()) + 1) + column  # list sizes: no overflow
        _, first, which = np.unique(key, return_index=True, return_inverse=True)
        formats = [row_format(per_row[k]) for k in first.tolist()]
        fmt = "".join([formats[i] for i in which.reshape(-1).tolist()])
    return fmt % tuple(out.tolist())


def write_ply(path, mesh: Mesh, *, binary: bool = True) -> None:
    """Write a mesh as PLY, exactly (round-trips through :func:`read_ply`).

    Writes ``x y z`` as ``double``; normals ``nx ny nz`` (double) when they can be
    stored per vertex; per-vertex UVs as ``texture_u texture_v`` (double) or
    per-corner UVs as ``list uchar double texcoord`` (double rather than MeshLab's
    float so values survive exactly; MeshLab and trimesh read both); vertex colours as
    ``uchar red green blue [alpha]``; polygons as ``list uchar int vertex_indices``
    (a wider count type for polygons of more than 255 corners); and ``comment
    TextureFile`` for :attr:`Mesh.texture`.

    Parameters
    ----------
    path : str or os.PathLike
        Destination; replaced atomically.
    mesh : Mesh
    binary : bool
        ``binary_little_endian`` when True (the default), else ``ascii`` (floats in
        shortest round-trip form, so also exact).

    Raises
    ------
    TypeError
        If ``mesh`` is not a :class:`Mesh`.
    ValueError
        If vertices, normals or UVs are NaN or infinite (PLY readers reject them),
        or the texture name has a line break.

    Notes
    -----
    PLY has no per-corner normals: normals that differ between the corners of one
    vertex are not written.  Colours are rounded to 8 bits.  Per-corner UVs come
    back as the distinct pairs in order of first use, so a UV table with unused or
    repeated entries is compacted (every corner keeps its exact value).
    Materials and groups have no PLY equivalent and are dropped.

    Examples
    --------
    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "tri.ply")
    >>> write_ply(path, Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]]),
    ...           binary=False)
    >>> print(open(path).read().split("end_header")[1].strip())
    0.0 0.0 0.0
    1.0 0.0 0.0
    0.0 1.0 0.0
    3 0 1 2
    """
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a facewrap Mesh, got {type(mesh).__name__}")
    n, m = mesh.n_vertices, mesh.n_faces
    vertices = np.asarray(mesh.vertices)
    if not np.isfinite(vertices).all():
        raise ValueError("mesh has NaN or infinite vertices")
    if mesh.texture is not None and ("\n" in mesh.texture or "\r" in mesh.texture):
        raise ValueError("texture name must not contain a line break")
    vcols = [_Column(f"property double {c}", vertices[:, k], "f8", "%r")
             for k, c in enumerate("xyz")]
    normals = _vertex_normals(mesh)
    if normals is not None:
        if not np.isfinite(normals).all():
            raise ValueError("mesh has NaN or infinite normals")
        vcols += [_Column(f"property double {c}", normals[:, k], "f8", "%r")
                  for k, c in enumerate(("nx", "ny", "nz"))]
    sizes, corners = np.asarray(mesh.face_sizes), np.asarray(mesh.face_indices)
    per_vertex_uv = (mesh.uvs is not None and len(mesh.uvs) == n
                     and np.array_equal(mesh.face_uvs, corners))
    if mesh.uvs is not None and not np.isfinite(mesh.uvs).all():
        raise ValueError("mesh has NaN or infinite texture coordinates")
    if per_vertex_uv:
        vcols += [_Column(f"property double {c}", np.asarray(mesh.uvs)[:, k], "f8", "%r")
                  for k, c in enumerate(("texture_u", "texture_v"))]
    if mesh.vertex_colors is not None:
        colors = np.clip(np.rint(np.asarray(mesh.vertex_colors) * 255), 0, 255)
        vcols += [_Column(f"property uchar {c}", colors[:, k], "u1", "%d")
                  for k, c in enumerate(_COLOR_NAMES[:colors.shape[1]])]
    index_ply, index_dtype = ("int", "i4") if n <= 2**31 - 1 else ("uint", "u4")
    fcols = [_list_column("vertex_indices", index_ply, index_dtype, "%d", sizes,
                          corners)]
    if mesh.uvs is not None and not per_vertex_uv:
        fcols.append(_list_column("texcoord", "double", "f8", "%r", 2 * sizes,
                                  np.asarray(mesh.uvs)[mesh.face_uvs].reshape(-1)))

    head = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0",
            "comment written by facewrap"]
    if mesh.texture is not None:
        head.append(f"comment TextureFile {mesh.texture}")
    head.append(f"element vertex {n}")
    head += [c.declaration for c in vcols]
    head.append(f"element face {m}")
    head += [c.declaration for c in fcols]
    head.append("end_header\n")
    head_bytes = "\n".join(head).encode("utf-8")
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with atomic_write(path, "wb") as fh:
        fh.write(head_bytes)
        if binary:
            fh.write(_pack_binary(vcols, n))
            fh.write(_pack_binary(fcols, m))
        else:
            fh.write(_format_ascii(vcols, n).encode("ascii"))
            fh.write(_format_ascii(fcols, m).encode("ascii"))
