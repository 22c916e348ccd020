"""Benchmark: non-rigid ICP registration against ground truth (issue 4).

* ICT-FaceKit cases (when ``../shared/data`` is present): ICT's neutral face region
  (9,409 v, cm, 68 landmarks, 53 expression shapes) onto scans made from ICT with
  another identity and an extreme expression, remeshed to another topology, with
  noise, a hole, in mm and moved (see ``_nicp_cases.py``).
* The built-in synthetic sample (jaw open, eyes shut, smile; noise, holes, crop).

Methods, same inputs, one run each: facewrap ``rbf`` (SPEC §1 baseline), ``affine``,
``graph``, ``blendshape``, ``hybrid``; peers ``trimesh.registration.nricp_amberg``
and ``nricp_sumner`` (default steps, template pre-aligned by the same landmark
similarity facewrap uses, landmarks as (triangle, barycentric) + target points);
MeshMonk ``pyramid_register`` (rigid + pyramid non-rigid, defaults, same
pre-alignment; it takes no landmarks) when ``meshmonk`` is importable.

Also: runtime of the hybrid model vs the number of blendshapes, and the speed
target (10k-vertex template onto a 200k-triangle scan, hybrid + 53 shapes).

Each method runs once, in a forked child stopped after ``FACEWRAP_BENCH_NICP_LIMIT``
seconds (default 240).  By default the first two ICT cases run (the issue's scream
and eyes-shut + smile; ~7 min on 2 lightly loaded cores);
``FACEWRAP_BENCH_NICP_FULL=1`` adds the pucker case (~9 min).  Generated scans are
cached in ``$TMPDIR/facewrap-bench-nicp`` (with ``last_run.json``, the raw numbers
and per-iteration histories of the last run).
"""

from __future__ import annotations

import os
import sys
import time
import traceback
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _nicp_cases as cases  # noqa: E402
from facewrap.geometry.similarity import similarity_transform  # noqa: E402
from facewrap.landmarks import pair_landmarks  # noqa: E402
from facewrap.wrapping import WrapSettings, wrap  # noqa: E402

FACEWRAP_MODELS = ("rbf", "affine", "graph", "blendshape", "hybrid")
PEERS = ("trimesh nricp_amberg", "trimesh nricp_sumner", "meshmonk pyramid")

ICT_CASES = [
    ("scream", "identity001", {"jawOpen": 1.0, "mouthStretch_L": 1.0,
                               "mouthStretch_R": 1.0}),
    ("eyes shut + smile", "identity002", {"eyeBlink_L": 1.0, "eyeBlink_R": 1.0,
                                          "mouthSmile_L": 1.0, "mouthSmile_R": 1.0}),
    ("pucker", "identity003", {"mouthPucker": 1.0, "mouthFunnel": 0.6}),
]


# -- helpers ---------------------------------------------------------------------
def _errors(V, case) -> dict:
    e = np.linalg.norm(np.asarray(V) - case.truth, axis=1)[case.mask]
    return {"mean": float(e.mean()), "p95": float(np.percentile(e, 95))}


def _prealign(case):
    """The template moved by facewrap's own landmark similarity (same weights as
    ``wrap``), the landmark pairs, and their targets."""
    ia, ib = pair_landmarks(case.landmarks, case.scan_landmarks)
    src = case.landmarks.positions(case.template)[ia]
    dst = case.scan_landmarks.positions(case.scan)[ib]
    try:
        from facewrap.wrapping.stages import alignment_weights
        w = alignment_weights(case.landmarks, ia)
    except Exception:          # private helper: fall back to equal weights
        w = None
    T = similarity_transform(src, dst, weights=w)
    return T.apply(case.template.vertices), ia, dst


def _landmarks_as_barycentric(case, ia):
    lm = case.landmarks
    F = case.template.triangles
    tri = np.empty(len(ia), dtype=np.int64)
    bary = np.zeros((len(ia), 3))
    for j, i in enumerate(ia):
        if lm.vertex[i] >= 0:
            hit = np.argwhere(F == lm.vertex[i])[0]
            tri[j] = hit[0]
            bary[j, hit[1]] = 1.0
        else:
            tri[j] = lm.triangle[i]
            bary[j] = lm.barycentric[i]
    return tri, bary


