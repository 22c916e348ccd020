"""Benchmark: facewrap and its peers side by side, whole processes, one run (issue 20).

Every system runs as a process of its own on the same files, and is timed from its
start to its exit (start-up, reading and writing included), its peak memory from the
operating system's accounting of that process (``os.wait4``):

* facewrap ``wrap --model hybrid`` (with the case's blendshapes) and
  ``--model graph``, as a user runs them (``python -m facewrap.cli wrap ...``);
* **Fast_RNRR** (Yao et al., CVPR 2020, C++): built here, in a temporary folder, with
  CMake, Eigen and OpenMesh (Debian's ``libeigen3-dev`` and ``libopenmesh-dev``) from a
  clone of github.com/Juyong/Fast_RNRR named by ``FACEWRAP_FAST_RNRR`` (a work tree or
  a git directory; never copied into this repository).  Its parameters are set in its
  ``main.cpp``: the temporary copy is patched so α and β can be given from outside,
  and it runs with the authors' defaults and with α = β = 30 (the best of a small
  sweep on these cases).  It reads the template and scan as OBJ and a file of
  ``template-vertex scan-vertex`` landmark pairs (each scan landmark at its nearest
  scan vertex);
* MeshMonk ``pyramid_register`` and trimesh's ``nricp_sumner``, the peer code of
  ``bench_nicp.py`` run in a child Python process (which also imports that module's
  facewrap helpers: the ``python`` start-up row says what that costs).

The peers get the template already moved by facewrap's landmark similarity (as in
``bench_nicp.py``).  Cases: the ground-truth cases of ``bench_nicp.py`` (the built-in
sample; ICT's face region, 9,409 v + 53 shapes, onto 60k-triangle extreme-expression
scans of other identities with 68 noisy landmarks: two by default, all three with
``FACEWRAP_BENCH_NICP_FULL=1``), accuracy as mean / p95 distance to the truth in mm;
and the real scans of ``bench_realscan.py``, fit distances only.

Timed methods run ``FACEWRAP_BENCH_PEERS_RUNS`` times (default 3) in turn (A B C A B C
...), so each ratio is taken run by run and the machine's drift cancels; the median
is shown.  One core: the same commands pinned to processor 0 (``sched_setaffinity``)
with one BLAS / OpenMP thread.  facewrap's on-disk cache (``facewrap.io.cache``) is a
fresh folder warmed by one untimed run, as on a user's second run of a template.
"""

from __future__ import annotations

import json
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_nicp as nicp  # noqa: E402
from _nicp_cases import Case  # noqa: E402

SOURCE_ENV = "FACEWRAP_FAST_RNRR"
RUNS = max(1, int(os.environ.get("FACEWRAP_BENCH_PEERS_RUNS", 3)))
TIME_LIMIT = nicp.TIME_LIMIT
ONE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                               "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")}
#: the α = β of Fast_RNRR's tuned rows
TUNED = 30.0
PYTHON_PEERS = ("meshmonk pyramid", "trimesh nricp_sumner")


# -- Fast_RNRR: a temporary build -------------------------------------------------
def _unpack_source(source: Path, into: Path) -> None:
    """The sources of a Fast_RNRR work tree or git directory into ``into`` (its
    ``data`` folder, ~100 MB of examples, left out)."""
    wanted = ["CMakeLists.txt", "cmake", "include", "src"]
    if (source / "CMakeLists.txt").is_file():
        for name in wanted:
            src = source / name
            (shutil.copytree if src.is_dir() else shutil.copy2)(src, into / name)
    else:
        tar = subprocess.run(["git", "--git-dir", str(source), "archive", "--format=tar",
                              "HEAD", *wanted], capture_output=True, check=True).stdout
        import io
        with tarfile.open(fileobj=io.BytesIO(tar)) as archive:
            archive.extractall(into, filter="data")
    (into / "data").mkdir(exist_ok=True)      # its CMakeLists.txt links this folder


