"""TOML text for job files and manifests: reading with line numbers, writing values.

:mod:`tomllib` reads TOML but forgets where each key was; :class:`TomlSource`
keeps the text so that an error can name the line of the key (or of the
``[table]`` header) it is about.  The writing half emits the few TOML forms job
files use (:func:`toml_value`, :func:`toml_string`, :func:`toml_key`).
"""

from __future__ import annotations

import math
import os
import re
import textwrap
import tomllib

from facewrap.errors import InputError
from facewrap.io.files import read_file_bytes

__all__ = ["TomlSource", "read_toml", "find_line", "toml_string", "toml_value",
           "toml_key", "comment_lines"]

_LOCATION = re.compile(r"\s*\(at line (\d+), column \d+\)\s*$")
_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"""^\s*(?:"([^"]+)"|'([^']+)'|([A-Za-z0-9_\-]+))\s*=""")
_BARE_KEY = re.compile(r"[A-Za-z0-9_\-]+")


def find_line(text: str, table: str, key: str | None, index: int | None = None
              ) -> int | None:
    """1-based line of ``key`` in ``[table]`` (the k-th ``[[table]]``), or of the header.

    Parameters
    ----------
    text : str
        The TOML text.
    table : str
        Dotted table name; ``""`` for top-level keys.
    key : str or None
        None: the line of the table's header.
    index : int, optional
        Which ``[[table]]`` of an array of tables (0-based).

    Examples
    --------
    >>> find_line("a = 1\\n[wrap]\\nmodel = 'rbf'\\n", "wrap", "model")
    3
    """
    current, count = "", {}
    for no, line in enumerate(text.splitlines(), start=1):
        m = _HEADER.match(line)
        if m:
            current = re.sub(r"\s*\.\s*", ".", m.group(2).strip())
            count[current] = count.get(current, 0) + 1
            if key is None and current == table and (
                    index is None or count[current] == index + 1):
                return no
            continue
        if key is None or current != table:
            continue
        if index is not None and count.get(current, 0) != index + 1:
            continue
        k = _KEY.match(line)
        if k and next(g for g in k.groups() if g) == key:
            return no
    return None


class TomlSource:
    """A TOML file's name and text, to name the line of a problem in errors.

    Parameters
    ----------
    path : str
        Named in errors.
    text : str, optional
        The file's text; without it, errors name the file only.
    """

    def __init__(self, path, text: str | None = None):
        self.path, self.text = path, text

    def line(self, table: str, key: str | None, index: int | None = None) -> int | None:
        """Line of ``key`` in ``[table]`` (see :func:`find_line`), or None."""
        return None if self.text is None else find_line(self.text, table, key, index)

    def error(self, problem: str, table: str, key: str | None = None,
              index: int | None = None) -> InputError:
        """An :class:`InputError` naming this file and the line of ``key``."""
        return InputError(problem, self.path, self.line(table, key, index))


def read_toml(path) -> tuple[dict, TomlSource]:
    """Read a UTF-8 TOML file.

    Returns
    -------
    data : dict
        As parsed by :mod:`tomllib`.
    source : TomlSource
        The file's name and text, for errors that name a line.

    Raises
    ------
    InputError
        Unreadable, not UTF-8, or invalid TOML (with the line tomllib names).
    """
    data = read_file_bytes(path, text=True)
    try:
        # "utf-8-sig": a byte-order mark (Windows editors write one) is not a statement
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (byte {exc.start})", path) from None
    try:
        return tomllib.loads(text), TomlSource(os.fspath(path), text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = _LOCATION.search(msg)
        line = int(m.group(1)) if m else None
        raise InputError(f"invalid TOML: {_LOCATION.sub('', msg)}", path, line) from None
    except ValueError as exc:   # an integer of more digits than int() converts
        raise InputError(f"invalid TOML: {str(exc).split(';')[0]}", path) from None
    except RecursionError:   # tomllib recurses once per level of nested arrays
        raise InputError("invalid TOML: nested too deeply", path) from None


_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n",
            "\f": "\\f", "\r": "\\r"}


def toml_string(s: str) -> str:
    """A basic TOML string (double quotes, escapes) that reads back as ``s``.

    >>> toml_string('a "b"')
    '"a \\\\"b\\\\""'
    """
    out = []
    for ch in s:
        if ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def toml_key(k: str) -> str:
    """A key, bare where TOML allows it, else quoted."""
    return k if _BARE_KEY.fullmatch(k) else toml_string(k)


def toml_value(v) -> str:
    """A scalar or array as TOML (bool, int, finite float, str or path, list, dict).

    >>> toml_value([1, 2.0, True, "x"])
    '[1, 2.0, true, "x"]'
    """
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"cannot write the non-finite number {v!r} to a job file")
        text = repr(v)
        return text if any(c in text for c in ".en") else text + ".0"
    if isinstance(v, (str, os.PathLike)):
        return toml_string(os.fspath(v))
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{toml_key(k)} = {toml_value(x)}"
                               for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} values to a job file")


def comment_lines(text: str, width: int = 86) -> list[str]:
    """``text`` as ``# ...`` comment lines of at most ``width`` characters."""
    return ["# " + t for t in textwrap.wrap(text, width)]
