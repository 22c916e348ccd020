"""Manifests: the list of jobs of a batch, read and checked before any job runs.

A **manifest** lists the jobs; a shared **job file** (:mod:`facewrap.jobs.jobfile`)
holds what they have in common (template, landmarks, settings), and its settings
table says the kind of every job (wrap by default, or transfer).

* CSV: a header row, then one job per row.  Columns ``scan`` and ``output``
  (unless the job file gives them), and optionally ``scan_landmarks`` (left out or
  empty: detected on the scan, see :class:`~facewrap.jobs.WrapJob`), ``name``, ``job`` (a
  job file for this row), any other job field (:class:`~facewrap.jobs.WrapJob`,
  :class:`~facewrap.jobs.TransferJob`) and any scalar setting (``smoothing``, or
  ``wrap.smoothing``).  An empty cell means "not overridden"; lines starting with
  ``#`` are comments.
* TOML: optional ``version = 1`` and ``job = "shared.toml"``, then one ``[[jobs]]``
  table per job with the same keys, settings in a ``[jobs.wrap]`` (or
  ``[jobs.transfer]``) sub-table (where ``[[jobs.wrap.stages]]`` can also go).

Relative paths are resolved against the folder of the file that holds them.  Every
problem with the manifest itself (unknown column, bad value, two jobs writing one
file, an output that is some job's input) is an :class:`~facewrap.errors.InputError`
raised before any job runs.
"""

from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass
from pathlib import Path

from facewrap.errors import InputError
from facewrap.io.files import read_file_bytes
from facewrap.io.paths import find_overlap
from facewrap.jobs import WRAP, JobKind, kind_of, read_job_tables
from facewrap.jobs.jobfile import (job_keys, job_values, require_job, settings_from_dict,
                                   settings_keys, settings_values)
from facewrap.jobs.toml_text import TomlSource, read_toml
from facewrap.jobs.values import field_types, parse_text, resolve_path

__all__ = ["BatchJob", "read_manifest", "done_record_path", "ROW_KEYS"]

#: Manifest keys that are not job fields: the job's name and its own job file.
ROW_KEYS = ("name", "job")


@dataclass
class BatchJob:
    """One job of a batch: files, settings and where it came from.

    Attributes
    ----------
    index : int
        0-based position in the manifest.
    name : str
        From the ``name`` column, else the main output's path relative to the
        manifest.
    job : WrapJob or TransferJob
        Absolute paths.
    settings : WrapSettings or TransferJobSettings
    source : str
        The manifest.
    line : int or None
        Its line in the manifest.
    kind : JobKind
        What the job is (:data:`facewrap.jobs.WRAP` unless the job file says).
    """
    index: int
    name: str
    job: object
    settings: object
    source: str = ""
    line: int | None = None
    kind: JobKind = WRAP


def done_record_path(job) -> str:
    """``OUTPUT.done.json``: the record that ``job`` finished, beside its main output.

    >>> from facewrap.jobs import WrapJob
    >>> done_record_path(WrapJob("t.obj", "s.obj", output="out/a.obj"))
    'out/a.obj.done.json'
    """
    return kind_of(job).output_of(job) + ".done.json"


@dataclass
class _Row:
    line: int | None
    meta: dict
    job: dict
    settings: dict


def _column_kind(name: str, kind: JobKind) -> tuple[str, str] | None:
    """("job"|"settings"|"meta", key) for a manifest column, None if unknown."""
    prefix = kind.name + "."
    jobs, settings = job_keys(None, kind), settings_keys(kind)
    if name in ROW_KEYS:
        return "meta", name
    if name.startswith(prefix) and name[len(prefix):] in settings:
        return "settings", name[len(prefix):]
    if name in jobs and name in settings:  # never today; a clash must be spelled out
        raise ValueError(f"column {name!r} is both a job and a setting key; write "
                         f"{prefix}{name} for the setting")
    if name in jobs:
        return "job", name
    if name in settings:
        return "settings", name
    return None


def _csv_header(path, header: list[str], line: int, kind: JobKind) -> list:
    """The (kind, key) of every column; unknown or repeated columns refused."""
    kinds = []
    for col in header:
        try:
            what = _column_kind(col, kind)
        except ValueError as exc:
            raise InputError(str(exc), path, line) from None
        if what is None:
            known = ", ".join([*ROW_KEYS, *job_keys(None, kind), *settings_keys(kind)])
            raise InputError(f"unknown column {col!r} (known: {known})", path, line)
        kinds.append(what)
    seen = set()
    for (_, key), col in zip(kinds, header):
        if key in seen:
            raise InputError(f"column {col!r} appears twice", path, line)
        seen.add(key)
    return kinds