def _patch_parameters(main_cpp: Path) -> dict:
    """Let ``FAST_RNRR_ALPHA`` / ``FAST_RNRR_BETA`` set α and β (the authors'
    values stay the defaults); returns those defaults."""
    text = main_cpp.read_text()
    defaults = {}
    for name in ("alpha", "beta"):
        pattern = rf"paras\.{name}\s*=\s*([0-9.eE+-]+)\s*;"
        found = re.search(pattern, text)
        if found is None:
            raise RuntimeError(f"no 'paras.{name} = ...;' in {main_cpp}")
        defaults[name] = float(found.group(1))
        env = f"FAST_RNRR_{name.upper()}"
        text = re.sub(pattern, f'paras.{name} = std::getenv("{env}") ? '
                               f'std::atof(std::getenv("{env}")) : {found.group(1)};', text)
    main_cpp.write_text("#include <cstdlib>\n" + text)
    return defaults


def _source_key(source: Path) -> str:
    """What identifies the sources: the commit of a git directory, else a digest of
    the work tree's code; with this script's patch (a new patch, a new build)."""
    import hashlib
    h = hashlib.sha1(_patch_parameters.__doc__.encode())
    if (source / "CMakeLists.txt").is_file():
        for f in sorted(source.glob("src/**/*")) + [source / "CMakeLists.txt"]:
            if f.is_file():
                h.update(f.read_bytes())
    else:
        h.update(subprocess.run(["git", "--git-dir", str(source), "rev-parse", "HEAD"],
                                capture_output=True, text=True, check=True).stdout.encode())
    return h.hexdigest()[:12]


def _build(tree: Path) -> str | None:
    """CMake configure and build in ``tree/build``; None, or why it failed."""
    for step in (["cmake", "-S", str(tree), "-B", str(tree / "build"),
                  "-DCMAKE_BUILD_TYPE=Release"],
                 ["cmake", "--build", str(tree / "build"), "-j", str(os.cpu_count())]):
        run = subprocess.run(step, capture_output=True, text=True)
        if run.returncode:
            errors = [s for s in (run.stdout + run.stderr).splitlines() if "rror" in s]
            return ("the build failed (Eigen and OpenMesh: apt-get install "
                    "libeigen3-dev libopenmesh-dev): " + " / ".join(errors[:3])[:300])
    return None


def build_fast_rnrr() -> tuple[Path | None, str, dict]:
    """``(binary, note, authors' α and β)``, built in a temporary folder (kept beside
    the cases of ``_nicp_cases.py`` for the next run, one per source and patch);
    ``binary`` is None and ``note`` says why when it cannot be built."""
    import _nicp_cases as cases
    source = os.environ.get(SOURCE_ENV)
    if not source:
        return None, f"skipped: set {SOURCE_ENV} to a clone of Juyong/Fast_RNRR", {}
    if not Path(source).exists():
        return None, f"skipped: {SOURCE_ENV}={source} does not exist", {}
    for tool in ("cmake", "c++", "git"):
        if shutil.which(tool) is None:
            return None, f"skipped: '{tool}' not found", {}
    try:
        key = _source_key(Path(source))
        tree = cases.CACHE / f"fast_rnrr-{key}"
        binary = tree / "build" / "Fast_RNRR"
        defaults_file = tree / "authors_defaults.json"
        if not (binary.is_file() and defaults_file.is_file()):
            shutil.rmtree(tree, ignore_errors=True)
            tree.mkdir(parents=True)
            _unpack_source(Path(source), tree)
            defaults = _patch_parameters(tree / "src" / "main.cpp")
            failed = _build(tree)
            if failed:
                return None, f"skipped: {failed}", {}
            defaults_file.write_text(json.dumps(defaults))
    except (OSError, subprocess.CalledProcessError, RuntimeError) as exc:
        return None, f"skipped: could not prepare the sources ({exc})", {}
    at = source if (Path(source) / "CMakeLists.txt").is_file() else "Juyong/Fast_RNRR at " + \
        subprocess.run(["git", "--git-dir", source, "rev-parse", "--short", "HEAD"],
                       capture_output=True, text=True).stdout.strip()
    return binary, f"built from {at}", json.loads(defaults_file.read_text())


# -- whole-process timing ---------------------------------------------------------
#: GNU time: it starts the command from its own small process, so the command's peak
#: memory is its own (a child forked from this Python process starts at this one's size)
GNU_TIME = "/usr/bin/time" if Path("/usr/bin/time").is_file() else None


