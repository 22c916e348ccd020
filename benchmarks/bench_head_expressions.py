"""Benchmark: ICT's full production head onto extreme expressions of unseen people.

The expression benchmarks (``bench_nicp``, ``bench_heldout``) wrap ICT's face
region, which has no parts; the head benchmarks (``bench_heads``,
``bench_head_variants``, ``bench_other_heads``) wrap whole heads onto neutral
faces.  A studio wraps its whole head (eyeballs, teeth, gums, tongue, mouth
socket) onto every scan of a capture, the jaw open among them.  Here ICT's full
neutral head (26,719 vertices) is wrapped with only its 68 landmark ids onto eight
identities no tuning used (011-018), one expression each: jaw open, jaw open with
a funnel, eyes shut, a one-sided smile, cheeks puffed, neutral, jaw open to the
side, the lower lip rolled in.  Each scan is made as ``bench_nicp`` makes its
cases (``_nicp_cases.ict_case``: the face region, another topology of ~60k
triangles, noise along the normal, a hole, noisy landmarks, mm, a random rigid
motion), with the truth.  Models: ``graph`` (what a head with no expression rig
gets) and ``hybrid`` (ICT's 53 full-head shapes).

Measures, per wrap: truth error mean / p95 (mm) over ICT's fitting vertices the
scan sees; triangles among ICT's fitting vertices turned past 90 degrees from the
pose the fitted weights make (from the aligned template for ``graph``) that the
truth has not turned from the aligned template (ICT's funnel rolls the lips past
90 degrees; a fit that follows is right to); part vertices on the other side of
the skin than on the template (``through``); the part vertices' mean distance to
the whole head's truth (``parts``: ICT's identity and expression applied to every
vertex, teeth and eyeballs included); time.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _nicp_cases as cases  # noqa: E402
from facewrap.geometry import flipped_triangles  # noqa: E402
from facewrap.landmarks import Landmarks  # noqa: E402
from facewrap.wrapping import WrapSettings, wrap  # noqa: E402
from facewrap.wrapping.follow import side_changes  # noqa: E402
from facewrap.wrapping.roles import PART, cached_hidden_surface  # noqa: E402

#: (name, identity, expression): one extreme each, identities no tuning used
CASES = (("jaw open", "identity011", {"jawOpen": 1.0}),
         ("jaw open + funnel", "identity012", {"jawOpen": 0.8, "mouthFunnel": 1.0}),
         ("eyes shut", "identity013", {"eyeBlink_L": 1.0, "eyeBlink_R": 1.0}),
         ("smile, left", "identity014", {"mouthSmile_L": 1.0}),
         ("cheeks puffed", "identity015", {"cheekPuff_L": 1.0, "cheekPuff_R": 1.0}),
         ("neutral", "identity016", {}),
         ("jaw open to the side", "identity017", {"jawOpen": 0.6, "jawLeft": 1.0}),
         ("lower lip rolled in", "identity018", {"mouthRollLower": 1.0, "jawOpen": 0.3}))
MODELS = ("graph", "hybrid")


def _head():
    """ICT's full neutral head, its 68 landmark ids, its fitting vertices, its 53
    full-head shapes and its parts (as the wrap finds them)."""
    kit = cases.ict_kit()
    head = kit.neutral
    fitting = np.zeros(head.n_vertices, bool)
    fitting[np.asarray(kit.indices["idx_to_fitting_verts"])] = True
    shapes = {n: np.asarray(kit.shape(n)) for n in kit.expression_names}
    landmarks = Landmarks.from_vertices(np.asarray(kit.indices["idx_to_landmark_verts"]))
    part = cached_hidden_surface(head.vertices, head.triangles).part
    return head, landmarks, fitting, shapes, part


def _full_truth(head, shapes, identity, expression, case) -> np.ndarray:
    """The whole head's truth (parts included: ICT's shapes move the teeth with the
    jaw) in the scan's frame: ICT's identity and expression, placed by the rigid
    motion that takes its face onto the case's truth."""
    from facewrap.geometry.similarity import similarity_transform
    kit = cases.ict_kit()
    P = np.asarray(kit.shape(identity), dtype=np.float64)
    for name, w in expression.items():
        P = P + w * (shapes[name] - head.vertices)
    n = len(case.truth)
    return similarity_transform(10.0 * P[:n], case.truth, scale=False).apply(10.0 * P)


