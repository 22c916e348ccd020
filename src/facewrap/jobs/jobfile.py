"""Job files: one TOML file describes a whole wrap, so studios can version settings.

A job file has three tables (and an optional ``version = 1``)::

    version = 1

    [inputs]                      # WrapJob fields with metadata table "inputs"
    template = "template.obj"
    template_landmarks = "template_landmarks.txt"
    scan = "scans/anna.obj"
    scan_landmarks = "scans/anna_landmarks.txt"

    [outputs]                     # WrapJob fields with metadata table "outputs"
    output = "out/anna.obj"
    report = "out/anna.json"

    [wrap]                        # WrapSettings fields
    model = "graph"
    node_spacing = 0.03

    [[wrap.stages]]               # list[Stage]: one table per stage
    iterations = 10
    stiffness = 1.0

The keys are not listed here: they are the fields of
:class:`~facewrap.jobs.wrap_job.WrapJob` and :class:`~facewrap.wrapping.stages.WrapSettings`, found
by introspection (:func:`dataclasses.fields`, :func:`typing.get_type_hints`), so
a new setting is a new key without touching this module.  Unknown keys and values
of the wrong type are :class:`~facewrap.errors.InputError` naming the file, the
line (where it can be found) and the key.  A key left out keeps its default; TOML
has no null, so an optional setting is "unset" by leaving it out.

Relative paths are resolved against the folder of the job file (``~`` is
expanded).  :func:`write_job` writes a commented template with every key, which
users start from; :func:`job_to_toml` is the small emitter behind it.

This module also owns the value conversion that batch manifests reuse
(:func:`convert_value` for TOML values, :func:`parse_text` for CSV cells).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import tomllib
import types
import typing
from pathlib import Path

from facewrap.errors import InputError
from facewrap.jobs.wrap_job import WrapJob, check_job_paths
from facewrap.wrapping import WrapSettings

__all__ = ["load_job", "write_job", "job_to_toml", "read_job_tables", "job_keys",
           "settings_keys", "convert_value", "parse_text", "settings_from_dict",
           "JOB_TABLES", "FORMAT_VERSION"]

#: Version of the job-file format written by :func:`write_job`.
FORMAT_VERSION = 1
#: Tables of a job file holding WrapJob fields.
JOB_TABLES = ("inputs", "outputs")
_TOP_KEYS = ("version", "description")


# -- introspection ---------------------------------------------------------------------
def _hints(cls) -> dict:
    return typing.get_type_hints(cls)


def job_keys(table: str | None = None) -> dict[str, dataclasses.Field]:
    """WrapJob fields by key, optionally those of one table (``"inputs"``...)."""
    return {f.name: f for f in dataclasses.fields(WrapJob)
            if table is None or f.metadata.get("table", "inputs") == table}


def settings_keys() -> dict[str, type]:
    """WrapSettings fields by key, with their (resolved) types."""
    hints = _hints(WrapSettings)
    return {f.name: hints[f.name] for f in dataclasses.fields(WrapSettings)}


def _optional(tp) -> tuple[object, bool]:
    """(inner type, True) for ``X | None``; (tp, False) otherwise."""
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) < len(typing.get_args(tp)):
            inner = args[0] if len(args) == 1 else typing.Union[tuple(args)]
            return inner, True
    return tp, False


def _type_name(tp) -> str:
    tp, opt = _optional(tp)
    origin = typing.get_origin(tp)
    if origin in (list, tuple):
        args = typing.get_args(tp)
        item = args[0] if args else typing.Any
        name = (f"array of [[...]] tables ({item.__name__})"
                if dataclasses.is_dataclass(item) else f"array of {_type_name(item)}s")
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


def _choices() -> dict[str, tuple]:
    """Allowed values of settings that ``facewrap wrap`` restricts to choices.

    Read from the CLI's own parser, so job files and options never disagree.
    """
    import argparse
    try:
        from facewrap.cli import build_parser
        parser = build_parser()
    except ImportError:  # a CLI being rebuilt must not break job files
        return {}
    names = set(settings_keys())
    for action in getattr(parser, "_actions", ()):
        if isinstance(action, argparse._SubParsersAction) and "wrap" in action.choices:
            return {a.dest: tuple(a.choices)
                    for a in getattr(action.choices["wrap"], "_actions", ())
                    if a.choices and a.dest in names}
    return {}


# -- values ----------------------------------------------------------------------------
class _Where:
    """How to name a value in an error: file, key path, line finder."""

    def __init__(self, path, text: str | None = None):
        self.path, self.text = path, text

    def line(self, table: str, key: str | None, index: int | None = None) -> int | None:
        return None if self.text is None else _find_line(self.text, table, key, index)

    def error(self, problem: str, table: str, key: str | None = None,
              index: int | None = None) -> InputError:
        return InputError(problem, self.path, self.line(table, key, index))


def _describe(value) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


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
        tables made into dataclasses).

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
    tp, _ = _optional(tp)
    origin = typing.get_origin(tp)
    bad = ValueError(f"{name!r} must be {_article(_type_name(tp))}, got "
                     f"{_describe(value)}")
    if tp is typing.Any:
        return value
    if origin is typing.Literal:
        if value not in typing.get_args(tp):
            raise ValueError(f"{name!r} must be {_type_name(tp)}, got {_describe(value)}")
        return value
    if origin in (typing.Union, types.UnionType):
        for option in typing.get_args(tp):
            try:
                return convert_value(value, option, name)
            except ValueError:
                continue
        raise bad
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
    raise ValueError(f"{name!r}: settings of type {tp!r} cannot be given in a file")


def _dataclass_from_table(cls, table: dict, name: str):
    hints = _hints(cls)
    known = {f.name for f in dataclasses.fields(cls)}
    for key in table:
        if key not in known:
            raise ValueError(f"unknown key {key!r} in {name} (known: "
                             f"{', '.join(sorted(known))})")
    values = {k: convert_value(v, hints[k], f"{name}.{k}") for k, v in table.items()}
    try:
        return cls(**values)
    except TypeError as exc:  # a required field is missing
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

    Examples
    --------
    >>> parse_text("0.5", float, "smoothing"), parse_text("no", bool, "project")
    (0.5, False)
    """
    tp, _ = _optional(tp)
    if tp is bool:
        if text.lower() not in _BOOL_TEXT:
            raise ValueError(f"{name!r} must be true or false, got {_describe(text)}")
        return _BOOL_TEXT[text.lower()]
    if tp is int:
        try:
            return int(text)
        except ValueError:
            raise ValueError(f"{name!r} must be an integer, got {_describe(text)}") from None
    if tp is float:
        try:
            value = float(text)
        except ValueError:
            raise ValueError(f"{name!r} must be a number, got {_describe(text)}") from None
        return convert_value(value, float, name)
    if tp in (str, Path) or typing.get_origin(tp) is typing.Literal:
        return convert_value(text, tp, name)
    raise ValueError(f"{name!r} ({_type_name(tp)}) cannot be set in a CSV cell; use a "
                     "TOML manifest or the job file")


