"""``facewrap transfer``: deformation transfer and avatar blendshapes from the shell.

Parsing and calling only: reads the meshes, markers and shapes, runs
:class:`~facewrap.transfer.DeformationTransfer` (or
:class:`~facewrap.transfer.AvatarTransfer` with ``--landmark-guided``), writes one
OBJ per shape in the target's topology, optionally a GLB with morph targets, the
correspondence (``--correspondence``: loaded when the file exists, else computed and
saved) and a JSON report.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

__all__ = ["register", "cmd_transfer"]


def _read_shapes(items, reference):
    """name -> (n, 3) from a folder or OBJ files (InputError names a bad file)."""
    from facewrap.datasets import load_shape_folder
    from facewrap.errors import InputError
    from facewrap.io.obj import read_obj_vertices
    shapes = {}
    for item in items:
        p = Path(item)
        if p.is_dir():
            shapes.update(load_shape_folder(p, reference))
        elif p.is_file():
            shapes[p.stem] = read_obj_vertices(p, reference.n_vertices)
        else:
            raise InputError("no such file or folder", p)
    if not shapes:
        raise InputError("no source shapes given", items[0] if items else None)
    return shapes


def _repairs(repairs, names) -> dict:
    """Per shape with new flipped triangles: found / repaired / remaining / rounds."""
    if not repairs:
        return {}
    return {name: {k: int(v[i]) for k, v in repairs.items()}
            for i, name in enumerate(names) if repairs["found"][i]}


def cmd_transfer(args) -> int:
    """Transfer source shapes onto the target; write OBJs (+ GLB, report)."""
    from facewrap.io import read_mesh
    from facewrap.io.landmarks import read_markers
    from facewrap.io.obj import write_obj
    from facewrap.avatar import AvatarTransfer, read_parts
    from facewrap.transfer import Correspondence, DeformationTransfer, find_correspondence
    from facewrap.transfer import check_markers
    from facewrap.avatar import IBUG51_PARTS
    t0 = time.perf_counter()
    source = read_mesh(args.source_neutral)
    target = read_mesh(args.target_neutral)
    src_ids, tgt_ids = check_markers(read_markers(args.markers), source.n_vertices,
                                     target.n_vertices, args.markers)
    shapes = _read_shapes(args.source_shapes, source)
    corr = None
    corr_path = Path(args.correspondence) if args.correspondence else None
    if corr_path is not None and corr_path.is_file():
        corr = Correspondence.load(corr_path)
        corr.check(source, target, corr_path)
    t1 = time.perf_counter()
    if args.landmark_guided:
        parts = read_parts(args.parts) if args.parts else IBUG51_PARTS
        model = AvatarTransfer(parts=parts, fix_flips=not args.no_fix_flips).fit(source, src_ids, target, tgt_ids,
                                                correspondence=corr,
                                                landmarks_path=args.markers)
        corr = model.correspondence_
    else:
        if corr is None:
            corr = find_correspondence(source, target, (src_ids, tgt_ids),
                                       markers_path=args.markers)
        anchor = "markers" if args.anchor is None else args.anchor
        if args.anchor is not None and not 0 <= args.anchor < target.n_vertices:
            from facewrap.errors import InputError
            raise InputError(f"--anchor {args.anchor} out of range (target has "
                             f"{target.n_vertices} vertices)", args.target_neutral)
        model = DeformationTransfer(anchor=anchor, fix_flips=not args.no_fix_flips
                                    ).fit(source, target, corr)
    if corr_path is not None and not corr_path.is_file():
        corr_path.parent.mkdir(parents=True, exist_ok=True)
        corr.save(corr_path)
    t2 = time.perf_counter()
    names = list(shapes)
    import numpy as np
    results = model.transfer(np.stack([shapes[k] for k in names]))
    t3 = time.perf_counter()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, X in zip(names, results):
        path = out / f"{name}.obj"
        write_obj(path, target.with_vertices(X))
        written.append(str(path))
    if args.gltf:
        from facewrap.io.gltf import write_gltf_morphs
        Path(args.gltf).parent.mkdir(parents=True, exist_ok=True)
        write_gltf_morphs(args.gltf, target, dict(zip(names, results)),
                          scale=args.gltf_scale)
    t4 = time.perf_counter()
    ambiguity = None
    if args.ambiguity:
        from facewrap.transfer import ambiguity_summary, partner_ambiguity
        ambiguity = ambiguity_summary(partner_ambiguity(
            corr, source, target, np.stack([shapes[k] for k in names])), target)
    t5 = time.perf_counter()
    report = {
        "source": str(args.source_neutral), "target": str(args.target_neutral),
        "method": "landmark-guided" if args.landmark_guided else "deformation transfer",
        "shapes": len(names), "outputs": written, "gltf": args.gltf,
        "correspondence": {"file": None if corr_path is None else str(corr_path),
                           "pairs": len(corr), **corr.stats},
        "flip_repairs": _repairs(getattr(model, "repairs_", None), names),
        "ambiguity": ambiguity,
        "timings": {"read": t1 - t0, "fit": t2 - t1, "transfer": t3 - t2,
                    "write": t4 - t3, "ambiguity": t5 - t4, "total": t5 - t0},
    }
    if args.report:
        from facewrap.io.atomic import atomic_write
        with atomic_write(args.report, "w") as fh:
            json.dump(report, fh, indent=1)
    if not args.quiet:
        print(f"wrote {len(names)} shapes to {out} ({report['method']}, "
              f"{len(corr)} triangle pairs, {report['timings']['total']:.2f} s)")
        if ambiguity is not None:
            print(f"partner ambiguity median {ambiguity['median']:.3g}, p90 "
                  f"{ambiguity['p90']:.3g}; markers would help most near target "
                  f"vertices {' '.join(map(str, ambiguity['marker_hints']))}")
    return 0


def register(subparsers) -> None:
    """Add the ``transfer`` subcommand to an argparse subparsers object."""
    p = subparsers.add_parser(
        "transfer", help="transfer poses/blendshapes onto a mesh of another topology",
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
    p.add_argument("--gltf", metavar="OUT.glb",
                   help="also write a GLB with the target neutral and named morph targets")
    p.add_argument("--gltf-scale", type=float, default=1.0,
                   help="scale positions in the GLB (0.01 for cm -> m; default 1)")
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
