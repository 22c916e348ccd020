"""Batches: many jobs from a manifest, in parallel, resumable after a crash.

The pieces, in the order a batch uses them:

* :mod:`.manifest` — read the manifest and job files into :class:`BatchJob`\\ s,
  checked before any job runs;
* :mod:`.records` — done-records, so a re-run skips finished jobs;
* :mod:`.engines` — a local process pool or a Dask cluster;
* :mod:`.summary` — one row per job, written as CSV and JSON.

:func:`run_one` runs (or skips) one job and never raises for a failing job: a
problem with one job's files is that job's failure, reported in the summary, and
never stops the others.  After ``kill -9`` there are complete outputs, absent
outputs, and perhaps leftover temporary files, which the re-run removes; never a
half-written output.  Inputs are only read.
"""

from __future__ import annotations

import os
import time
import traceback
import warnings

from facewrap.batch.engines import default_workers, run_in_pool, run_on_dask
from facewrap.batch.manifest import BatchJob
from facewrap.batch.records import (fingerprint, read_done_record, record_matches,
                                    remove_stale, scalar_metrics, worker_name,
                                    write_done_record)
from facewrap.batch.summary import (DONE, FAILED, PENDING, SKIPPED, BatchResult,
                                    summary_row, write_summary)
from facewrap.errors import InputError
from facewrap.jobs import InputWarning
from facewrap.version import __version__

__all__ = ["run_one", "run_batch", "skipped_row"]

#: Seconds between rewrites of the summary during a long run.
SUMMARY_INTERVAL = 5.0


def skipped_row(bj: BatchJob, fp: dict | None = None) -> dict | None:
    """The summary row of a job whose done-record matches (it is finished), else None."""
    rec = read_done_record(bj.job)
    if rec is None or not record_matches(rec, fp or fingerprint(bj.job, bj.settings)):
        return None
    return summary_row(bj, SKIPPED, seconds=rec.get("seconds", 0.0),
                       host=rec.get("host", ""), metrics=rec.get("metrics", {}),
                       warnings=rec.get("warnings", []),
                       scan_landmarks=rec.get("scan_landmarks", ""),
                       units=rec.get("units", ""))


def _one_line_error(exc: BaseException) -> str:
    if isinstance(exc, InputError):
        error = str(exc)
    elif isinstance(exc, FileNotFoundError):
        error = f"{exc.filename}: no such file"
    else:
        frame = traceback.extract_tb(exc.__traceback__)[-1]
        error = (f"{type(exc).__name__}: {exc} (in {os.path.basename(frame.filename)}:"
                 f"{frame.lineno})")
    return " ".join(error.split())


def run_one(bj: BatchJob) -> dict:
    """Run (or skip) one job; never raises for a failing job.

    Parameters
    ----------
    bj : BatchJob

    Returns
    -------
    dict
        A summary row: ``status`` is "skipped" when a matching done-record was
        found, "done" after a successful run (outputs and then the done-record
        written atomically), "failed" with ``error`` (one line) otherwise.
    """
    t0 = time.perf_counter()
    try:
        fp = fingerprint(bj.job, bj.settings)
        skipped = skipped_row(bj, fp)
        if skipped is not None:
            return skipped
        remove_stale(bj.job)
        for out in bj.kind.outputs(bj.job):
            os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", InputWarning)  # they are in the report
            report = bj.kind.run(bj.job, bj.settings)
        seconds = time.perf_counter() - t0
        write_done_record(bj.job, fp, report, seconds)
        return summary_row(bj, DONE, seconds=seconds, host=worker_name(),
                           metrics=scalar_metrics(report.get("metrics", {})),
                           warnings=report.get("warnings", []),
                           scan_landmarks=report.get("scan_landmarks_source", ""),
                           units=report.get("units", ""))
    except Exception as exc:  # noqa: BLE001 - one job's failure must not stop a batch
        return summary_row(bj, FAILED, seconds=time.perf_counter() - t0,
                           host=worker_name(), error=_one_line_error(exc))


def run_batch(jobs: list[BatchJob], *, workers: int | None = None, dask=None,
              summary: str | os.PathLike | None = None, on_result=None,
              manifest: str | None = None) -> BatchResult:
    """Run jobs (skipping finished ones) and write one summary.

    Parameters
    ----------
    jobs : list of BatchJob
        From :func:`~facewrap.batch.manifest.read_manifest`.
    workers : int, optional
        Parallel jobs; default one per core (at most one per job).  1 runs the jobs
        one after another in this process.
    dask : str or distributed.Client, optional
        ``"local"`` (a LocalCluster of ``workers`` processes), a scheduler address
        (``"tcp://host:8786"``) or a connected Client.  Every worker must see the
        same paths.
    summary : path, optional
        Summary file stem: ``<summary>.csv`` and ``<summary>.json`` are written
        atomically (and rewritten during a long run).
    on_result : callable, optional
        Called with each row as jobs finish (progress output).
    manifest : str, optional
        Named in the summary.

    Returns
    -------
    BatchResult
    """
    workers = max(1, min(workers or default_workers(), len(jobs) or 1))
    engine = ("dask" if dask is not None else "serial" if workers == 1 else "processes")
    rows = {bj.index: summary_row(bj, PENDING) for bj in jobs}
    meta = {"manifest": manifest, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "workers": workers, "engine": engine, "facewrap": __version__}
    last = [time.monotonic()]

    def report(row):
        rows[row["index"]] = row
        if on_result is not None:
            on_result(row)
        if summary is not None and time.monotonic() - last[0] > SUMMARY_INTERVAL:
            write_summary(summary, [rows[i] for i in sorted(rows)], meta)
            last[0] = time.monotonic()

    todo = []
    for bj in jobs:  # finished jobs are skipped here, without starting any worker
        skipped = skipped_row(bj)
        if skipped is None:
            todo.append(bj)
        else:
            report(skipped)
    if todo and dask is not None:
        run_on_dask(todo, dask, workers, report, run_one)
    elif todo and (workers == 1 or len(todo) == 1):
        for bj in todo:
            report(run_one(bj))
    elif todo:
        run_in_pool(todo, workers, report, run_one)
    result = BatchResult([rows[i] for i in sorted(rows)])
    meta["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    if summary is not None:
        result.csv_path, result.json_path = write_summary(summary, result.rows, meta)
    return result