# -- reading ---------------------------------------------------------------------------
_LOCATION = re.compile(r"\s*\(at line (\d+), column \d+\)\s*$")
_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"""^\s*(?:"([^"]+)"|'([^']+)'|([A-Za-z0-9_\-]+))\s*=""")


def _find_line(text: str, table: str, key: str | None, index: int | None = None
               ) -> int | None:
    """1-based line of ``key`` in ``[table]`` (k-th ``[[table]]``), or of the header."""
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


def _read_toml(path) -> tuple[dict, str]:
    from facewrap.io.files import read_file_bytes
    data = read_file_bytes(path, text=True)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (byte {exc.start})", path) from None
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = _LOCATION.search(msg)
        line = int(m.group(1)) if m else None
        raise InputError(f"invalid TOML: {_LOCATION.sub('', msg)}", path, line) from None


def _resolve(value: str, folder: Path) -> str:
    p = Path(os.path.expanduser(value))
    return os.path.normpath(p if p.is_absolute() else folder / p)


def _job_values(table: dict, name: str, where: _Where, folder: Path) -> dict:
    """Convert one ``[inputs]``/``[outputs]`` table (or manifest row) to WrapJob values."""
    fields = job_keys(name) if name in JOB_TABLES else job_keys()
    hints = _hints(WrapJob)
    out = {}
    for key, value in table.items():
        if key not in fields:
            other = [t for t in JOB_TABLES if key in job_keys(t)]
            hint = (f"; it belongs in [{other[0]}]" if other else
                    f" (known: {', '.join(fields)})")
            raise where.error(f"unknown key {key!r} in [{name}]{hint}", name, key)
        try:
            v = convert_value(value, hints[key], key)
        except ValueError as exc:
            raise where.error(f"[{name}] {exc}", name, key) from None
        if fields[key].metadata.get("path"):
            if not v:
                raise where.error(f"[{name}] {key!r} is an empty path", name, key)
            v = _resolve(v, folder)
        out[key] = v
    return out