def _csv_cells(row: _Row, kinds, cells, folder: Path, kind: JobKind) -> None:
    job_types, set_types = field_types(kind.job_class), settings_keys(kind)
    paths = {k for k, f in job_keys(None, kind).items() if f.metadata.get("path")}
    for (what, key), cell in zip(kinds, cells):
        cell = cell.strip()
        if not cell:
            continue
        if what == "meta":
            row.meta[key] = cell
        elif what == "job":
            value = parse_text(cell, job_types[key], key)
            row.job[key] = resolve_path(value, folder) if key in paths else value
        else:
            row.settings[key] = parse_text(cell, set_types[key], key)


def _csv_rows(path, text: str, kind: JobKind) -> list[_Row]:
    lines = text.splitlines()
    content = [(no, ln) for no, ln in enumerate(lines, start=1)
               if ln.strip() and not ln.lstrip().startswith("#")]
    if not content:
        raise InputError("empty manifest: no header row", path)
    reader = csv.reader(io.StringIO("\n".join(ln for _, ln in content)))
    try:
        rows = list(reader)
    except csv.Error as exc:
        raise InputError(f"malformed CSV: {exc}", path, content[reader.line_num - 1][0]
                         if 0 < reader.line_num <= len(content) else None) from None
    header = [h.strip() for h in rows[0]]
    kinds = _csv_header(path, header, content[0][0], kind)
    if len(rows) < 2:
        raise InputError("no jobs: the manifest has a header but no rows", path)
    folder = Path(os.path.abspath(path)).parent
    out = []
    for (no, _), cells in zip(content[1:], rows[1:]):
        if len(cells) != len(header):
            raise InputError(f"row has {len(cells)} cells but the header has "
                             f"{len(header)}", path, no)
        row = _Row(no, {}, {}, {})
        try:
            _csv_cells(row, kinds, cells, folder, kind)
        except ValueError as exc:
            raise InputError(str(exc), path, no) from None
        out.append(row)
    return out


def _toml_shared_job(data: dict, where: TomlSource, folder: Path) -> str | None:
    """Check a TOML manifest's top level; returns its shared job file, if any."""
    for key in data:
        if key not in ("version", "job", "jobs"):
            raise where.error(f"unknown key {key!r} (a TOML manifest has version, job "
                              "and [[jobs]])", "", key)
    if data.get("version", 1) != 1 or isinstance(data.get("version"), bool):
        raise where.error(f"unknown manifest version {data['version']!r}", "", "version")
    shared = data.get("job")
    if shared is not None:
        if not isinstance(shared, str) or not shared:
            raise where.error("'job' must be the path of a job file", "", "job")
        shared = resolve_path(shared, folder)
    return shared


def _toml_row(k: int, item, path, line, folder: Path, kind: JobKind) -> _Row:
    if not isinstance(item, dict):
        raise InputError("'jobs' must be an array of tables ([[jobs]])", path, line)
    row = _Row(line, {}, {}, {})
    job_part = {}
    for key, value in item.items():
        if key in ROW_KEYS:
            if not isinstance(value, str) or not value:
                raise InputError(f"[[jobs]] {key!r} must be a non-empty string",
                                 path, line)
            row.meta[key] = resolve_path(value, folder) if key == "job" else value
        elif key == kind.name:
            if not isinstance(value, dict):
                raise InputError(f"[[jobs]] {key!r} must be a table ([jobs.{key}])",
                                 path, line)
            try:
                row.settings = settings_values(value, TomlSource(path),
                                               f"jobs.{kind.name}", kind)
            except InputError as exc:
                raise InputError(f"job {k + 1}: {exc.problem}", path, line) from None
        elif key in settings_keys(kind):
            raise InputError(f"[[jobs]] setting {key!r} goes in a [jobs.{kind.name}] "
                             "table", path, line)
        else:
            job_part[key] = value
    try:
        row.job = job_values(job_part, "jobs", TomlSource(path), folder, kind)
    except InputError as exc:
        raise InputError(exc.problem, path, line) from None
    return row


def _toml_rows(path, data: dict, where: TomlSource, kind: JobKind) -> list[_Row]:
    items = data.get("jobs")
    if not isinstance(items, list) or not items:
        raise InputError("no jobs: add one [[jobs]] table per job", path)
    folder = Path(os.path.abspath(path)).parent
    return [_toml_row(k, item, path, where.line("jobs", None, k), folder, kind)
            for k, item in enumerate(items)]


def _read_csv_text(path) -> str:
    raw = read_file_bytes(path, text=True)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (byte {exc.start})", path) from None


def _own_tables(row: _Row, folder: Path, cache: dict, kind: JobKind, path):
    """The tables of a row's own job file (read once per file), of the batch's kind."""
    own = resolve_path(row.meta["job"], folder)
    if own not in cache:
        cache[own] = read_job_tables(own)
    if cache[own].kind is not kind:
        raise InputError(f"job file {own} is a {cache[own].kind.name} job but the "
                         f"batch runs {kind.name} jobs", path, row.line)
    return cache[own]


