"""STL scans, binary or ASCII, read here (not by trimesh).

An STL is a triangle soup by design (three corners per triangle); exactly
coincident corners are merged into shared vertices by the caller
(:func:`~facewrap.io.trimesh_formats.read_trimesh_format`), so the scan is one
surface.  Binary files are told from ASCII ones by their size (80-byte header,
triangle count, 50 bytes per triangle: a binary STL may start with ``solid``
too).  ASCII files are read row by row, every row checked against the format's
fixed pattern (``facet`` / ``outer loop`` / three ``vertex`` rows / ``endloop``
/ ``endfacet``) and a bad one named by its line: trimesh's reader took a file
missing its last ``endsolid`` as holding no triangles, and read a vertex row with
a word among its numbers as the numbers before it, silently.
"""

from __future__ import annotations

import re
import struct
import warnings

import numpy as np

from facewrap.errors import InputError
from facewrap.io.files import nul_at_ends, read_file_bytes, read_file_head

__all__ = ["read_stl"]

#: the rows of one facet, by their first word
_FACET = ("facet", "outer", "vertex", "vertex", "vertex", "endloop", "endfacet")
_BINARY_TRIANGLE = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)),
                             ("attribute", "<u2")])


def read_stl(path, size: int) -> tuple[np.ndarray, np.ndarray]:
    """The corners of an STL file's triangles, one row per corner.

    Parameters
    ----------
    path : str or os.PathLike
    size : int
        The file's size in bytes (non-zero).

    Returns
    -------
    V : (3m, 3) float64
        Corner positions, three per triangle, in file order.
    F : (m, 3) int64
        ``[[0, 1, 2], [3, 4, 5], ...]``.

    Raises
    ------
    InputError
        Naming the file (and line): a binary STL cut short or of no triangles, an
        ASCII STL with a row out of the format's pattern, a value that is not a
        number, cut short inside a facet, or with no facets.
    """
    head = read_file_head(path, 84)
    if len(head) == 84:
        count = struct.unpack("<I", head[80:84])[0]
        if 84 + 50 * count == size:
            if count == 0:
                raise InputError("STL holds no triangles", path)
            data = read_file_bytes(path)
            corners = np.frombuffer(data, _BINARY_TRIANGLE, count, 84)["corners"]
            return _soup(corners.reshape(-1, 3).astype(np.float64))
    if head.lstrip()[:5].lower() == b"solid" and not nul_at_ends(path, size):
        return _soup(_ascii_corners(path))
    if len(head) < 84:
        raise InputError(f"not an STL file ({size} bytes: shorter than a binary STL "
                         "header)", path)
    count = struct.unpack("<I", head[80:84])[0]
    raise InputError(f"truncated or not a binary STL: the header says {count} triangles "
                     f"({84 + 50 * count} bytes), the file has {size} bytes", path)


def _soup(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return V, np.arange(len(V), dtype=np.int64).reshape(-1, 3)


#: the first word of every line that has one (the rows' keywords, in order)
_KEYWORD = re.compile(r"^[ \t]*(\S+)", re.M)
#: what follows the keyword of every ``vertex`` row
_VERTEX_VALUES = re.compile(r"^[ \t]*vertex(?![^ \t\r\n])([^\r\n]*)", re.M)


def _ascii_corners(path) -> np.ndarray:
    """Every ``vertex`` row of an ASCII STL, (3m, 3) float64, each solid checked."""
    text = read_file_bytes(path, text=True).decode("utf-8", errors="replace")
    corners = _one_clean_solid(text.lstrip("\ufeff").lower())
    return corners if corners is not None else _checked_corners(text, path)


def _one_clean_solid(text: str) -> np.ndarray | None:
    """The corners of a file that is one solid of whole facets, every vertex row three
    numbers (what exporters write), found by two regular expressions and one
    conversion in C; None for anything else, which :func:`_checked_corners` reads
    row by row (and names the line of what is wrong).  Five times faster than row
    by row on a 60k-triangle scan."""
    words = _KEYWORD.findall(text)
    if words[-1:] == ["endsolid"]:
        words.pop()
    body = words[1:]
    m = len(body) // len(_FACET)
    if words[:1] != ["solid"] or m == 0 or body != list(_FACET) * m:
        return None
    with warnings.catch_warnings():     # numpy stops at a token that is no number
        warnings.simplefilter("ignore", DeprecationWarning)
        try:
            values = np.fromstring(" ".join(_VERTEX_VALUES.findall(text)), sep=" ")
        except ValueError:
            return None
    return values.reshape(-1, 3) if len(values) == 9 * m else None


def _checked_corners(text: str, path) -> np.ndarray:
    """:func:`_ascii_corners` row by row: every solid, each row checked."""
    rows = [(no, ln.strip()) for no, ln in enumerate(text.lstrip("\ufeff").splitlines(),
                                                     start=1) if ln.strip()]
    words = [row.split(None, 1)[0].lower() for _, row in rows]
    corners, i = [], 0
    while i < len(rows):
        if words[i] != "solid":
            raise InputError(f"expected 'solid', found {rows[i][1][:40]!r}", path,
                             rows[i][0])
        # a missing last 'endsolid' (some exporters stop after the last facet): the
        # solid runs to the end of the file and its facets are read all the same
        end = next((j for j in range(i + 1, len(rows)) if words[j] == "endsolid"),
                   len(rows))
        corners.append(_solid_corners(rows[i + 1:end], words[i + 1:end], path,
                                      ended=end < len(rows)))
        i = end + 1
    V = np.concatenate(corners) if corners else np.zeros((0, 3))
    if not len(V):
        raise InputError("STL holds no triangles (no facets between 'solid' and "
                         "'endsolid')", path)
    return V


def _solid_corners(rows, words, path, ended: bool) -> np.ndarray:
    """The corners of one solid's facets, every row checked against :data:`_FACET`."""
    size = len(_FACET)
    pattern = np.resize(np.array(_FACET, dtype=object), len(rows))
    wrong = np.flatnonzero(np.array(words, dtype=object) != pattern)
    if len(wrong):
        k = wrong[0]
        raise InputError(f"expected '{_FACET[k % size]}', found {rows[k][1][:40]!r}",
                         path, rows[k][0])
    n = len(rows) - len(rows) % size
    if n < len(rows):      # the last facet is not complete
        problem = ("ends early ('endsolid' before its 'endfacet')" if ended
                   else "runs to the end of the file (cut short?)")
        raise InputError(f"the facet of line {rows[n][0]} {problem}", path)
    vertex_rows = [rows[k] for k in range(n) if k % size in (2, 3, 4)]
    values = [row.split()[1:] for _, row in vertex_rows]
    for (no, row), v in zip(vertex_rows, values):
        if len(v) != 3:
            raise InputError(f"vertex row is not three numbers: {row[:60]!r}", path, no)
    try:
        return np.array(values, dtype=np.float64)
    except ValueError:
        for (no, row), v in zip(vertex_rows, values):   # name the first bad row
            try:
                np.array(v, dtype=np.float64)
            except ValueError:
                raise InputError(f"vertex row is not three numbers: {row[:60]!r}", path,
                                 no) from None
        raise
