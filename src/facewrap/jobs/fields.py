"""How job dataclasses describe their fields, and the path check every job shares.

A field of a job dataclass (:class:`~facewrap.jobs.WrapJob`,
:class:`~facewrap.jobs.TransferJob`) says in its ``metadata`` which job-file table
it belongs to (``"inputs"`` or ``"outputs"``) and whether it is a path (resolved
against the job file's folder).  Job files (:mod:`facewrap.jobs.jobfile`) and
batches (:mod:`facewrap.batch`) derive their keys from that, so a new field is a
new key there.
"""

from __future__ import annotations

import os
from dataclasses import field

from facewrap.errors import InputError

__all__ = ["input_field", "output_field", "check_outputs_apart"]


def input_field(**kw):
    """A dataclass field for an input path (``[inputs]`` table)."""
    return field(metadata={"table": "inputs", "path": True}, **kw)


def output_field(path: bool = True, **kw):
    """A dataclass field of the ``[outputs]`` table (a path unless ``path=False``)."""
    return field(metadata={"table": "outputs", "path": path}, **kw)


def check_outputs_apart(outputs: list[str], inputs: list[str], source=None) -> None:
    """No output is an input, and no two outputs are the same file.

    Parameters
    ----------
    outputs, inputs : list of path
    source : path, optional
        Named in errors (job file, manifest); default the offending output.

    Raises
    ------
    InputError
    """
    ins = {os.path.realpath(p) for p in inputs}
    seen = set()
    for o in outputs:
        real = os.path.realpath(o)
        if real in ins:
            raise InputError(f"output {o!r} is also an input; inputs are never "
                             "overwritten", source or o)
        if real in seen:
            raise InputError(f"two outputs of one job are the same file {o!r}",
                             source or o)
        seen.add(real)