def _batch_job(k: int, row: _Row, base, own, path, folder: Path, kind: JobKind):
    job_vals = {**(base.job if base else {}), **(own.job if own else {}), **row.job}
    set_vals = {**(base.settings if base else {}), **(own.settings if own else {}),
                **row.settings}
    where = f"job {k + 1}: "
    try:
        settings = settings_from_dict(set_vals, kind=kind)
    except ValueError as exc:
        raise InputError(where + str(exc), path, row.line) from None
    if kind.settings_field:
        job_vals[kind.settings_field] = settings
    try:
        job = require_job(job_vals, path, where, kind)
    except InputError as exc:
        raise InputError(exc.problem + " (give it in the manifest or the job file)",
                         path, row.line) from None
    try:
        kind.check_paths(job)
    except InputError as exc:
        raise InputError(where + exc.problem, path, row.line) from None
    name = row.meta.get("name") or os.path.relpath(kind.output_of(job), folder)
    return BatchJob(k, name, job, settings, path, row.line, kind)


def read_manifest(path, job_file=None) -> list[BatchJob]:
    """Read a manifest (CSV or TOML) and the job files it uses into jobs.

    Parameters
    ----------
    path : str or os.PathLike
        ``.csv`` or ``.toml`` (see the module docstring).
    job_file : str or os.PathLike, optional
        Shared job file; wins over a TOML manifest's ``job`` key.

    Returns
    -------
    list of BatchJob
        In manifest order, paths absolute.

    Raises
    ------
    InputError
        Naming the manifest or job file and line.
    """
    path = os.fspath(path)
    folder = Path(os.path.abspath(path)).parent
    ext = os.path.splitext(path)[1].lower()
    if ext == ".toml":
        data, where = read_toml(path)
        shared = _toml_shared_job(data, where, folder)
    elif ext in (".csv", ".txt", ".tsv"):
        text, shared = _read_csv_text(path), None
    else:
        raise InputError(f"unknown manifest format {ext or '(no extension)'!r}; use "
                         ".csv or .toml", path)
    shared = os.fspath(job_file) if job_file is not None else shared
    base = read_job_tables(shared) if shared else None
    kind = base.kind if base else WRAP
    rows = (_toml_rows(path, data, where, kind) if ext == ".toml"
            else _csv_rows(path, text, kind))
    cache: dict = {}
    jobs = []
    for k, row in enumerate(rows):
        own = _own_tables(row, folder, cache, kind, path) if "job" in row.meta else None
        jobs.append(_batch_job(k, row, base, own, path, folder, kind))
    _check_batch(jobs, path)
    return jobs


def _check_batch(jobs: list[BatchJob], path) -> None:
    """No two jobs write one file, nor one inside the other's output folder; no job
    writes another's input; names unique."""
    writers: dict[str, BatchJob] = {}
    for bj in jobs:
        for out in bj.kind.outputs(bj.job) + [done_record_path(bj.job)]:
            key = os.path.realpath(out)
            if key in writers:
                other = writers[key]
                raise InputError(f"jobs {other.index + 1} (line {other.line}) and "
                                 f"{bj.index + 1} both write {out!r}", path, bj.line)
            writers[key] = bj
    for key, bj in writers.items():
        # an output inside another job's output folder (a rig's shapes, a transfer's
        # out): the two jobs' files mix, and each one's done-record stops matching
        # its folder once the other writes there, so a resumed batch redoes it
        parent = os.path.dirname(key)
        while parent and parent != os.path.dirname(parent):
            other = writers.get(parent)
            if other is not None and other is not bj:
                raise InputError(f"job {bj.index + 1} writes {key!r} inside {parent!r}, an "
                                 f"output folder of job {other.index + 1} (line "
                                 f"{other.line}); give the jobs folders apart", path,
                                 bj.line)
            parent = os.path.dirname(parent)
    outputs = list(writers)
    for bj in jobs:
        # one job's output is, or lies in, another job's input (file or folder)
        hit = find_overlap(outputs, bj.kind.inputs(bj.job))
        if hit is not None:
            other, relation = writers[hit[0]], hit[1]
            inside = "" if relation.startswith("is also") else f" (it {relation})"
            raise InputError(f"job {other.index + 1} (line {other.line}) writes "
                             f"{hit[0]!r}, an input of job {bj.index + 1}{inside}; "
                             "inputs are never overwritten", path, bj.line)
    names: dict[str, BatchJob] = {}
    for bj in jobs:
        if bj.name in names:
            raise InputError(f"two jobs are named {bj.name!r} (lines "
                             f"{names[bj.name].line} and {bj.line})", path, bj.line)
        names[bj.name] = bj
