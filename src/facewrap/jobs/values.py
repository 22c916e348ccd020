"""Values of job files and manifests: checked against a field's type and converted.

A job file, a TOML manifest and a CSV manifest all give settings and paths as
text or TOML values; these functions check one value against the type hint of
the dataclass field it sets (:func:`convert_value` for TOML values,
:func:`parse_text` for CSV cells) and say in words what was expected
(:func:`type_name`).  Paths are resolved against the folder of the file that
holds them (:func:`resolve_path`).  Callers add the file and the line.
"""

from __future__ import annotations

import dataclasses
import math
import os
import types
import typing
from pathlib import Path

__all__ = ["field_types", "optional_inner", "type_name", "describe_value",
           "convert_value", "parse_text", "resolve_path", "is_table_list"]


def field_types(cls) -> dict[str, object]:
    """Resolved type hints of a dataclass's fields, by field name."""
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)}


def optional_inner(tp) -> tuple[object, bool]:
    """``(X, True)`` for a hint ``X | None``; ``(tp, False)`` otherwise.

    >>> optional_inner(int | None), optional_inner(str)
    ((<class 'int'>, True), (<class 'str'>, False))
    """
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) < len(typing.get_args(tp)):
            inner = args[0] if len(args) == 1 else typing.Union[tuple(args)]
            return inner, True
    return tp, False


def is_table_list(tp) -> type | None:
    """The item dataclass of a ``list[SomeDataclass]`` hint (an array of tables), else None."""
    inner, _ = optional_inner(tp)
    item = (typing.get_args(inner) or [None])[0]
    if typing.get_origin(inner) is list and dataclasses.is_dataclass(item):
        return item
    return None


def type_name(tp) -> str:
    """A type hint in words, as a job-file user reads it.

    >>> type_name(float | None)
    'number (optional)'
    """
    tp, opt = optional_inner(tp)
    origin = typing.get_origin(tp)
    if origin in (list, tuple):
        args = typing.get_args(tp)
        item = args[0] if args else typing.Any
        name = (f"array of [[...]] tables ({item.__name__})"
                if dataclasses.is_dataclass(item) else f"array of {type_name(item)}s")
    elif origin is dict:
        name = "table"
    elif origin is typing.Literal:
        name = "one of " + ", ".join(repr(a) for a in typing.get_args(tp))
    elif dataclasses.is_dataclass(tp):
        name = f"table ({tp.__name__})"
    else:
        name = {bool: "boolean (true/false)", int: "integer", float: "number",
                str: "string"}.get(tp, getattr(tp, "__name__", str(tp)))
    return name + (" (optional)" if opt else "")


def _article(noun: str) -> str:
    return ("an " if noun[:1] in "aeiou" else "a ") + noun


