"""Benchmark: reading and writing a 1M-triangle OBJ next to trimesh (issue 20: >= 3x
faster, bit-exact round trip), as calls and as fresh processes; where a whole
``facewrap wrap`` spends its time reading and checking its inputs (ICT face + 53
shapes onto a 60k-triangle scan and onto the same scan subdivided to ~1M triangles,
when ../shared/data is present); refusing bogus 2 GB sparse files whose headers
claim 10^8 vertices (target < 1 s and < 200 MB each).

Fresh-process figures alternate the two commands (A B A B ...) and take the median
of the per-pair ratios, so a machine whose speed drifts still gives a fair ratio.
"""

from __future__ import annotations

import importlib.util
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
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


SRC = Path(__file__).resolve().parents[1] / "src"
PAIRS = 5

# One call in a fresh interpreter: seconds of the call itself (imports and set-up
# before the clock starts) and the peak memory.
_CALL = """
import sys, time
{setup}
t = time.perf_counter()
{code}
seconds = time.perf_counter() - t
peak = next(int(line.split()[1]) for line in open("/proc/self/status")
            if line.startswith("VmHWM:")) / 1024
print(seconds, peak)
"""
_CODE = {   # (set-up, timed call)
    "facewrap read": ("from facewrap.io.obj import read_obj", "read_obj(sys.argv[1])"),
    "trimesh read": ("import trimesh", "trimesh.load(sys.argv[1], process=False)"),
    "facewrap write": ("from facewrap.io.obj import read_obj, write_obj\n"
                       "m = read_obj(sys.argv[1])", "write_obj(sys.argv[2], m)"),
    "trimesh write": ("import trimesh\nm = trimesh.load(sys.argv[1], process=False)",
                      "m.export(sys.argv[2])"),
}


def _call(name: str) -> str:
    setup, code = _CODE[name]
    return _CALL.format(setup=setup, code=code)


def _process(argv: list[str]) -> tuple[float, float, float]:
    """(whole-process wall s, the timed call's s, peak MB) of one fresh interpreter."""
    env = dict(os.environ, PYTHONPATH=str(SRC))
    t = time.perf_counter()
    out = subprocess.run(argv, env=env, capture_output=True, text=True, check=True)
    wall = time.perf_counter() - t
    call, peak = (float(x) for x in out.stdout.split()[-2:])
    return wall, call, peak


def paired(a: list[str], b: list[str], pairs: int = PAIRS) -> dict:
    """Run A and B in turn ``pairs`` times after one warm-up each: medians, and the
    median of the per-pair ratios A/B (whole process and the timed call)."""
    _process(a), _process(b)
    ra, rb = [], []
    for _ in range(pairs):
        ra.append(_process(a))
        rb.append(_process(b))
    med = lambda rows, k: statistics.median(r[k] for r in rows)  # noqa: E731
    return {"a_wall": med(ra, 0), "b_wall": med(rb, 0), "a_call": med(ra, 1),
            "b_call": med(rb, 1), "a_peak": med(ra, 2), "b_peak": med(rb, 2),
            "wall_ratio": statistics.median(x[0] / y[0] for x, y in zip(ra, rb)),
            "call_ratio": statistics.median(x[1] / y[1] for x, y in zip(ra, rb))}


def _accelerators() -> str:
    have = [m for m in ("fastnumbers", "orjson") if importlib.util.find_spec(m)]
    return ", ".join(have) if have else "none (numpy and repr)"