def run_process(argv, *, env=None, one_core=False, cwd=None) -> dict:
    """Run ``argv`` to its end: wall and CPU seconds and peak memory (MB) of that
    process (GNU ``time``'s accounting; ``os.wait4``'s when it is absent, then floored
    at this process's size); raises with its last words if it fails or runs over
    :data:`TIME_LIMIT`."""
    full_env = {**os.environ, **(env or {}), **(ONE_THREAD if one_core else {})}
    with tempfile.NamedTemporaryFile() as err, tempfile.NamedTemporaryFile("r") as acct:
        wrapped = ([GNU_TIME, "-f", "%M %U %S", "-o", acct.name] if GNU_TIME else [])
        t = time.perf_counter()
        proc = subprocess.Popen([*wrapped, *map(str, argv)], env=full_env, cwd=cwd,
                                stdout=subprocess.DEVNULL, stderr=err,
                                preexec_fn=(lambda: os.sched_setaffinity(0, {0}))
                                if one_core else None)
        try:
            proc.wait(TIME_LIMIT)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            raise RuntimeError(f"stopped after {TIME_LIMIT:.0f} s (time limit)") from None
        wall = time.perf_counter() - t
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        if proc.returncode:
            err.seek(0)
            tail = err.read().decode(errors="replace").strip().splitlines()[-2:]
            raise RuntimeError(f"exit {proc.returncode}: {' / '.join(tail)[:200]}")
        fields = acct.read().split()[-3:] if GNU_TIME else []
    if len(fields) == 3:
        peak_kb, cpu = float(fields[0]), float(fields[1]) + float(fields[2])
    else:       # no GNU time: all children so far, an upper bound
        peak_kb, cpu = usage.ru_maxrss, float("nan")
    return {"wall": wall, "cpu": cpu, "peak_mb": peak_kb / 1024.0}


# -- the cases as files -----------------------------------------------------------
def _nearest_vertices(V, points) -> np.ndarray:
    from scipy.spatial import cKDTree
    return cKDTree(V).query(points)[1]


def write_case(case: Case, folder: Path) -> dict:
    """The files every system reads: template and scan OBJs, landmarks (facewrap JSON
    with names, so the pairing is the in-process one), the blendshapes, and the
    peers' inputs (the template moved by the landmark similarity; Fast_RNRR's
    vertex pairs)."""
    from facewrap.io import write_mesh
    from facewrap.io.landmarks import write_landmarks_json
    from facewrap.mesh import Mesh
    folder.mkdir(parents=True)
    paths = {k: folder / n for k, n in [
        ("template", "template.obj"), ("scan", "scan.obj"),
        ("template_landmarks", "template_landmarks.json"),
        ("scan_landmarks", "scan_landmarks.json"), ("aligned", "template_aligned.obj"),
        ("pairs", "landmark_pairs.txt")]}
    write_mesh(paths["template"], case.template)
    write_mesh(paths["scan"], case.scan)
    write_landmarks_json(paths["template_landmarks"], case.landmarks)
    write_landmarks_json(paths["scan_landmarks"], case.scan_landmarks)
    if case.blendshapes:
        paths["blendshapes"] = folder / "blendshapes"
        paths["blendshapes"].mkdir()
        for name, P in case.blendshapes.items():
            write_mesh(paths["blendshapes"] / f"{name}.obj", case.template.with_vertices(P))
    V0, ia, dst = nicp._prealign(case)
    write_mesh(paths["aligned"], Mesh(V0, case.template.triangles))
    tri, bary = nicp._landmarks_as_barycentric(case, ia)
    src = case.template.triangles[tri, np.argmax(bary, axis=1)]
    pairs = np.c_[src, _nearest_vertices(case.scan.vertices, dst)]
    paths["pairs"].write_text("".join(f"{a} {b}\n" for a, b in pairs.tolist()))
    return paths


def _read_vertices(path: Path, n: int) -> np.ndarray:
    from facewrap.io import read_mesh
    V = read_mesh(path).vertices
    if len(V) < n:
        raise RuntimeError(f"{path.name} has {len(V)} vertices, the template {n}")
    return V[:n]        # OpenMesh appends a copy of a non-manifold vertex at the end


def facewrap_command(paths: dict, model: str, out: Path) -> list:
    argv = [sys.executable, "-m", "facewrap.cli", "wrap", paths["template"], paths["scan"],
            "-o", out, "--template-landmarks", paths["template_landmarks"],
            "--scan-landmarks", paths["scan_landmarks"], "--model", model,
            "--report", out.with_suffix(".json"), "-q"]
    return argv + (["--blendshapes", paths["blendshapes"]] if model == "hybrid" else [])


