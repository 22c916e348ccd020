"""Run every benchmark and write docs/benchmarks.md (``make bench``).

Each ``benchmarks/bench_*.py`` module has ``run() -> dict`` and
``markdown(result) -> str``.  Results are measured on this machine in one run.

facewrap runs from compiled bytecode, as an installed package does (pip compiles
at install; an editable install writes ``__pycache__`` on its first run): the
sources are compiled once here, and ``PYTHONDONTWRITEBYTECODE`` (set on some
machines, this one included) is cleared for the benchmarks and their children.
Without that, every timed process would compile facewrap's ~150 modules again
(0.15-0.3 s), which no user's second run pays; the peers' packages are compiled
by pip in any case.
"""

from __future__ import annotations

import argparse
import importlib
import platform
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def compile_facewrap() -> None:
    """facewrap's sources compiled to bytecode beside them (``__pycache__``, ignored
    by git), and bytecode writing allowed in this process and its children."""
    import compileall
    import os

    import facewrap
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    sys.dont_write_bytecode = False
    compileall.compile_dir(str(Path(facewrap.__file__).parent), quiet=1)


def main() -> int:
    compile_facewrap()
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=str(HERE.parent / "docs" / "benchmarks.md"))
    ap.add_argument("names", nargs="*", help="bench_* modules to run (default all)")
    args = ap.parse_args()
    names = args.names or sorted(p.stem for p in HERE.glob("bench_*.py"))
    import os
    cpu = os.cpu_count()
    parts = ["# Benchmarks", "",
             f"Measured by `make bench` on {time.strftime('%Y-%m-%d')}: "
             f"{platform.machine()}, {cpu} cores, Python {platform.python_version()}. "
             "Times are wall-clock seconds, best of the repeats stated in each "
             "benchmark's source. facewrap runs from compiled bytecode, as an "
             "installed package does (see `benchmarks/run_all.py`).", ""]
    failed = []
    for name in names:
        t = time.perf_counter()
        try:  # one broken benchmark must not lose the others' results
            mod = importlib.import_module(name)
            result = mod.run()
            text = mod.markdown(result)
        except Exception as exc:  # noqa: BLE001 - reported in the document
            failed.append(name)
            text = f"## {name}\n\n**failed**: `{type(exc).__name__}: {exc}`\n"
        parts.append(text)
        parts.append(f"_{name}: {time.perf_counter() - t:.0f} s to run._\n")
        print(text, flush=True)
    Path(args.out).write_text("\n".join(parts))
    print(f"wrote {args.out}")
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
