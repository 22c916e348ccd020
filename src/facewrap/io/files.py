"""Reading a user's file into memory with one clear error when it cannot be read."""

from __future__ import annotations

import codecs
import json
import os
import re
from pathlib import Path

from facewrap.errors import InputError
from facewrap.io.paths import special_kind
# the limit is the units' (meshes and the geometry check it too); kept importable here
from facewrap.units import COORDINATE_LIMIT, first_too_large, too_large

__all__ = ["read_file_bytes", "read_file_head", "file_size", "nul_at_ends", "read_json",
           "read_format_items", "memory_budget", "not_a_file", "COORDINATE_LIMIT",
           "first_too_large", "check_coordinates", "folder_files", "natural_key"]


# How much of each end of a file is looked at before the whole is read: enough to
# catch a binary or sparse (zero-filled) file handed to a text reader, small enough
# to cost nothing.
_SAMPLE_BYTES = 1 << 16

# Byte-order marks of the wide Unicode encodings a text file is saved in on Windows
# (PowerShell 5's ">" and Out-File, Notepad's and Excel's "Unicode"): the mark, the
# codec of what follows it, bytes per code unit.  UTF-32 LE first: its mark begins
# with UTF-16 LE's.
_WIDE_BOMS = ((codecs.BOM_UTF32_LE, "utf-32-le", 4), (codecs.BOM_UTF32_BE, "utf-32-be", 4),
              (codecs.BOM_UTF16_LE, "utf-16-le", 2), (codecs.BOM_UTF16_BE, "utf-16-be", 2))


def not_a_file(path) -> InputError:
    """The error for an input ``path`` that is not a regular file, saying what it is.

    Examples
    --------
    >>> str(not_a_file("/")), str(not_a_file("/dev/null"))
    ('/: is a folder, not a file', '/dev/null: is a character device, not a regular file')
    >>> str(not_a_file("/no/such"))
    '/no/such: no such file'
    """
    if os.path.isdir(path):
        return InputError("is a folder, not a file", path)
    kind = special_kind(path)
    if kind:
        return InputError(f"is {kind}, not a regular file", path)
    if os.path.islink(path):
        return InputError("is a symlink to a missing file", path)
    return InputError("no such file", path)


def check_coordinates(values, path, what: str = "vertex") -> None:
    """Refuse coordinates beyond :data:`COORDINATE_LIMIT` in magnitude.

    The format readers stay exact (a 1e308 round-trips); the meshes, shapes and
    points a command reads pass here, where no head can be that size.

    Parameters
    ----------
    values : (n, 3) float64
    path : path
        Named in the error.
    what : str
        What a row is ("vertex", "landmark").

    Raises
    ------
    InputError
        ``path: vertex 5 has coordinate 1e+30, too large (...)``.
    """
    problem = too_large(values, what)
    if problem is not None:
        raise InputError(problem, path)


def memory_budget() -> int:
    """Bytes one command may plan to hold: half the machine's memory, or half the
    process's address-space limit (``ulimit -v``) when that is lower.

    Work whose memory need is known up front (a texture bake, an animation's
    frames) is refused before it starts when it needs more, instead of failing
    after minutes with an allocation error.
    """
    try:
        budget = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") // 2
    except (AttributeError, ValueError, OSError):   # not a POSIX system
        budget = 4 << 30
    try:
        import resource
        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
    except (ImportError, OSError, ValueError):
        return budget
    return budget if limit == resource.RLIM_INFINITY else min(budget, limit // 2)


def file_size(path) -> int:
    """Size of ``path`` in bytes; :class:`InputError` naming it when it cannot be read.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    int
    """
    if os.path.lexists(path) and not os.path.isfile(path):   # say what it is instead
        raise not_a_file(path)
    try:
        return os.stat(path).st_size
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.strerror}", path) from None