def _methods(paths: dict, work: Path, rnrr: Path | None, defaults: dict) -> list[dict]:
    """Every timed method of a case: its name, command, environment and output."""
    out = []
    for model in (("hybrid", "graph") if "blendshapes" in paths else ("graph",)):
        o = work / f"facewrap-{model}.obj"
        out.append({"method": f"facewrap wrap --model {model}", "output": o,
                    "argv": facewrap_command(paths, model, o), "env": {}})
    if rnrr is not None:
        for label, ab in ((f"Fast_RNRR, authors' α = {defaults['alpha']:g}, "
                           f"β = {defaults['beta']:g}", None),
                          (f"Fast_RNRR, α = β = {TUNED:g}", TUNED)):
            prefix = work / ("rnrr-tuned-" if ab else "rnrr-default-")
            # waiting OpenMP threads sleep: on a shared machine spinning ones lose
            # their core's slices to the other processes (seen here: 6× the wall time)
            env = {"OMP_WAIT_POLICY": "PASSIVE"}
            env.update({} if ab is None else {"FAST_RNRR_ALPHA": str(ab),
                                              "FAST_RNRR_BETA": str(ab)})
            out.append({"method": label, "output": Path(f"{prefix}res.obj"), "env": env,
                        "argv": [rnrr, paths["aligned"], paths["scan"], prefix,
                                 paths["pairs"]]})
    return out


def _python_peer_methods(paths: dict, work: Path) -> list[dict]:
    return [{"method": peer, "output": work / f"{peer.split()[0]}.npy", "env": {},
             "argv": [sys.executable, Path(__file__), "--peer", peer, "--case",
                      paths["template"].parent, "--out", work / f"{peer.split()[0]}.npy"]}
            for peer in nicp._peers_available() if peer in PYTHON_PEERS]


def _peer_child(peer: str, folder: Path, out: Path) -> None:
    """A Python peer in this process, on the files of :func:`write_case`."""
    from facewrap.io import read_mesh
    from facewrap.io.landmarks import read_landmarks
    case = Case(folder.name, read_mesh(folder / "template.obj"),
                read_landmarks(folder / "template_landmarks.json"), None,
                read_mesh(folder / "scan.obj"),
                read_landmarks(folder / "scan_landmarks.json"), None, None)
    np.save(out, nicp.peer_vertices(case, peer))


def _accuracy(V, case: Case, ground_truth: bool) -> dict:
    if ground_truth:
        return nicp._errors(V, case)
    import bench_realscan
    m = bench_realscan.measures(V, case)
    return {"mean": m["fit_mean"], "p95": m["fit_p95"], "landmark_mean": m["landmark_mean"]}


def _timed_rounds(methods: list[dict], runs: int, one_core: bool) -> None:
    """``runs`` runs of every method in turn (A B A B ...), into ``m["runs"]`` or
    ``m["one_core_runs"]``; a failure is kept as ``m["error"]``."""
    key = "one_core_runs" if one_core else "runs"
    for _ in range(runs):
        for m in methods:
            if "error" in m:
                continue
            try:
                m.setdefault(key, []).append(run_process(m["argv"], env=m["env"],
                                                         one_core=one_core))
            except RuntimeError as exc:
                m["error"] = str(exc)


def _summary(m: dict, case: Case, ground_truth: bool, n: int) -> dict:
    row = {"method": m["method"]}
    if "error" in m:
        return {**row, "error": m["error"]}
    out = Path(m["output"])
    V = np.load(out) if out.suffix == ".npy" else _read_vertices(out, n)
    row.update(_accuracy(V, case, ground_truth))
    for key, runs in (("", m.get("runs", [])), ("one_core_", m.get("one_core_runs", []))):
        if runs:
            row[key + "wall"] = statistics.median(r["wall"] for r in runs)
            row[key + "walls"] = [r["wall"] for r in runs]
            row[key + "peak_mb"] = max(r["peak_mb"] for r in runs)
            row[key + "cpu"] = statistics.median(r["cpu"] for r in runs)
    return row


def _ratios(rows: list[dict], baseline: str) -> None:
    """Each row's wall ÷ the baseline's, run by run (median), where both ran."""
    base = next((r for r in rows if r["method"] == baseline and "walls" in r), None)
    for r in rows:
        for key in ("walls", "one_core_walls"):
            if base is not None and key in r and key in base:
                pairs = [a / b for a, b in zip(r[key], base[key])]
                r[key.replace("walls", "ratio")] = statistics.median(pairs)


