"""Writing job files: every key, with a comment saying what it is.

:func:`write_job` writes a commented template that users start from;
:func:`job_to_toml` is the emitter behind it, which :func:`~facewrap.jobs.jobfile.
load_job` reads back to an equal job and settings.  Comments are the first
sentence of each field's numpydoc description (:func:`attribute_docs`), and the
allowed values of choice settings come from the settings class's constraints.
"""

from __future__ import annotations

import dataclasses
import os
import re
import typing
from pathlib import Path

from facewrap.io.atomic import atomic_write
from facewrap.jobs.jobfile import (FORMAT_VERSION, JOB_TABLES, job_keys, setting_choices,
                                   settings_keys)
from facewrap.jobs.kinds import kind_of
from facewrap.jobs.toml_text import comment_lines, toml_value
from facewrap.jobs.values import field_types, is_table_list, optional_inner, type_name
from facewrap.jobs.wrap_job import WrapJob

__all__ = ["job_to_toml", "write_job", "attribute_docs"]


def attribute_docs(cls) -> dict[str, str]:
    """First sentence of each attribute's numpydoc description (for comments).

    Parameters
    ----------
    cls : type
        A class whose docstring has an ``Attributes`` section.

    Returns
    -------
    dict
        Attribute name → first sentence (roles such as ``:class:`` removed).
    """
    lines = (cls.__doc__ or "").expandtabs().splitlines()
    out, names, desc, inside, indent = {}, [], [], False, None

    def flush():
        text = " ".join(desc).strip()
        text = re.sub(r":\w+:`~?(?:[\w.]*\.)?([^`]+)`", r"\1", text).replace("``", "")
        first = re.split(r"(?<=\.)\s", text, maxsplit=1)[0] if text else ""
        for n in names:
            out.setdefault(n, first)

    def underline(k):
        return k + 1 < len(lines) and set(lines[k + 1].strip()) == {"-"}

    for k, line in enumerate(lines):
        stripped = line.strip()
        if stripped == "Attributes" and underline(k):
            inside, indent = True, len(line) - len(line.lstrip())
            continue
        if not inside or set(stripped) == {"-"}:
            continue
        if stripped and len(line) - len(line.lstrip()) == indent:
            if underline(k):
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
    tp, _ = optional_inner(tp)
    return {bool: False, int: 0, float: 0.0, str: ""}.get(tp)


def _switched_off(tp) -> str | None:
    """TOML that reads back as None for a setting whose default is not None
    (``WrapSettings`` maps an empty ``weight_range`` to None), or None if there is
    none."""
    tp, _ = optional_inner(tp)
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


def _unset_line(key: str, tp) -> str:
    example = _placeholder(tp)
    shown = "..." if example is None else toml_value(example)
    return f"# {key} = {shown}    # {type_name(tp)}; unset by default"


def _emit_table(lines: list, name: str, values: dict, types_: dict, docs: dict,
                paths: set, folder: Path | None, choices: dict | None = None,
                defaults: dict | None = None) -> list:
    """Scalar keys of one table; returns the (key, items, class) of array-of-table keys."""
    later = []
    choices = choices or {}
    defaults = defaults or {}
    lines += ["", f"[{name}]"]
    for key, value in values.items():
        tp = types_[key]
        item = is_table_list(tp)
        if item is not None:
            later.append((key, value, item))
            continue
        note = docs.get(key, "")
        if key in choices:
            note += f" One of: {', '.join(map(str, choices[key]))}."
        lines += comment_lines(note.strip())
        off = _switched_off(tp) if defaults.get(key) is not None else None
        if value is None:  # off where the default is on, else unset
            lines.append(f"{key} = {off}" if off is not None else _unset_line(key, tp))
            continue
        if key in paths:
            value = ([_relative(v, folder) for v in value] if isinstance(value, list)
                     else _relative(value, folder))
        lines.append(f"{key} = {toml_value(value)}")
    return later


