"""Batches: many wrap jobs from a manifest, in parallel, resumable after a crash.

A **manifest** lists the jobs; a shared **job file** (:mod:`facewrap.jobs.jobfile`)
holds what they have in common (template, landmarks, settings).

* CSV: a header row, then one job per row.  Columns ``scan``, ``scan_landmarks``,
  ``output`` (unless the job file gives them), and optionally ``name``, ``job`` (a
  job file for this row), any other :class:`~facewrap.jobs.wrap_job.WrapJob` field and any
  scalar :class:`~facewrap.wrapping.stages.WrapSettings` field (``smoothing``, or
  ``wrap.smoothing``).  An empty cell means "not overridden"; lines starting with
  ``#`` are comments.
* TOML: optional ``version = 1`` and ``job = "shared.toml"``, then one ``[[jobs]]``
  table per job with the same keys, settings in a ``[jobs.wrap]`` sub-table (where
  ``[[jobs.wrap.stages]]`` can also go).

Relative paths are resolved against the folder of the file that holds them.  Every
problem with the manifest itself (unknown column, bad value, two jobs writing one
file, an output that is some job's input) is an :class:`~facewrap.errors.InputError`
raised before any job runs; a problem with one job's files is that job's failure,
reported in the summary, and never stops the others.

Jobs run in a local process pool (one per core by default) or on a Dask
distributed cluster (:func:`run_batch` with ``dask="local"`` or a scheduler
address): both call :func:`run_one` on each job.  A job that finishes writes its
outputs atomically and then a **done-record** ``OUTPUT.done.json`` holding a
fingerprint of its inputs (sizes and modification times), settings and output
files; on a re-run a job whose record still matches is skipped, anything else is
redone.  After ``kill -9`` there are complete outputs, absent outputs, and
perhaps leftover temporary files, which the re-run removes; never a half-written
output.  Inputs are only read.
"""

from __future__ import annotations

import contextlib
import csv
import glob
import hashlib
import io
import json
import os
import socket
import time
import traceback
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

from facewrap.version import __version__
from facewrap.errors import InputError
from facewrap.jobs import InputWarning, WrapJob, check_job_paths, job_inputs, job_outputs
from facewrap.jobs.jobfile import (_hints, _Where, _job_values, _read_toml, _require_job, _resolve,
                       _settings_values, job_keys, parse_text, read_job_tables,
                       settings_from_dict, settings_keys)
from facewrap.wrapping import WrapSettings

__all__ = ["BatchJob", "BatchResult", "read_manifest", "run_one", "run_batch",
           "fingerprint", "done_record_path", "read_done_record", "write_summary",
           "default_workers", "SUMMARY_COLUMNS"]

#: Statuses of a job in a summary.
DONE, SKIPPED, FAILED, PENDING = "done", "skipped", "failed", "pending"
#: Columns of the CSV summary (then one per metric).
SUMMARY_COLUMNS = ("index", "name", "status", "output", "seconds", "error", "warnings",
                   "host")
_METRICS = ("fit_mean", "fit_p95", "fit_max", "fit_coverage", "landmark_mean",
            "landmark_max")


@dataclass
class BatchJob:
    """One job of a batch: files, settings and where it came from.

    Attributes
    ----------
    index : int
        0-based position in the manifest.
    name : str
        From the ``name`` column, else the output's path relative to the manifest.
    job : WrapJob
        Absolute paths.
    settings : WrapSettings
    source : str
        The manifest.
    line : int or None
        Its line in the manifest.
    """
    index: int
    name: str
    job: WrapJob
    settings: WrapSettings
    source: str = ""
    line: int | None = None


@dataclass
class BatchResult:
    """What became of every job, in manifest order.

    Attributes
    ----------
    rows : list of dict
        One per job: ``index``, ``name``, ``status`` ("done", "skipped", "failed"
        or "pending"), ``output``, ``seconds``, ``error``, ``warnings``, ``host``,
        ``metrics``.
    csv_path, json_path : str or None
        Where the summary was written.
    """
    rows: list
    csv_path: str | None = None
    json_path: str | None = None

    def count(self, status: str) -> int:
        """Number of jobs with ``status``."""
        return sum(r["status"] == status for r in self.rows)

    @property
    def ok(self) -> bool:
        """True when no job failed or is left pending."""
        return all(r["status"] in (DONE, SKIPPED) for r in self.rows)