def obj_vs_trimesh(folder: Path) -> list[dict]:
    """facewrap against trimesh on the 1M-triangle grid: UVs, and UVs + normals."""
    mesh = grid_mesh(710)   # 1,005,362 triangles
    variants = {"v/vt": mesh,
                "v/vt/vn": Mesh(mesh.vertices, mesh.triangles, uvs=mesh.uvs,
                                face_uvs=mesh.triangles, normals=_unit_normals(mesh),
                                face_normals=mesh.triangles)}
    rows = []
    for name, m in variants.items():
        path = folder / f"grid_{name.replace('/', '')}.obj"
        write_obj(path, m)
        back = read_obj(path)
        exact = all(np.array_equal(x.view(np.int64), y.view(np.int64)) for x, y in
                    ((back.vertices, m.vertices), (back.uvs, m.uvs)))
        if m.normals is not None:
            exact = exact and np.array_equal(back.normals.view(np.int64),
                                             m.normals.view(np.int64))
        py = [sys.executable, "-c"]
        out = str(folder / "out.obj")
        read = paired(py + [_call("facewrap read"), str(path)],
                      py + [_call("trimesh read"), str(path)])
        write = paired(py + [_call("facewrap write"), str(path), out],
                       py + [_call("trimesh write"), str(path), out])
        rows.append({"case": f"{len(m.triangles):,} triangles, {name} "
                             f"({path.stat().st_size / 1e6:.0f} MB)",
                     "exact": exact, "read": read, "write": write})
        path.unlink()
    return rows


def _unit_normals(mesh: Mesh) -> np.ndarray:
    n = np.random.default_rng(0).normal(size=mesh.vertices.shape)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _wrap_case(folder: Path) -> dict | None:
    """ICT face + 53 shapes, a 60k-triangle scan of another identity and that scan
    subdivided to ~1M triangles, as files (None without ../shared/data)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import _nicp_cases as cases
    if not cases.ict_available():
        return None
    import trimesh
    kit = cases.ict_kit()
    case = cases.ict_case("io: ICT face → 60k scan", kit.identity_names[1],
                          {"jawOpen": 0.9, "mouthSmile_L": 0.7, "eyeBlink_R": 1.0})
    (folder / "shapes").mkdir()
    write_obj(folder / "template.obj", case.template)
    np.savetxt(folder / "template_landmarks.txt", kit.landmarks.vertex, fmt="%d")
    for name, v in case.blendshapes.items():
        write_obj(folder / "shapes" / f"{name}.obj", case.template.with_vertices(v))
    points = case.scan_landmarks.positions(case.scan)
    (folder / "scan_landmarks.txt").write_text(
        "".join(" ".join(map(repr, p.tolist())) + "\n" for p in points))
    write_obj(folder / "scan60k.obj", case.scan)
    V, F = case.scan.vertices, case.scan.triangles
    while len(F) < 900_000:
        V, F = trimesh.remesh.subdivide(V, F)
    write_obj(folder / "scan1m.obj", Mesh(V, F))
    return {"shapes": len(case.blendshapes), "scan60k": len(case.scan.triangles),
            "scan1m": len(F), "template": case.template.n_vertices}


_WRAP = """
import sys
from facewrap.cli import main
rc = main()   # the command line of this process: as the `facewrap` script runs
peak = next(int(line.split()[1]) for line in open("/proc/self/status")
            if line.startswith("VmHWM:")) / 1024