def describe_value(value) -> str:
    """``repr(value)``, shortened to 40 characters for one-line messages."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _convert_scalar(value, tp, bad: ValueError, name: str):
    """bool, int, float and string-like hints (anything else: ``NotImplemented``)."""
    if tp is bool:
        if not isinstance(value, bool):
            raise bad
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise bad
        if not math.isfinite(value):
            raise ValueError(f"{name!r} must be a finite number, got {value!r}")
        return float(value)
    if tp is str or tp is Path or tp is os.PathLike:
        if not isinstance(value, str):
            raise bad
        return value
    return NotImplemented


def _convert_container(value, tp, origin, bad: ValueError, name: str):
    """list, tuple, dict and dataclass hints (anything else: ``NotImplemented``)."""
    if origin in (list, tuple):
        if not isinstance(value, list):
            raise bad
        args = typing.get_args(tp)
        item = args[0] if args else typing.Any
        items = [convert_value(v, item, f"{name}[{k}]") for k, v in enumerate(value)]
        return items if origin is list else tuple(items)
    if origin is dict:
        if not isinstance(value, dict):
            raise bad
        item = typing.get_args(tp)[1] if typing.get_args(tp) else typing.Any
        return {str(k): convert_value(v, item, f"{name}.{k}") for k, v in value.items()}
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise bad
        return _dataclass_from_table(tp, value, name)
    return NotImplemented


def convert_value(value, tp, name: str):
    """Check a TOML value against a field type and convert it.

    Parameters
    ----------
    value : object
        As parsed by :mod:`tomllib`.
    tp : type
        The field's type hint: bool, int, float, str, ``X | None``, ``Literal``,
        ``list[X]``, ``tuple[X, ...]``, ``dict[str, X]`` or a dataclass.
    name : str
        The key, for messages (``"wrap.smoothing"``).

    Returns
    -------
    object
        The converted value (ints promoted to float where a float is wanted,
        tables made into dataclasses, which check their own values).

    Raises
    ------
    ValueError
        Saying what was expected; callers add the file and line.

    Examples
    --------
    >>> convert_value(1, float, "smoothing")
    1.0
    >>> convert_value("yes", bool, "project")
    Traceback (most recent call last):
    ...
    ValueError: 'project' must be a boolean (true/false), got 'yes'
    """
    tp, _ = optional_inner(tp)
    origin = typing.get_origin(tp)
    bad = ValueError(f"{name!r} must be {_article(type_name(tp))}, got "
                     f"{describe_value(value)}")
    if tp is typing.Any:
        return value
    if origin is typing.Literal:
        if value not in typing.get_args(tp):
            raise ValueError(f"{name!r} must be {type_name(tp)}, got "
                             f"{describe_value(value)}")
        return value
    if origin in (typing.Union, types.UnionType):
        for option in typing.get_args(tp):
            try:
                return convert_value(value, option, name)
            except ValueError:
                continue
        raise bad
    out = _convert_scalar(value, tp, bad, name)
    if out is NotImplemented:
        out = _convert_container(value, tp, origin, bad, name)
    if out is not NotImplemented:
        return out
    raise ValueError(f"{name!r}: settings of type {tp!r} cannot be given in a file")


def _dataclass_from_table(cls, table: dict, name: str):
    types_ = field_types(cls)
    for key in table:
        if key not in types_:
            raise ValueError(f"unknown key {key!r} in {name} (known: "
                             f"{', '.join(sorted(types_))})")
    values = {k: convert_value(v, types_[k], f"{name}.{k}") for k, v in table.items()}
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:  # a required field missing, a value refused
        raise ValueError(f"{name}: {exc}") from None


_BOOL_TEXT = {"true": True, "yes": True, "1": True, "on": True,
              "false": False, "no": False, "0": False, "off": False}


def parse_text(text: str, tp, name: str):
    """Convert a text cell (CSV manifests) to a field's type.

    Parameters
    ----------
    text : str
        The cell, stripped.  Callers treat an empty cell as "not given".
    tp : type
        Field type; only scalars (bool, int, float, str, Literal, optional) can be
        written in a cell.
    name : str
        Column name, for messages.

    Raises
    ------
    ValueError
        Saying what was expected.

    Examples
    --------
    >>> parse_text("0.5", float, "smoothing"), parse_text("no", bool, "project")
    (0.5, False)
    """
    tp, _ = optional_inner(tp)
    if tp is bool:
        if text.lower() not in _BOOL_TEXT:
            raise ValueError(f"{name!r} must be true or false, got {describe_value(text)}")
        return _BOOL_TEXT[text.lower()]
    if tp is int:
        try:
            return int(text)
        except ValueError:
            raise ValueError(f"{name!r} must be an integer, got "
                             f"{describe_value(text)}") from None
    if tp is float:
        try:
            value = float(text)
        except ValueError:
            raise ValueError(f"{name!r} must be a number, got "
                             f"{describe_value(text)}") from None
        return convert_value(value, float, name)
    if tp in (str, Path) or typing.get_origin(tp) is typing.Literal:
        return convert_value(text, tp, name)
    raise ValueError(f"{name!r} ({type_name(tp)}) cannot be set in a CSV cell; use a "
                     "TOML manifest or the job file")


def resolve_path(value: str, folder: Path) -> str:
    """``value`` with ``~`` expanded, made absolute against ``folder`` and normalised.

    >>> resolve_path("scans/a.obj", Path("/data/jobs"))
    '/data/jobs/scans/a.obj'
    """
    p = Path(os.path.expanduser(value))
    return os.path.normpath(p if p.is_absolute() else folder / p)
