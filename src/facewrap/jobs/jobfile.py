"""Job files: one TOML file describes a whole job, so studios can version settings.

A wrap job file has three tables (and an optional ``version = 1``)::

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

A transfer job file has a ``[transfer]`` table (:class:`~facewrap.jobs.transfer_job.
TransferJobSettings` fields) instead of ``[wrap]``, and the inputs and outputs of a
:class:`~facewrap.jobs.transfer_job.TransferJob`.  A rig job file has a ``[rig]`` table
(the :class:`~facewrap.wrapping.WrapSettings` of the neutral's wrap; it may be
empty, it names the kind) and the inputs and outputs of a
:class:`~facewrap.jobs.rig_job.RigJob` (``expression_scans`` and
``expression_landmarks`` are arrays of paths).  The settings table names the
kind of job (:mod:`facewrap.jobs.kinds`); a partial file without one (a batch's
shared inputs) is of the kind whose keys it uses.

The keys are not listed here: they are the fields of the job and settings
dataclasses, found by introspection (:func:`dataclasses.fields`,
:func:`typing.get_type_hints`), so a new setting is a new key without touching
this module; allowed values come from the settings classes' constraint tables
(:func:`facewrap.params.choices_of`).  Unknown keys and values of the wrong type
or out of range are :class:`~facewrap.errors.InputError` naming the file, the line
(where it can be found) and the key.  A key left out keeps its default; TOML has
no null, so an optional setting is "unset" by leaving it out.

Relative paths are resolved against the folder of the job file (``~`` is
expanded).  :mod:`facewrap.jobs.jobfile_writer` writes job files.
"""

from __future__ import annotations

import dataclasses
import os
import re
from dataclasses import dataclass
from pathlib import Path

from facewrap.errors import InputError
from facewrap.io.paths import check_outputs_apart
from facewrap.jobs.kinds import JOB_KINDS, JobKind
from facewrap.jobs.toml_text import TomlSource, read_toml
from facewrap.jobs.values import convert_value, field_types, resolve_path
from facewrap.params import choices_of

__all__ = ["load_job", "read_job_tables", "JobTables", "job_keys", "settings_keys",
           "setting_choices", "job_values", "settings_values", "settings_from_dict",
           "require_job", "JOB_TABLES", "TOP_KEYS", "FORMAT_VERSION"]

#: Version of the job-file format.
FORMAT_VERSION = 1
#: Tables of a job file holding job fields (paths); the settings table is the kind's.
JOB_TABLES = ("inputs", "outputs")
#: Top-level keys of a job file besides its tables.
TOP_KEYS = ("version", "description")


def _kind(kind: str | JobKind) -> JobKind:
    return kind if isinstance(kind, JobKind) else JOB_KINDS[kind]


# -- keys ------------------------------------------------------------------------------
def job_keys(table: str | None = None, kind: str | JobKind = "wrap"
             ) -> dict[str, dataclasses.Field]:
    """Job fields by key, optionally those of one table (``"inputs"``, ``"outputs"``).

    The settings of a job that holds them (``TransferJob.settings``) are not keys.
    """
    return {f.name: f for f in dataclasses.fields(_kind(kind).job_class)
            if f.metadata.get("table", "inputs") in JOB_TABLES
            and (table is None or f.metadata.get("table", "inputs") == table)}


def settings_keys(kind: str | JobKind = "wrap") -> dict[str, type]:
    """Settings fields of a kind of job by key, with their (resolved) types."""
    return field_types(_kind(kind).settings_class)


def setting_choices(kind: str | JobKind = "wrap") -> dict[str, tuple]:
    """Allowed values of the settings restricted to choices (from their constraints)."""
    cls = _kind(kind).settings_class
    out = {}
    for key in settings_keys(kind):
        choices = choices_of(cls, key)
        if choices is not None:
            out[key] = choices
    return out


# -- values ----------------------------------------------------------------------------
def _path_value(value, key: str, name: str, where: TomlSource, folder: Path):
    """A path (or list of paths) resolved against ``folder``; empty paths refused."""
    items = value if isinstance(value, list) else [value]
    if not all(items) or not items:
        raise where.error(f"[{name}] {key!r} is an empty path", name, key)
    if any("\0" in v for v in items if isinstance(v, str)):
        # no file system takes it ("embedded null byte", naming nothing, later)
        raise where.error(f"[{name}] {key!r} holds a NUL character (\\u0000)", name, key)
    resolved = [resolve_path(v, folder) for v in items]
    return resolved if isinstance(value, list) else resolved[0]


