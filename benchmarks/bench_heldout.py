"""Benchmark: held-out ICT-FaceKit identities and expressions, and where they fail.

The other benchmarks wrap a few ICT identities (000-010) in a few expressions; the
project is judged on identities and expressions it never tuned on.  Here eight
identities no other benchmark or test uses (011-018) are crossed with seeded
expressions drawn from ICT's 53 shapes, five per identity (40 cases):

* one extreme (a fixed list, one per identity): jaw fully open, eyes shut, mouth
  funnel, mouth pucker, both cheeks puffed, a one-sided smile each side, jaw open
  with a funnel;
* one random shape at full strength, one random pair at full strength;
* one random combination of three and one of four shapes at weights 0.5-1.0.

ICT's ``mouthClose`` closes the lips against ``jawOpen`` and is not a pose
alone: when drawn, ``jawOpen`` joins it at least at its weight.

Each case is a scan made by ``_nicp_cases.ict_case`` (ICT's neutral face + the
identity + the expression, remeshed to ~60k triangles, normal noise, a hole,
noisy landmarks, mm, random rigid motion; with the truth), wrapped by
``facewrap.wrapping.wrap`` with the models ``hybrid`` (ICT's 53 shapes as
blendshapes) and ``graph``, exactly as ``bench_nicp`` does, each in a forked
child with ``bench_nicp``'s time limit.  Measures per wrap:

* truth error mean / p95 (mm) over the vertices the scan sees (``bench_nicp``),
  after the projection and (in brackets) before it (``result.warped``);
* flipped triangles: normal turned past 90° from the similarity-aligned template,
  among triangles of ICT's fitting vertices (:func:`facewrap.geometry.flipped_triangles`);
* new creases: :func:`facewrap.geometry.new_creases`, over the whole face region;
* both also as those the truth itself has not: ICT's shapes roll the inner lips
  past 90° and fold the eyelids, and a fit that follows them is right to;
* landmark error (mm, the wrap's own: fitted landmarks against the noisy scan
  landmarks), the wrap's warnings, seconds;
* where the error sits: :func:`face_regions` labels the template's vertices
  (lips, eyelids, nostrils, nose, brows, jaw line, cheeks, forehead, sides and
  neck, from the 68 landmarks); the region holding most of the vertices in the
  wrap's worst 5 % is reported, before and after projection.

Scans are cached in ``$TMPDIR/facewrap-bench-nicp`` (the first run makes them,
~4 s each); the raw numbers of the last run go to ``last_heldout.json`` there.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _nicp_cases as cases  # noqa: E402
import bench_nicp as nicp  # noqa: E402
from facewrap.geometry import flipped_triangles, new_creases  # noqa: E402
from facewrap.geometry.similarity import similarity_transform  # noqa: E402
from facewrap.wrapping import WrapSettings, wrap  # noqa: E402

MODELS = ("hybrid", "graph")
IDENTITIES = tuple(f"identity{i:03d}" for i in range(11, 19))
#: one per identity, in order
EXTREMES = ({"jawOpen": 1.0}, {"eyeBlink_L": 1.0, "eyeBlink_R": 1.0},
            {"mouthFunnel": 1.0}, {"mouthPucker": 1.0},
            {"cheekPuff_L": 1.0, "cheekPuff_R": 1.0}, {"mouthSmile_L": 1.0},
            {"mouthSmile_R": 1.0}, {"jawOpen": 1.0, "mouthFunnel": 1.0})
SEED = 2024
REGIONS = ("lips", "eyelids", "nostrils", "nose", "brows", "jaw line", "cheeks",
           "forehead", "sides and neck")
#: iBUG-68 landmark groups and the radius (cm, on ICT's neutral) a region reaches
_GROUPS = (("lips", range(48, 68), 0.8), ("eyelids", range(36, 48), 0.8),
           ("nostrils", range(31, 36), 0.7), ("nose", range(27, 31), 1.0),
           ("brows", range(17, 27), 1.2), ("jaw line", range(0, 17), 1.5))


# -- the cases ---------------------------------------------------------------------
def expressions(names, n_identities: int = len(IDENTITIES), seed: int = SEED) -> list:
    """Per identity, five (kind, {shape: weight}) expressions: its extreme, then a
    random single, pair, three and four (seeded; the same on every run)."""
    rng = np.random.default_rng(seed)
    names = sorted(names)
    out = []
    for i in range(n_identities):
        rows = [("extreme", dict(EXTREMES[i % len(EXTREMES)]))]
        for kind, k in (("single", 1), ("pair", 2), ("three", 3), ("four", 4)):
            picked = rng.choice(names, size=k, replace=False)
            w = np.ones(k) if k <= 2 else np.round(rng.uniform(0.5, 1.0, size=k), 2)
            expr = {str(n): float(x) for n, x in zip(picked, w)}
            if "mouthClose" in expr:          # lips closed over an open jaw
                expr["jawOpen"] = max(expr.get("jawOpen", 0.0), expr["mouthClose"])
            rows.append((kind, expr))
        out.append(rows)
    return out


def held_out_cases(quick: bool = False) -> list[tuple[str, str, str, dict]]:
    """(name, kind, identity, expression) of every case (quick: two identities,
    their extreme and their four-shape combination)."""
    names = cases.ict_template()[2].keys()
    out = []
    for identity, rows in zip(IDENTITIES, expressions(names)):
        for j, (kind, expr) in enumerate(rows):
            out.append((f"{identity[-3:]}.{j}", kind, identity, expr))
    if quick:
        out = [c for c in out if c[2] in IDENTITIES[:2] and c[1] in ("extreme", "four")]
    return out


# -- measures ----------------------------------------------------------------------
def face_regions(vertices, landmark_vertices) -> np.ndarray:
    """(n,) int8 index into :data:`REGIONS` for each vertex of ICT's face (cm, y up).

    A vertex belongs to the landmark group (lips, eyelids, nostrils, nose, brows,
    jaw line) it is nearest to relative to the group's reach; a vertex beyond
    every reach is on the sides and neck (outside the jaw's outer landmarks or
    below the chin), the forehead (above the brows) or the cheeks.
    """
    V = np.asarray(vertices, dtype=np.float64)
    lm = V[np.asarray(landmark_vertices)]
    rel = np.stack([np.linalg.norm(V[:, None] - lm[list(g)][None], axis=2).min(axis=1) / r
                    for _, g, r in _GROUPS], axis=1)
    label = np.argmin(rel, axis=1).astype(np.int8)
    far = rel.min(axis=1) > 1.0
    brows_y = lm[17:27, 1].mean()
    sides = (np.abs(V[:, 0]) > np.abs(lm[[0, 16], 0]).mean()) | (V[:, 1] < lm[8, 1])
    other = np.where(sides, REGIONS.index("sides and neck"),
                     np.where(V[:, 1] > brows_y, REGIONS.index("forehead"),
                              REGIONS.index("cheeks")))
    return np.where(far, other, label).astype(np.int8)


def _where(err, mask, regions) -> dict:
    """The region holding most of the worst 5 % of ``err`` over ``mask``, its
    share of them, and the mean error (mm) per region."""
    e, r = err[mask], regions[mask]
    worst = r[e >= np.percentile(e, 95)]
    counts = np.bincount(worst, minlength=len(REGIONS))
    top = int(np.argmax(counts))
    return {"region": REGIONS[top], "share": float(counts[top] / max(len(worst), 1)),
            "by_region": {REGIONS[k]: float(e[r == k].mean())
                          for k in range(len(REGIONS)) if (r == k).any()}}


def _by_region(triangle_ids, T, regions) -> dict:
    got = np.bincount(regions[T[triangle_ids, 0]], minlength=len(REGIONS))
    return {REGIONS[k]: int(c) for k, c in enumerate(got) if c}


def _flips_and_creases(V, aligned, T, inside):
    """Flipped fitting triangles (ids) and new creases (pairs as ``i * t + j``)."""
    flips = np.flatnonzero(flipped_triangles(V, aligned, T) & inside)
    pairs = new_creases(V, aligned, T)
    return flips, pairs[:, 0] * len(T) + pairs[:, 1]


def measure(case, result, fitting, regions) -> dict:
    """Every measure of one wrap of ``case`` (see the module's docstring)."""
    T = case.template.triangles
    inside = fitting[T].all(axis=1)
    aligned = result.transform.apply(case.template.vertices)
    flips, creases = _flips_and_creases(result.vertices, aligned, T, inside)
    # the truth's own: ICT's shapes roll the inner lips and fold the eyelids
    truth_aligned = similarity_transform(case.template.vertices, case.truth).apply(
        case.template.vertices)
    truth_flips, truth_creases = _flips_and_creases(case.truth, truth_aligned, T, inside)
    extra_flips = np.setdiff1d(flips, truth_flips)
    extra_creases = np.setdiff1d(creases, truth_creases)
    err = np.linalg.norm(result.vertices - case.truth, axis=1)
    err0 = np.linalg.norm(result.warped - case.truth, axis=1)
    return {**nicp._errors(result.vertices, case),
            "unprojected": nicp._errors(result.warped, case),
            "flips": len(flips), "creases": len(creases),
            "truth_flips": len(truth_flips), "truth_creases": len(truth_creases),
            "extra_flips": len(extra_flips), "extra_creases": len(extra_creases),
            "flip_regions": _by_region(extra_flips, T, regions),
            "crease_regions": _by_region(extra_creases // len(T), T, regions),
            "landmark_mean": float(result.metrics.get("landmark_mean", np.nan)),
            "landmark_max": float(result.metrics.get("landmark_max", np.nan)),
            "warnings": list(result.warnings),
            "where": _where(err, case.mask, regions),
            "where_unprojected": _where(err0, case.mask, regions)}


def wrap_case(case, model: str, fitting, regions) -> dict:
    """``case`` wrapped as ``bench_nicp.run_facewrap`` does it, measured."""
    t = time.perf_counter()
    res = wrap(case.template, case.scan, case.landmarks, case.scan_landmarks,
               WrapSettings(model=model, project=True),
               blendshapes=case.blendshapes if model in ("blendshape", "hybrid") else None)
    seconds = time.perf_counter() - t
    return {"model": model, "time": seconds, **measure(case, res, fitting, regions)}


# -- the run -----------------------------------------------------------------------
def _template_labels():
    face, _, _ = cases.ict_template()
    kit = cases.ict_kit()
    fitting = np.zeros(face.n_vertices, bool)
    ids = np.asarray(kit.indices["idx_to_fitting_verts"])
    fitting[ids[ids < face.n_vertices]] = True
    return fitting, face_regions(face.vertices, kit.indices["idx_to_landmark_verts"])


def run(quick: bool = False, log=print) -> dict:
    if not cases.ict_available():
        return {"rows": [], "notes": ["skipped: ../shared/data/ict-facekit is absent"]}
    t_all = time.perf_counter()
    load0 = os.getloadavg()
    fitting, regions = _template_labels()
    rows = []
    for name, kind, identity, expr in held_out_cases(quick):
        case = cases.ict_case(f"held-out {name}", identity, expr)
        for model in MODELS:
            r = nicp._safe(wrap_case, case, model, fitting, regions, method=model)
            r.update(case=name, kind=kind, identity=identity, expression=expr,
                     model=model)
            rows.append(r)
            log(f"  {name} {model}: " + (f"FAILED {r['error']}" if "error" in r else
                f"{r['mean']:.2f} / {r['p95']:.2f} mm, {r['flips']} flips, "
                f"{r['creases']} creases, {len(r['warnings'])} warnings, "
                f"{r['time']:.1f} s  [{case.note}]"))
    out = {"rows": rows, "notes": [], "load": (load0, os.getloadavg()),
           "seconds": time.perf_counter() - t_all, "cases": len(rows) // len(MODELS)}
    try:                          # raw numbers for the diagnosis
        cases.CACHE.mkdir(parents=True, exist_ok=True)
        (cases.CACHE / "last_heldout.json").write_text(json.dumps(out, default=float))
    except OSError:
        pass
    return out


# -- markdown ----------------------------------------------------------------------
def _expr(e: dict) -> str:
    return " + ".join(f"{k} {w:g}" for k, w in e.items())


def _total(rows, key) -> str:
    """All of ``key`` / those the truth has not / cases with any the truth has not."""
    extra = [r[f"extra_{key}"] for r in rows]
    return (f"{sum(r[key] for r in rows)} / {sum(extra)} "
            f"({sum(x > 0 for x in extra)})")


def _summary_row(model, rows) -> str:
    ok = [r for r in rows if "error" not in r]
    mean = np.array([r["mean"] for r in ok])
    p95 = np.array([r["p95"] for r in ok])

    def three(x):
        return (f"{np.median(x):.2f} / {np.percentile(x, 90):.2f} / {x.max():.2f}"
                if len(x) else "—")
    return (f"| {model} | {len(ok)} of {len(rows)} | {three(mean)} | {three(p95)} | "
            f"{_total(ok, 'flips')} | {_total(ok, 'creases')} | "
            f"{sum(bool(r['warnings']) for r in ok)} | "
            f"{np.median([r['time'] for r in ok]):.1f} |")


def _worst_rows(rows, k=5) -> list[str]:
    ok = sorted((r for r in rows if "error" not in r), key=lambda r: -r["p95"])[:k]
    L = []
    for r in ok:
        w, w0 = r["where"], r["where_unprojected"]
        up = r["unprojected"]
        L.append(f"| {r['case']} {r['identity']} | {_expr(r['expression'])} | "
                 f"{r['mean']:.2f} ({up['mean']:.2f}) | {r['p95']:.2f} ({up['p95']:.2f}) | "
                 f"{w['region']} {w['share']:.0%} ({w0['region']} {w0['share']:.0%}) | "
                 f"{r['flips']} / {r['extra_flips']} | {r['creases']} / {r['extra_creases']} | "
                 f"{r['landmark_mean']:.2f} | "
                 f"{'; '.join(r['warnings']) or '—'} | {r['time']:.1f} |")
    return L


def markdown(result: dict) -> str:
    L = ["### Held-out ICT identities and expressions", ""]
    for n in result.get("notes", []):
        L += [f"_{n}_", ""]
    rows = result.get("rows", [])
    if not rows:
        return "\n".join(L) + "\n"
    l0, l1 = result["load"]
    first = [r for r in rows if r["model"] == MODELS[0] and "error" not in r]
    truth = {k: sum(r[f"truth_{k}"] for r in first) for k in ("flips", "creases")}
    L += [f"ICT identities {IDENTITIES[0][-3:]}–{IDENTITIES[-1][-3:]} (used by no other "
          f"benchmark or test) × seeded expressions from ICT's 53 shapes: per identity "
          "one extreme (jaw fully open, eyes shut, funnel, pucker, cheeks puffed, "
          "one-sided smiles, jaw open + funnel), one shape and one pair at full "
          "strength, a combination of three and one of four at 0.5–1.0 "
          f"({result['cases']} cases, see `benchmarks/bench_heldout.py`). Scans as "
          "`bench_nicp`'s (`_nicp_cases.ict_case`: ~60k triangles of another topology, "
          "0.2 mm normal noise, a 15 mm hole, 0.5 mm landmark noise, mm, random rigid "
          "motion); ICT's face region (9,409 v) wrapped with `hybrid` (53 shapes) and "
          "`graph`, one run each. Error = ‖result − truth‖ (mm) over the vertices the "
          "scan sees, after projection (before it in brackets); flips = triangles of "
          "ICT's fitting vertices turned past 90° from the aligned template; creases = "
          "edge-adjacent triangle pairs more than 90° apart in the result but not in "
          "the template. Both are given as all / those the truth has not (ICT's shapes "
          "themselves roll the inner lips past 90° and fold the eyelids: the truths "
          f"hold {truth['flips']} flips and {truth['creases']} creases over the cases), "
          "with the cases having any the truth has not in brackets; landmark = the "
          "wrap's mean "
          "landmark error (mm) against the noisy scan landmarks. Load average at start "
          f"/ end {l0[0]:.1f} / {l1[0]:.1f} ({os.cpu_count()} cores).", "",
          "| model | cases run | mean (mm): median / p90 / worst | p95 (mm): median / "
          "p90 / worst | flips: all / not in truth (cases) | new creases: all / not in "
          "truth (cases) | cases with warnings | "
          "median time (s) |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for m in MODELS:
        L.append(_summary_row(m, [r for r in rows if r["model"] == m]))
    L.append("")
    for m in MODELS:
        L += [f"**Worst 5 by p95, {m}** (where: the region holding most of the worst "
              "5 % of vertices and its share, after projection (before))", "",
              "| case | expression | mean (mm) | p95 (mm) | where | flips: all / not in "
              "truth | creases: all / not in truth | "
              "landmark (mm) | warnings | time (s) |",
              "|---|---|---:|---:|---|---:|---:|---:|---|---:|"]
        L += _worst_rows([r for r in rows if r["model"] == m])
        L.append("")
    failed = [r for r in rows if "error" in r]
    for r in failed:
        L.append(f"- {r['case']} {r['model']} failed: {r['error']}")
    L += ["Each case's error by region, before and after the projection, along and "
          "across the normal: `cd benchmarks && ../.venv/bin/python "
          "studies/heldout_diagnosis.py 018.0 011.1`.", ""]
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    print(markdown(run(quick="--quick" in sys.argv)))