def _settings_values(table: dict, where: _Where, name: str = "wrap") -> dict:
    """Convert a ``[wrap]`` table to WrapSettings keyword values."""
    keys = settings_keys()
    choices = _choices()
    out = {}
    for key, value in table.items():
        if key not in keys:
            raise where.error(f"unknown key {key!r} in [{name}] (known: "
                              f"{', '.join(keys)})", name, key)
        try:
            v = convert_value(value, keys[key], key)
        except ValueError as exc:
            # errors inside [[wrap.stages]] name the stage table when they can
            stage = re.search(rf"\b{key}\[(\d+)\]", str(exc))
            line = None
            if stage:
                line = where.line(f"{name}.{key}", None, int(stage.group(1)))
            raise InputError(f"[{name}] {exc}", where.path,
                             line or where.line(name, key)) from None
        if key in choices and v not in choices[key]:
            raise where.error(f"[{name}] {key!r} must be one of "
                              f"{', '.join(map(str, choices[key]))}; got {v!r}", name, key)
        out[key] = v
    return out


def settings_from_dict(values: dict, base: WrapSettings | None = None) -> WrapSettings:
    """WrapSettings from converted values, over ``base`` (default: the defaults)."""
    return dataclasses.replace(base or WrapSettings(), **values)


def read_job_tables(path) -> tuple[dict, dict]:
    """Read a job file that may be partial (a batch's shared settings).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    job : dict
        WrapJob values given by ``[inputs]`` and ``[outputs]``, paths resolved
        against the file's folder.
    settings : dict
        WrapSettings values given by ``[wrap]``, converted.

    Raises
    ------
    InputError
        Invalid TOML, unknown table or key, wrong type, unknown version.
    """
    data, text = _read_toml(path)
    where = _Where(os.fspath(path), text)
    folder = Path(os.path.abspath(path)).parent
    tables = (*JOB_TABLES, "wrap")
    for key, value in data.items():
        if key in tables:
            if not isinstance(value, dict):
                raise where.error(f"{key!r} must be a table ([{key}])", "", key)
        elif key not in _TOP_KEYS:
            line = (where.line(key, None) if isinstance(value, (dict, list))
                    else where.line("", key))
            raise InputError(f"unknown {'table' if isinstance(value, dict) else 'key'} "
                             f"{key!r} (a job file has "
                             f"{', '.join(f'[{t}]' for t in tables)} and "
                             f"{', '.join(_TOP_KEYS)})", where.path, line)
    version = data.get("version", FORMAT_VERSION)
    if version != FORMAT_VERSION or isinstance(version, bool):
        raise where.error(f"unknown job-file version {version!r} (this facewrap reads "
                          f"version {FORMAT_VERSION})", "", "version")
    if not isinstance(data.get("description", ""), str):
        raise where.error("'description' must be a string", "", "description")
    job = {}
    for name in JOB_TABLES:
        job.update(_job_values(data.get(name, {}), name, where, folder))
    return job, _settings_values(data.get("wrap", {}), where)


def _require_job(values: dict, path, what: str = "") -> WrapJob:
    missing = [f.name for f in dataclasses.fields(WrapJob)
               if f.default is dataclasses.MISSING
               and f.default_factory is dataclasses.MISSING and f.name not in values]
    if missing:
        where = ", ".join(f"{m!r} in [{job_keys()[m].metadata.get('table', 'inputs')}]"
                          for m in missing)
        raise InputError(f"{what}missing {where}", path)
    return WrapJob(**values)