def job_values(table: dict, name: str, where: TomlSource, folder: Path,
               kind: str | JobKind = "wrap") -> dict:
    """Convert one ``[inputs]``/``[outputs]`` table (or a manifest row) to job values.

    Parameters
    ----------
    table : dict
        Key → TOML value.
    name : str
        The table's name: ``"inputs"`` or ``"outputs"`` (only that table's keys are
        allowed), anything else for a manifest row (keys of both).
    where : TomlSource
        Named in errors.
    folder : Path
        Relative paths are resolved against it.
    kind : str or JobKind

    Raises
    ------
    InputError
        Unknown key (saying which table it belongs in), wrong type, empty path.
    """
    fields = job_keys(name, kind) if name in JOB_TABLES else job_keys(None, kind)
    types_ = field_types(_kind(kind).job_class)
    out = {}
    for key, value in table.items():
        if key not in fields:
            other = [t for t in JOB_TABLES if key in job_keys(t, kind)]
            hint = (f"; it belongs in [{other[0]}]" if other else
                    f" (known: {', '.join(fields)})")
            raise where.error(f"unknown key {key!r} in [{name}]{hint}", name, key)
        try:
            v = convert_value(value, types_[key], key)
        except ValueError as exc:
            raise where.error(f"[{name}] {exc}", name, key) from None
        if fields[key].metadata.get("path"):
            v = _path_value(v, key, name, where, folder)
        out[key] = v
    return out


def _conversion_error(exc: ValueError, key: str, name: str, where: TomlSource):
    """Errors inside ``[[wrap.stages]]`` name the stage table's line when they can."""
    stage = re.search(rf"\b{key}\[(\d+)\]", str(exc))
    line = where.line(f"{name}.{key}", None, int(stage.group(1))) if stage else None
    return InputError(f"[{name}] {exc}", where.path, line or where.line(name, key))


def settings_values(table: dict, where: TomlSource, name: str | None = None,
                    kind: str | JobKind = "wrap") -> dict:
    """Convert a settings table (``[wrap]``, ``[transfer]``) to keyword values.

    Each value is converted to its field's type and checked against the settings
    class's constraints, so an error names the key and its line.

    Parameters
    ----------
    table : dict
    where : TomlSource
    name : str, optional
        The table's name in messages (default: the kind's, e.g. ``"wrap"``).
    kind : str or JobKind

    Raises
    ------
    InputError
    """
    kind = _kind(kind)
    name = name or kind.name
    keys, choices = settings_keys(kind), setting_choices(kind)
    out = {}
    for key, value in table.items():
        if key not in keys:
            raise where.error(f"unknown key {key!r} in [{name}] (known: "
                              f"{', '.join(keys)})", name, key)
        try:
            v = convert_value(value, keys[key], key)
        except ValueError as exc:
            raise _conversion_error(exc, key, name, where) from None
        if key in choices and v not in choices[key]:
            raise where.error(f"[{name}] {key!r} must be one of "
                              f"{', '.join(map(str, choices[key]))}; got {v!r}", name, key)
        try:  # the class's own constraints, the other fields at their defaults
            kind.settings_class(**{key: v})
        except ValueError as exc:
            raise where.error(f"[{name}] {exc}", name, key) from None
        out[key] = v
    return out


def settings_from_dict(values: dict, base=None, kind: str | JobKind = "wrap"):
    """Settings from converted values, over ``base`` (default: the defaults).

    Raises
    ------
    ValueError
        When the settings class refuses a value (naming the field).
    """
    base = base if base is not None else _kind(kind).settings_class()
    return dataclasses.replace(base, **values)


# -- reading ---------------------------------------------------------------------------
@dataclass
class JobTables:
    """What a job file (perhaps partial) gives.

    Attributes
    ----------
    job : dict
        Job values of ``[inputs]`` and ``[outputs]``, paths resolved against the
        file's folder.
    settings : dict
        Settings values of the kind's table, converted and checked.
    kind : JobKind
    """
    job: dict
    settings: dict
    kind: JobKind