def measure_case(case: Case, ground_truth: bool, rnrr, defaults: dict,
                 folder: Path, log) -> dict:
    paths = write_case(case, folder / "case")
    work = folder / "out"
    work.mkdir()
    methods = _methods(paths, work, rnrr, defaults)
    for m in methods:                 # warm-up: disk caches, facewrap's cache, errors
        try:
            run_process(m["argv"], env=m["env"])
        except RuntimeError as exc:
            m["error"] = str(exc)
    probes = [{"method": name, "argv": [sys.executable, "-c", code], "env": {}}
              for name, code in STARTUP_PROBES]
    _timed_rounds(methods + probes, RUNS, one_core=False)
    _timed_rounds(methods, max(1, RUNS - 1), one_core=True)
    slow = _python_peer_methods(paths, work)
    _timed_rounds(slow, 1, one_core=False)
    n = case.template.n_vertices
    rows = [_summary(m, case, ground_truth, n) for m in methods + slow]
    _ratios(rows, f"Fast_RNRR, α = β = {TUNED:g}")
    for r in rows:
        log(f"  {case.name}: {_row_text(r)}")
    hybrid = next((m for m in methods if m["method"].endswith("hybrid")), methods[0])
    return {"name": case.name, "note": case.note, "ground_truth": ground_truth,
            "template_vertices": n, "scan_triangles": len(case.scan.triangles),
            "shapes": len(case.blendshapes or ()), "rows": rows,
            "where": where_seconds(hybrid, rows[methods.index(hybrid)], probes)}


def import_shares(argv, env) -> dict:
    """Each top-level package's share of the import time of one run, from the self
    times of ``python -X importtime``."""
    run = subprocess.run([argv[0], "-X", "importtime", *map(str, argv[1:])],
                         capture_output=True, text=True, env={**os.environ, **env})
    by_package: dict = {}
    for line in run.stderr.splitlines():
        parts = line.split("|")
        if line.startswith("import time:") and len(parts) == 3:
            self_us = parts[0].split(":")[1].strip()
            if self_us.isdigit():
                top = parts[2].strip().split(".")[0]
                by_package[top] = by_package.get(top, 0) + int(self_us)
    total = sum(by_package.values()) or 1
    named = {k: by_package.pop(k, 0) / total for k in ("scipy", "numpy", "facewrap", "igl")}
    return {**named, "other": sum(by_package.values()) / total}


#: the start-up probes timed beside facewrap's run: the interpreter alone, and the
#: interpreter with the modules a whole ``facewrap wrap`` imports
STARTUP_PROBES = (("python -c pass", "pass"),
                  ("python + the imports of a wrap",
                   "import facewrap.cli, facewrap.cli.wrap, facewrap.jobs.wrap_job, "
                   "facewrap.wrapping.stages, facewrap.datasets"))


def where_seconds(method: dict, row: dict, probes: list[dict]) -> dict | None:
    """Where a facewrap run's whole-process seconds go: start-up and imports (the
    probes, timed in the same rounds), its report's timings, and the rest (argument
    parsing, input checks, exit)."""
    if "error" in row or "wall" not in row or any("runs" not in p for p in probes):
        return None
    report = json.loads(Path(method["output"]).with_suffix(".json").read_text())
    t = report["timings"]
    bare, imported = (statistics.median(r["wall"] for r in p["runs"]) for p in probes)
    fitted = ("setup", "align", "model_setup", "icp", "warp", "landmark_pull", "project")
    steps = [("Python start-up", bare), ("imports", imported - bare),
             ("reading the inputs", t.get("read", 0.0)),
             ("set-up: scan tree, roles, hidden surface", t.get("setup", 0.0)),
             ("landmark alignment", t.get("align", 0.0)),
             ("model set-up", t.get("model_setup", 0.0)),
             ("ICP", t.get("icp", t.get("warp", 0.0))),
             ("landmark pull", t.get("landmark_pull", 0.0)),
             ("projection", t.get("project", 0.0)),
             ("finish: pins, folds, parts, metrics",
              t.get("fit", 0.0) - sum(t.get(k, 0.0) for k in fitted)),
             ("writing", t.get("write", 0.0) + t.get("bake", 0.0))]
    rest = row["wall"] - sum(s for _, s in steps)
    return {"method": row["method"], "wall": row["wall"],
            "imports": import_shares(method["argv"], method["env"]),
            "steps": steps + [("the rest: parsing, input checks, exit (the probes ran "
                               "in other moments: on a loaded machine it can come out "
                               "below 0)", rest)]}


