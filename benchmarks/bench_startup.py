"""Benchmark: whole-process start-up and one whole ``facewrap wrap`` (issue 20's
"import only what a command uses").  Each command runs as a fresh process; the
median of several runs after one warm-up is reported (the machine is shared)."""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RUNS = 7


def _median_seconds(argv: list[str], runs: int = RUNS) -> float:
    subprocess.run(argv, check=True, capture_output=True)          # warm-up (disk cache)
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        subprocess.run(argv, check=True, capture_output=True)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def run() -> dict:
    from facewrap.sample import make_scan, make_template, write_sample
    py = [sys.executable]
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        tpl = make_template()
        p = write_sample(d / "in", tpl, make_scan(tpl))
        wrap = py + ["-m", "facewrap.cli", "wrap", str(p["template"]), str(p["scan"]),
                     "-o", str(d / "out.obj"), "--template-landmarks",
                     str(p["template_landmarks"]), "--scan-landmarks",
                     str(p["scan_landmarks"]), "--blendshapes", str(d / "in" / "blendshapes"),
                     "-q"]
        rows = [
            ("python -c 'import facewrap'", py + ["-c", "import facewrap"]),
            ("facewrap --help", py + ["-m", "facewrap.cli", "--help"]),
            ("facewrap wrap --help", py + ["-m", "facewrap.cli", "wrap", "--help"]),
            (f"facewrap wrap: sample ({tpl.mesh.n_vertices:,} v, hybrid, "
             f"{len(tpl.blendshapes)} shapes)", wrap),
        ]
        return {"rows": [{"case": name, "seconds": _median_seconds(argv)}
                         for name, argv in rows], "runs": RUNS}


def markdown(result: dict) -> str:
    lines = ["### Start-up and a whole wrap, as fresh processes", "",
             f"Median wall time of {result['runs']} runs after one warm-up "
             "(`python -m facewrap.cli`, outputs to a temporary folder).", "",
             "| command | wall (s) |", "|---|---:|"]
    lines += [f"| {r['case']} | {r['seconds']:.3f} |" for r in result["rows"]]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown(run()))