def read_file_head(path, size: int) -> bytes:
    """The first ``size`` bytes of ``path`` (fewer when the file is shorter).

    Readers look at a header this way before deciding how much to read, so a file
    whose header promises more than it holds is refused without reading it whole.
    """
    try:
        with open(path, "rb") as fh:
            return fh.read(size)
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.strerror}", path) from None


def nul_at_ends(path, size: int) -> bool:
    """Whether the first or last 64 KiB of a file of ``size`` bytes hold a NUL byte.

    A text file never holds one; a binary file, or a sparse one (its holes read
    as zeros), almost always does at one end.  Costs two small reads.
    """
    try:
        with open(path, "rb") as fh:
            if b"\0" in fh.read(_SAMPLE_BYTES):
                return True
            if size > _SAMPLE_BYTES:
                fh.seek(max(size - _SAMPLE_BYTES, _SAMPLE_BYTES))
                return b"\0" in fh.read(_SAMPLE_BYTES)
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.strerror}", path) from None
    return False


def read_file_bytes(path, text: bool = False) -> bytes:
    """The whole file; :class:`InputError` naming it when missing, unreadable or empty.

    Parameters
    ----------
    path : str or os.PathLike
    text : bool
        Also reject binary data (a NUL byte) for text formats.  Both ends of the
        file are looked at first, so a binary or sparse multi-GB file is refused
        without being read.  Text saved as UTF-16 or UTF-32 with its byte-order
        mark (Windows' "Unicode") is returned as UTF-8, the mark left out.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "ids.txt"
    >>> _ = p.write_bytes("3536\\r\\n3252\\r\\n".encode("utf-16"))
    >>> read_file_bytes(p, text=True)
    b'3536\\r\\n3252\\r\\n'
    """
    if text:
        size = file_size(path)
        wide = _wide_encoding(read_file_head(path, 4))
        if wide is not None:
            return _read_wide_text(path, size, *wide)
        if nul_at_ends(path, size):
            raise InputError("binary data, not a text file", path)
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.strerror}", path) from None
    # (isspace stops at the first other byte; strip would copy a 50 MB scan)
    if not data or data.isspace():
        raise InputError("empty file", path)
    if text and b"\0" in data:
        raise InputError("binary data, not a text file", path)
    return data


def _wide_encoding(head: bytes):
    """(mark, codec, unit) of the wide Unicode encoding whose mark ``head`` starts
    with, or None (UTF-8 and ASCII text, binary data)."""
    for bom, codec, unit in _WIDE_BOMS:
        if head.startswith(bom):
            return bom, codec, unit
    return None


def _read_wide_text(path, size: int, bom: bytes, codec: str, unit: int) -> bytes:
    """A UTF-16 or UTF-32 text file (with its byte-order mark) as UTF-8 bytes.

    Every text reader then works on UTF-8 as usual: its line numbers and messages
    are those of the file.  As for UTF-8, both ends are looked at before the whole
    is read, and a NUL character (binary data, or the zeros of a sparse file)
    is refused.
    """
    name = codec[:-3].upper()   # "UTF-16"
    try:
        with open(path, "rb") as fh:
            head = fh.read(_SAMPLE_BYTES)
            tail = b""
            if size > 2 * _SAMPLE_BYTES:
                start = size - _SAMPLE_BYTES
                fh.seek(start - (start - len(bom)) % unit)   # on a code unit
                tail = fh.read(_SAMPLE_BYTES)
            for sample in (head[len(bom):], tail):
                sample = sample[:len(sample) - len(sample) % unit]
                if "\0" in sample.decode(codec, errors="replace"):
                    raise InputError(f"binary data, not a text file ({name})", path)
            fh.seek(len(bom))
            data = fh.read()
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.strerror}", path) from None
    try:
        text = data.decode(codec)
    except UnicodeDecodeError as exc:
        raise InputError(f"not {name} text (byte {exc.start + len(bom)}), though it "
                         f"starts with the {name} byte-order mark", path) from None
    if not text or text.isspace():
        raise InputError("empty file", path)
    if "\0" in text:
        raise InputError(f"binary data, not a text file ({name})", path)
    return text.encode("utf-8")