def load_job(path) -> tuple[WrapJob, WrapSettings]:
    """Read a job file into the job's files and its settings.

    Parameters
    ----------
    path : str or os.PathLike
        A TOML job file (see the module docstring).

    Returns
    -------
    job : WrapJob
        Absolute, normalised paths.
    settings : WrapSettings

    Raises
    ------
    InputError
        Naming the job file (and line): invalid TOML, unknown keys, wrong types,
        missing required inputs or outputs, an output that is an input.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "job.toml"
    >>> write_job(p)
    >>> job, settings = load_job(p)
    >>> pathlib.Path(job.scan).name, settings.model
    ('scan.obj', 'auto')
    """
    values, settings = read_job_tables(path)
    job = _require_job(values, path)
    check_job_paths(job, source=path)
    return job, settings_from_dict(settings)


# -- writing -----------------------------------------------------------------------------
_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n",
            "\f": "\\f", "\r": "\\r"}


def _toml_string(s: str) -> str:
    out = []
    for ch in s:
        if ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _toml_value(v) -> str:
    """A scalar or array as TOML (bool, int, finite float, str, list, dict)."""
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
        return _toml_string(os.fspath(v))
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}"
                               for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} values to a job file")


def _toml_key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_\-]+", k) else _toml_string(k)


def _attribute_docs(cls) -> dict[str, str]:
    """First sentence of each attribute's numpydoc description (for comments)."""
    doc = (cls.__doc__ or "").expandtabs()
    lines = doc.splitlines()
    out, names, desc, inside, indent = {}, [], [], False, None

    def flush():
        text = " ".join(desc).strip()
        text = re.sub(r":\w+:`~?(?:[\w.]*\.)?([^`]+)`", r"\1", text).replace("``", "")
        first = re.split(r"(?<=\.)\s", text, maxsplit=1)[0] if text else ""
        for n in names:
            out.setdefault(n, first)

    for k, line in enumerate(lines):
        stripped = line.strip()
        if stripped == "Attributes" and k + 1 < len(lines) and set(
                lines[k + 1].strip()) == {"-"}:
            inside, indent = True, len(line) - len(line.lstrip())
            continue
        if not inside or set(stripped) == {"-"}:
            continue
        if stripped and len(line) - len(line.lstrip()) == indent:
            if k + 1 < len(lines) and set(lines[k + 1].strip()) == {"-"}:
                break  # next section
            flush()
            head, _, rest = stripped.partition(" : ")
            names = [n.strip() for n in head.split(",")]
            desc = [rest] if rest.startswith("see ") else []
        elif stripped:
            desc.append(stripped)
    flush()
    return out


def _placeholder(tp):
    tp, _ = _optional(tp)
    return {bool: False, int: 0, float: 0.0, str: ""}.get(tp)


def _switched_off(tp) -> str | None:
    """TOML that reads back as None for a setting whose default is not None
    (``WrapSettings`` maps an empty ``weight_range`` to None), or None if there is
    none."""
    tp, _ = _optional(tp)
    if typing.get_origin(tp) in (tuple, list):
        return "[]"
    return None


def _relative(value: str, folder: Path | None) -> str:
    if folder is None:
        return value
    try:
        return os.path.relpath(value, folder)
    except ValueError:  # another drive on Windows
        return value


def _comment(text: str) -> list[str]:
    import textwrap
    return ["# " + t for t in textwrap.wrap(text, 86)]


def _emit_table(lines: list, name: str, values: dict, types_: dict, docs: dict,
                paths: set, folder: Path | None, choices: dict | None = None,
                defaults: dict | None = None) -> list:
    """Scalar keys of one table; returns the (key, items) of array-of-table keys."""
    later = []
    choices = choices or {}
    defaults = defaults or {}
    lines += ["", f"[{name}]"]
    for key, value in values.items():
        tp = types_[key]
        inner, _ = _optional(tp)
        item = (typing.get_args(inner) or [None])[0]
        if typing.get_origin(inner) is list and dataclasses.is_dataclass(item):
            later.append((key, value, item))
            continue
        note = docs.get(key, "")
        if key in choices:
            note += f" One of: {', '.join(map(str, choices[key]))}."
        lines += _comment(note.strip())
        off = _switched_off(tp) if defaults.get(key) is not None else None
        if value is None and off is not None:       # off, where the default is on
            lines.append(f"{key} = {off}")
            continue
        if value is None:
            example = _placeholder(tp)
            shown = "..." if example is None else _toml_value(example)
            lines.append(f"# {key} = {shown}    # {_type_name(tp)}; unset by default")
            continue
        if key in paths and isinstance(value, str):
            value = _relative(value, folder)
        lines.append(f"{key} = {_toml_value(value)}")
    return later


