"""Summaries of a batch: one row per job, written as CSV and JSON.

Every job ends as one summary row (:func:`summary_row`): its status ("done",
"skipped", "failed" or "pending"), main output, seconds, one-line error, input
warnings, worker, the unit of its distances and scalar metrics.  :func:`write_summary` writes the rows
atomically as ``<stem>.csv`` (for spreadsheets) and ``<stem>.json`` (everything).
"""

from __future__ import annotations

import csv
import io
import json
import os
from dataclasses import dataclass
from pathlib import Path

from facewrap.batch.manifest import BatchJob
from facewrap.io.atomic import atomic_write

__all__ = ["DONE", "SKIPPED", "FAILED", "PENDING", "STATUSES", "SUMMARY_COLUMNS",
           "METRIC_COLUMNS", "BatchResult", "summary_row", "write_summary",
           "summary_stem"]

#: Statuses of a job in a summary.
DONE, SKIPPED, FAILED, PENDING = "done", "skipped", "failed", "pending"
STATUSES = (DONE, SKIPPED, FAILED, PENDING)
#: Columns of the CSV summary (then one per metric of :data:`METRIC_COLUMNS`).
SUMMARY_COLUMNS = ("index", "name", "status", "output", "seconds", "error", "warnings",
                   "host", "scan_landmarks", "units")
#: Metrics of a wrap report shown as CSV columns (distances in the row's ``units``;
#: jobs of one batch may be in different units, so the unit is a column, not a name).
METRIC_COLUMNS = ("fit_mean", "fit_p95", "fit_max", "fit_coverage", "landmark_mean",
                  "landmark_max")


@dataclass
class BatchResult:
    """What became of every job, in manifest order.

    Attributes
    ----------
    rows : list of dict
        One per job (see :func:`summary_row`).
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


def summary_row(bj: BatchJob, status: str, **values) -> dict:
    """The summary row of a job: ``index``, ``name``, ``status``, ``output``,
    ``seconds``, ``error``, ``warnings``, ``host``, ``scan_landmarks`` (a wrap's
    ``"file"`` or ``"detected"``), ``units`` (of the distances among ``metrics``:
    the job report's), ``metrics`` (``values`` override the empty defaults)."""
    row = {"index": bj.index, "name": bj.name, "status": status,
           "output": getattr(bj.job, bj.kind.main_output), "seconds": 0.0, "error": "",
           "warnings": [], "host": "", "scan_landmarks": "", "units": "", "metrics": {}}
    row.update(values)
    return row


def _csv_text(rows: list[dict]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow([*SUMMARY_COLUMNS, *METRIC_COLUMNS])
    for r in rows:
        writer.writerow([r["index"], r["name"], r["status"], r["output"],
                         f"{r['seconds']:.3f}", r["error"], len(r["warnings"]), r["host"],
                         r.get("scan_landmarks", ""), r.get("units", ""),
                         *(("" if r["metrics"].get(m) is None else repr(r["metrics"][m]))
                           for m in METRIC_COLUMNS)])
    return buf.getvalue()


def write_summary(stem, rows: list[dict], meta: dict | None = None) -> tuple[str, str]:
    """Write ``<stem>.csv`` and ``<stem>.json`` atomically; returns both paths.

    The CSV has :data:`SUMMARY_COLUMNS` and one column per fit metric; the JSON
    holds ``meta``, status counts and the full rows.
    """
    stem = os.fspath(stem)
    os.makedirs(os.path.dirname(os.path.abspath(stem)), exist_ok=True)
    counts = {s: sum(r["status"] == s for r in rows) for s in STATUSES}
    csv_path, json_path = stem + ".csv", stem + ".json"
    with atomic_write(csv_path, "w", encoding="utf-8", newline="") as fh:
        fh.write(_csv_text(rows))
    with atomic_write(json_path, "w", encoding="utf-8") as fh:
        json.dump({"format": "facewrap.batch-summary", "version": 1, **(meta or {}),
                   "counts": counts, "jobs": rows}, fh, indent=1)
    return csv_path, json_path


def summary_stem(manifest, folder=None) -> str:
    """``<folder>/<manifest name>.summary`` (folder: the manifest's by default)."""
    manifest = Path(os.path.abspath(manifest))
    folder = Path(folder) if folder is not None else manifest.parent
    return str(folder / (manifest.stem + ".summary"))
