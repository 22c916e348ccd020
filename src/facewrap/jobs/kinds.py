"""The kinds of job (wrap, transfer, rig): what job files and batches need of each.

A :class:`JobKind` ties a job dataclass to its settings dataclass, the name of
its settings table in a job file (``[wrap]``, ``[transfer]``, ``[rig]``), and the functions
that list its inputs and outputs, check its paths and run it.  Job files
(:mod:`facewrap.jobs.jobfile`) and batches (:mod:`facewrap.batch`) work through
this table only, so a new kind of job is one entry in :data:`JOB_KINDS`.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from typing import Callable

from facewrap.jobs.rig_job import (RigJob, check_rig_job_paths, rig_job_inputs,
                                   rig_job_outputs, run_rig_job)
from facewrap.jobs.transfer_job import (TransferJob, TransferJobSettings,
                                        check_transfer_job_paths, run_transfer_job,
                                        transfer_job_inputs, transfer_job_outputs)
from facewrap.jobs.wrap_job import (WrapJob, check_job_paths, job_inputs, job_outputs,
                                    run_wrap_job)
from facewrap.wrapping import WrapSettings

__all__ = ["JobKind", "JOB_KINDS", "WRAP", "TRANSFER", "RIG", "kind_of"]


@dataclass(frozen=True)
class JobKind:
    """One kind of job.

    Attributes
    ----------
    name : str
        The settings table of its job files (``"wrap"``, ``"transfer"``).
    job_class : type
        Dataclass of the job's files; path fields say their table in ``metadata``.
    settings_class : type
        Dataclass of its settings.
    run : callable
        ``run(job, settings) -> report dict``; writes the outputs.
    inputs, outputs : callable
        ``job -> list of paths`` read / written.
    check_paths : callable
        ``check_paths(job, source=None)``: raises InputError before any work.
    main_output : str
        The field naming the output a done-record sits beside.
    summary : str
        What a job of this kind does, for the header of a job file.
    subject : str
        The input field that tells one job of a batch from the next (a wrap's
        scan), for listings.
    settings_field : str or None
        The job's field holding its settings, when the job holds them.
    """
    name: str
    job_class: type
    settings_class: type
    run: Callable
    inputs: Callable
    outputs: Callable
    check_paths: Callable
    main_output: str
    summary: str
    subject: str
    settings_field: str | None = None

    def output_of(self, job) -> str:
        """The main output path of ``job`` (normalised: no trailing separator)."""
        return os.path.normpath(getattr(job, self.main_output))


def _run_transfer(job: TransferJob, settings: TransferJobSettings) -> dict:
    return run_transfer_job(dataclasses.replace(job, settings=settings))


WRAP = JobKind(name="wrap", job_class=WrapJob, settings_class=WrapSettings,
               run=run_wrap_job, inputs=job_inputs, outputs=job_outputs,
               check_paths=check_job_paths, main_output="output",
               summary="fits the template onto the scan", subject="scan")
TRANSFER = JobKind(name="transfer", job_class=TransferJob,
                   settings_class=TransferJobSettings, run=_run_transfer,
                   inputs=transfer_job_inputs, outputs=transfer_job_outputs,
                   check_paths=check_transfer_job_paths, main_output="out",
                   summary="transfers the source shapes onto the target",
                   subject="source_shapes", settings_field="settings")
# the neutral's wrap settings are the [rig] table; the method is a job field
RIG = JobKind(name="rig", job_class=RigJob, settings_class=WrapSettings, run=run_rig_job,
              inputs=rig_job_inputs, outputs=rig_job_outputs,
              check_paths=check_rig_job_paths, main_output="output",
              summary="builds the person's rig (neutral, shapes, GLB) from their scan",
              subject="scan")
#: Every kind of job, by the name of its settings table.
JOB_KINDS = {k.name: k for k in (WRAP, TRANSFER, RIG)}


def kind_of(job) -> JobKind:
    """The kind of a job instance (WrapJob, TransferJob, RigJob)."""
    for kind in JOB_KINDS.values():
        if isinstance(job, kind.job_class):
            return kind
    raise TypeError(f"not a job: {type(job).__name__}")