def read_json(path):
    """A JSON file's content; :class:`InputError` naming the file (and line) when
    it is missing, empty or not valid JSON."""
    text = read_file_bytes(path, text=True).decode("utf-8-sig", errors="replace")
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON: {exc.msg}", path, exc.lineno) from None
    except ValueError as exc:   # an integer of more digits than int() converts
        raise InputError(f"invalid JSON: {str(exc).split(';')[0]}", path) from None
    except RecursionError:   # the C decoder recurses once per nesting level
        raise InputError("invalid JSON: nested too deeply", path) from None


def read_format_items(path, format_name: str, key: str, what: str) -> list:
    """The list of items of a facewrap JSON file, checked to be of its format.

    facewrap's own JSON files (landmarks, face parts) are objects that name their
    format (``{"format": "facewrap.landmarks", "landmarks": [...]}``), so a file of
    another kind is refused with one clear message.

    Parameters
    ----------
    path : str or os.PathLike
    format_name : str
        The expected ``"format"`` value, e.g. ``"facewrap.landmarks"``.
    key : str
        The key of the item list, e.g. ``"landmarks"``.
    what : str
        What the file holds, for the message ("landmark", "parts").

    Returns
    -------
    list
        The non-empty list under ``key`` (items not checked).

    Raises
    ------
    InputError
        Naming the file: missing, invalid JSON, another format, or no items.
    """
    d = read_json(path)
    if not isinstance(d, dict) or d.get("format") != format_name:
        raise InputError(f'not a facewrap {what} file ("format": "{format_name}" missing)',
                         path)
    if d.get("version", 1) != 1:   # a later format may mean its fields differently
        raise InputError(f"format version {str(d['version'])[:20]} is not supported "
                         "(this facewrap reads version 1)", path)
    items = d.get(key)
    if not isinstance(items, list) or not items:
        raise InputError(f"'{key}' must be a non-empty list", path)
    return items


def natural_key(name: str) -> tuple:
    """Sort key of a file name with its runs of digits read as numbers, so that
    ``frame_2`` comes before ``frame_10`` (plain string order puts it after).

    >>> sorted(["f_10.obj", "f_2.obj", "f_1.obj"], key=natural_key)
    ['f_1.obj', 'f_2.obj', 'f_10.obj']
    """
    parts = re.split(r"(\d+)", name)
    return tuple((0, int(t), t) if t.isdigit() else (1, 0, t) for t in parts if t), name


def folder_files(folder, suffixes, natural: bool = False) -> list[Path]:
    """The files of ``folder`` whose extension is one of ``suffixes`` (any case),
    hidden ones left out, in name order.

    Hidden files are never a user's data: ``._name.obj`` is the resource fork macOS
    writes beside every file it copies onto a foreign disk (binary, not a mesh),
    ``.name.obj`` an editor's or a sync tool's copy.

    Parameters
    ----------
    folder : path
    suffixes : iterable of str
        Lower-case extensions with their dot (``".obj"``).
    natural : bool
        Numbers in names by value (:func:`natural_key`): for files that are frames of
        a sequence, often numbered without leading zeros.

    Returns
    -------
    list of Path

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> for name in ("f_10.obj", "f_2.OBJ", "._f_2.obj", "notes.txt"):
    ...     _ = (d / name).write_text("")
    >>> [p.name for p in folder_files(d, [".obj"], natural=True)]
    ['f_2.OBJ', 'f_10.obj']
    """
    suffixes = tuple(suffixes)
    found = [p for p in Path(folder).iterdir()
             if p.suffix.lower() in suffixes and not p.name.startswith(".")]
    return sorted(found, key=(lambda p: natural_key(p.name)) if natural else None)
