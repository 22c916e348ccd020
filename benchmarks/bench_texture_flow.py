"""Benchmark: expression wraps refined by texture (issue 19, optical flow).

A person's expression scans are wrapped as :func:`facewrap.rig.build_rig` wraps
them (warm-started from the neutral's wrap, geometry only), then refined by
:func:`facewrap.rig.refine_by_texture` against two reference textures in the
template's layout:

- **baked**: the neutral scan's texture baked onto the neutral's wrap, what
  ``build_rig`` uses.  The refinement can only put each vertex on the skin the
  *neutral's wrap* put it on, so against the ground truth its floor is the
  neutral wrap's own tangential error;
- **true skin**: the skin's own image in the template's layout (the oracle
  reference: what the baked texture would be after a perfect neutral wrap).  It
  measures the flow refinement itself.

Errors (mm, over the fitted vertices the scan sees) per expression: the
*tangential* error (the part of result − truth in the truth's tangent plane, the
slide geometry cannot see), the total error, and the tangential error against
the neutral's correspondence (where the neutral wrap's skin truly went in this
expression: the error that enters the rig's shapes).

Cases: (a) the built-in sample, its procedural skin (512² texture), expressions
made on identity 1; (b) ICT-FaceKit identity 004 made a person whose expressions
are not ICT's (``bench_rig``: a 1.4× one-sided smile, brows rising unevenly, a
twisting jaw), scanned in another topology with noise and a hole, each scan
given a procedural skin in ICT's UV layout (each scan vertex takes the UV of its
source point on the truth).  Each case's rig is also built with the refinement on,
as ``build_rig`` runs it, and timed: beyond the neutral (its wrap, shapes and
baked texture), the seconds per expression scan (its wrap, its refinement, its
share of the stabilisation and the example fit).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _nicp_cases as cases  # noqa: E402
from facewrap.geometry import ClosestPointTree  # noqa: E402
from facewrap.geometry.normals import vertex_normals  # noqa: E402
from facewrap.mesh import Mesh  # noqa: E402
from facewrap.rig import TextureFlowSettings, build_rig, refine_by_texture  # noqa: E402
from facewrap.texture.bake import bake_texture  # noqa: E402
from facewrap.wrapping.follow import follow_skin  # noqa: E402
from facewrap.wrapping.roles import FITTED, PART  # noqa: E402

SAMPLE_EXPRESSIONS = ({"brow_raise": 1.0}, {"smile": 1.0}, {"jaw_open": 0.6, "smile": 0.4})
OFF = TextureFlowSettings(enabled=False)


def _errors(V, truth, T, mask) -> dict:
    """Tangential and total error (mean, mm) of ``V`` against ``truth`` over ``mask``."""
    N = vertex_normals(np.nan_to_num(truth), T)
    d = V - truth
    tangential = d - np.einsum("ij,ij->i", d, N)[:, None] * N
    return {"tangential": float(np.linalg.norm(tangential, axis=1)[mask].mean()),
            "total": float(np.linalg.norm(d, axis=1)[mask].mean())}


def _carried(neutral_wrap, neutral_truth, truth, T):
    """Where the neutral wrap's skin truly went: each neutral wrap vertex's place on
    the true neutral (triangle + barycentric), in the expression's truth."""
    cp = ClosestPointTree(np.nan_to_num(neutral_truth), T).query(neutral_wrap)
    return np.einsum("kj,kjd->kd", cp.barycentric, np.nan_to_num(truth)[T[cp.triangles]])


