"""Jobs: one unit of work from files to files (a wrap, a transfer), and job files.

* :mod:`.wrap_job` — :class:`WrapJob` and :func:`run_wrap_job`;
* :mod:`.transfer_job` — :class:`TransferJob` and :func:`run_transfer_job`;
* :mod:`.kinds` — what job files and batches need of each kind of job;
* :mod:`.jobfile` — reading TOML job files; :mod:`.jobfile_writer` — writing them;
* :mod:`.values` — checking and converting values; :mod:`.toml_text` — TOML text.
"""

from facewrap.jobs.jobfile import load_job, read_job_tables
from facewrap.jobs.jobfile_writer import job_to_toml, write_job
from facewrap.jobs.kinds import JOB_KINDS, TRANSFER, WRAP, JobKind, kind_of
from facewrap.jobs.transfer_job import (TransferJob, TransferJobSettings,
                                        check_transfer_job_paths, run_transfer_job,
                                        transfer_job_inputs, transfer_job_outputs)
from facewrap.jobs.wrap_job import (InputWarning, WrapJob, check_job_paths, job_inputs,
                                    job_outputs, read_mesh_landmarks, run_wrap_job)

__all__ = [
    # wrap jobs
    "WrapJob", "run_wrap_job", "InputWarning", "check_job_paths", "job_inputs",
    "job_outputs", "read_mesh_landmarks",
    # transfer jobs
    "TransferJob", "TransferJobSettings", "run_transfer_job", "check_transfer_job_paths",
    "transfer_job_inputs", "transfer_job_outputs",
    # kinds of job
    "JobKind", "JOB_KINDS", "WRAP", "TRANSFER", "kind_of",
    # job files
    "load_job", "read_job_tables", "job_to_toml", "write_job",
]
