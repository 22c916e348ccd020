"""Benchmark: reading and writing a 1M-triangle OBJ (target <= 10 s each) and the
ICT-FaceKit neutral (when ../shared/data is present); refusing bogus 2 GB sparse
files whose headers claim 10^8 vertices (target < 1 s and < 200 MB each)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
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


BOGUS_SIZE = 2 << 30  # 2 GiB, sparse: the holes cost no disk
_BOGUS_HEADS = {
    "ASCII PLY, header: 10^8 vertices": (
        "bogus_ascii.ply", b"ply\nformat ascii 1.0\nelement vertex 100000000\n"
        b"property float x\nproperty float y\nproperty float z\nend_header\n"),
    "binary PLY, header: 10^8 double vertices": (
        "bogus_binary.ply", b"ply\nformat binary_little_endian 1.0\n"
        b"element vertex 100000000\nproperty double x\nproperty double y\n"
        b"property double z\nend_header\n"),
    "OBJ, one triangle then zeros": ("bogus.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
}
# Run in a fresh interpreter so its peak memory is the reader's own.
_REFUSE = """
import json, resource, sys, time
from facewrap.errors import InputError
from facewrap.io import read_mesh
t = time.perf_counter()
try:
    read_mesh(sys.argv[1]); message = None
except InputError as exc:
    message = str(exc)
seconds = time.perf_counter() - t
try:  # VmHWM: ru_maxrss keeps the parent's size from before the exec (Linux)
    peak = next(int(line.split()[1]) for line in open("/proc/self/status")
                if line.startswith("VmHWM:")) / 1024
except OSError:
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"seconds": seconds, "peak_mb": peak, "message": message}))
"""


def refusals(folder: Path) -> list[dict]:
    """Time and peak memory (MB) of refusing each bogus sparse file."""
    rows = []
    for case, (name, head) in _BOGUS_HEADS.items():
        path = folder / name
        with open(path, "wb") as fh:
            fh.write(head)
            fh.truncate(BOGUS_SIZE)
        env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1] / "src"))
        out = subprocess.run([sys.executable, "-c", _REFUSE, str(path)], env=env,
                             capture_output=True, text=True, check=True).stdout
        rows.append({"case": case, **json.loads(out)})
        path.unlink()
    return rows


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
        refused = refusals(Path(tmp))
    return {"title": "OBJ reading and writing", "rows": rows, "refusals": refused}


def markdown(result: dict) -> str:
    lines = [f"### {result['title']}", "", "| case | read (s) | write (s) |",
             "|---|---:|---:|"]
    for r in result["rows"]:
        lines.append(f"| {r['case']} | {r['read_s']:.2f} | {r['write_s']:.2f} |")
    lines += ["", f"Refusing a bogus {BOGUS_SIZE / 2**30:.0f} GiB sparse file (fresh "
              "interpreter; peak memory includes Python and numpy):", "",
              "| file | refused in (s) | peak memory (MB) | message |", "|---|---:|---:|---|"]
    for r in result.get("refusals", []):
        message = (r["message"] or "NOT REFUSED").split(": ", 1)[-1]
        lines.append(f"| {r['case']} | {r['seconds']:.2f} | {r['peak_mb']:.0f} | "
                     f"{message} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown(run()))
