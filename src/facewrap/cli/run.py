"""``facewrap run JOB.toml``: run the job (wrap, transfer or rig) a job file describes.

Parsing and one call.  The job file format is :mod:`facewrap.jobs.jobfile`'s;
``--write-template`` writes a commented wrap job file with every key to start
from, ``--dry-run`` checks a job file and its inputs and prints the job as
resolved (absolute paths, every setting) without writing anything.
"""

from __future__ import annotations

import os

from facewrap.cli.transfer import print_transfer_summary
from facewrap.cli.wrap import run_wrap_job_verbosely
from facewrap.errors import InputError
from facewrap.io.paths import check_writable
from facewrap.jobs import RIG, TRANSFER, job_to_toml, kind_of, load_job, run_transfer_job, write_job

__all__ = ["register", "cmd_run"]


def cmd_run(args) -> int:
    """Run, check (``--dry-run``) or write (``--write-template``) a job file."""
    if args.write_template:
        if not args.job.lower().endswith(".toml"):
            # `run scan.obj --write-template --force` would put TOML over a mesh
            raise InputError("a job file's name ends in .toml; not written", args.job)
        if os.path.exists(args.job) and not args.force:
            raise InputError("already exists (use --force to replace it)", args.job)
        check_writable(files=[args.job])
        write_job(args.job)
        if not args.quiet:
            print(f"wrote {args.job}")
        return 0
    job, settings = load_job(args.job)
    kind = kind_of(job)
    if args.dry_run:
        for p in kind.inputs(job):
            if not os.path.exists(p):
                raise InputError(f"no such file: {p}", args.job)
        print(job_to_toml(job, settings, header=f"{args.job}, resolved (dry run: "
                                                "nothing written)"), end="")
        return 0
    if kind is TRANSFER:
        report = run_transfer_job(job)
        if not args.quiet:
            print_transfer_summary(report)
    elif kind is RIG:
        from facewrap.cli.rig import run_rig_job_verbosely   # its imports, on use
        run_rig_job_verbosely(job, settings, quiet=args.quiet)
    else:
        run_wrap_job_verbosely(job, settings, quiet=args.quiet)
    return 0


def register(subparsers, summary: str) -> None:
    """Add ``run`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser(
        "run", help=summary,
        description="Run the job a TOML job file describes (inputs, outputs and "
                    "[wrap], [transfer] or [rig] settings; paths relative to the file). Start "
                    "from `facewrap run --write-template job.toml`.")
    p.add_argument("job", metavar="JOB.toml", help="job file")
    p.add_argument("--dry-run", action="store_true",
                   help="check the job file and its inputs, print the resolved job, "
                        "write nothing")
    p.add_argument("--write-template", action="store_true",
                   help="write a commented job file with every key to JOB.toml")
    p.add_argument("--force", action="store_true",
                   help="with --write-template: replace an existing file")
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_run)
