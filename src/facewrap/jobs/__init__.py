"""Jobs: one unit of work from files to files (a wrap, a transfer), and job files.

* :mod:`.wrap_job` — :class:`WrapJob` and :func:`run_wrap_job`;
* :mod:`.transfer_job` — :class:`TransferJob` and :func:`run_transfer_job`;
* :mod:`.rig_job` — :class:`RigJob` and :func:`run_rig_job` (a person's rig);
* :mod:`.kinds` — what job files and batches need of each kind of job;
* :mod:`.jobfile` — reading TOML job files; :mod:`.jobfile_writer` — writing them;
* :mod:`.values` — checking and converting values; :mod:`.toml_text` — TOML text.
"""

from facewrap.lazy import lazy_exports

#: public name -> the module that defines it, imported on first use
_PUBLIC = {
    "load_job": "facewrap.jobs.jobfile",
    "read_job_tables": "facewrap.jobs.jobfile",
    "job_to_toml": "facewrap.jobs.jobfile_writer",
    "write_job": "facewrap.jobs.jobfile_writer",
    "JOB_KINDS": "facewrap.jobs.kinds",
    "TRANSFER": "facewrap.jobs.kinds",
    "RIG": "facewrap.jobs.kinds",
    "RigJob": "facewrap.jobs.rig_job",
    "run_rig_job": "facewrap.jobs.rig_job",
    "check_rig_job_paths": "facewrap.jobs.rig_job",
    "rig_job_inputs": "facewrap.jobs.rig_job",
    "rig_job_outputs": "facewrap.jobs.rig_job",
    "WRAP": "facewrap.jobs.kinds",
    "JobKind": "facewrap.jobs.kinds",
    "kind_of": "facewrap.jobs.kinds",
    "TransferJob": "facewrap.jobs.transfer_job",
    "TransferJobSettings": "facewrap.jobs.transfer_job",
    "check_transfer_job_paths": "facewrap.jobs.transfer_job",
    "run_transfer_job": "facewrap.jobs.transfer_job",
    "transfer_job_inputs": "facewrap.jobs.transfer_job",
    "transfer_job_outputs": "facewrap.jobs.transfer_job",
    "InputWarning": "facewrap.errors",
    "WrapJob": "facewrap.jobs.wrap_job",
    "check_job_paths": "facewrap.jobs.wrap_job",
    "job_inputs": "facewrap.jobs.wrap_job",
    "job_outputs": "facewrap.jobs.wrap_job",
    "read_mesh_landmarks": "facewrap.jobs.wrap_job",
    "run_wrap_job": "facewrap.jobs.wrap_job",
}
lazy_exports(__name__, _PUBLIC)

__all__ = [
    # wrap jobs
    "WrapJob", "run_wrap_job", "InputWarning", "check_job_paths", "job_inputs",
    "job_outputs", "read_mesh_landmarks",
    # transfer jobs
    "TransferJob", "TransferJobSettings", "run_transfer_job", "check_transfer_job_paths",
    "transfer_job_inputs", "transfer_job_outputs",
    # rig jobs
    "RigJob", "run_rig_job", "check_rig_job_paths", "rig_job_inputs", "rig_job_outputs",
    # kinds of job
    "JobKind", "JOB_KINDS", "WRAP", "TRANSFER", "RIG", "kind_of",
    # job files
    "load_job", "read_job_tables", "job_to_toml", "write_job",
]