# -- manifests ---------------------------------------------------------------------------
_ROW_KEYS = ("name", "job")


def _column_kind(name: str) -> tuple[str, str] | None:
    """("job"|"settings"|"meta", key) for a manifest column, None if unknown."""
    if name in _ROW_KEYS:
        return "meta", name
    if name.startswith("wrap.") and name[5:] in settings_keys():
        return "settings", name[5:]
    in_job, in_settings = name in job_keys(), name in settings_keys()
    if in_job and in_settings:  # never today; a clash must be spelled out
        raise ValueError(f"column {name!r} is both a job and a setting key; write "
                         f"wrap.{name} for the setting")
    if in_job:
        return "job", name
    if in_settings:
        return "settings", name
    return None


@dataclass
class _Row:
    line: int | None
    meta: dict
    job: dict
    settings: dict


def _csv_rows(path, text: str) -> list[_Row]:
    lines = text.splitlines()
    content = [(no, ln) for no, ln in enumerate(lines, start=1)
               if ln.strip() and not ln.lstrip().startswith("#")]
    if not content:
        raise InputError("empty manifest: no header row", path)
    reader = csv.reader(io.StringIO("\n".join(ln for _, ln in content)))
    try:
        rows = list(reader)
    except csv.Error as exc:
        raise InputError(f"malformed CSV: {exc}", path, content[reader.line_num - 1][0]
                         if 0 < reader.line_num <= len(content) else None) from None
    header = [h.strip() for h in rows[0]]
    header_line = content[0][0]
    kinds = []
    for col in header:
        try:
            kind = _column_kind(col)
        except ValueError as exc:
            raise InputError(str(exc), path, header_line) from None
        if kind is None:
            known = ", ".join([*_ROW_KEYS, *job_keys(), *settings_keys()])
            raise InputError(f"unknown column {col!r} (known: {known})", path, header_line)
        kinds.append(kind)
    seen = set()
    for col in header:
        if col in seen or (col.startswith("wrap.") and col[5:] in seen):
            raise InputError(f"column {col!r} appears twice", path, header_line)
        seen.add(col[5:] if col.startswith("wrap.") else col)
    if len(rows) < 2:
        raise InputError("no jobs: the manifest has a header but no rows", path)
    folder = Path(os.path.abspath(path)).parent
    job_types = _hints(WrapJob)
    set_types = settings_keys()
    out = []
    for (no, _), cells in zip(content[1:], rows[1:]):
        if len(cells) != len(header):
            raise InputError(f"row has {len(cells)} cells but the header has "
                             f"{len(header)}", path, no)
        row = _Row(no, {}, {}, {})
        for (kind, key), cell in zip(kinds, cells):
            cell = cell.strip()
            if not cell:
                continue
            try:
                if kind == "meta":
                    row.meta[key] = cell
                elif kind == "job":
                    value = parse_text(cell, job_types[key], key)
                    if job_keys()[key].metadata.get("path"):
                        value = _resolve(value, folder)
                    row.job[key] = value
                else:
                    row.settings[key] = parse_text(cell, set_types[key], key)
            except ValueError as exc:
                raise InputError(str(exc), path, no) from None
        out.append(row)
    return out


def _toml_rows(path, data: dict, text: str) -> tuple[list[_Row], str | None]:
    where = _Where(path, text)
    folder = Path(os.path.abspath(path)).parent
    for key in data:
        if key not in ("version", "job", "jobs"):
            raise where.error(f"unknown key {key!r} (a TOML manifest has version, job "
                              "and [[jobs]])", "", key)
    if data.get("version", 1) != 1 or isinstance(data.get("version"), bool):
        raise where.error(f"unknown manifest version {data['version']!r}", "", "version")
    shared = data.get("job")
    if shared is not None:
        if not isinstance(shared, str) or not shared:
            raise where.error("'job' must be the path of a job file", "", "job")
        shared = _resolve(shared, folder)
    items = data.get("jobs")
    if not isinstance(items, list) or not items:
        raise InputError("no jobs: add one [[jobs]] table per job", path)
    out = []
    for k, item in enumerate(items):
        line = where.line("jobs", None, k)
        if not isinstance(item, dict):
            raise InputError("'jobs' must be an array of tables ([[jobs]])", path, line)
        row = _Row(line, {}, {}, {})
        job_part = {}
        for key, value in item.items():
            if key in _ROW_KEYS:
                if not isinstance(value, str) or not value:
                    raise InputError(f"[[jobs]] {key!r} must be a non-empty string",
                                     path, line)
                row.meta[key] = _resolve(value, folder) if key == "job" else value
            elif key == "wrap":
                if not isinstance(value, dict):
                    raise InputError("[[jobs]] 'wrap' must be a table ([jobs.wrap])",
                                     path, line)
                try:
                    row.settings = _settings_values(value, _Where(path), "jobs.wrap")
                except InputError as exc:
                    raise InputError(f"job {k + 1}: {exc.problem}", path, line) from None
            elif key in settings_keys():
                raise InputError(f"[[jobs]] setting {key!r} goes in a [jobs.wrap] table",
                                 path, line)
            else:
                job_part[key] = value
        try:
            row.job = _job_values(job_part, "jobs", _Where(path), folder)
        except InputError as exc:
            raise InputError(exc.problem, path, line) from None
        out.append(row)
    return out, shared