def _emit_table_arrays(lines: list, table: str, later: list, docs: dict) -> None:
    """``[[table.key]]`` tables (e.g. ``[[wrap.stages]]``); an example when unset."""
    for key, items, cls in later:
        hints = field_types(cls)
        if items is None:
            lines += [""] + comment_lines(f"{key}: {docs.get(key, '')} One "
                                          f"[[{table}.{key}]] table each; unset = the "
                                          "model's default. For example:")
            items, prefix = [cls()], "# "
        else:
            prefix = ""
        for item in items:
            lines += ["", f"{prefix}[[{table}.{key}]]"]
            for f in dataclasses.fields(cls):
                v = getattr(item, f.name)
                if v is None:
                    lines.append(f"# {f.name} = ...    # {type_name(hints[f.name])}")
                else:
                    lines.append(f"{prefix}{f.name} = {toml_value(v)}")


def job_to_toml(job, settings=None, relative_to=None, header: str | None = None) -> str:
    """The text of a job file for ``job`` and ``settings`` (see :func:`write_job`).

    Parameters
    ----------
    job : WrapJob or TransferJob
    settings : WrapSettings or TransferJobSettings, optional
        Default: the job's own settings if it holds them, else the defaults.
    relative_to : path, optional
        Folder the paths are written relative to (the job file's folder).
    header : str, optional
        Comment lines at the top.

    Returns
    -------
    str
        TOML that :func:`~facewrap.jobs.jobfile.load_job` reads back to equal
        ``job`` and ``settings``.
    """
    kind = kind_of(job)
    if settings is None:
        settings = (getattr(job, kind.settings_field) if kind.settings_field
                    else kind.settings_class())
    folder = None if relative_to is None else Path(os.path.abspath(relative_to))
    lines = [f"# {h}" if h else "#" for h in (header or "").splitlines()]
    lines.append(f"version = {FORMAT_VERSION}")
    job_docs, job_types = attribute_docs(kind.job_class), field_types(kind.job_class)
    paths = {k for k, f in job_keys(None, kind).items() if f.metadata.get("path")}
    for table in JOB_TABLES:
        values = {k: getattr(job, k) for k in job_keys(table, kind)}
        _emit_table(lines, table, values, job_types, job_docs, paths, folder)
    set_types, set_docs = settings_keys(kind), attribute_docs(kind.settings_class)
    values = {k: getattr(settings, k) for k in set_types}
    defaults = {f.name: f.default for f in dataclasses.fields(kind.settings_class)}
    later = _emit_table(lines, kind.name, values, set_types, set_docs, set(), folder,
                        setting_choices(kind), defaults)
    _emit_table_arrays(lines, kind.name, later, set_docs)
    return "\n".join(lines) + "\n"


def _template_job(folder: Path) -> WrapJob:
    return WrapJob(template=str(folder / "template.obj"), scan=str(folder / "scan.obj"),
                   template_landmarks=str(folder / "template_landmarks.txt"),
                   scan_landmarks=str(folder / "scan_landmarks.txt"),
                   output=str(folder / "out" / "fitted.obj"))


def write_job(path, job=None, settings=None) -> None:
    """Write a job file (atomically): every key, with a comment saying what it is.

    Parameters
    ----------
    path : str or os.PathLike
        Destination; its folder is created when missing.
    job : WrapJob or TransferJob, optional
        Default: a wrap of ``template.obj``, ``scan.obj``... beside the job file,
        the result in ``out/fitted.obj`` (the names ``facewrap sample`` writes).
    settings : WrapSettings or TransferJobSettings, optional
        Default: the job's own or the defaults.
    """
    folder = Path(os.path.abspath(path)).parent
    folder.mkdir(parents=True, exist_ok=True)
    job = job or _template_job(folder)
    header = (f"facewrap job file: `facewrap run THIS.toml` {kind_of(job).summary}."
              "\nPaths are relative to this file's folder. A key left out "
              "keeps its default;\nunknown keys are errors. Optional keys are shown "
              "commented out.")
    text = job_to_toml(job, settings, relative_to=folder, header=header)
    with atomic_write(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
