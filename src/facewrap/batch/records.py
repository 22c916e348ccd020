"""Done-records: how a re-run of a batch knows which jobs are finished.

A job that finishes writes its outputs atomically and then a **done-record**
``OUTPUT.done.json`` holding a :func:`fingerprint` of its inputs (sizes and
modification times), job, settings and facewrap version, and the size, time and
SHA-256 of each output.  On a re-run a job whose record still matches
(:func:`record_matches`) is skipped; anything else is redone, after
:func:`remove_stale` has deleted the old record and any temporary files a killed
run left behind.  Outputs may be files or folders (a transfer's shapes).
"""

from __future__ import annotations

import contextlib
import glob
import hashlib
import json
import os
import shutil
import socket
import time
from dataclasses import asdict

from facewrap.batch.manifest import done_record_path
from facewrap.io.atomic import atomic_write
from facewrap.io.paths import STAGE_PREFIX, hidden_name
from facewrap.jobs import kind_of
from facewrap.version import __version__

__all__ = ["path_stat", "settings_digest", "fingerprint", "read_done_record",
           "record_matches", "write_done_record", "remove_stale", "scalar_metrics",
           "worker_name"]

#: ``format`` of a done-record file.
RECORD_FORMAT = "facewrap.done"


def worker_name() -> str:
    """``host:pid`` of this process, as records and summaries name a worker."""
    return f"{socket.gethostname()}:{os.getpid()}"


def path_stat(path) -> dict:
    """Size and modification time of a file, or of every file in a folder.

    Returns
    -------
    dict
        ``{"size", "mtime_ns"}`` for a file; relative path → that, for a folder;
        ``{"missing": True}`` when absent.
    """
    try:
        if os.path.isdir(path):
            return {os.path.relpath(p, path): path_stat(p)
                    for p in sorted(glob.glob(os.path.join(glob.escape(path), "**", "*"),
                                              recursive=True)) if os.path.isfile(p)}
        st = os.stat(path)
    except OSError:
        return {"missing": True}
    return {"size": st.st_size, "mtime_ns": st.st_mtime_ns}


def settings_digest(settings) -> str:
    """SHA-256 of the settings (canonical JSON)."""
    text = json.dumps(asdict(settings), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def fingerprint(job, settings) -> dict:
    """What a finished job depends on: inputs (sizes, mtimes), job, settings, version.

    Two runs with equal fingerprints give the same outputs, so a done-record with
    the current fingerprint means the job need not run again.
    """
    return {"facewrap": __version__,
            "job": {k: v for k, v in asdict(job).items() if v is not None},
            "settings": settings_digest(settings),
            "inputs": {p: path_stat(p) for p in kind_of(job).inputs(job)}}


def _sha256(path) -> str:
    """SHA-256 of a file, or of a folder's files in name order."""
    h = hashlib.sha256()
    files = ([path] if not os.path.isdir(path) else
             sorted(glob.glob(os.path.join(glob.escape(path), "**", "*"), recursive=True)))
    for name in files:
        if not os.path.isfile(name):
            continue
        with open(name, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


def read_done_record(job) -> dict | None:
    """The job's done-record, or None when absent or unreadable."""
    try:
        with open(done_record_path(job), encoding="utf-8") as fh:
            rec = json.load(fh)
    except (OSError, ValueError):
        return None
    return rec if isinstance(rec, dict) and rec.get("format") == RECORD_FORMAT else None


def _unchanged(path, recorded: dict) -> bool:
    now = path_stat(path)
    if "files" in recorded:  # a folder
        return recorded["files"] == now
    return (now.get("size") == recorded.get("size")
            and now.get("mtime_ns") == recorded.get("mtime_ns"))


def record_matches(rec: dict | None, fp: dict) -> bool:
    """True when the record is for this fingerprint and its outputs are still as written.

    Parameters
    ----------
    rec : dict or None
        From :func:`read_done_record`.
    fp : dict
        The job's current :func:`fingerprint`.
    """
    if rec is None or rec.get("fingerprint") != fp:
        return False
    outputs = rec.get("outputs")
    if not isinstance(outputs, dict) or not outputs:
        return False
    return all(isinstance(st, dict) and _unchanged(path, st)
               for path, st in outputs.items())


def scalar_metrics(metrics: dict) -> dict:
    """The numbers of a report's metrics (the rest stays in the report)."""
    return {k: v for k, v in metrics.items() if isinstance(v, (int, float))}


def write_done_record(job, fp: dict, report: dict, seconds: float) -> None:
    """Write the done-record of a finished job (atomically, after its outputs)."""
    outputs = {}
    for p in kind_of(job).outputs(job):
        st = path_stat(p)
        outputs[p] = ({"files": st} if os.path.isdir(p) else st) | {"sha256": _sha256(p)}
    rec = {"format": RECORD_FORMAT, "version": 1, "fingerprint": fp,
           "outputs": outputs, "seconds": seconds, "host": worker_name(),
           "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
           "metrics": scalar_metrics(report.get("metrics", {})),
           "model": report.get("settings", {}).get("model"),
           "warnings": report.get("warnings", []),
           "scan_landmarks": report.get("scan_landmarks_source", ""),
           "units": report.get("units", "")}   # of the metrics' distances
    with atomic_write(done_record_path(job), "w", encoding="utf-8") as fh:
        json.dump(rec, fh, indent=1)


def remove_stale(job) -> None:
    """Delete a stale done-record and the temporary and staged files (or staged
    folders) a killed run left behind: a worker stopped by Ctrl-C or SIGKILL
    between staging an output and moving it into place."""
    record = done_record_path(job)
    with contextlib.suppress(FileNotFoundError):
        os.unlink(record)
    for out in kind_of(job).outputs(job) + [record]:
        folder, base = os.path.split(os.path.abspath(out))
        for pattern in _leftover_patterns(folder, base):
            for tmp in glob.glob(os.path.join(glob.escape(folder), pattern)):
                if os.path.isdir(tmp) and not os.path.islink(tmp):
                    shutil.rmtree(tmp, ignore_errors=True)
                else:
                    with contextlib.suppress(OSError):
                        os.unlink(tmp)


def _leftover_patterns(folder: str, base: str) -> list[str]:
    """Glob patterns of the hidden names output ``base`` is written under in
    ``folder``: temporary, staged, and a staged file's temporary."""
    # (a staged name's token is 8 hex digits: "*" could reach into another output's
    # name that ends in this one's; a long name is written shortened: hidden_name)
    token = "?" * 8 + "-"
    patterns = [".tmp-*-" + glob.escape(base)]
    for prefix in (".tmp-" + token, STAGE_PREFIX + token,
                   ".tmp-" + token + STAGE_PREFIX + token):
        name = hidden_name(prefix, base, folder)[len(prefix):]
        patterns.append(prefix + glob.escape(name))
    return patterns

