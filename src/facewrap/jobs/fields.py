"""How job dataclasses describe their fields.

A field of a job dataclass (:class:`~facewrap.jobs.WrapJob`,
:class:`~facewrap.jobs.TransferJob`) says in its ``metadata`` which job-file table
it belongs to (``"inputs"`` or ``"outputs"``) and whether it is a path (resolved
against the job file's folder).  Job files (:mod:`facewrap.jobs.jobfile`) and
batches (:mod:`facewrap.batch`) derive their keys from that, so a new field is a
new key there.
"""

from __future__ import annotations

import os
from dataclasses import field, fields

from facewrap.params import expect_instance

__all__ = ["input_field", "output_field", "check_job_fields"]


def input_field(**kw):
    """A dataclass field for an input path (``[inputs]`` table)."""
    return field(metadata={"table": "inputs", "path": True}, **kw)


def output_field(path: bool = True, **kw):
    """A dataclass field of the ``[outputs]`` table (a path unless ``path=False``)."""
    return field(metadata={"table": "outputs", "path": path}, **kw)


def check_job_fields(job, kind: type) -> None:
    """Raise unless ``job`` is a ``kind`` whose path fields hold paths.

    A number where a file belongs failed deep in a reader ("expected str, bytes or
    os.PathLike object", naming no field), and one path where a list of them
    belongs was read as a list of its characters.

    Parameters
    ----------
    job : object
    kind : type
        The job dataclass (:class:`~facewrap.jobs.WrapJob`, ...).

    Raises
    ------
    TypeError
        Naming the field.

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class Job:
    ...     scans: list = input_field()
    >>> check_job_fields(Job(["a.obj"]), Job)
    >>> check_job_fields(Job("a.obj"), Job)
    Traceback (most recent call last):
    ...
    TypeError: Job.scans must be a list of paths, got 'a.obj'
    """
    expect_instance(job, kind, "job")
    for f in fields(job):
        if not f.metadata.get("path"):
            continue
        value = getattr(job, f.name)
        listed = "list" in str(f.type)
        if listed and not isinstance(value, (list, tuple)):
            raise TypeError(f"{kind.__name__}.{f.name} must be a list of paths, got "
                            f"{value!r}")
        # a list's None stands for "none for this one"; a field's for "not given"
        optional = listed or f.default is None
        for item in value if listed else [value]:
            if (item is None and optional) or (isinstance(item, (str, os.PathLike))
                                               and os.fspath(item) != ""):
                continue
            raise TypeError(f"{kind.__name__}.{f.name} must be a path (str or "
                            f"os.PathLike){' or None' if optional else ''}, got {item!r}")
