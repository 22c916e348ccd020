"""``facewrap wrap TEMPLATE SCAN -o OUT``: one wrap job from the command line.

Parsing and one call: the options become a :class:`~facewrap.jobs.WrapJob` and a
:class:`~facewrap.wrapping.WrapSettings` (:mod:`.fit_options`), run by
:func:`~facewrap.jobs.run_wrap_job`.
"""

from __future__ import annotations

import sys
import warnings

from facewrap.cli.fit_options import (add_fit_options, add_wrap_file_options,
                                      wrap_settings_from_args)
from facewrap.jobs import InputWarning, WrapJob, run_wrap_job
from facewrap.units import UNKNOWN, add_units_argument, format_distance, units_note

__all__ = ["register", "cmd_wrap", "run_job_verbosely", "run_wrap_job_verbosely",
           "wrap_summary_line"]


def run_job_verbosely(run, summary, job, settings, quiet: bool = False) -> dict:
    """Run a job for the command line (a wrap, a rig): ``run(job, settings)``, its
    input warnings as one ``facewrap: warning:`` line each, then unless ``quiet``
    what was detected, the one line ``summary(job, report)`` and the units note."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", InputWarning)
        report = run(job, settings)
    for w in caught:
        if issubclass(w.category, InputWarning):
            print(f"facewrap: warning: {w.message}", file=sys.stderr)
    if not quiet:
        for what, found in report.get("detected_landmarks", {}).items():
            print(f"{what} landmarks detected: {len(found['low_confidence'])} of 68 "
                  "low-confidence, left out")
        print(summary(job, report))
        if report.get("units_source") == "inferred":
            print(units_note(report["units"], "inferred"))
    return report


def run_wrap_job_verbosely(job, settings, quiet: bool = False) -> dict:
    """Run a wrap job for the command line (:func:`run_job_verbosely`)."""
    return run_job_verbosely(run_wrap_job, wrap_summary_line, job, settings, quiet)


def wrap_summary_line(job, report: dict) -> str:
    """The one-line summary of a finished wrap job; every distance with its unit."""
    m, t, unit = report["metrics"], report["timings"], report.get("units", UNKNOWN)
    # a run with warnings is never summed up as if it were fine
    flag = (f"; {len(report['warnings'])} warning(s) above: check the inputs"
            if report.get("warnings") else "")
    return (f"wrote {job.output}: {report['vertices']} vertices, model "
            f"{report['settings']['model']}, fit mean {format_distance(m['fit_mean'], unit)}"
            f" p95 {format_distance(m['fit_p95'], unit)}, landmarks mean "
            f"{format_distance(m.get('landmark_mean'), unit)}, {t['total']:.2f} s{flag}")


def cmd_wrap(args) -> int:
    """Fit the template to the scan and write the template-topology result."""
    job = WrapJob(template=args.template, scan=args.scan,
                  template_landmarks=args.template_landmarks,
                  template_profile=args.template_profile, fit_mask=args.fit_mask,
                  pin=args.pin,
                  scan_landmarks=args.scan_landmarks, output=args.output,
                  blendshapes=args.blendshapes, exclude=args.exclude,
                  texture=args.texture, texture_size=args.texture_size,
                  report=args.report, gltf=args.gltf, output_frame=args.output_frame,
                  units=args.units)
    run_wrap_job_verbosely(job, wrap_settings_from_args(args), quiet=args.quiet)
    return 0


def register(subparsers, summary: str) -> None:
    """Add ``wrap`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser("wrap", help=summary)
    p.add_argument("template", help="template mesh (OBJ/PLY)")
    p.add_argument("scan", help="scan mesh (OBJ/PLY)")
    p.add_argument("-o", "--output", required=True, help="output mesh (OBJ/PLY)")
    add_wrap_file_options(p)
    add_fit_options(p)
    p.add_argument("--report", help="write metrics and timings as JSON")
    p.add_argument("--gltf", metavar="OUT.glb|OUT.gltf",
                   help="also write the fitted mesh as glTF (binary .glb or JSON .gltf, "
                        "by extension): smooth normals, a PBR material, the baked "
                        "texture; positions in metres (as they are when the unit is "
                        "unknown)")
    add_units_argument(p)
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_wrap)
