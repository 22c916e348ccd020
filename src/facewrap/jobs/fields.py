"""How job dataclasses describe their fields.

A field of a job dataclass (:class:`~facewrap.jobs.WrapJob`,
:class:`~facewrap.jobs.TransferJob`) says in its ``metadata`` which job-file table
it belongs to (``"inputs"`` or ``"outputs"``) and whether it is a path (resolved
against the job file's folder).  Job files (:mod:`facewrap.jobs.jobfile`) and
batches (:mod:`facewrap.batch`) derive their keys from that, so a new field is a
new key there.
"""

from __future__ import annotations

from dataclasses import field

__all__ = ["input_field", "output_field"]


def input_field(**kw):
    """A dataclass field for an input path (``[inputs]`` table)."""
    return field(metadata={"table": "inputs", "path": True}, **kw)


def output_field(path: bool = True, **kw):
    """A dataclass field of the ``[outputs]`` table (a path unless ``path=False``)."""
    return field(metadata={"table": "outputs", "path": path}, **kw)