def run_facewrap(case, model, blendshapes=None, scan_tree=None) -> dict:
    shapes = blendshapes if blendshapes is not None else case.blendshapes
    c = time.process_time()
    t = time.perf_counter()
    res = wrap(case.template, case.scan, case.landmarks, case.scan_landmarks,
               WrapSettings(model=model, project=True),
               blendshapes=shapes if model in ("blendshape", "hybrid") else None,
               scan_tree=scan_tree)
    total = time.perf_counter() - t
    out = {"method": f"facewrap {model}", "time": total, "cpu": time.process_time() - c,
           **_errors(res.vertices, case),
           "unprojected": _errors(res.warped, case), "timings": dict(res.timings),
           "iterations": len(res.history),
           "top_weights": ({} if res.weights is None else {
               n: float(w) for w, n in sorted(zip(res.weights, res.shape_names),
                                              key=lambda x: -abs(x[0]))[:5]}),
           "history": [{k: v for k, v in h.items() if isinstance(v, (int, float, str))}
                       for h in res.history]}
    return out


def _cold_and_warm(case) -> dict:
    """The speed case twice in one process: the first run builds the template's
    deformation graphs (a fresh process), the second finds them cached (as every
    later job of a batch or frame of a sequence does)."""
    cold = run_facewrap(case, "hybrid")
    warm = run_facewrap(case, "hybrid")
    return {**cold, "warm": {k: warm[k] for k in ("time", "cpu", "timings", "mean", "p95")}}


def run_peer(case, peer) -> dict:
    c = time.process_time()
    t = time.perf_counter()
    V = peer_vertices(case, peer)
    total = time.perf_counter() - t
    return {"method": peer, "time": total, "cpu": time.process_time() - c,
            **_errors(V, case)}


def peer_vertices(case, peer) -> np.ndarray:
    """A peer's registration of ``case.template`` onto ``case.scan`` from facewrap's
    landmark similarity (the peers' own alignment options differ)."""
    import trimesh
    V0, ia, dst = _prealign(case)
    src = trimesh.Trimesh(V0, case.template.triangles, process=False)
    tgt = trimesh.Trimesh(case.scan.vertices, case.scan.triangles, process=False)
    if peer == "trimesh nricp_amberg":
        tri, bary = _landmarks_as_barycentric(case, ia)
        V = trimesh.registration.nricp_amberg(src, tgt, source_landmarks=(tri, bary),
                                              target_positions=dst)
    elif peer == "trimesh nricp_sumner":
        tri, bary = _landmarks_as_barycentric(case, ia)
        V = trimesh.registration.nricp_sumner(src, tgt, source_landmarks=(tri, bary),
                                              target_positions=dst)
    elif peer == "meshmonk pyramid":
        import meshmonk
        meshmonk.set_log_level("error") if hasattr(meshmonk, "set_log_level") else None
        V = meshmonk.pyramid_register(floating=src, target=tgt,
                                      rigid_params={}).aligned_vertices
    else:
        raise ValueError(peer)
    return np.asarray(V, dtype=np.float64)


#: seconds a single method may run before it is stopped and reported as timed out
#: FACEWRAP_BENCH_NICP_FULL=1 runs every ICT case (default: the first two)
FULL = os.environ.get("FACEWRAP_BENCH_NICP_FULL", "") not in ("", "0")
TIME_LIMIT = float(os.environ.get("FACEWRAP_BENCH_NICP_LIMIT", 240))


def _safe(fn, *args, method="?", **kw) -> dict:
    """``fn(*args, **kw)`` in a forked child with :data:`TIME_LIMIT`; a failure or
    a timeout is a result, not a crash."""
    import multiprocessing as mp

    def call():
        try:
            return fn(*args, **kw)
        except Exception as exc:
            traceback.print_exc()
            return {"method": method, "error": f"{type(exc).__name__}: {exc}"[:200]}

    try:
        ctx = mp.get_context("fork")
    except ValueError:           # no fork (Windows, macOS spawn): run inline
        return call()
    recv, send = ctx.Pipe(duplex=False)

    def child():
        send.send(call())

    proc = ctx.Process(target=child, daemon=True)
    proc.start()
    send.close()
    try:
        if recv.poll(TIME_LIMIT):
            out = recv.recv()
        else:
            out = {"method": method, "error": f"stopped after {TIME_LIMIT:.0f} s "
                                              "(time limit)"}
    except EOFError:
        out = {"method": method, "error": f"child died (exit code {proc.exitcode})"}
    proc.kill()
    proc.join()
    return out