def _row_text(r):
    if "error" in r:
        return f"{r['method']}: FAILED {r['error']}"
    wall = f", {r['wall']:.2f} s" if "wall" in r else ""
    return f"{r['method']}: {r['mean']:.2f} / {r['p95']:.2f} mm{wall}"


def _cases(log) -> list[tuple[Case, bool]]:
    import _nicp_cases as cases
    out = [(cases.sample_case(), True)]
    if cases.ict_available():
        for name, ident, expr in nicp.ICT_CASES[:None if nicp.FULL else 2]:
            log(f"ICT case {name}")
            out.append((cases.ict_case(name, ident, expr), True))
    import bench_realscan
    out += [(c, False) for c, _ in bench_realscan._cases()]
    return out


def run(log=None) -> dict:
    log = log or nicp._log
    load0 = os.getloadavg()
    out = {"cases": [], "notes": [], "runs": RUNS}
    cache = os.environ.get("FACEWRAP_CACHE_DIR")
    with tempfile.TemporaryDirectory(prefix="facewrap-bench-peers-") as tmp:
        tmp = Path(tmp)
        os.environ["FACEWRAP_CACHE_DIR"] = str(tmp / "facewrap-cache")   # the children's
        try:
            _run_all(tmp, out, log)
        finally:
            if cache is None:
                os.environ.pop("FACEWRAP_CACHE_DIR", None)
            else:
                os.environ["FACEWRAP_CACHE_DIR"] = cache
    out["load"] = (load0, os.getloadavg())
    return out


def _run_all(tmp: Path, out: dict, log) -> None:
    """Build Fast_RNRR, time Python's start-up with the peers' helpers, run the cases."""
    rnrr, note, defaults = build_fast_rnrr()
    out["fast_rnrr"] = note
    log(f"Fast_RNRR: {note}")
    missing = [p for p in PYTHON_PEERS if p not in nicp._peers_available()]
    if missing:
        out["notes"].append(f"skipped (not importable): {', '.join(missing)}")
    out["python_start"] = statistics.median(run_process(
        [sys.executable, "-c", "import bench_nicp"], env={"PYTHONPATH": os.pathsep.join(
            [str(HERE), os.environ.get("PYTHONPATH", "")])})["wall"] for _ in range(3))
    for i, (case, ground_truth) in enumerate(_cases(log)):
        log(f"case {case.name}")
        out["cases"].append(measure_case(case, ground_truth, rnrr, defaults,
                                         tmp / f"case{i}", log))


# -- the document -----------------------------------------------------------------
def _cell(r: dict, key: str, spec: str = ".2f", suffix: str = "") -> str:
    return f"{format(r[key], spec)}{suffix}" if key in r else "–"


def _summary_table(result: dict) -> list[str]:
    """Ratios first: facewrap's hybrid (or graph) ÷ Fast_RNRR α = β = 30 per case."""
    L = ["| case | facewrap ÷ Fast_RNRR, wall (2 cores) | one core | CPU seconds | "
         "facewrap mean / p95 (mm) | Fast_RNRR mean / p95 (mm) |",
         "|---|---:|---:|---:|---:|---:|"]
    tuned = f"Fast_RNRR, α = β = {TUNED:g}"
    for c in result["cases"]:
        fw = next((r for r in c["rows"] if r["method"].startswith("facewrap")
                   and "error" not in r), None)
        rn = next((r for r in c["rows"] if r["method"] == tuned and "error" not in r), None)
        if fw is None or rn is None:
            continue
        cpu = (f"{fw['cpu'] / rn['cpu']:.2f}×" if fw.get("cpu") and rn.get("cpu") else "–")
        L.append(f"| {c['name']} ({fw['method'].split()[-1]}) | {_cell(fw, 'ratio', '.2f', '×')}"
                 f" | {_cell(fw, 'one_core_ratio', '.2f', '×')} | {cpu} | {fw['mean']:.2f} / "
                 f"{fw['p95']:.2f} | {rn['mean']:.2f} / {rn['p95']:.2f} |")
    return L + [""]


