"""Benchmark: peak memory of registering a ~10k-vertex template onto a 1M-triangle
scan with ``facewrap wrap`` (issue target: <= 4 GB), built-in sample.

Each run is a fresh interpreter running ``facewrap wrap``; its peak resident set size
is the process's ``VmHWM`` (Linux), so it includes the interpreter, numpy/scipy/libigl
and everything the wrap allocates.
The scan is the sample at ``resolution=690`` (about 1.02M triangles), written as OBJ
to a temporary folder first."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

from facewrap.sample import make_scan, make_template, write_sample

#: Models measured: the RBF warp, and the default (non-rigid ICP) when it runs.
MODELS = ("rbf", "auto")
LIMIT_GB = 4.0


#: Runs ``facewrap ARGS`` and reports the process's own peak RSS (VmHWM: the
#: high-water mark of its address space after exec; ``ru_maxrss`` would also count
#: the parent's pages copied at fork).
_WRAPPER = ("import sys\nfrom facewrap.cli import main\ntry:\n"
            "    rc = main()\nexcept SystemExit as exc:\n    rc = exc.code\n"
            "hwm = next(l for l in open('/proc/self/status') if l.startswith('VmHWM'))\n"
            "print('PEAK_KB', hwm.split()[1], file=sys.stderr)\nsys.exit(rc)\n")


def _peak(args: list[str]) -> dict:
    """Run ``facewrap ARGS`` in a fresh interpreter: wall time, exit status, peak RSS
    (bytes) and the last line of stderr on failure."""
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", _WRAPPER, *args], capture_output=True,
                          text=True)
    lines = proc.stderr.strip().splitlines()
    peak = next((int(ln.split()[1]) * 1024 for ln in lines if ln.startswith("PEAK_KB")), 0)
    errors = [ln for ln in lines if not ln.startswith("PEAK_KB")]
    return {"seconds": time.perf_counter() - t, "rc": proc.returncode, "peak": peak,
            "error": errors[-1] if errors and proc.returncode else ""}


def run() -> dict:
    template = make_template(resolution=76)
    scan = make_scan(template, resolution=690, texture_size=64)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        paths = write_sample(Path(tmp), template, scan)
        size = paths["scan"].stat().st_size
        base = _peak(["--version"])
        rows.append({"case": "interpreter + facewrap imported (baseline)", **base})
        read = _peak(["info", str(paths["scan"])])
        rows.append({"case": f"`facewrap info` of the scan ({size / 1e6:.0f} MB OBJ)",
                     **read})
        for model in MODELS:
            out = Path(tmp) / f"fitted_{model}.obj"
            res = _peak(["wrap", str(paths["template"]), str(paths["scan"]),
                         "--template-landmarks", str(paths["template_landmarks"]),
                         "--scan-landmarks", str(paths["scan_landmarks"]),
                         "-o", str(out), "--model", model, "-q"])
            rows.append({"case": f"`facewrap wrap --model {model}`: "
                                 f"{template.mesh.n_vertices:,}-vertex template onto "
                                 f"{len(scan.mesh.triangles):,} triangles", **res})
    return {"title": "memory: 1M-triangle scan", "rows": rows}


def markdown(result: dict) -> str:
    lines = [f"### {result['title']}", "",
             "| run | peak RSS (GB) | wall (s) | result |", "|---|---:|---:|---|"]
    for r in result["rows"]:
        ok = "ok" if r["rc"] == 0 else f"exit {r['rc']}: {r['error'][:80]}"
        if r["rc"] == 0 and "wrap" in r["case"]:
            ok += " (within 4 GB)" if r["peak"] <= LIMIT_GB * 2**30 else " (OVER 4 GB)"
        lines.append(f"| {r['case']} | {r['peak'] / 2**30:.2f} | {r['seconds']:.1f} | "
                     f"{ok} |")
    lines += ["", "Peak resident memory (VmHWM) of each `facewrap` process, including "
              "the Python interpreter and libraries. Target: a 1M-triangle scan "
              "registers within 4 GB."]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown(run()))
