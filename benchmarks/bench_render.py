"""Benchmark: headless pictures of 100k- and 1M-triangle meshes (issue target: a
100k-triangle picture <= 1 s), with facewrap's numpy rasteriser; and, for
comparison, VTK offscreen (pyvista) when it is installed and can open an offscreen
context here (run in a subprocess: a missing OpenGL library must not kill the run).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np

from _timing import best_of
from facewrap.report import heatmap_figure, render_mesh
from facewrap.sample import make_scan, make_template

SIZE = (800, 800)
REPEATS = 3


def subdivide(V: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Midpoint subdivision: every triangle into four (vectorised)."""
    e = np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
    key = np.sort(e, axis=1)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    mids = len(V) + inv.reshape(3, -1).T                  # (t, 3): m01, m12, m20
    V2 = np.concatenate([V, V[uniq].mean(axis=1)])
    a, b, c = T.T
    m01, m12, m20 = mids.T
    T2 = np.concatenate([np.stack([a, m01, m20], 1), np.stack([m01, b, m12], 1),
                         np.stack([m20, m12, c], 1), np.stack([m01, m12, m20], 1)])
    return V2, T2


_VTK_SCRIPT = textwrap.dedent("""
    import json, sys, time
    import numpy as np
    data = np.load(sys.argv[1])
    out = {}
    import pyvista as pv
    pv.OFF_SCREEN = True
    for name in ("m100k", "m1m"):
        V, T = data[name + "_V"], data[name + "_T"]
        faces = np.hstack([np.full((len(T), 1), 3), T]).ravel()
        mesh = pv.PolyData(V, faces)
        times = []
        for k in range(3):
            t = time.perf_counter()
            p = pv.Plotter(off_screen=True, window_size=(800, 800))
            p.add_mesh(mesh, color="lightgray", smooth_shading=True)
            p.view_xy()
            p.screenshot(return_img=True)
            window = p.ren_win.GetClassName()
            p.close()
            times.append(time.perf_counter() - t)
        out[name] = {"first": times[0], "best": min(times), "window": window}
    print(json.dumps(out))
""")


def _vtk_times(meshes: dict) -> dict | str:
    """pyvista offscreen render times in a subprocess, or why there are none."""
    try:
        import importlib.util
        if importlib.util.find_spec("pyvista") is None:
            return "pyvista not installed"
    except ImportError:
        return "pyvista not installed"
    with tempfile.TemporaryDirectory() as d:
        npz = Path(d) / "meshes.npz"
        np.savez(npz, **{f"{k}_{a}": v for k, (V, T) in meshes.items()
                         for a, v in (("V", V), ("T", T))})
        script = Path(d) / "vtk_bench.py"
        script.write_text(_VTK_SCRIPT)
        try:
            run = subprocess.run([sys.executable, str(script), str(npz)], capture_output=True,
                                 text=True, timeout=300)
        except subprocess.TimeoutExpired:
            return "timed out"
    if run.returncode != 0:
        last = (run.stderr.strip().splitlines() or ["?"])[-1]
        return f"failed (exit {run.returncode}: {last[:120]})"
    return json.loads(run.stdout.strip().splitlines()[-1])


def run() -> dict:
    tpl = make_template()
    scan = make_scan(tpl, resolution=215, texture_size=8, transform=False)
    V1, T1 = scan.mesh.vertices, scan.mesh.triangles          # ~100k triangles
    big = make_scan(tpl, resolution=171, texture_size=8, transform=False)
    Vb, Tb = big.mesh.vertices, big.mesh.triangles
    for _ in range(2):
        Vb, Tb = subdivide(Vb, Tb)                           # ~62k -> ~250k -> ~1M
    rows = []
    for label, (V, T) in (("100k", (V1, T1)), ("1M", (Vb, Tb))):
        values = np.linalg.norm(V - V.mean(axis=0), axis=1)
        for view in ("front", "three_quarter", "side"):
            s = best_of(lambda: render_mesh((V, T), view=view, size=SIZE), REPEATS)[0]
            rows.append({"mesh": f"{len(T):,} triangles", "what": f"shaded, {view}",
                         "seconds": s})
        s = best_of(lambda: render_mesh((V, T), view="three_quarter", size=SIZE,
                                        scalars=values), REPEATS)[0]
        rows.append({"mesh": f"{len(T):,} triangles", "what": "heatmap, three_quarter",
                     "seconds": s})
        if label == "100k":
            s = best_of(lambda: heatmap_figure((V, T), values, title="distance",
                                               size=(400, 480)), 2)[0]
            rows.append({"mesh": f"{len(T):,} triangles",
                         "what": "heatmap figure: 3 views 400x480 + colour bar",
                         "seconds": s})
    vtk = _vtk_times({"m100k": (V1, T1), "m1m": (Vb, Tb)})
    return {"title": "pictures: numpy software rasteriser", "rows": rows, "vtk": vtk,
            "sizes": {"100k": len(T1), "1M": len(Tb)}}


def markdown(result: dict) -> str:
    lines = [f"### {result['title']}", "",
             f"{SIZE[0]}x{SIZE[1]} pixels, 2x2 supersampling (so 1600x1600 rasterised), "
             "smooth shading, white background; best of "
             f"{REPEATS}.", "",
             "| mesh | picture | seconds |", "|---|---|---:|"]
    for r in result["rows"]:
        lines.append(f"| {r['mesh']} | {r['what']} | {r['seconds']:.2f} |")
    vtk = result["vtk"]
    lines.append("")
    if isinstance(vtk, dict):
        n = result["sizes"]
        lines += ["VTK offscreen (pyvista, new plotter per picture, 800x800, no "
                  "supersampling), for comparison:", "",
                  "| mesh | first picture (s) | best of 3 (s) | render window |",
                  "|---|---:|---:|---|"]
        for key, label in (("m100k", "100k"), ("m1m", "1M")):
            v = vtk[key]
            lines.append(f"| {n[label]:,} triangles | {v['first']:.2f} | "
                         f"{v['best']:.2f} | {v['window']} |")
        lines += ["", "VTK's wheel renders offscreen only through a system OpenGL "
                  "(here EGL from Debian's libegl-mesa0 + llvmpipe); a machine with "
                  "only pip wheels has none, so facewrap uses the numpy rasteriser."]
    else:
        lines.append(f"VTK offscreen (pyvista) for comparison: {vtk}.")
    lines.append("")
    lines.append("Target: a 100k-triangle picture <= 1 s.")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown(run()))
