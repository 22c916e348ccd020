"""Reading a user's file into memory with one clear error when it cannot be read."""

from __future__ import annotations

import json

from facewrap.errors import InputError

__all__ = ["read_file_bytes", "read_json"]


def read_file_bytes(path, text: bool = False) -> bytes:
    """The whole file; :class:`InputError` naming it when missing, unreadable or empty.

    Parameters
    ----------
    path : str or os.PathLike
    text : bool
        Also reject binary data (a NUL byte) for text formats.
    """
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.strerror}", path) from None
    if not data.strip():
        raise InputError("empty file", path)
    if text and b"\0" in data:
        raise InputError("binary data, not a text file", path)
    return data


def read_json(path):
    """A JSON file's content; :class:`InputError` naming the file (and line) when
    it is missing, empty or not valid JSON."""
    text = read_file_bytes(path, text=True).decode("utf-8", errors="replace")
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON: {exc.msg}", path, exc.lineno) from None