def read_manifest(path, job_file=None) -> list[BatchJob]:
    """Read a manifest (CSV or TOML) and the job files it uses into jobs.

    Parameters
    ----------
    path : str or os.PathLike
        ``.csv`` or ``.toml`` (see the module docstring).
    job_file : str or os.PathLike, optional
        Shared job file; wins over a TOML manifest's ``job`` key.

    Returns
    -------
    list of BatchJob
        In manifest order, paths absolute.

    Raises
    ------
    InputError
        Naming the manifest or job file and line.
    """
    from facewrap.io.files import read_file_bytes
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext == ".toml":
        data, text = _read_toml(path)
        rows, shared = _toml_rows(path, data, text)
    elif ext in (".csv", ".txt", ".tsv"):
        raw = read_file_bytes(path, text=True)
        try:
            text = raw.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise InputError(f"not UTF-8 text (byte {exc.start})", path) from None
        rows, shared = _csv_rows(path, text), None
    else:
        raise InputError(f"unknown manifest format {ext or '(no extension)'!r}; use "
                         ".csv or .toml", path)
    shared = os.fspath(job_file) if job_file is not None else shared
    base_job, base_settings = read_job_tables(shared) if shared else ({}, {})
    cache: dict[str, tuple[dict, dict]] = {}
    folder = Path(os.path.abspath(path)).parent
    jobs: list[BatchJob] = []
    for k, row in enumerate(rows):
        job_vals, set_vals = dict(base_job), dict(base_settings)
        if "job" in row.meta:
            own = _resolve(row.meta["job"], folder)
            if own not in cache:
                cache[own] = read_job_tables(own)
            job_vals.update(cache[own][0])
            set_vals.update(cache[own][1])
        job_vals.update(row.job)
        set_vals.update(row.settings)
        where = f"job {k + 1}: "
        try:
            job = _require_job(job_vals, path, where)
        except InputError as exc:
            raise InputError(exc.problem + " (give it in the manifest or the job file)",
                             path, row.line) from None
        try:
            check_job_paths(job)
        except InputError as exc:
            raise InputError(where + exc.problem, path, row.line) from None
        name = row.meta.get("name") or os.path.relpath(job.output, folder)
        jobs.append(BatchJob(k, name, job, settings_from_dict(set_vals), path, row.line))
    _check_batch(jobs, path)
    return jobs


def _check_batch(jobs: list[BatchJob], path) -> None:
    """No two jobs write one file; no job writes another's input; names unique."""
    writers: dict[str, BatchJob] = {}
    for bj in jobs:
        for out in job_outputs(bj.job) + [done_record_path(bj.job)]:
            key = os.path.realpath(out)
            if key in writers:
                other = writers[key]
                raise InputError(f"jobs {other.index + 1} (line {other.line}) and "
                                 f"{bj.index + 1} both write {out!r}", path, bj.line)
            writers[key] = bj
    for bj in jobs:
        for inp in job_inputs(bj.job):
            key = os.path.realpath(inp)
            if key in writers:
                other = writers[key]
                raise InputError(f"job {other.index + 1} (line {other.line}) writes "
                                 f"{inp!r}, an input of job {bj.index + 1}; inputs are "
                                 "never overwritten", path, bj.line)
    names: dict[str, BatchJob] = {}
    for bj in jobs:
        if bj.name in names:
            raise InputError(f"two jobs are named {bj.name!r} (lines "
                             f"{names[bj.name].line} and {bj.line})", path, bj.line)
        names[bj.name] = bj


