"""Benchmark: real scans without ground truth, facewrap next to its peers.

On a real scan nothing says where each template vertex belongs, so a result is
judged by what a user checks: how tightly it fits the scan away from the scan's
borders, whether the landmarks stay where they were put, and whether triangles
fold.  Cases (from ../shared/data, skipped when absent):

* ICT-FaceKit's face (9,409 v, 68 landmarks, 53 expression shapes, cm) onto
  menpo's ``james`` scan (12,228 triangles, 68 landmarks, mm);
* MeshMonk's own face template (7,160 v, 5 landmarks) onto MeshMonk's demo scan
  (10,000 v with neck and shoulders) — the peer's home ground.

Every method starts from the same landmark similarity and gets the same
landmarks (MeshMonk takes none); each runs in a forked child with a time limit
(:func:`bench_nicp._safe`).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_nicp as nicp  # noqa: E402
from _nicp_cases import Case  # noqa: E402
from facewrap.evaluate import surface_distances  # noqa: E402
from facewrap.geometry import new_creases, triangle_quality  # noqa: E402
from facewrap.landmarks import pair_landmarks, snap_to_surface  # noqa: E402
from facewrap.wrapping import WrapSettings, wrap  # noqa: E402

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def _cases() -> list[tuple[Case, tuple]]:
    from facewrap.io import read_mesh
    from facewrap.io.landmarks import read_landmarks, read_ljson
    out = []
    james = DATA / "scans/james/james.obj"
    if james.is_file() and nicp.cases.ict_available():
        from facewrap.io.profile import read_template_profile
        face, landmarks, shapes = nicp.cases.ict_template()
        scan = read_mesh(james)
        fitting = np.zeros(face.n_vertices, bool)
        ids = read_template_profile(nicp.cases.ict_kit().folder / "vertex_indices.json").fitting
        fitting[ids[ids < face.n_vertices]] = True
        out.append((Case("ICT face → james", face, landmarks, shapes, scan,
                         read_ljson(DATA / "scans/james/james.ljson"), None, fitting),
                    ("hybrid", "graph")))
    mm = DATA / "scans/meshmonk"
    if (mm / "DemoFace_10K.obj").is_file():
        template = read_mesh(mm / "Template.obj")
        # MeshMonk's template landmarks are x, y, z points: put them on the surface
        # once, so every method gets the same ones
        lm, _ = snap_to_surface(read_landmarks(mm / "TemplateLandmarks.csv"),
                                template.vertices, template.triangles)
        out.append((Case("MeshMonk template → MeshMonk demo face", template, lm, None,
                         read_mesh(mm / "DemoFace_10K.obj"),
                         read_landmarks(mm / "DemoFaceLandmarks.csv"), None, None),
                    ("graph",)))
    return out


def _folds(V, ref, T) -> int:
    """Edge-adjacent triangle pairs that face apart in ``V`` but not in the
    template: a crease or fold the fit made, whatever the global pose
    (:func:`facewrap.geometry.new_creases`)."""
    return len(new_creases(V, ref, T))


def measures(V, case: Case, aligned=None) -> dict:
    """Fit (away from the scan's borders), landmark error and folds of ``V``.

    ``aligned`` (n, 3): the template as the method's own similarity put it (a
    wrap's ``transform``), which ``flipped`` is counted against, as
    :mod:`bench_heads` and the wrap count; ``flipped_umeyama`` is counted against
    the template fitted onto ``V`` by a similarity over all its vertices (the
    only choice for a peer).  The two differ by a degree or two, enough to count
    triangles the unfolding left just short of 90 degrees (ICT face onto james,
    graph: 2 against 0)."""
    T = case.template.triangles
    # case.mask: the vertices a template means to fit (ICT's own fitting vertices),
    # the same for every method; None: all
    d = surface_distances(V, case.scan, exclude_border=True, mask=case.mask)
    ia, ib = pair_landmarks(case.landmarks, case.scan_landmarks)
    e = np.linalg.norm(case.landmarks.positions(V, T)[ia]
                       - case.scan_landmarks.positions(case.scan.vertices,
                                                       case.scan.triangles)[ib], axis=1)
    q = triangle_quality(V, T, reference=case.template.vertices)
    flipped = q.flipped if aligned is None else triangle_quality(
        V, T, reference=aligned, align=False).flipped
    # only where the scan is: off the scan a template is free to do anything
    on = d.covered[T].all(axis=1)
    return {"fit_mean": float(d.counted().mean()),
            "fit_p95": float(np.percentile(d.counted(), 95)),
            "coverage": d.coverage, "landmark_mean": float(e.mean()),
            "landmark_max": float(e.max()),
            "flipped": int(flipped[on].sum()), "flipped_umeyama": int(q.flipped[on].sum()),
            "flipped_all": int(flipped.sum()),
            "folds": _folds(V, case.template.vertices, T)}


def run_facewrap(case: Case, model: str, pull: bool = True) -> dict:
    c = time.process_time()
    t = time.perf_counter()
    res = wrap(case.template, case.scan, case.landmarks, case.scan_landmarks,
               WrapSettings(model=model, landmark_pull=pull),
               blendshapes=case.blendshapes if model == "hybrid" else None)
    total = time.perf_counter() - t
    aligned = res.transform.apply(case.template.vertices)
    return {"method": f"facewrap {model}" + ("" if pull else ", no landmark pull"),
            "time": total,
            "cpu": time.process_time() - c, **measures(res.vertices, case, aligned),
            "unprojected": measures(res.warped, case, aligned)}


#: seeds of the perturbed runs: landmark noise of this size (mm, the scan's units)
PERTURB_SEEDS = range(5)
PERTURB_NOISE = 0.1


def perturbed_runs(case: Case) -> list[dict]:
    """The hybrid wrap of ``case`` with its scan landmarks moved by
    ``PERTURB_NOISE`` mm of noise, one run per seed: fit p95 and the triangles of
    the fitting set turned past 90 degrees from the fit's own expression (the
    aligned template plus its fitted shapes, :attr:`ModelFit.rest`: what facewrap
    unfolds against, since ICT's own expressions turn triangles of the neutral).
    The wrap is run stage by stage, as :func:`wrap` runs it, to have that pose."""
    from facewrap.geometry import turned_triangles
    from facewrap.landmarks import Landmarks
    from facewrap.wrapping.stages import (align, finish_fit, fit_model, prepare_wrap,
                                          project, pull_landmarks)
    T = case.template.triangles
    counted = case.mask[T].all(axis=1) if case.mask is not None else np.ones(len(T), bool)
    rows = []
    for seed in PERTURB_SEEDS:
        lm = case.scan_landmarks
        P = lm.positions(case.scan.vertices, case.scan.triangles)
        P = P + np.random.default_rng(seed).normal(scale=PERTURB_NOISE, size=P.shape)
        problem = prepare_wrap(case.template, case.scan, case.landmarks,
                               Landmarks.from_points(P, lm.names),
                               WrapSettings(model="hybrid"), blendshapes=case.blendshapes)
        similarity = align(problem)
        fitted = fit_model(problem, similarity.apply(case.template.vertices), similarity,
                           None)
        V, _ = pull_landmarks(problem, fitted.vertices)
        projection = project(problem, V, reference=fitted.rest)
        out, _ = finish_fit(problem, projection.vertices, similarity, projection,
                            rest=fitted.rest)
        fit = measures(out, case, similarity.apply(case.template.vertices))
        rows.append({"seed": seed, "fit_p95": fit["fit_p95"],
                     "flipped_rest": int(turned_triangles(out, fitted.rest, T)[counted].sum()),
                     "flipped": fit["flipped"]})
    return rows


def run_peer(case: Case, peer: str) -> dict:
    c = time.process_time()
    t = time.perf_counter()
    V = nicp.peer_vertices(case, peer)
    total = time.perf_counter() - t
    return {"method": peer, "time": total, "cpu": time.process_time() - c,
            **measures(V, case)}


def run() -> dict:
    out = {"cases": [], "notes": []}
    found = _cases()
    if not found:
        out["notes"].append("skipped: ../shared/data/scans is absent")
    for case, models in found:
        rows = [nicp._safe(run_facewrap, case, m, method=f"facewrap {m}")
                for m in models]
        # what the landmark pull (WrapSettings.landmark_tolerance) changes
        rows.append(nicp._safe(run_facewrap, case, models[-1], False,
                               method=f"facewrap {models[-1]}, no landmark pull"))
        rows += [nicp._safe(run_peer, case, p, method=p) for p in nicp._peers_available()]
        out["cases"].append({"name": case.name, "template": case.template.n_vertices,
                             "scan": len(case.scan.triangles),
                             "landmarks": len(pair_landmarks(case.landmarks,
                                                             case.scan_landmarks)[0]),
                             "rows": rows,
                             "perturbed": perturbed_runs(case) if "hybrid" in models
                             else []})
    return out


def markdown(r: dict) -> str:
    L = ["### Real scans without ground truth: fit, landmarks, folds", "",
         "Fit = distance from each result vertex to the scan, over the vertices whose "
         "closest scan point is not on the scan's border (holes, outline) — the part "
         "of the template the scan sees — and, for ICT, among ICT's own fitting "
         "vertices (`idx_to_fitting_verts`: not the nostril interiors, eye rims and "
         "inner lips that facewrap leaves to follow); mm. Landmarks = distance between the "
         "template's landmarks on the result and the scan's. Flipped = triangles on "
         "the seen part whose normal turned past 90° from the (similarity-aligned) "
         "template's (the wrap's own landmark similarity for facewrap; for a peer, a "
         "similarity over all vertices, facewrap's count against that in square brackets); "
         "folds = edge-adjacent triangle pairs facing apart that did not "
         "in the template, anywhere. facewrap pulls landmarks the fit left more "
         "than 0.2 % of the template's size from their targets to that distance "
         "(`WrapSettings.landmark_tolerance`; one row without), then projects onto "
         "the scan (which makes its fit ~0 where the scan is clean); its result "
         "before the projection is in brackets.", ""]
    for note in r.get("notes", []):
        L += [note, ""]
    for c in r["cases"]:
        L += [f"**{c['name']}** — template {c['template']:,} v, scan "
              f"{c['scan']:,} triangles, {c['landmarks']} landmarks.", "",
              "| method | fit mean / p95 (mm) | landmarks mean / max (mm) | flipped "
              "(seen) | folds | time (s) |", "|---|---:|---:|---:|---:|---:|"]
        for x in c["rows"]:
            if "error" in x:
                L.append(f"| {x['method']} | failed: {x['error']} | | | | |")
                continue
            u = x.get("unprojected")
            um = f" [{x['flipped_umeyama']}]" if u else ""

            def both(key, fmt=".2f", x=x, u=u):
                v = format(x[key], fmt)
                return f"{v} ({format(u[key], fmt)})" if u else v
            L.append(f"| {x['method']} | {both('fit_mean')} / {both('fit_p95')} | "
                     f"{both('landmark_mean')} / {both('landmark_max')} | "
                     f"{both('flipped', 'd')}{um} | {both('folds', 'd')} | "
                     f"{x['time']:.1f} |")
        L.append("")
        if c.get("perturbed"):
            L += [f"The hybrid again with the scan landmarks moved by {PERTURB_NOISE} mm "
                  "of noise (one seed a run): fit p95 (mm); flipped in the fitting set "
                  "against the fit's own expression (the aligned template plus its "
                  "fitted shapes, what facewrap unfolds against) and, as above, against "
                  "the neutral on the seen part.", "",
                  "| seed | fit p95 (mm) | flipped vs its expression | flipped vs the "
                  "neutral (seen) |", "|---:|---:|---:|---:|"]
            L += [f"| {x['seed']} | {x['fit_p95']:.3f} | {x['flipped_rest']} | "
                  f"{x['flipped']} |" for x in c["perturbed"]]
            L.append("")
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    print(markdown(run()))
