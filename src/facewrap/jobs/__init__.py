"""Jobs: one unit of work from files to files (a wrap), and the TOML job-file format."""

from facewrap.jobs.jobfile import job_to_toml, load_job, write_job
from facewrap.jobs.wrap_job import InputWarning, WrapJob, check_job_paths, job_inputs, job_outputs, read_mesh_landmarks, run_wrap_job

__all__ = [
    "job_to_toml", "load_job", "write_job", "InputWarning", "WrapJob", "check_job_paths", "job_inputs", "job_outputs", "read_mesh_landmarks", "run_wrap_job",
]