def _rigs(template, neutral_scan, neutral_image, landmarks, scan_landmarks, shapes,
          scans, images, expression_landmarks, weights):
    """The rig by geometry alone (whose expression wraps the rows refine) and the
    seconds of the rig built with the refinement on, as ``build_rig`` runs it (the
    neutral's bake, then each expression's wrap, refinement, stabilisation, fit)."""
    common = dict(expression_scans=scans, expression_landmarks=expression_landmarks,
                  expression_weights=weights)
    rig = build_rig(template, neutral_scan, landmarks, scan_landmarks, shapes,
                    texture_flow=OFF, **common)
    on = build_rig(template, neutral_scan, landmarks, scan_landmarks, shapes,
                   texture=neutral_image, expression_textures=images, **common)
    t = dict(on.timings)
    t["per_expression"] = (t["total"] - t["wrap"] - t["shapes"] - t.get("texture", 0.0)
                           ) / len(scans)
    return rig, t


def _refined(template, w, reference, scan, image, settings):
    roles = w.roles
    aligned = w.transform.apply(template.vertices)
    follow = ((lambda V: follow_skin(template.triangles, aligned, V, roles))
              if (roles == PART).any() else None)
    return refine_by_texture(template, w.vertices, reference, scan, image, settings,
                             movable=roles == FITTED, on_scan=w.projection.projected,
                             follow=follow)


def _rows(template, rig, neutral_scan, neutral_image, oracle, items, face_T, settings):
    """Per expression: errors of the geometric wrap and of both refinements."""
    t = time.perf_counter()
    baked = bake_texture(rig.wrap.mesh, neutral_scan, neutral_image,
                         size=settings.texture_size).image
    bake_s = time.perf_counter() - t
    rows = []
    for w, (name, scan, image, truth, mask, neutral_truth) in zip(rig.expression_wraps,
                                                                  items):
        mask = mask & w.projection.projected
        carried = _carried(rig.wrap.vertices, neutral_truth, truth, face_T)
        row = {"expression": name, "geometry": _errors(w.vertices, truth, template.triangles,
                                                       mask)}
        row["geometry"]["carried"] = _errors(w.vertices, carried, template.triangles,
                                             mask)["tangential"]
        for label, reference in (("baked", baked), ("true skin", oracle)):
            cpu = time.process_time()
            r = _refined(template, w, reference, scan, image, settings)
            cpu = time.process_time() - cpu
            e = _errors(r.vertices, truth, template.triangles, mask)
            e["carried"] = _errors(r.vertices, carried, template.triangles,
                                   mask)["tangential"]
            e.update(seconds=r.seconds, cpu=cpu, rounds=sum(x["kept"] for x in r.rounds),
                     matches=r.rounds[0]["matches"] if r.rounds else 0)
            row[label] = e
        rows.append(row)
    return rows, bake_s


def run_sample(settings=None) -> dict:
    from facewrap.sample import make_scan, make_template
    settings = settings or TextureFlowSettings()
    tpl = make_template()
    neutral = make_scan(tpl, weights={}, seed=0)
    scans = [make_scan(tpl, weights=w, seed=j + 1) for j, w in enumerate(SAMPLE_EXPRESSIONS)]
    rig, timed = _rigs(tpl.mesh, neutral.mesh, neutral.texture, tpl.landmarks,
                       neutral.landmarks, tpl.blendshapes, [s.mesh for s in scans],
                       [s.texture for s in scans], [s.landmarks for s in scans],
                       list(SAMPLE_EXPRESSIONS))
    n_face = len(tpl.parts["face"])
    T = tpl.mesh.triangles
    face_T = T[(T < n_face).all(axis=1)]
    face = np.arange(tpl.mesh.n_vertices) < n_face
    items = [(" + ".join(f"{k} {v:g}" for k, v in w.items()), s.mesh, s.texture,
              s.ground_truth, face & np.isfinite(s.ground_truth).all(axis=1),
              neutral.ground_truth) for w, s in zip(SAMPLE_EXPRESSIONS, scans)]
    # the sample template's UVs are the scans' parameter layout: the skin's own image
    rows, bake_s = _rows(tpl.mesh, rig, neutral.mesh, neutral.texture, neutral.texture,
                         items, face_T, settings)
    return {"case": "sample", "rows": rows, "bake_s": bake_s, "rig_timings": timed,
            "neutral": _errors(rig.wrap.vertices, neutral.ground_truth, T,
                               face & np.isfinite(neutral.ground_truth).all(axis=1)
                               & rig.wrap.projection.projected)}