def _case_table(c: dict) -> list[str]:
    what = "mean / p95 error (mm)" if c["ground_truth"] else "fit mean / p95 (mm)"
    L = [f"**{c['name']}** — template {c['template_vertices']:,} v"
         + (f" + {c['shapes']} shapes" if c["shapes"] else "")
         + f", scan {c['scan_triangles']:,} triangles. {c['note']}", "",
         f"| system | {what} | wall (s) | ÷ Fast_RNRR α = β = {TUNED:g} | one core (s) "
         "| one core ÷ | CPU (s) | peak memory (MB) |",
         "|---|---:|---:|---:|---:|---:|---:|---:|"]
    if not c["ground_truth"]:
        L[1:1] = ["", "No truth here: fit = distance to the scan away from its borders "
                  "(`bench_realscan.measures`). facewrap projects onto the scan at the "
                  "end, so its fit is ~0 wherever the scan is clean; "
                  "`bench_realscan.py` has its landmark errors and folds."]
    for r in c["rows"]:
        if "error" in r:
            L.append(f"| {r['method']} | failed: {r['error']} | | | | | | |")
            continue
        L.append(f"| {r['method']} | {r['mean']:.2f} / {r['p95']:.2f} | "
                 f"{_cell(r, 'wall')} | {_cell(r, 'ratio', '.2f', '×')} | "
                 f"{_cell(r, 'one_core_wall')} | {_cell(r, 'one_core_ratio', '.2f', '×')} | "
                 f"{_cell(r, 'cpu')} | {_cell(r, 'peak_mb', '.0f')} |")
    return L + [""]


def _where_table(c: dict) -> list[str]:
    w = c.get("where")
    if not w:
        return []
    shares = ", ".join(f"{k} {100 * v:.0f} %" for k, v in w["imports"].items())
    L = [f"Where the {w['wall']:.2f} s of `{w['method']}` on **{c['name']}** go: "
         "start-up and imports are processes timed in the same rounds (`python -c "
         "pass`; `python -c 'import ...'` of the modules a wrap loads, less the "
         "former), the steps are the wrap's own `timings` (its report JSON), the rest "
         "is the whole-process wall time less all those. The imports by package "
         f"(self times under `python -X importtime`): {shares}.", "",
         "| step | s | share |", "|---|---:|---:|"]
    L += [f"| {name} | {s:.2f} | {100 * s / w['wall']:.0f} % |" for name, s in w["steps"]]
    return L + [""]


def markdown(result: dict) -> str:
    L = ["### Peers side by side, whole processes", "",
         "Each system a process of its own on the same files (start-up, reading and "
         "writing included); wall = median of "
         f"{result['runs']} runs taken in turn, ratios run by run; one core = pinned to "
         "processor 0 with one BLAS/OpenMP thread; peak = the largest resident size of "
         "the process (GNU `time`'s accounting). The peers start from facewrap's landmark similarity. "
         f"Fast_RNRR: {result.get('fast_rnrr', '?')} (2 OpenMP threads unless one core, "
         "`OMP_WAIT_POLICY=PASSIVE`). "
         "MeshMonk and trimesh run once, in a Python child that also imports "
         "`bench_nicp.py`'s facewrap helpers (that start-up alone: "
         f"{result.get('python_start', float('nan')):.2f} s). facewrap's disk cache "
         "(hidden surfaces, shape folders) is warm: a user's second run. On a loaded "
         "machine wall times stretch with the load (see the load average at the end): "
         "the CPU seconds are the steadier figure.", ""]
    L += [n + "\n" for n in result.get("notes", [])]
    L += _summary_table(result)
    for c in result["cases"]:
        L += _case_table(c)
    ref = next((c for c in result["cases"] if c["name"] == nicp.ICT_CASES[0][0]),
               result["cases"][0] if result["cases"] else None)
    if ref is not None:
        L += _where_table(ref)
    if "load" in result:
        L.append(f"Load average before / after: {result['load'][0][0]:.1f} / "
                 f"{result['load'][1][0]:.1f}.")
    return "\n".join(L) + "\n"


def main(argv=None) -> int:
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--peer", help="run one Python peer on a case folder (a child)")
    ap.add_argument("--case", type=Path)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args(argv)
    if args.peer:
        _peer_child(args.peer, args.case, args.out)
        return 0
    print(markdown(run()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