def _one(head, landmarks, fitting, shapes, part, case, model, full_truth) -> dict:
    t = time.perf_counter()
    r = wrap(head, case.scan, landmarks, case.scan_landmarks, WrapSettings(model=model),
             blendshapes=shapes if model == "hybrid" else None)
    seconds = time.perf_counter() - t
    n_face = len(case.truth)
    seen = case.mask & fitting[:n_face]
    e = np.linalg.norm(r.vertices[:n_face][seen] - case.truth[seen], axis=1)
    T = head.triangles
    aligned = r.transform.apply(head.vertices)
    rest = aligned if r.weights is None else r.transform.apply(
        head.vertices + sum(w * (shapes[k] - head.vertices)
                            for k, w in zip(r.shape_names, r.weights)))
    face = fitting[T].all(axis=1) & (T < n_face).all(axis=1)
    flips = flipped_triangles(r.vertices, rest, T) & face
    # the truth's own turns (ICT's shapes roll the inner lips past 90 degrees:
    # a fit that follows them is right to) are not counted
    truth = np.vstack([case.truth, aligned[n_face:]])
    own = flipped_triangles(truth, aligned, T) & face
    through = side_changes(T, aligned, r.vertices, np.where(part, PART, 0).astype(np.int8))
    parts = np.linalg.norm(r.vertices[part] - full_truth[part], axis=1)
    return {"mean": float(e.mean()), "p95": float(np.percentile(e, 95)),
            "flips": int((flips & ~own).sum()), "truth_flips": int(own.sum()),
            "through": int(through.sum()), "parts": float(parts.mean()),
            "time": seconds}


def run() -> dict:
    if not cases.ict_available():
        return {"rows": [], "notes": ["skipped: ../shared/data/ict-facekit is absent"]}
    head, landmarks, fitting, shapes, part = _head()
    rows = []
    for name, identity, expression in CASES:
        case = cases.ict_case(f"head expressions {name}", identity, expression)
        truth = _full_truth(head, shapes, identity, expression, case)
        for model in MODELS:
            r = _one(head, landmarks, fitting, shapes, part, case, model, truth)
            r.update(case=name, identity=identity, model=model)
            rows.append(r)
            print(f"  {name} {model}: {r['mean']:.3f} / {r['p95']:.3f} mm, "
                  f"{r['flips']} flips, {r['through']} through, parts "
                  f"{r['parts']:.2f} mm, {r['time']:.1f} s")
    return {"rows": rows, "notes": [], "vertices": head.n_vertices,
            "parts": int(part.sum())}


def markdown(r: dict) -> str:
    L = ["### ICT's full head onto extreme expressions of unseen people", ""]
    if not r["rows"]:
        return "\n".join(L + [f"- {n}" for n in r["notes"]] + [""])
    L += [f"ICT's full neutral head ({r['vertices']:,} vertices, {r['parts']:,} of them "
          "parts: eyeballs, teeth, gums, tongue, mouth socket, eye occlusion) wrapped with "
          "only its 68 landmark ids onto ICT identities 011-018 in one expression each, "
          "scanned as `bench_nicp` scans its cases (`benchmarks/bench_head_expressions.py`). "
          "Truth = distance to the truth over ICT's fitting vertices the scan sees (mm); "
          "flips = triangles among them turned past 90° from the pose the fitted weights "
          "make, that the truth has not turned (ICT's funnel and lip roll turn some); "
          "through = part vertices on the other side of the skin than on the "
          "template; parts = mean distance of the part vertices to the truth's (ICT's "
          "shapes move the teeth with the jaw and close the lids over still "
          "eyeballs; its own lids pass through the eyeballs, so a part that keeps "
          "its side of the skin is some way off). One run each.", "",
          "| expression (identity) | graph: truth mean / p95 (mm) | flips | through | "
          "parts (mm) | time (s) | hybrid: truth mean / p95 (mm) | flips | through | "
          "parts (mm) | time (s) |",
          "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    by_case = {}
    for row in r["rows"]:
        by_case.setdefault((row["case"], row["identity"]), {})[row["model"]] = row
    for (name, identity), models in by_case.items():
        cells = []
        for model in MODELS:
            x = models[model]
            cells.append(f"{x['mean']:.3f} / {x['p95']:.3f} | {x['flips']} | "
                         f"{x['through']} | {x['parts']:.2f} | {x['time']:.1f}")
        L.append(f"| {name} ({identity[-3:]}) | " + " | ".join(cells) + " |")
    for model in MODELS:
        xs = [m[model] for m in by_case.values()]
        L.append(f"\n{model}: mean of means {np.mean([x['mean'] for x in xs]):.3f} mm, "
                 f"mean of p95s {np.mean([x['p95'] for x in xs]):.3f} mm, "
                 f"{sum(x['flips'] for x in xs)} flips, "
                 f"{sum(x['through'] for x in xs)} through, parts "
                 f"{np.mean([x['parts'] for x in xs]):.2f} mm from the truth's.")
    return "\n".join(L + [""])


if __name__ == "__main__":
    print(markdown(run()))
