"""``facewrap rig NEUTRAL [EXPRESSION_SCAN ...] --template T --blendshapes DIR -o OUT``.

A person's rig from their scans.

Parsing and one call: the options become a :class:`~facewrap.jobs.RigJob` and the
neutral's :class:`~facewrap.wrapping.WrapSettings` (the wrap's own options,
:mod:`.fit_options`), run by :func:`~facewrap.jobs.run_rig_job`, which writes
``OUT/neutral.obj``, ``OUT/shapes/``, ``OUT/rig.glb`` and ``OUT/rig.json``.
"""

from __future__ import annotations

import numpy as np

from facewrap.cli.fit_options import (add_fit_options, add_wrap_file_options,
                                      wrap_settings_from_args)
from facewrap.cli.wrap import run_job_verbosely
from facewrap.jobs import RigJob, run_rig_job
from facewrap.rig import PERSONALISE_METHODS
from facewrap.units import UNKNOWN, add_units_argument, format_distance

__all__ = ["register", "cmd_rig", "run_rig_job_verbosely", "rig_summary_line"]


def rig_summary_line(job: RigJob, report: dict) -> str:
    """The one-line summary of a finished rig job; every number with its unit."""
    m, t, unit = report["metrics"], report["timings"], report.get("units", UNKNOWN)
    flag = (f"; {len(report['warnings'])} warning(s) above: check the inputs"
            if report.get("warnings") else "")
    examples = report.get("examples", [])
    said = ""
    if examples:   # how well the rig reproduces its examples, and the worst one
        means = [e["error"]["mean"] for e in examples]
        before = float(np.mean([e["neutral_only_error"]["mean"] for e in examples]))
        said = (f", {len(examples)} expression scan(s) reproduced to mean "
                f"{format_distance(float(np.mean(means)), unit)} (worst "
                f"{format_distance(max(means), unit)}; neutral-only rig "
                f"{format_distance(before, unit)})")
    return (f"wrote {job.output}: {report['vertices']} vertices, {len(report['shapes'])} "
            f"shapes ({report['method']}), fit mean {format_distance(m['fit_mean'], unit)}"
            f" p95 {format_distance(m['fit_p95'], unit)}, landmarks mean "
            f"{format_distance(m.get('landmark_mean'), unit)}{said}, {t['total']:.2f} s"
            f"{flag}")


def run_rig_job_verbosely(job: RigJob, settings, quiet: bool = False) -> dict:
    """Run a rig job for the command line, as a wrap job is
    (:func:`~facewrap.cli.wrap.run_job_verbosely`)."""
    return run_job_verbosely(run_rig_job, rig_summary_line, job, settings, quiet)


def cmd_rig(args) -> int:
    """Wrap the neutral scan, make the template's shapes the person's, write the rig."""
    job = RigJob(template=args.template, scan=args.scan, blendshapes=args.blendshapes,
                 output=args.output, expression_scans=list(args.expression_scans),
                 expression_landmarks=list(args.expression_landmarks or ()),
                 scan_landmarks=args.scan_landmarks,
                 template_landmarks=args.template_landmarks,
                 template_profile=args.template_profile, exclude=args.exclude,
                 fit_mask=args.fit_mask, pin=args.pin, texture=args.texture,
                 texture_size=args.texture_size, method=args.method, units=args.units,
                 expression_textures=list(args.expression_textures or ()),
                 texture_flow=not args.no_texture_flow)
    run_rig_job_verbosely(job, wrap_settings_from_args(args), quiet=args.quiet)
    return 0


def register(subparsers, summary: str) -> None:
    """Add ``rig`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser(
        "rig", help=summary,
        description="A person's rig from their scans: the template wrapped onto the "
                    "neutral scan (hybrid model), every template shape made theirs and, "
                    "with expression scans, corrected so the rig reproduces them "
                    "(example-based rigging); written as OUT/neutral.obj, "
                    "OUT/shapes/<name>.obj, OUT/rig.glb (morph targets, texture, "
                    "metres) and OUT/rig.json (the report).")
    p.add_argument("scan", metavar="NEUTRAL_SCAN",
                   help="the person's neutral scan (OBJ/PLY)")
    p.add_argument("expression_scans", metavar="EXPRESSION_SCAN", nargs="*",
                   help="scans of the person's expressions (OBJ/PLY; any head pose)")
    p.add_argument("--template", required=True, help="template mesh (OBJ/PLY)")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="output folder")
    p.add_argument("--method", choices=PERSONALISE_METHODS, default=RigJob.method,
                   help="how the template's shapes are carried onto the person: "
                        "deformation transfer, or the displacements as they are "
                        "(default %(default)s)")
    add_wrap_file_options(p)
    p.add_argument("--expression-landmarks", nargs="+", metavar="FILE",
                   help="one landmark file per expression scan, in their order (as "
                        "--scan-landmarks; default: detected on each scan)")
    p.add_argument("--expression-textures", nargs="+", metavar="IMAGE",
                   help="one texture image per expression scan, in their order: with "
                        "--texture, each expression's wrap is refined by matching the "
                        "textures (optical flow; needs facewrap[flow])")
    p.add_argument("--no-texture-flow", action="store_true",
                   help="wrap the expression scans by geometry alone, even when "
                        "textures are given")
    add_fit_options(p, blendshapes_required=True, output_frame=False)
    add_units_argument(p)
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_rig)
