"""Benchmark: reading and writing a 1M-triangle OBJ (target <= 10 s each) and the
ICT-FaceKit neutral (when ../shared/data is present)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from _timing import best_of
from facewrap.io.obj import read_obj, write_obj
from facewrap.mesh import Mesh

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def grid_mesh(n: int) -> Mesh:
    """An (n x n) height-field grid of 2 (n-1)^2 triangles with per-vertex UVs."""
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    V = np.stack([u.ravel(), v.ravel(), 0.1 * np.sin(7 * u).ravel()], 1)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = (x.ravel() for x in (i[:-1, :-1], i[:-1, 1:], i[1:, 1:], i[1:, :-1]))
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return Mesh(V, F, uvs=V[:, :2])


def run() -> dict:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        mesh = grid_mesh(710)  # 1,005,362 triangles
        path = Path(tmp) / "big.obj"
        tw, _ = best_of(lambda: write_obj(path, mesh), 2)
        tr, back = best_of(lambda: read_obj(path), 2)
        assert np.array_equal(back.vertices, mesh.vertices)
        rows.append({"case": f"grid, {len(mesh.triangles):,} triangles, UVs "
                             f"({path.stat().st_size / 1e6:.0f} MB)",
                     "read_s": tr, "write_s": tw})
        ict = DATA / "ict-facekit" / "FaceXModel" / "generic_neutral_mesh.obj"
        if ict.is_file():
            tr, m = best_of(lambda: read_obj(ict), 3)
            tw, _ = best_of(lambda: write_obj(Path(tmp) / "ict.obj", m), 3)
            rows.append({"case": "ICT-FaceKit neutral (26,719 v, quads, 28,911 UVs)",
                         "read_s": tr, "write_s": tw})
        try:
            import trimesh
            t, _ = best_of(lambda: trimesh.load(path, process=False), 1)
            rows.append({"case": "trimesh.load of the same 1M-triangle OBJ (peer)",
                         "read_s": t, "write_s": float("nan")})
        except ImportError:
            pass
    return {"title": "OBJ reading and writing", "rows": rows}


def markdown(result: dict) -> str:
    lines = [f"### {result['title']}", "", "| case | read (s) | write (s) |",
             "|---|---:|---:|"]
    for r in result["rows"]:
        lines.append(f"| {r['case']} | {r['read_s']:.2f} | {r['write_s']:.2f} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown(run()))