def _kind_of_tables(data: dict, where: TomlSource) -> JobKind:
    """The kind named by the settings table, else the one whose keys the file uses."""
    named = [k for k in JOB_KINDS.values() if k.name in data]
    if len(named) > 1:  # the error points at the later table
        later = max(named, key=lambda k: where.line(k.name, None) or 0)
        raise where.error(f"a job file has one settings table, not "
                          f"{' and '.join(f'[{k.name}]' for k in named)}", later.name)
    if named:
        return named[0]
    given = {key for t in JOB_TABLES if isinstance(data.get(t), dict) for key in data[t]}
    for kind in JOB_KINDS.values():
        if given <= set(job_keys(None, kind)):
            return kind
    return JOB_KINDS["wrap"]


def _check_top_level(data: dict, where: TomlSource, tables: tuple) -> None:
    for key, value in data.items():
        if key in tables:
            if not isinstance(value, dict):
                raise where.error(f"{key!r} must be a table ([{key}])", "", key)
        elif key not in TOP_KEYS:
            line = (where.line(key, None) if isinstance(value, (dict, list))
                    else where.line("", key))
            raise InputError(f"unknown {'table' if isinstance(value, dict) else 'key'} "
                             f"{key!r} (a job file has "
                             f"{', '.join(f'[{t}]' for t in tables)} and "
                             f"{', '.join(TOP_KEYS)})", where.path, line)
    version = data.get("version", FORMAT_VERSION)
    if version != FORMAT_VERSION or isinstance(version, bool):
        raise where.error(f"unknown job-file version {version!r} (this facewrap reads "
                          f"version {FORMAT_VERSION})", "", "version")
    if not isinstance(data.get("description", ""), str):
        raise where.error("'description' must be a string", "", "description")


def read_job_tables(path) -> JobTables:
    """Read a job file that may be partial (a batch's shared settings).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    JobTables

    Raises
    ------
    InputError
        Invalid TOML, unknown table or key, wrong type or value, unknown version.
    """
    data, where = read_toml(path)
    kind = _kind_of_tables(data, where)
    _check_top_level(data, where, (*JOB_TABLES, kind.name))
    folder = Path(os.path.abspath(path)).parent
    job = {}
    for name in JOB_TABLES:
        job.update(job_values(data.get(name, {}), name, where, folder, kind))
    return JobTables(job, settings_values(data.get(kind.name, {}), where, kind=kind),
                     kind)


def require_job(values: dict, path, what: str = "", kind: str | JobKind = "wrap"):
    """The job of ``values``; an InputError names every required key left out.

    Parameters
    ----------
    values : dict
        Job values (from :func:`job_values`).
    path : path
        Named in the error.
    what : str
        Prefix of the message (``"job 3: "``).
    kind : str or JobKind
    """
    kind = _kind(kind)
    keys = job_keys(None, kind)
    missing = [f.name for f in dataclasses.fields(kind.job_class)
               if f.default is dataclasses.MISSING
               and f.default_factory is dataclasses.MISSING and f.name not in values]
    if missing:
        where = ", ".join(f"{m!r} in [{keys[m].metadata.get('table', 'inputs')}]"
                          for m in missing)
        raise InputError(f"{what}missing {where}", path)
    return kind.job_class(**values)


def load_job(path):
    """Read a job file into the job's files and its settings.

    Parameters
    ----------
    path : str or os.PathLike
        A TOML job file (see the module docstring).

    Returns
    -------
    job : WrapJob or TransferJob
        Absolute, normalised paths (a TransferJob holds its settings too).
    settings : WrapSettings or TransferJobSettings

    Raises
    ------
    InputError
        Naming the job file (and line): invalid TOML, unknown keys, wrong types or
        values, missing required inputs or outputs, an output that is an input.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from facewrap.jobs.jobfile_writer import write_job
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "job.toml"
    >>> write_job(p)
    >>> job, settings = load_job(p)
    >>> pathlib.Path(job.scan).name, settings.model
    ('scan.obj', 'auto')
    """
    tables = read_job_tables(path)
    kind = tables.kind
    try:
        settings = settings_from_dict(tables.settings, kind=kind)
    except ValueError as exc:
        raise InputError(f"[{kind.name}] {exc}", path) from None
    values = dict(tables.job)
    if kind.settings_field:
        values[kind.settings_field] = settings
    job = require_job(values, path, kind=kind)
    kind.check_paths(job, source=path)
    # the job file is read too: an output spelt as the job file itself would replace it
    check_outputs_apart(kind.outputs(job), [path], source=path)
    return job, settings
