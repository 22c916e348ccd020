"""Batches of jobs: manifests, a local process pool or Dask, resume after a crash.

See :mod:`facewrap.batch.runner` for how the pieces fit.
"""

from facewrap.batch.engines import default_workers
from facewrap.batch.manifest import BatchJob, done_record_path, read_manifest
from facewrap.batch.records import fingerprint, read_done_record, record_matches
from facewrap.batch.runner import run_batch, run_one
from facewrap.batch.summary import (DONE, FAILED, PENDING, SKIPPED, SUMMARY_COLUMNS,
                                    BatchResult, summary_stem, write_summary)

__all__ = ["BatchJob", "BatchResult", "read_manifest", "run_one", "run_batch",
           "fingerprint", "done_record_path", "read_done_record", "record_matches",
           "write_summary", "summary_stem", "default_workers", "SUMMARY_COLUMNS",
           "DONE", "SKIPPED", "FAILED", "PENDING"]
