"""``facewrap transfer``: deformation transfer and avatar blendshapes from the shell.

Parsing and one call: the options become a :class:`~facewrap.jobs.TransferJob`
run by :func:`~facewrap.jobs.run_transfer_job`, which reads the meshes, markers
and shapes, runs :class:`~facewrap.transfer.DeformationTransfer` (or
:class:`~facewrap.avatar.AvatarTransfer` with ``--landmark-guided``) and writes
one OBJ per shape in the target's topology, optionally a GLB with morph targets,
the correspondence (``--correspondence``: loaded when the file exists, else
computed and saved) and a JSON report.
"""

from __future__ import annotations

from pathlib import Path

from facewrap.errors import InputError
from facewrap.jobs import TransferJob, TransferJobSettings, run_transfer_job
from facewrap.params import SettingsError

__all__ = ["register", "cmd_transfer", "transfer_job_from_args", "print_transfer_summary"]


def transfer_job_from_args(args) -> TransferJob:
    """The :class:`~facewrap.jobs.TransferJob` of ``facewrap transfer``'s options."""
    try:
        settings = TransferJobSettings(landmark_guided=args.landmark_guided,
                                       anchor=args.anchor, fix_flips=not args.no_fix_flips,
                                       ambiguity=args.ambiguity, gltf_scale=args.gltf_scale)
    except SettingsError as exc:   # named as the option that set it
        option = "--no-fix-flips" if exc.field == "fix_flips" else \
            "--" + exc.field.replace("_", "-")
        raise InputError(exc.problem, option) from None
    return TransferJob(source_neutral=args.source_neutral,
                       target_neutral=args.target_neutral, markers=args.markers,
                       source_shapes=list(args.source_shapes), out=args.out,
                       parts=args.parts, correspondence=args.correspondence,
                       gltf=args.gltf, report=args.report, settings=settings)


def print_transfer_summary(report: dict) -> None:
    """One line on what was written (and one on the ambiguity, when measured)."""
    print(f"wrote {report['shapes']} shapes to {Path(report['job']['out'])} "
          f"({report['method']}, {report['correspondence']['pairs']} triangle pairs, "
          f"{report['timings']['total']:.2f} s)")
    ambiguity = report["ambiguity"]
    if ambiguity is not None:
        print(f"partner ambiguity (spread of pose gradients, unitless) median "
              f"{ambiguity['median']:.3g}, p90 "
              f"{ambiguity['p90']:.3g}; markers would help most near target "
              f"vertices {' '.join(map(str, ambiguity['marker_hints']))}")


def cmd_transfer(args) -> int:
    """Transfer source shapes onto the target; write OBJs (+ GLB, report)."""
    report = run_transfer_job(transfer_job_from_args(args))
    if not args.quiet:
        print_transfer_summary(report)
    return 0


def register(subparsers, summary: str) -> None:
    """Add ``transfer`` to the ``facewrap`` subcommands (``summary``: its line in ``--help``)."""
    p = subparsers.add_parser(
        "transfer", help=summary,
        description="Deformation transfer (Sumner & Popovic 2004) or, with "
                    "--landmark-guided, avatar blendshapes (Onizuka et al. 2019).")
    p.add_argument("source_neutral", help="source reference mesh (OBJ/PLY)")
    p.add_argument("target_neutral", help="target reference mesh (OBJ/PLY)")
    p.add_argument("--source-shapes", nargs="+", required=True, metavar="DIR_OR_FILE",
                   help="folder(s) of OBJ shapes or OBJ files in the source topology")
    p.add_argument("--markers", required=True,
                   help="marker pairs 'source_vid target_vid' per line (optional count "
                        "line first, 0-based), .yml, or facewrap marker JSON; with "
                        "--landmark-guided, the landmarks in part order (51 iBUG)")
    p.add_argument("-o", "--out", required=True, help="output folder (one OBJ per shape)")
    p.add_argument("--landmark-guided", action="store_true",
                   help="Onizuka et al. 2019: landmark motion with per-part frames")
    p.add_argument("--parts", help="face parts JSON (default: 51-point iBUG layout)")
    p.add_argument("--gltf", metavar="OUT.glb|OUT.gltf",
                   help="also write glTF (binary .glb or JSON .gltf, by extension) with the "
                        "target neutral and named morph targets")
    p.add_argument("--gltf-scale", type=float, default=TransferJobSettings.gltf_scale,
                   help="scale positions in the glTF file (0.01 for cm -> m; default 1)")
    p.add_argument("--correspondence", metavar="F.npz",
                   help="reuse this correspondence file, or compute and save it here")
    p.add_argument("--anchor", type=int, default=None,
                   help="target vertex kept in place (default: follow the markers' "
                        "centroid)")
    p.add_argument("--ambiguity", action="store_true",
                   help="also measure where the result depends on the correspondence "
                        "(spread of the candidate partners' pose gradients) and name "
                        "target vertices where more markers would help (report and "
                        "output)")
    p.add_argument("--no-fix-flips", action="store_true",
                   help="keep triangles the transfer turns over (by default a pose "
                        "with new flipped triangles is re-solved locally until none "
                        "is left)")
    p.add_argument("--report", metavar="F.json", help="write timings and counts as JSON")
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_transfer)