def compare_methods() -> list[dict]:
    """DIS against Farnebäck on the sample's brow raise (true-skin reference, so the
    flow alone decides): tangential error and CPU seconds of the refinement."""
    from facewrap.sample import make_scan, make_template
    from facewrap.wrapping import WrapSettings, wrap
    tpl = make_template()
    scan = make_scan(tpl, weights={"brow_raise": 1.0}, seed=1)
    w = wrap(tpl.mesh, scan.mesh, tpl.landmarks, scan.landmarks,
             WrapSettings(model="hybrid"), blendshapes=tpl.blendshapes)
    n_face = len(tpl.parts["face"])
    mask = ((np.arange(tpl.mesh.n_vertices) < n_face)
            & np.isfinite(scan.ground_truth).all(axis=1) & w.projection.projected)
    T = tpl.mesh.triangles
    rows = [{"method": "geometry alone", **_errors(w.vertices, scan.ground_truth, T, mask)}]
    for method in ("dis", "farneback"):
        cpu = time.process_time()
        r = _refined(tpl.mesh, w, scan.texture, scan.mesh, scan.texture,
                     TextureFlowSettings(method=method))
        rows.append({"method": method, "cpu": time.process_time() - cpu,
                     **_errors(r.vertices, scan.ground_truth, T, mask)})
    return rows


def skin_image(size: int = 2048, seed: int = 7) -> np.ndarray:
    """(size, size, 3) uint8: a procedural skin (blotches and freckles at a few
    scales on a skin tone), for any UV layout."""
    from scipy.ndimage import gaussian_filter
    rng = np.random.default_rng(seed)
    shade = np.zeros((size, size))
    for sigma, amp in ((48.0, 0.10), (12.0, 0.08), (4.0, 0.06), (1.5, 0.04)):
        f = gaussian_filter(rng.standard_normal((size, size)), sigma * size / 2048,
                            mode="wrap")
        shade += amp * f / max(f.std(), 1e-12)
    tone = np.array([0.85, 0.64, 0.52])
    img = tone * (1.0 + shade)[..., None]
    return np.clip(np.rint(255 * img), 0, 255).astype(np.uint8)


def _textured_scan(scan: Mesh, truth, template: Mesh) -> Mesh:
    """``scan`` with each vertex given the UV of its source point on the truth
    (the template's layout on the true surface)."""
    cp = ClosestPointTree(truth, template.triangles).query(scan.vertices)
    corner_uvs = template.uvs[template.triangle_uvs][cp.triangles]       # (k, 3, 2)
    uvs = np.einsum("kj,kjd->kd", cp.barycentric, corner_uvs)
    return Mesh(scan.vertices, scan.triangles, uvs=uvs)


def run_ict(k: int = 3, settings=None) -> dict:
    import bench_rig
    settings = settings or TextureFlowSettings()
    examples = bench_rig.EXAMPLES[:k]
    neutral, face, own, frame, made = bench_rig._example_cases(
        bench_rig.EXAMPLE_IDENTITY, examples)
    template = neutral.template
    image = skin_image()
    n_scan = _textured_scan(neutral.scan, neutral.truth, template)
    scans = [_textured_scan(c.scan, c.truth, template) for c, _ in made]
    rig, timed = _rigs(template, n_scan, image, neutral.landmarks, neutral.scan_landmarks,
                       neutral.blendshapes, scans, [image] * len(scans),
                       [c.scan_landmarks for c, _ in made], list(examples))
    # the neutral correspondence is found in the template's topology, so each
    # expression's truth may stay in its own (moved) frame
    items = [(", ".join(f"{n} {v:g}" for n, v in w.items()), s, image, c.truth, c.mask,
              neutral.truth) for (c, _), s, w in zip(made, scans, examples)]
    rows, bake_s = _rows(template, rig, n_scan, image, image, items,
                         template.triangles, settings)
    return {"case": f"ICT {bench_rig.EXAMPLE_IDENTITY}", "rows": rows, "bake_s": bake_s,
            "rig_timings": timed,
            "neutral": _errors(rig.wrap.vertices, neutral.truth, template.triangles,
                               neutral.mask & rig.wrap.projection.projected)}


