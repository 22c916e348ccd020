"""``facewrap report RUN.json -o DIR``: the HTML page of a finished wrap run.

Parsing and one call to :func:`facewrap.report.page.build_report_page`, which
reads the run's JSON report and the meshes it names and writes ``DIR/index.html``.
"""

from __future__ import annotations

from pathlib import Path

from facewrap.cli.evaluate import read_ground_truth, view_axes
from facewrap.io.paths import check_output_paths, new_folders_removed_on_failure
from facewrap.units import add_units_argument

__all__ = ["register", "cmd_report"]


def cmd_report(args) -> int:
    """Build the HTML page of a wrap run and print its path."""
    # deferred: the other commands (and `facewrap --help`) do not pay for this import
    from facewrap.report.page import build_report_page, load_run_report, run_meshes
    up, front = view_axes(args.template_up, args.template_front,
                          "--template-up/--template-front")
    inputs = [args.run_report, *(args.image or ()), args.ground_truth]
    check_output_paths(files=[Path(args.out) / "index.html"], folders=[args.out],
                       inputs=[p for p in inputs if p])
    truth = None
    if args.ground_truth:
        run = load_run_report(args.run_report)
        result = run_meshes(run["job"], Path(args.run_report))[2]
        truth = read_ground_truth(args.ground_truth, result)
    with new_folders_removed_on_failure(args.out):   # a failed page leaves no folder
        page = build_report_page(args.run_report, args.out, images=args.image or (),
                                 units=args.units, ground_truth=truth,
                                 template_up=up, template_front=front, title=args.title)
    print(page)
    return 0


def register(subparsers, summary: str) -> None:
    """Add ``report`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser(
        "report", help=summary,
        description="Build one self-contained HTML page from the JSON report of "
                    "'facewrap wrap --report': tables of the numbers, pictures and an "
                    "interactive 3D view of template, scan and result with distance "
                    "heatmaps.  Works offline.")
    p.add_argument("run_report", metavar="RUN_REPORT.json",
                   help="JSON report written by 'facewrap wrap --report'")
    p.add_argument("-o", "--out", required=True, metavar="DIR",
                   help="output folder (index.html is written there)")
    p.add_argument("--image", action="append", metavar="PNG",
                   help="extra picture to include (repeatable)")
    add_units_argument(p)
    p.add_argument("--ground-truth", metavar="MESH|NPY",
                   help="true positions of the result's vertices (a mesh in its "
                        "topology, or an (n, 3) .npy with NaN rows to skip): adds a "
                        "heatmap of the distance to them")
    p.add_argument("--template-up", type=float, nargs=3, default=(0.0, 1.0, 0.0),
                   metavar=("X", "Y", "Z"), help="template's up axis (default 0 1 0)")
    p.add_argument("--template-front", type=float, nargs=3, default=(0.0, 0.0, 1.0),
                   metavar=("X", "Y", "Z"),
                   help="template's facing direction (default 0 0 1)")
    p.add_argument("--title", help="page title")
    p.set_defaults(func=cmd_report)