# -- done-records --------------------------------------------------------------------------
def done_record_path(job: WrapJob) -> str:
    """``OUTPUT.done.json``: the record that ``job`` finished."""
    return job.output + ".done.json"


def _stat(path) -> dict:
    """Size and modification time of a file, or of every file in a folder."""
    try:
        if os.path.isdir(path):
            return {os.path.relpath(p, path): _stat(p)
                    for p in sorted(glob.glob(os.path.join(glob.escape(path), "**", "*"),
                                              recursive=True)) if os.path.isfile(p)}
        st = os.stat(path)
    except OSError:
        return {"missing": True}
    return {"size": st.st_size, "mtime_ns": st.st_mtime_ns}


def settings_digest(settings: WrapSettings) -> str:
    """SHA-256 of the settings (canonical JSON)."""
    text = json.dumps(asdict(settings), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def fingerprint(job: WrapJob, settings: WrapSettings) -> dict:
    """What a finished job depends on: inputs (sizes, mtimes), job, settings, version.

    Two runs with equal fingerprints give the same outputs, so a done-record with
    the current fingerprint means the job need not run again.
    """
    return {"facewrap": __version__,
            "job": {k: v for k, v in asdict(job).items() if v is not None},
            "settings": settings_digest(settings),
            "inputs": {p: _stat(p) for p in job_inputs(job)}}


def _sha256(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_done_record(job: WrapJob) -> dict | None:
    """The job's done-record, or None when absent or unreadable."""
    try:
        with open(done_record_path(job), encoding="utf-8") as fh:
            rec = json.load(fh)
    except (OSError, ValueError):
        return None
    return rec if isinstance(rec, dict) and rec.get("format") == "facewrap.done" else None


def _record_matches(rec: dict | None, fp: dict) -> bool:
    """The record is for this fingerprint and its outputs are still as written."""
    if rec is None or rec.get("fingerprint") != fp:
        return False
    outputs = rec.get("outputs")
    if not isinstance(outputs, dict) or not outputs:
        return False
    for path, st in outputs.items():
        now = _stat(path)
        if now.get("size") != st.get("size") or now.get("mtime_ns") != st.get("mtime_ns"):
            return False
    return True


def _write_done_record(job: WrapJob, fp: dict, report: dict, seconds: float) -> None:
    from facewrap.io.atomic import atomic_write
    outputs = {}
    for p in job_outputs(job):
        outputs[p] = {**_stat(p), "sha256": _sha256(p)}
    rec = {"format": "facewrap.done", "version": 1, "fingerprint": fp,
           "outputs": outputs, "seconds": seconds,
           "host": f"{socket.gethostname()}:{os.getpid()}",
           "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
           "metrics": _scalar_metrics(report.get("metrics", {})),
           "model": report.get("settings", {}).get("model"),
           "warnings": report.get("warnings", [])}
    with atomic_write(done_record_path(job), "w", encoding="utf-8") as fh:
        json.dump(rec, fh, indent=1)


def _scalar_metrics(metrics: dict) -> dict:
    return {k: v for k, v in metrics.items() if isinstance(v, (int, float))}


def _remove_stale(job: WrapJob) -> None:
    """Delete a stale done-record and temporary files a killed run left behind."""
    with contextlib.suppress(FileNotFoundError):
        os.unlink(done_record_path(job))
    for out in job_outputs(job) + [done_record_path(job)]:
        folder, base = os.path.split(os.path.abspath(out))
        for tmp in glob.glob(os.path.join(glob.escape(folder),
                                          ".tmp-*-" + glob.escape(base))):
            with contextlib.suppress(OSError):
                os.unlink(tmp)


# -- running ---------------------------------------------------------------------------------
def _row(bj: BatchJob, status: str, **kw) -> dict:
    row = {"index": bj.index, "name": bj.name, "status": status,
           "output": bj.job.output, "seconds": 0.0, "error": "", "warnings": [],
           "host": "", "metrics": {}}
    row.update(kw)
    return row


def _skip_row(bj: BatchJob, fp: dict | None = None) -> dict | None:
    """The summary row of a job whose done-record matches, else None."""
    rec = read_done_record(bj.job)
    if rec is None or not _record_matches(rec, fp or fingerprint(bj.job, bj.settings)):
        return None
    return _row(bj, SKIPPED, seconds=rec.get("seconds", 0.0), host=rec.get("host", ""),
                metrics=rec.get("metrics", {}), warnings=rec.get("warnings", []))


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
    host = f"{socket.gethostname()}:{os.getpid()}"
    try:
        fp = fingerprint(bj.job, bj.settings)
        skipped = _skip_row(bj, fp)
        if skipped is not None:
            return skipped
        _remove_stale(bj.job)
        for out in job_outputs(bj.job):
            os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
        from facewrap.jobs import run_wrap_job
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", InputWarning)  # they are in the report
            report = run_wrap_job(bj.job, bj.settings)
        seconds = time.perf_counter() - t0
        _write_done_record(bj.job, fp, report, seconds)
        return _row(bj, DONE, seconds=seconds, host=host,
                    metrics=_scalar_metrics(report.get("metrics", {})),
                    warnings=report.get("warnings", []))
    except InputError as exc:
        error = str(exc)
    except FileNotFoundError as exc:
        error = f"{exc.filename}: no such file"
    except Exception as exc:  # noqa: BLE001 - one job's failure must not stop a batch
        frame = traceback.extract_tb(exc.__traceback__)[-1]
        error = (f"{type(exc).__name__}: {exc} (in {os.path.basename(frame.filename)}:"
                 f"{frame.lineno})")
    return _row(bj, FAILED, seconds=time.perf_counter() - t0, host=host,
                error=" ".join(error.split()))


def default_workers() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


@contextlib.contextmanager
def _single_threaded_blas():
    """Workers of a pool get one BLAS/OpenMP thread each (as Dask's do)."""
    names = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
    old = {n: os.environ.get(n) for n in names}
    for n in names:
        os.environ.setdefault(n, "1")
    try:
        yield
    finally:
        for n, v in old.items():
            if v is None:
                os.environ.pop(n, None)
            else:
                os.environ[n] = v


_STARTED = None


def _pool_init(started) -> None:
    global _STARTED
    _STARTED = started


def _run_tracked(func, bj: BatchJob) -> dict:
    """Mark the job started in shared memory (survives the worker's death)."""
    if _STARTED is not None:
        _STARTED[bj.index] = 1
    return func(bj)


def _pool_context():
    """A fork server with facewrap imported once (workers start in milliseconds);
    spawn where there is none.  Never plain fork: the parent may hold threads."""
    import multiprocessing
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["facewrap.batch.runner", "facewrap.jobs.wrap_job", "facewrap.wrapping.stages"])
        return ctx
    return multiprocessing.get_context("spawn")


def _run_pool(jobs, workers, report, func=None):
    """Process pool; a worker that dies (crash, out of memory) fails only its job.

    When the pool breaks, the jobs that had started and not finished are retried
    one at a time in a single-worker pool (a second death marks that job failed)
    and the others go back to a new pool.
    """
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool
    func = func or run_one
    ctx = _pool_context()
    started = ctx.RawArray("b", max((bj.index for bj in jobs), default=0) + 1)
    todo, isolated, idle_breaks = list(jobs), [], 0
    while todo or isolated:
        if isolated:
            batch, alone = [isolated.pop(0)], True
        else:
            batch, todo, alone = todo, [], False
        finished = set()
        for bj in batch:
            started[bj.index] = 0
        with _single_threaded_blas():
            pool = ProcessPoolExecutor(max_workers=1 if alone else min(workers, len(batch)),
                                       mp_context=ctx, initializer=_pool_init,
                                       initargs=(started,))
            futures = {pool.submit(_run_tracked, func, bj): bj for bj in batch}
        try:
            for fut in as_completed(futures):
                row = fut.result()
                finished.add(row["index"])
                report(row)
        except BrokenProcessPool:
            if alone:
                report(_row(batch[0], FAILED, error="the worker process died (crash or "
                            "out of memory) while running this job"))
                continue
            left = [bj for bj in batch if bj.index not in finished]
            isolated += [bj for bj in left if started[bj.index]]
            todo = [bj for bj in left if not started[bj.index]]
            idle_breaks = 0 if len(todo) < len(left) else idle_breaks + 1
            if idle_breaks >= 2:  # workers die before any job starts
                for bj in todo:
                    report(_row(bj, FAILED, error="worker processes die on start"))
                todo = []
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _run_dask(jobs, address, workers, report):
    from distributed import Client, LocalCluster, as_completed
    cluster = None
    if address == "local":
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    elif isinstance(address, str):
        client = Client(address)
    else:  # a Client given by the caller
        client, address = address, None
    try:
        futures = {}
        for bj in jobs:
            fut = client.submit(run_one, bj, key=f"facewrap-job-{bj.index}-{os.getpid()}"
                                f"-{time.time_ns()}", pure=False)
            futures[fut] = bj
        for fut in as_completed(list(futures)):
            bj = futures[fut]
            try:
                report(fut.result())
            except Exception as exc:  # noqa: BLE001 - worker lost, cancelled...
                report(_row(bj, FAILED, error=f"{type(exc).__name__} on the Dask "
                            f"cluster: {' '.join(str(exc).split())}"))
    finally:
        if address is not None:
            client.close()
        if cluster is not None:
            cluster.close()


def run_batch(jobs: list[BatchJob], *, workers: int | None = None, dask=None,
              summary: str | os.PathLike | None = None, on_result=None,
              manifest: str | None = None) -> BatchResult:
    """Run jobs (skipping finished ones) and write one summary.

    Parameters
    ----------
    jobs : list of BatchJob
        From :func:`read_manifest`.
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
    rows = {bj.index: _row(bj, PENDING) for bj in jobs}
    meta = {"manifest": manifest, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "workers": workers, "engine": engine,
            "facewrap": __version__}
    result = BatchResult([])
    last = [time.monotonic()]

    def report(row):
        rows[row["index"]] = row
        if on_result is not None:
            on_result(row)
        if summary is not None and time.monotonic() - last[0] > 5.0:
            write_summary(summary, [rows[i] for i in sorted(rows)], meta)
            last[0] = time.monotonic()

    todo = []
    for bj in jobs:  # finished jobs are skipped here, without starting any worker
        skipped = _skip_row(bj)
        if skipped is None:
            todo.append(bj)
        else:
            report(skipped)
    if not todo:
        pass
    elif dask is not None:
        _run_dask(todo, dask, workers, report)
    elif workers == 1 or len(todo) == 1:
        for bj in todo:
            report(run_one(bj))
    else:
        _run_pool(todo, workers, report)
    result.rows = [rows[i] for i in sorted(rows)]
    meta["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    if summary is not None:
        result.csv_path, result.json_path = write_summary(summary, result.rows, meta)
    return result


def write_summary(stem, rows: list[dict], meta: dict | None = None) -> tuple[str, str]:
    """Write ``<stem>.csv`` and ``<stem>.json`` atomically; returns both paths.

    The CSV has :data:`SUMMARY_COLUMNS` and one column per fit metric; the JSON
    holds ``meta``, status counts and the full rows.
    """
    from facewrap.io.atomic import atomic_write
    stem = os.fspath(stem)
    os.makedirs(os.path.dirname(os.path.abspath(stem)), exist_ok=True)
    counts = {s: sum(r["status"] == s for r in rows) for s in (DONE, SKIPPED, FAILED,
                                                              PENDING)}
    csv_path, json_path = stem + ".csv", stem + ".json"
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow([*SUMMARY_COLUMNS, *_METRICS])
    for r in rows:
        writer.writerow([r["index"], r["name"], r["status"], r["output"],
                         f"{r['seconds']:.3f}", r["error"], len(r["warnings"]), r["host"],
                         *(("" if r["metrics"].get(m) is None else repr(r["metrics"][m]))
                           for m in _METRICS)])
    with atomic_write(csv_path, "w", encoding="utf-8", newline="") as fh:
        fh.write(buf.getvalue())
    with atomic_write(json_path, "w", encoding="utf-8") as fh:
        json.dump({"format": "facewrap.batch.runner-summary", "version": 1, **(meta or {}),
                   "counts": counts, "jobs": rows}, fh, indent=1)
    return csv_path, json_path


def summary_stem(manifest, folder=None) -> str:
    """``<folder>/<manifest name>.summary`` (folder: the manifest's by default)."""
    manifest = Path(os.path.abspath(manifest))
    folder = Path(folder) if folder is not None else manifest.parent
    return str(folder / (manifest.stem + ".summary"))

