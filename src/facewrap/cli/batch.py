"""``facewrap batch MANIFEST``: many wrap jobs, in parallel, resumable (parsing only).

Manifests, job files, done-records and summaries are :mod:`facewrap.batch`'s.
Exit status: 0 when every job is done (or was already), 1 when some job failed,
2 when the manifest or job file is wrong (nothing runs then).
"""

from __future__ import annotations

import argparse
import os
import sys

from facewrap.errors import InputError


__all__ = ["register", "cmd_batch"]


def _positive(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError("must be at least 1")
    return n


def _shown(value) -> str:
    """A path, or paths joined by spaces (a transfer's source shapes)."""
    return " ".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value)


def cmd_batch(args) -> int:
    """Read the manifest, run (or list) its jobs, write the summary."""
    # deferred: the other commands (and `facewrap --help`) do not pay for this import
    from facewrap.batch import (FAILED, SKIPPED, fingerprint, read_done_record, read_manifest,
                                record_matches, run_batch, summary_stem)
    from facewrap.io.paths import check_output_paths
    from facewrap.progress import progress
    from facewrap.io.paths import check_outputs_apart
    jobs = read_manifest(args.manifest, job_file=args.job)
    # the manifest and the shared job file are read too: no job may write over them
    check_outputs_apart([p for bj in jobs for p in bj.kind.outputs(bj.job)],
                        [args.manifest, *([args.job] if args.job else [])],
                        source=args.manifest)
    if args.dry_run:
        for bj in jobs:
            done = record_matches(read_done_record(bj.job), fingerprint(bj.job,
                                                                        bj.settings))
            print(f"{bj.index + 1:>4} {'finished' if done else 'to run':<8} {bj.name}: "
                  f"{_shown(getattr(bj.job, bj.kind.subject))} -> "
                  f"{getattr(bj.job, bj.kind.main_output)}")
        return 0
    total, seen = len(jobs), [0]

    def on_result(row):
        seen[0] += 1
        bar.advance()
        if row["status"] == FAILED:
            print(f"facewrap: job {row['name']} failed: {row['error']}", file=sys.stderr)
        elif not args.quiet:
            extra = "" if row["status"] == SKIPPED else f" ({row['seconds']:.1f} s)"
            print(f"[{seen[0]}/{total}] {row['status']} {row['name']}{extra}", flush=True)

    stem = summary_stem(args.manifest, args.summary)
    # the summary is one more output: apart from every job's inputs and outputs
    check_output_paths(files=[stem + ".csv", stem + ".json"],
                       inputs=[args.manifest, *([args.job] if args.job else []),
                               *(p for bj in jobs for p in bj.kind.inputs(bj.job)),
                               *(p for bj in jobs for p in bj.kind.outputs(bj.job))])
    # a bar of finished jobs on a terminal (the lines above print whatever the output)
    with progress(total, "batch") as bar:
        try:
            result = run_batch(jobs, workers=args.workers, dask=args.dask, summary=stem,
                               on_result=on_result, manifest=os.path.abspath(args.manifest))
        except (ValueError, OSError) as exc:
            if not args.dask:
                raise
            # a job's failure is its row: what escapes is the cluster's
            raise InputError(f"cannot use the Dask scheduler {args.dask!r}: {exc}",
                             "--dask") from None
    counts = ", ".join(f"{result.count(s)} {s}" for s in ("done", "skipped", "failed"))
    if not args.quiet or not result.ok:
        print(f"{counts}; summary: {result.csv_path}", file=sys.stdout if result.ok
              else sys.stderr)
    return 0 if result.ok else 1


def register(subparsers, summary: str) -> None:
    """Add ``batch`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser(
        "batch", help=summary,
        description="Run the jobs of a manifest (CSV: scan, scan_landmarks, output "
                    "and optional override columns; or TOML [[jobs]]) with the "
                    "settings of a shared job file, in parallel. Finished jobs leave "
                    "OUTPUT.done.json; re-running skips them. A failed job is "
                    "reported in the summary and does not stop the others.")
    p.add_argument("manifest", metavar="MANIFEST", help="manifest (.csv or .toml)")
    p.add_argument("--job", metavar="JOB.toml",
                   help="shared job file (template, landmarks, [wrap] settings)")
    p.add_argument("--workers", type=_positive, default=None, metavar="N",
                   help="jobs at once (default: one per core; 1 = in this process)")
    p.add_argument("--dask", metavar="ADDRESS",
                   help="run on a Dask cluster: a scheduler address, or 'local' for a "
                        "local cluster of --workers processes")
    p.add_argument("--summary", metavar="DIR",
                   help="folder of the summary (MANIFEST.summary.csv/.json; default: "
                        "the manifest's folder)")
    p.add_argument("--dry-run", action="store_true",
                   help="list the jobs and which are already finished; run nothing")
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_batch)