def job_to_toml(job: WrapJob, settings: WrapSettings | None = None,
                relative_to=None, header: str | None = None) -> str:
    """The text of a job file for ``job`` and ``settings`` (see :func:`write_job`).

    Parameters
    ----------
    job : WrapJob
    settings : WrapSettings, optional
        Default ``WrapSettings()``.
    relative_to : path, optional
        Folder the paths are written relative to (the job file's folder).
    header : str, optional
        Comment lines at the top.

    Returns
    -------
    str
        TOML that :func:`load_job` reads back to equal ``job`` and ``settings``.
    """
    settings = settings or WrapSettings()
    folder = None if relative_to is None else Path(os.path.abspath(relative_to))
    lines = [f"# {h}" if h else "#" for h in (header or "").splitlines()]
    lines.append(f"version = {FORMAT_VERSION}")
    job_docs, job_types = _attribute_docs(WrapJob), _hints(WrapJob)
    paths = {k for k, f in job_keys().items() if f.metadata.get("path")}
    for table in JOB_TABLES:
        values = {k: getattr(job, k) for k in job_keys(table)}
        _emit_table(lines, table, values, job_types, job_docs, paths, folder)
    set_types, set_docs = settings_keys(), _attribute_docs(WrapSettings)
    values = {k: getattr(settings, k) for k in set_types}
    later = _emit_table(lines, "wrap", values, set_types, set_docs, set(), folder,
                        _choices(), {f.name: f.default for f in dataclasses.fields(WrapSettings)})
    for key, items, cls in later:
        hints = _hints(cls)
        if items is None:
            lines += [""] + _comment(f"{key}: {set_docs.get(key, '')} One [[wrap.{key}]] "
                                     "table each; unset = the model's default. "
                                     "For example:")
            items, prefix = [cls()], "# "
        else:
            prefix = ""
        for item in items:
            lines += ["", f"{prefix}[[wrap.{key}]]"]
            for f in dataclasses.fields(cls):
                v = getattr(item, f.name)
                if v is None:
                    lines.append(f"# {f.name} = ...    # {_type_name(hints[f.name])}")
                else:
                    lines.append(f"{prefix}{f.name} = {_toml_value(v)}")
    return "\n".join(lines) + "\n"


def _template_job(folder: Path) -> WrapJob:
    return WrapJob(template=str(folder / "template.obj"), scan=str(folder / "scan.obj"),
                   template_landmarks=str(folder / "template_landmarks.txt"),
                   scan_landmarks=str(folder / "scan_landmarks.txt"),
                   output=str(folder / "out" / "fitted.obj"))


def write_job(path, job: WrapJob | None = None, settings: WrapSettings | None = None
              ) -> None:
    """Write a job file (atomically): every key, with a comment saying what it is.

    Parameters
    ----------
    path : str or os.PathLike
        Destination; its folder is created when missing.
    job : WrapJob, optional
        Default: ``template.obj``, ``scan.obj``... beside the job file, the result
        in ``out/fitted.obj`` (the names ``facewrap sample`` writes).
    settings : WrapSettings, optional
        Default ``WrapSettings()``.
    """
    from facewrap.io.atomic import atomic_write
    folder = Path(os.path.abspath(path)).parent
    folder.mkdir(parents=True, exist_ok=True)
    job = job or _template_job(folder)
    header = ("facewrap job file: `facewrap run THIS.toml` fits the template onto "
              "the scan.\nPaths are relative to this file's folder. A key left out "
              "keeps its default;\nunknown keys are errors. Optional keys are shown "
              "commented out.")
    text = job_to_toml(job, settings, relative_to=folder, header=header)
    with atomic_write(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
