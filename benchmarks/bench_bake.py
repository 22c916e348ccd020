"""Benchmark: texture baking as studios ask for it, whole ``facewrap wrap`` processes.

ICT-FaceKit's full head (26,719 v; 13 images: its UDIM tiles 1001-1007 and the eye
materials that overlap in tile 1001) and its face region (9,409 v, one image) baked
from menpo's ``james`` scan and photo, landmarks only, at the texture sizes
studios use (1024, 4096; 8192 for the face region).  Each row a fresh process:
wall and CPU seconds, peak memory (GNU ``time``), and the bake's own seconds from
the report's ``timings``.  The texels are rasterised and baked band by band of
about a million (:data:`facewrap.texture.bake.BLOCK_TEXELS`), so the peak memory
grows with the image (its bytes and the padding's distance transform), not with
the texels in flight.
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_peers import run_process  # noqa: E402

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
ICT = DATA / "ict-facekit" / "FaceXModel"
JAMES = DATA / "scans" / "james"
#: (template, texture size) of each row; the 8K face region shows the memory bound
ROWS = (("full head", 1024), ("full head", 4096), ("face region", 1024),
        ("face region", 4096), ("face region", 8192))


def _templates(folder: Path) -> dict:
    """The full head as published (its profile beside it) and its face region (ICT's
    parts table: the first 9,230 faces) as an OBJ, and ICT's 68 landmark ids."""
    from facewrap.io import read_mesh, write_mesh
    from facewrap.io.landmarks import write_vertex_indices
    from facewrap.io.profile import read_template_profile
    head = read_mesh(ICT / "generic_neutral_mesh.obj")
    ibug = read_template_profile(ICT / "vertex_indices.json").landmarks
    face, _ = head.submesh(np.arange(9230))
    write_mesh(folder / "face.obj", face)
    lm = folder / "landmarks.txt"
    write_vertex_indices(lm, ibug)
    return {"full head": ICT / "generic_neutral_mesh.obj", "face region": folder / "face.obj",
            "landmarks": lm}


def run() -> dict:
    if not (ICT / "generic_neutral_mesh.obj").is_file() or not JAMES.is_dir():
        return {"rows": [], "notes": ["skipped: ../shared/data is absent"]}
    rows = []
    with tempfile.TemporaryDirectory(prefix="facewrap-bench-bake-") as tmp:
        tmp = Path(tmp)
        paths = _templates(tmp)
        for name, size in ROWS:
            out = tmp / f"{name.replace(' ', '_')}_{size}"
            argv = [sys.executable, "-m", "facewrap.cli", "wrap", paths[name],
                    JAMES / "james.obj", "--template-landmarks", paths["landmarks"],
                    "--scan-landmarks", JAMES / "james.ljson", "--texture",
                    JAMES / "james.jpg", "--texture-size", str(size), "-o",
                    out / "head.obj", "--report", out / "report.json", "-q"]
            r = run_process(argv)
            report = json.loads((out / "report.json").read_text())
            texture = report.get("texture", {})
            r.update(template=name, size=size, bake=report["timings"].get("bake"),
                     images=len(texture.get("images", [])) or 1,
                     coverage=texture.get("coverage"))
            rows.append(r)
    return {"rows": rows, "notes": []}


def markdown(r: dict) -> str:
    lines = ["### Texture baking: ICT's head from james at 1K, 4K and 8K", "",
             "`facewrap wrap` of ICT-FaceKit's full head (26,719 v, 13 images: UDIM "
             "tiles 1001-1007 and the eye materials overlapping in 1001) or its face "
             "region (9,409 v, one image) onto menpo's james, landmarks only, "
             "`--texture james.jpg --texture-size N`; each row one fresh process "
             "(wrap, bake, PNGs and OBJ written).  Texels are rasterised row by row "
             "(only the columns each row of a triangle reaches) and baked band by band "
             "of about a million, so memory grows with the image, not with the texels "
             "in flight.", ""]
    if not r["rows"]:
        return "\n".join(lines + r["notes"]) + "\n"
    lines += ["| template | texture size (texels) | images | wall (s) | of it the bake (s) "
              "| CPU (s) | peak (MiB) |", "|---|---:|---:|---:|---:|---:|---:|"]
    for row in r["rows"]:
        bake = "–" if row["bake"] is None else f"{row['bake']:.1f}"
        lines.append(f"| {row['template']} | {row['size']}² | {row['images']} | "
                     f"{row['wall']:.1f} | {bake} | {row['cpu']:.1f} | "
                     f"{row['peak_mb']:.0f} |")
    return "\n".join(lines + [""] + r["notes"]) + "\n"


if __name__ == "__main__":
    print(markdown(run()))