def _peers_available() -> list[str]:
    out = ["trimesh nricp_amberg", "trimesh nricp_sumner"]
    try:
        import meshmonk
        del meshmonk
        out.append("meshmonk pyramid")
    except ImportError:
        pass
    return out


def _log(msg):
    print(msg, file=sys.stderr, flush=True)


def run_case(case, models=FACEWRAP_MODELS, peers=None, log=None) -> dict:
    log = log or _log
    V0 = _prealign(case)[0]
    rows = [{"method": "start: landmark similarity (all methods)", "time": 0.0,
             **_errors(V0, case)}]
    for m in models:
        r = _safe(run_facewrap, case, m, method=f"facewrap {m}")
        log(f"  {case.name}: {_row_text(r)}")
        rows.append(r)
    for p in (peers if peers is not None else _peers_available()):
        r = _safe(run_peer, case, p, method=p)
        log(f"  {case.name}: {_row_text(r)}")
        rows.append(r)
    return {"name": case.name, "note": case.note, "template_vertices":
            case.template.n_vertices, "scan_triangles": len(case.scan.triangles),
            "scan_vertices": case.scan.n_vertices, "mask": int(case.mask.sum()),
            "rows": rows}


def _row_text(r):
    if "error" in r:
        return f"{r['method']}: FAILED {r['error']}"
    return f"{r['method']}: {r['mean']:.2f} / {r['p95']:.2f} mm, {r['time']:.1f} s"


def _top_shapes(shapes: dict, k: int) -> dict:
    """The k shapes that move the face most (deterministic)."""
    neutral = cases.ict_template()[0].vertices
    mag = {n: float(np.linalg.norm(v - neutral, axis=1).sum()) for n, v in shapes.items()}
    names = sorted(shapes, key=lambda n: (-mag[n], n))[:k]
    return {n: shapes[n] for n in names}


def run(quick: bool = False, log=None) -> dict:
    log = log or _log
    load0 = os.getloadavg()
    t_all = time.perf_counter()
    out = {"cases": [], "scaling": None, "speed": None, "notes": []}
    # the built-in sample
    log("sample case")
    out["cases"].append(run_case(cases.sample_case(), log=log))
    if not cases.ict_available():
        out["notes"].append("ICT-FaceKit sections skipped: ../shared/data/ict-facekit "
                            "is absent.")
    else:
        n_cases = 1 if quick else (len(ICT_CASES) if FULL else 2)
        ict = []
        for name, ident, expr in ICT_CASES[:n_cases]:
            log(f"ICT case {name}")
            c = cases.ict_case(name, ident, expr)
            ict.append(c)
            out["cases"].append(run_case(c, log=log))
        # runtime vs number of blendshapes (hybrid; 0 shapes = the graph model, see
        # markdown); k = 0 and k = 53 are the first ICT case's graph / hybrid rows
        c = ict[0]
        first = {r["method"]: r for r in out["cases"][1]["rows"]}
        rows = []
        for k in (0, 10, 25, 53):
            if k in (0, 53):
                r = dict(first["facewrap graph" if k == 0 else "facewrap hybrid"])
            else:
                r = _safe(run_facewrap, c, "hybrid", blendshapes=_top_shapes(c.blendshapes, k),
                          method="facewrap hybrid")
            r["shapes"] = k
            log(f"  scaling k={k}: {_row_text(r)}")
            rows.append(r)
        out["scaling"] = {"case": c.name, "rows": rows, **_fit_slope(rows)}
        # speed target: 10k template onto a 200k-triangle scan
        log("speed target")
        name, ident, expr = ICT_CASES[0]
        big = cases.ict_case(name + " 200k", ident, expr, n_triangles=200000)
        r = _safe(_cold_and_warm, big, method="facewrap hybrid")
        out["speed"] = {"case": big.name, "scan_triangles": len(big.scan.triangles),
                        "template_vertices": big.template.n_vertices,
                        "mask": int(big.mask.sum()), **r}
    out["load"] = (load0, os.getloadavg())
    out["seconds"] = time.perf_counter() - t_all
    try:                          # raw numbers (histories included) for later study
        import json
        cases.CACHE.mkdir(parents=True, exist_ok=True)
        (cases.CACHE / "last_run.json").write_text(json.dumps(out, default=float))
    except OSError:
        pass
    return out


