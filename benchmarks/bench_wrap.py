"""Benchmark: the §1 pipeline (align + RBF warp + projection, ``model="rbf"``) of a
~10k-vertex template onto a ~200k-triangle scan (issue target: <= 2 s), built-in
sample; and ICT face onto menpo's james scan when ../shared/data is present.  The
non-rigid ICP models are measured in bench_nicp.py."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from facewrap.sample import make_scan, make_template
from facewrap.wrapping import WrapSettings, wrap

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def run() -> dict:
    rows = []
    template = make_template(resolution=76)
    scan = make_scan(template, resolution=300, texture_size=64)
    best = None
    for _ in range(2):
        t = time.perf_counter()
        res = wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks,
                   WrapSettings(model="rbf"))
        total = time.perf_counter() - t
        if best is None or total < best[0]:
            best = (total, res)
    total, res = best
    face = template.parts["face"]
    err = np.linalg.norm(res.vertices[face] - scan.ground_truth[face], axis=1)
    seen = res.projection.projected[face]
    rows.append({"case": f"sample: {template.mesh.n_vertices:,}-vertex template onto "
                         f"{len(scan.mesh.triangles):,}-triangle scan (jaw open, eyes shut)",
                 "total": total, **{k: v for k, v in res.timings.items() if k != "total"},
                 "gt": f"{err[seen].mean():.2f} / {np.percentile(err[seen], 95):.2f}"})
    if (DATA / "scans/james/james.obj").is_file():
        from facewrap.datasets import ICTFaceKit
        from facewrap.io import read_mesh
        from facewrap.io.landmarks import read_ljson
        kit = ICTFaceKit(DATA / "ict-facekit" / "FaceXModel")
        face_mesh = kit.part_mesh("face")
        james = read_mesh(DATA / "scans/james/james.obj")
        lm = read_ljson(DATA / "scans/james/james.ljson")
        t = time.perf_counter()
        res = wrap(face_mesh, james, kit.landmarks, lm, WrapSettings(model="rbf"))
        total = time.perf_counter() - t
        m = res.metrics
        # picture for the docs: james's texture baked into ICT's UV layout
        from facewrap.texture import bake_texture, load_image, save_png
        t = time.perf_counter()
        baked = bake_texture(res.mesh, james, load_image(DATA / "scans/james/james.jpg"),
                             size=1024)
        bake_s = time.perf_counter() - t
        from PIL import Image
        small = np.asarray(Image.fromarray(baked.image).resize((512, 512)))
        save_png(Path(__file__).resolve().parents[1] / "docs" / "images" /
                 "ict_face_james_texture.png", small)
        rows.append({"case": "ICT face (9,409 v) onto james (12,228 triangles), 68 "
                             f"landmarks: landmark error {m['landmark_mean']:.2f} mm, "
                             f"fit {m['fit_mean']:.2f} / {m['fit_p95']:.2f} mm; texture bake "
                             f"1024² {bake_s:.2f} s",
                     "total": total,
                     **{k: v for k, v in res.timings.items() if k != "total"},
                     "gt": "n/a"})
    return {"title": "wrap: align + RBF warp + projection", "rows": rows}


def markdown(result: dict) -> str:
    lines = [f"### {result['title']}", "",
             "| case | setup (s) | align (s) | warp (s) | project (s) | total (s) | "
             "GT error on seen face, mean / p95 (mm) |", "|---|---:|---:|---:|---:|---:|---:|"]
    for r in result["rows"]:
        lines.append(f"| {r['case']} | {r['setup']:.3f} | {r['align']:.3f} | "
                     f"{r['warp']:.3f} | {r['project']:.3f} | {r['total']:.2f} | {r['gt']} |")
    lines += ["", "Ground-truth error is over template vertices that landed on the scan "
              "(the template head is larger than the cropped scan). Landmarks + RBF + "
              "projection leave the tangential sliding of an extreme expression (jaw "
              "open, eyes shut) uncorrected; that is the non-rigid ICP's job (issue 4). "
              "Targets: align + RBF + projection of a 10k template onto a 200k-triangle "
              "scan <= 2 s."]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown(run()))