print(0.0, peak)
sys.exit(rc)
"""


def wrap_reading(folder: Path, runs: int = 3) -> list[dict]:
    """Whole ``facewrap wrap --model hybrid`` processes: wall, peak, and the report's
    reading + checking seconds (the rest is the fit, start-up and writing)."""
    info = _wrap_case(folder)
    if info is None:
        return []
    rows = []
    for scan in ("scan60k", "scan1m"):
        args = ["wrap", str(folder / "template.obj"), str(folder / f"{scan}.obj"),
                "--template-landmarks", str(folder / "template_landmarks.txt"),
                "--scan-landmarks", str(folder / "scan_landmarks.txt"),
                "--blendshapes", str(folder / "shapes"), "--model", "hybrid",
                "-o", str(folder / "out.obj"), "--report", str(folder / "report.json"),
                "-q"]
        for cache in ("cold", "warm"):
            walls, reads, peaks = [], [], []
            for _ in range(runs):
                env_dir = folder / f"cache-{scan}-{cache}-{len(walls)}"
                os.environ["FACEWRAP_CACHE_DIR"] = str(
                    env_dir if cache == "cold" else folder / f"cache-{scan}")
                if cache == "warm" and not walls:
                    _process([sys.executable, "-c", _WRAP, *args])   # fills the cache
                wall, _, peak = _process([sys.executable, "-c", _WRAP, *args])
                report = json.loads((folder / "report.json").read_text())
                walls.append(wall), peaks.append(peak)
                reads.append(report["read_seconds"])
            os.environ.pop("FACEWRAP_CACHE_DIR", None)
            rows.append({"case": f"{info['template']:,} v + {info['shapes']} shapes onto "
                                 f"{info[scan]:,} triangles, shape cache {cache}",
                         "wall": statistics.median(walls), "peak": statistics.median(peaks),
                         "read": statistics.median(reads)})
    return rows


def run() -> dict:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        old_cache = os.environ.get("FACEWRAP_CACHE_DIR")
        try:
            import trimesh  # noqa: F401
            versus = obj_vs_trimesh(Path(tmp))
        except ImportError:
            versus = []
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
        path.unlink()
        (Path(tmp) / "wrap").mkdir()
        try:
            wraps = wrap_reading(Path(tmp) / "wrap")
        except ImportError as exc:   # igl / trimesh make the scans
            wraps = [{"case": f"skipped: {exc}"}]
        finally:
            if old_cache is not None:
                os.environ["FACEWRAP_CACHE_DIR"] = old_cache
        refused = refusals(Path(tmp))
    return {"title": "OBJ reading and writing", "versus": versus, "rows": rows,
            "wraps": wraps, "refusals": refused, "accelerators": _accelerators(),
            "pairs": PAIRS}


def markdown(result: dict) -> str:
    lines = [f"### {result['title']}", ""]
    if result.get("versus"):
        lines += [f"facewrap against trimesh (`trimesh.load(..., process=False)`, "
                  f"`export`), fresh interpreters, {result['pairs']} alternating pairs, "
                  "medians of the per-pair ratios: the call alone (imports and, for "
                  "writing, the read before it are not timed) and the whole process; "
                  f"float accelerators present: {result['accelerators']}.", "",
                  "| OBJ | read: trimesh / facewrap (call) | whole process | "
                  "write: trimesh / facewrap (call) | whole process | facewrap read / "
                  "write (s) | trimesh read / write (s) | peak read MB (fw / trimesh) | "
                  "round trip |", "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
        for r in result["versus"]:
            rd, wr = r["read"], r["write"]
            lines.append(
                f"| {r['case']} | **{1 / rd['call_ratio']:.1f}x** | "
                f"{1 / rd['wall_ratio']:.1f}x | **{1 / wr['call_ratio']:.1f}x** | "
                f"{1 / wr['wall_ratio']:.1f}x | {rd['a_call']:.2f} / {wr['a_call']:.2f} | "
                f"{rd['b_call']:.2f} / {wr['b_call']:.2f} | {rd['a_peak']:.0f} / "
                f"{rd['b_peak']:.0f} | {'bit-exact' if r['exact'] else 'NOT EXACT'} |")
        lines += ["", "trimesh writes `%.8f` (not a round trip); facewrap the shortest "
                  "representation that reads back to the same float64.", ""]
    lines += ["| case | read (s) | write (s) |", "|---|---:|---:|"]
    for r in result["rows"]:
        lines.append(f"| {r['case']} | {r['read_s']:.2f} | {r['write_s']:.2f} |")
    if result.get("wraps"):
        lines += ["", "Whole `facewrap wrap --model hybrid` processes (median of 3): "
                  "reading + checking the inputs (the report's `read_seconds`) against "
                  "the rest (start-up, fit, writing). A cold cache is a new cache "
                  "folder (the 53 shape OBJs parsed, the template's deformation graphs "
                  "built); a warm one answers both by content.", "",
                  "| case | wall (s) | reading + checks (s) | rest (s) | peak (MB) |",
                  "|---|---:|---:|---:|---:|"]
        for r in result["wraps"]:
            if "wall" not in r:
                lines.append(f"| {r['case']} | | | | |")
                continue
            lines.append(f"| {r['case']} | {r['wall']:.2f} | {r['read']:.2f} | "
                         f"{r['wall'] - r['read']:.2f} | {r['peak']:.0f} |")
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