def _fit_slope(rows) -> dict:
    ok = [r for r in rows if "error" not in r and r["shapes"] > 0]
    if len(ok) < 2:
        return {}
    k = np.array([r["shapes"] for r in ok], float)
    res = {}
    for key, y in (("total", np.array([r["time"] for r in ok])),
                   ("cpu", np.array([r.get("cpu", np.nan) for r in ok])),
                   ("per_iteration", np.array([r["timings"].get("icp", np.nan) /
                                               max(r["iterations"], 1) for r in ok]))):
        A = np.c_[k, np.ones_like(k)]
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        pred = A @ coef
        ss = ((y - y.mean()) ** 2).sum()
        r2 = 1 - ((y - pred) ** 2).sum() / ss if ss > 0 else float("nan")
        res[key] = {"slope": float(coef[0]), "intercept": float(coef[1]), "r2": float(r2)}
    return res


# -- markdown --------------------------------------------------------------------
def _fmt(r, key, spec=".2f"):
    return format(r[key], spec) if key in r else "—"


def markdown(result: dict) -> str:
    L = ["### Non-rigid ICP against ground truth (issue 4)", ""]
    l0, l1 = result.get("load", ((0, 0, 0), (0, 0, 0)))
    L.append(f"Machine load average at start / end: {l0[0]:.1f} / {l1[0]:.1f} "
             f"({os.cpu_count()} cores; other work ran concurrently, so times are "
             f"indicative). One run per method; total {result.get('seconds', 0):.0f} s.")
    L.append("")
    L.append("Error = ‖result − truth‖ per template vertex, in mm, over the vertices "
             "whose true position lies on the scan (within 1 mm, closest triangle not "
             "on the scan's border or hole). facewrap projects onto the scan at the end; "
             "the error before projection is in brackets. Peers start from the same "
             "landmark similarity as facewrap and get the same 68 landmarks (MeshMonk "
             "takes none).")
    L.append("")
    for c in result["cases"]:
        L.append(f"**{c['name']}** — {c['note']}; template {c['template_vertices']:,} v, "
                 f"scan {c['scan_triangles']:,} triangles; error over "
                 f"{c['mask']:,} vertices.")
        L.append("")
        L.append("| method | mean (mm) | p95 (mm) | time (s) | CPU (s) | iterations |")
        L.append("|---|---:|---:|---:|---:|---:|")
        for r in c["rows"]:
            if "error" in r:
                L.append(f"| {r['method']} | failed: {r['error']} | | | | |")
                continue
            up = r.get("unprojected")
            mean = f"{r['mean']:.2f}" + (f" ({up['mean']:.2f})" if up else "")
            p95 = f"{r['p95']:.2f}" + (f" ({up['p95']:.2f})" if up else "")
            cpu = f"{r['cpu']:.1f}" if "cpu" in r else "—"
            tm = f"{r['time']:.1f}" if r["time"] else "—"
            L.append(f"| {r['method']} | {mean} | {p95} | {tm} | {cpu} | "
                     f"{r.get('iterations', '—')} |")
        L.append("")
        by = {r["method"]: r for r in c["rows"] if "error" not in r}
        if all(f"facewrap {m}" in by for m in ("graph", "blendshape", "hybrid")):
            h, g, b = (by[f"facewrap {m}"] for m in ("hybrid", "graph", "blendshape"))
            wins = all(h[k] < min(g[k], b[k]) for k in ("mean", "p95"))
            L.append(f"- hybrid vs graph / blendshape (mean, p95): {h['mean']:.2f} vs "
                     f"{g['mean']:.2f} / {b['mean']:.2f}; {h['p95']:.2f} vs {g['p95']:.2f} / "
                     f"{b['p95']:.2f} mm — hybrid best on both: "
                     f"{'yes' if wins else 'no'}")
        for r in c["rows"]:
            if r.get("top_weights"):
                L.append(f"- {r['method']} largest blend weights: " + ", ".join(
                    f"{n} {w:.2f}" for n, w in r["top_weights"].items()))
        L.append("")
    L.append("The sample's template is a whole head and its scan a cropped face with "
             "holes (only ~58 % of the template lies on the scan): facewrap rejects "
             "correspondences on the scan's border, the trimesh peers only drop those "
             "beyond a distance threshold (10 % of the template size), MeshMonk weighs "
             "them by inlier probability. MeshMonk uses no landmarks, so a wide-open "
             "mouth (scream, the sample's jaw) stays largely unmatched. ICT scans: see "
             "`_nicp_cases.py` "
             "(remesh by midpoint subdivision + libigl edge-collapse decimation, vertices "
             "snapped to the true surface; 0.2 mm normal noise; a 15 mm hole on the left "
             "cheek; mm, random rigid motion; landmarks = true positions + 0.5 mm noise).")
    L.append("")
    for n in result.get("notes", []):
        L += [f"_{n}_", ""]
    sc = result.get("scaling")
    if sc:
        L += [f"**Runtime vs number of blendshapes** (hybrid, ICT face 9,409 v onto the "
              f"'{sc['case']}' scan; the k shapes that move the face most; k = 0 is the "
              "graph model, since the hybrid needs shapes)", "",
              "| shapes | total (s) | CPU (s) | model setup (s) | ICP (s) | iterations | "
              "s / iteration | mean / p95 (mm) |", "|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in sc["rows"]:
            if "error" in r:
                L.append(f"| {r['shapes']} | failed: {r['error']} | | | | | | |")
                continue
            t = r["timings"]
            L.append(f"| {r['shapes']} | {r['time']:.1f} | {r.get('cpu', float('nan')):.1f} | "
                     f"{t.get('model_setup', 0):.2f} | "
                     f"{t.get('icp', 0):.1f} | {r['iterations']} | "
                     f"{t.get('icp', 0) / max(r['iterations'], 1):.3f} | "
                     f"{r['mean']:.2f} / {r['p95']:.2f} |")
        L.append("")
        for key, label in (("total", "wall time"), ("cpu", "CPU time"),
                           ("per_iteration", "ICP wall time per iteration")):
            if key in sc:
                f = sc[key]
                L.append(f"- {label}: slope {f['slope']:.4f} s per shape, intercept "
                         f"{f['intercept']:.3f} s, R² {f['r2']:.3f} (fit over k = 10, 25, 53)")
        L.append("")
    sp = result.get("speed")
    if sp:
        L.append(f"**Speed target** (≤ 3 s): ICT face ({sp['template_vertices']:,} v) onto "
                 f"a {sp['scan_triangles']:,}-triangle scan, hybrid + 53 shapes.")
        L.append("")
        if "error" in sp:
            L.append(f"Failed: {sp['error']}")
        else:
            t = sp["timings"]
            keys = [k for k in ("setup", "align", "model_setup", "icp", "project")
                    if k in t]
            L.append("| total (s) | CPU (s) | " + " | ".join(f"{k} (s)" for k in keys) +
                     " | iterations | s / iteration (median, max) | mean / p95 (mm) |")
            L.append("|---:|---:|" + "---:|" * len(keys) + "---:|---:|---:|")
            secs = [h["seconds"] for h in sp["history"] if "seconds" in h]
            per = (f"{np.median(secs):.3f}, {max(secs):.3f}" if secs else "—")
            L.append(f"| {sp['time']:.2f} | {sp.get('cpu', float('nan')):.2f} | " +
                     " | ".join(f"{t[k]:.2f}" for k in keys) +
                     f" | {sp['iterations']} | {per} | {sp['mean']:.2f} / {sp['p95']:.2f} |")
            w = sp.get("warm")
            if w:
                tw = w["timings"]
                L.append(f"| {w['time']:.2f} (graphs cached) | {w['cpu']:.2f} | " +
                         " | ".join(f"{tw[k]:.2f}" if k in tw else "" for k in keys) +
                         f" | | | {w['mean']:.2f} / {w['p95']:.2f} |")
            stages = {}
            for h in sp["history"]:
                key = (h.get("model", "?"), h.get("stage", "?"), h.get("nodes"))
                n, s = stages.get(key, (0, 0.0))
                stages[key] = (n + 1, s + h.get("seconds", 0.0))
            L.append("")
            L.append("The first row is a fresh process (it builds the template's two "
                     "deformation graphs); the second runs again in that process, as "
                     "later jobs of a batch or frames of a sequence do.  `setup` is the "
                     "scan's AABB tree, `model_setup` the coarse pose + blend-weight "
                     "pre-fit and graph build, `icp` the main fit, `project` the final "
                     "projection.  Per stage: " + "; ".join(
                         f"{m} stage {st}{f' ({nd} nodes)' if nd else ''}: {n} it, {s:.2f} s"
                         for (m, st, nd), (n, s) in stages.items()))
        L.append("")
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    quick = "--quick" in sys.argv
    print(markdown(run(quick=quick)))
