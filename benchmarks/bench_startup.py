"""Benchmark: whole-process start-up and one whole ``facewrap wrap`` (issue 20's
"import only what a command uses").  Each command runs as a fresh process; the
median of several runs after one warm-up is reported (the machine is shared), with
the modules the process holds when it ends (facewrap's own and all)."""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RUNS = 7

# runs ``facewrap ARGV`` as ``python -m facewrap.cli`` does, then says how many modules
# (facewrap's, all) the process holds, as the last line on standard error
_COUNT_MODULES = """import runpy, sys
sys.argv = ["facewrap", *sys.argv[1:]]
try:
    runpy.run_module("facewrap.cli", run_name="__main__")
except SystemExit:
    pass
print(sum(m.split(".")[0] == "facewrap" for m in sys.modules), len(sys.modules),
      file=sys.stderr)
"""


def _modules(argv: list[str]) -> tuple[int, int]:
    """(facewrap modules, all modules) a fresh process of ``argv`` holds at its end:
    ``python -m facewrap.cli ...`` or ``python -c CODE``."""
    if argv[1:3] == ["-m", "facewrap.cli"]:
        probe = [argv[0], "-c", _COUNT_MODULES, *argv[3:]]
    else:
        count = _COUNT_MODULES[_COUNT_MODULES.index("print("):]
        probe = [argv[0], "-c", f"import sys\n{argv[2]}\n{count}"]
    run = subprocess.run(probe, capture_output=True, text=True, check=True)
    own, every = run.stderr.strip().splitlines()[-1].split()
    return int(own), int(every)


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
        return {"rows": [{"case": name, "seconds": _median_seconds(argv),
                          "modules": _modules(argv)} for name, argv in rows], "runs": RUNS}


def markdown(result: dict) -> str:
    lines = ["### Start-up and a whole wrap, as fresh processes", "",
             f"Median wall time of {result['runs']} runs after one warm-up "
             "(`python -m facewrap.cli`, outputs to a temporary folder).", "",
             "| command | wall (s) | modules: facewrap's / all |", "|---|---:|---:|"]
    lines += [f"| {r['case']} | {r['seconds']:.3f} | {r['modules'][0]} / {r['modules'][1]} |"
              for r in result["rows"]]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown(run()))