def run(quick: bool = False, log=print) -> dict:
    out = {"cases": [run_sample()], "notes": [], "methods": compare_methods()}
    log("texture flow sample: " + _summary(out["cases"][-1]))
    if cases.ict_available():
        out["cases"].append(run_ict(2 if quick else 3))
        log("texture flow ICT: " + _summary(out["cases"][-1]))
    else:
        out["notes"].append("ICT case skipped: ../shared/data/ict-facekit not found")
    return out


def _summary(case: dict) -> str:
    return (", ".join(f"{r['geometry']['tangential']:.3f} -> {r['baked']['tangential']:.3f}"
                      f" / {r['true skin']['tangential']:.3f}" for r in case["rows"])
            + f" mm; {case['rig_timings']['per_expression']:.2f} s per expression")


def markdown(result: dict) -> str:
    lines = ["## Expression wraps refined by texture (issue 19)", "",
             __doc__.split("\n\n", 1)[1].strip(), ""]
    for case in result["cases"]:
        n = case["neutral"]
        lines += [f"**{case['case']}** (the neutral wrap's own error: tangential "
                  f"{n['tangential']:.3f} mm, total {n['total']:.3f} mm; baking its texture "
                  f"{case['bake_s']:.2f} s):", "",
                  "| expression | reference | tangential (mm) | change | total (mm) | "
                  "tangential vs the neutral's skin (mm) | rounds kept | CPU s |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in case["rows"]:
            g = r["geometry"]
            lines.append(f"| {r['expression']} | geometry alone | {g['tangential']:.3f} | | "
                         f"{g['total']:.3f} | {g['carried']:.3f} | | |")
            for label in ("baked", "true skin"):
                e = r[label]
                change = 100.0 * (e["tangential"] / g["tangential"] - 1.0)
                lines.append(f"| | {label} | {e['tangential']:.3f} | {change:+.0f} % | "
                             f"{e['total']:.3f} | {e['carried']:.3f} | {e['rounds']} | "
                             f"{e['cpu']:.1f} |")
        t = case.get("rig_timings")
        if t:
            lines += ["", f"`build_rig` with the refinement on ({len(case['rows'])} "
                      f"expressions, s): neutral wrap {t['wrap']:.2f}, shapes "
                      f"{t['shapes']:.2f}, the neutral's texture {t.get('texture', 0):.2f} "
                      f"and the refinements {t.get('texture_flow', 0):.2f} (both on threads "
                      f"beside the wraps), expression wraps with them {t['expressions']:.2f}, "
                      f"stabilisation {t['stabilise']:.2f}, "
                      f"example fit {t['examples']:.2f}: **{t['per_expression']:.2f} s per "
                      "expression** beyond the neutral (the whole less its wrap, shapes "
                      "and bake)."]
        lines.append("")
    if result.get("methods"):
        lines += ["The flow: DIS against Farnebäck (sample, brow raise, true-skin "
                  "reference; OpenCV's defaults otherwise):", "",
                  "| flow | tangential (mm) | total (mm) | CPU s |", "|---|---|---|---|"]
        for m in result["methods"]:
            cpu = f"{m['cpu']:.1f}" if "cpu" in m else ""
            lines.append(f"| {m['method']} | {m['tangential']:.3f} | {m['total']:.3f} | "
                         f"{cpu} |")
        lines.append("")
    lines += result["notes"]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown(run(quick="--quick" in sys.argv)))
