"""``facewrap demo``: the main job on the built-in sample, end to end.

Writes the synthetic template and scan (an extreme expression: jaw open, eyes
shut, noise, holes) to ``OUT/input``, runs ``facewrap wrap`` on them through the
real command line (alignment, RBF warp, projection, texture baking, JSON report),
then measures the result against the sample's known ground truth.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["run_demo"]


def run_demo(out: Path, verbose: bool = True) -> int:
    """Run the demo into folder ``out``; returns the exit status."""
    from .cli import main
    from .io import read_mesh
    from .sample import make_scan, make_template, write_sample

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    template = make_template()
    scan = make_scan(template)
    paths = write_sample(out / "input", template, scan)
    wrapped = out / "wrapped.obj"
    report = out / "report.json"
    argv = ["wrap", str(paths["template"]), str(paths["scan"]), "-o", str(wrapped),
            "--template-landmarks", str(paths["template_landmarks"]),
            "--scan-landmarks", str(paths["scan_landmarks"]),
            "--texture", str(paths["scan_texture"]), "--texture-size", "512",
            "--report", str(report)]
    if not verbose:
        argv.append("--quiet")
    status = main(argv)
    if status != 0:
        return status
    # ground truth is known for the sample: how far is each vertex from where it
    # truly belongs on the scan?
    from .geometry import ClosestPointTree
    fitted = read_mesh(wrapped).vertices
    face = template.parts["face"]
    err = np.linalg.norm(fitted[face] - scan.ground_truth[face], axis=1)
    # "seen": vertices whose true position is on the scan away from its borders
    # (the template head is larger than the cropped, holed scan)
    gt_tree = ClosestPointTree(scan.mesh.vertices, scan.mesh.triangles)
    on_scan = gt_tree.query(scan.ground_truth[face])
    seen = ~gt_tree.boundary_triangles[on_scan.triangles] & (on_scan.distances < 1.0)
    data = json.loads(report.read_text())
    stats = {}
    for name, e in (("face_seen_by_scan", err[seen]), ("whole_head", err)):
        stats[name] = {"vertices": int(len(e)), "mean": float(e.mean()),
                       "p95": float(np.percentile(e, 95)), "max": float(e.max())}
    data["ground_truth_error_mm"] = stats
    from .io.atomic import atomic_write
    with atomic_write(report, "w") as fh:
        json.dump(data, fh, indent=1)
    if verbose:
        for name, st in stats.items():
            print(f"ground-truth vertex error, {name.replace('_', ' ')} "
                  f"({st['vertices']} vertices): mean {st['mean']:.2f} mm, "
                  f"p95 {st['p95']:.2f} mm")
        print(f"outputs in {out.resolve()}:")
        for p in sorted(out.iterdir()):
            print(f"  {p.name}")
    return 0
