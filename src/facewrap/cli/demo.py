"""``facewrap demo``: the main job on the built-in sample, end to end.

Writes the synthetic template, its blendshapes and a scan (another identity in
an extreme expression: jaw open, eyes shut, smile; noise, holes) to
``OUT/input``, runs ``facewrap wrap`` on them through the real command line
(alignment, hybrid non-rigid ICP, projection, texture baking, JSON report),
measures the result against the sample's known ground truth, draws a heatmap of
that error and before/after pictures, and builds the HTML report
(``facewrap report``), whose path it prints last.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["run_demo"]


def run_demo(out: Path, verbose: bool = True) -> int:
    """Run the demo into folder ``out``; returns the exit status."""
    from facewrap.cli import main
    from facewrap.io import read_mesh
    from facewrap.sample import make_scan, make_template, write_sample

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    template = make_template()
    scan = make_scan(template)
    paths = write_sample(out / "input", template, scan)
    # the eyeballs are not on a scan (closed lids cover them): they follow the face
    from facewrap.io.landmarks import write_vertex_indices
    from facewrap.landmarks import Landmarks
    exclude = out / "input" / "exclude_eyeballs.txt"
    write_vertex_indices(exclude, Landmarks.from_vertices(np.concatenate(
        [template.parts["eyeball_left"], template.parts["eyeball_right"]])))
    wrapped = out / "wrapped.obj"
    report = out / "report.json"
    argv = ["wrap", str(paths["template"]), str(paths["scan"]), "-o", str(wrapped),
            "--template-landmarks", str(paths["template_landmarks"]),
            "--scan-landmarks", str(paths["scan_landmarks"]),
            "--blendshapes", str(paths["blendshapes/blink"].parent),
            "--exclude", str(exclude),
            "--texture", str(paths["scan_texture"]), "--texture-size", "512",
            "--report", str(report)]
    if not verbose:
        argv.append("--quiet")
    status = main(argv)
    if status != 0:
        return status
    # ground truth is known for the sample: how far is each vertex from where it
    # truly belongs on the scan?
    from facewrap.geometry import ClosestPointTree
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
    from facewrap.io.atomic import atomic_write
    with atomic_write(report, "w") as fh:
        json.dump(data, fh, indent=1)
    pictures = _pictures(out, template, scan, fitted, face, seen, err)
    page_dir = out / "report"
    status = main(["report", str(report), "-o", str(page_dir), "--title",
                   "facewrap demo: hybrid wrap of the built-in sample"]
                  + [a for p in pictures for a in ("--image", str(p))])
    if status != 0:
        return status
    if verbose:
        for name, st in stats.items():
            print(f"ground-truth vertex error, {name.replace('_', ' ')} "
                  f"({st['vertices']} vertices): mean {st['mean']:.2f} mm, "
                  f"p95 {st['p95']:.2f} mm")
        print(f"outputs in {out.resolve()}:")
        for p in sorted(out.iterdir()):
            print(f"  {p.name}")
        print(f"HTML report: {(page_dir / 'index.html').resolve()}")
    return 0


def _pictures(out: Path, template, scan, fitted, face, seen, err) -> list[Path]:
    """Ground-truth error heatmap and scan / result side by side (PNG files)."""
    from facewrap.report import heatmap_figure, render_views, save_png, side_by_side
    from facewrap.report import frame_from_axes
    # the scan was moved by a random similarity: look at both from the face's
    # front, i.e. the template's +z and +y turned by that similarity
    A = np.asarray(scan.transform)[:3, :3]
    frame = frame_from_axes(up=A @ [0.0, 1.0, 0.0], front=A @ [0.0, 0.0, 1.0])
    values = np.full(len(fitted), np.nan)
    values[face[seen]] = err[seen]
    heat = out / "error_heatmap.png"
    save_png(heat, heatmap_figure((fitted, template.mesh.triangles), values, units="mm",
                                  title="distance to ground truth", clim=(0.0, 2.0),
                                  frame=frame))
    views = render_views([scan.mesh, (fitted, template.mesh.triangles)],
                         views=("front",), size=(420, 480), frame=frame)
    both = out / "scan_and_result.png"
    save_png(both, side_by_side(views, [f"scan ({len(scan.mesh.triangles):,} triangles, "
                                        "holes, noise)",
                                        "fitted template (quads, UVs kept)"]))
    return [heat, both]
