"""Where the held-out benchmark's worst wraps go wrong (``bench_heldout``).

For each named case and model: the truth error per face region before the
projection (``result.warped``: ICP + landmark pull) and after it (projection +
finish), split into the part along the truth's normal (off the surface) and the
part across it (sliding on the surface); for the worst 5 % of vertices, how far
they are from the scan, and their place relative to the chin; the flipped
triangles and new creases the truth has not, by region, and whether they were
there before the projection.

    cd benchmarks && ../.venv/bin/python studies/heldout_diagnosis.py 018.0 011.0
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import _nicp_cases as cases  # noqa: E402
import bench_heldout as heldout  # noqa: E402
from facewrap.geometry import ClosestPointTree, triangle_normals, vertex_normals  # noqa: E402
from facewrap.geometry.similarity import similarity_transform  # noqa: E402
from facewrap.wrapping import WrapSettings, wrap  # noqa: E402


def _split(V, case, normals):
    d = V - case.truth
    along = np.abs(np.einsum("ij,ij->i", d, normals))
    return np.linalg.norm(d, axis=1), along, np.sqrt(np.maximum(
        np.einsum("ij,ij->i", d, d) - along ** 2, 0.0))


def _region_table(case, res, regions, normals):
    m = case.mask
    rows = []
    for name, V in (("before projection", res.warped), ("after", res.vertices)):
        e, along, across = _split(V, case, normals)
        for k, reg in enumerate(heldout.REGIONS):
            sel = m & (regions == k)
            if sel.any():
                rows.append((name, reg, int(sel.sum()), e[sel].mean(),
                             np.percentile(e[sel], 95), e[sel].max(), along[sel].mean(),
                             across[sel].mean()))
    print("    stage | region | n | mean | p95 | max | along normal | across (mm)")
    for r in rows:
        print(f"    {r[0]} | {r[1]} | {r[2]} | {r[3]:.2f} | {r[4]:.2f} | {r[5]:.2f} | "
              f"{r[6]:.2f} | {r[7]:.2f}")


def _worst(case, res, regions, tree, normals, lm_chin):
    for name, V in (("before projection", res.warped), ("after", res.vertices)):
        e, along, across = _split(V, case, normals)
        m = case.mask
        cut = np.percentile(e[m], 95)
        w = m & (e >= cut)
        dist = tree.query(V[w]).distances
        # height relative to the chin landmark along the template's up axis, cm
        up = case.template.vertices[w, 1] - lm_chin[1]
        counts = np.bincount(regions[w], minlength=len(heldout.REGIONS))
        where = ", ".join(f"{heldout.REGIONS[k]} {c}" for k, c in enumerate(counts) if c)
        print(f"    worst 5 % {name}: {w.sum()} v (error >= {cut:.2f} mm; {where}); "
              f"error mean {e[w].mean():.2f} mm = along normal {along[w].mean():.2f} / "
              f"across {across[w].mean():.2f}; distance to scan median "
              f"{np.median(dist):.2f} max {dist.max():.2f} mm; template height "
              f"above the chin landmark median {np.median(up):.2f} cm "
              f"({(up < 0).mean():.0%} below it)")


def _turn(V, ref, T):
    a, b = triangle_normals(V, T), triangle_normals(ref, T)
    cos = np.einsum("ij,ij->i", a, b) / np.maximum(
        np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-30)
    return np.degrees(np.arccos(np.clip(cos, -1, 1)))


def _neighbours(T):
    from facewrap.geometry.adjacency import triangle_adjacency
    return triangle_adjacency(T)


def _artefacts(case, res, regions, fitting):
    T = case.template.triangles
    inside = fitting[T].all(axis=1)
    al = res.transform.apply(case.template.vertices)
    tal = similarity_transform(case.template.vertices, case.truth).apply(
        case.template.vertices)
    tf, tc = heldout._flips_and_creases(case.truth, tal, T, inside)
    for name, V in (("before projection", res.warped), ("after", res.vertices)):
        f, c = heldout._flips_and_creases(V, al, T, inside)
        ef, ec = np.setdiff1d(f, tf), np.setdiff1d(c, tc)
        turn = _turn(V, al, T)[ef]
        truth_turn = _turn(case.truth, tal, T)[ef]
        if len(ef):
            print(f"    {name}: flips not in truth turned {np.median(turn):.0f} deg median "
                  f"(max {turn.max():.0f}); the truth turns those {np.median(truth_turn):.0f}"
                  f" deg median (min {truth_turn.min():.0f}); neighbours of a truth flip: "
                  f"{np.isin(_neighbours(T)[ef], tf).any(axis=1).mean():.0%}")
        print(f"    {name}: flips {len(f)} ({len(ef)} not in truth: "
              f"{heldout._by_region(ef, T, regions)}), creases {len(c)} ({len(ec)} not "
              f"in truth: {heldout._by_region(ec // len(T), T, regions)})")


def main(names):
    fitting, regions = heldout._template_labels()
    kit = cases.ict_kit()
    chin = cases.ict_template()[0].vertices[kit.indices["idx_to_landmark_verts"][8]]
    table = {c[0]: c for c in heldout.held_out_cases()}
    for name in names:
        _, kind, identity, expr = table[name]
        case = cases.ict_case(f"held-out {name}", identity, expr)
        tree = ClosestPointTree(case.scan.vertices, case.scan.triangles)
        normals = vertex_normals(case.truth, case.template.triangles)
        print(f"== {name} {case.note}")
        for model in heldout.MODELS:
            res = wrap(case.template, case.scan, case.landmarks, case.scan_landmarks,
                       WrapSettings(model=model, project=True),
                       blendshapes=case.blendshapes if model == "hybrid" else None)
            top = ""
            if res.weights is not None:
                order = np.argsort(-np.abs(res.weights))[:5]
                top = ", ".join(f"{res.shape_names[i]} {res.weights[i]:.2f}" for i in order)
            print(f"  -- {model}: {heldout.nicp._errors(res.vertices, case)} "
                  f"(before projection {heldout.nicp._errors(res.warped, case)}) "
                  f"{('weights: ' + top) if top else ''}")
            _region_table(case, res, regions, normals)
            _worst(case, res, regions, tree, normals, chin)
            _artefacts(case, res, regions, fitting)
            print(f"    projection: {res.metrics.get('projection')}; finish: "
                  f"{res.metrics.get('finish')}; pull: {res.metrics.get('landmark_pull')}")


if __name__ == "__main__":
    main(sys.argv[1:])
