"""Benchmark: variants of a production head a studio might hand us, landmarks only.

ICT-FaceKit's full head (26,719 v, cm) as published and changed the ways an
exporter or a studio changes a head: other units (mm, m), another up axis (Z-up),
turned 180° about the vertical, every polygon triangulated, the vertex order of
the file permuted (parts first, skin last, polygons in the same order), another
ICT identity as the template, parts removed (a head with teeth only: eyeballs,
tear films and lashes gone) and the face region with the eyeballs only.  Each is
wrapped as ``facewrap wrap`` does with no ``vertex_indices.json`` beside the
template (the landmark ids as a plain list, the model "auto": graph) onto menpo's
``james`` (68 landmarks), MeshMonk's demo face (5 landmarks) and two ICT
identities made into face-scanner-like scans with a truth (:mod:`_head_scans`).

Measures, over ICT's ``idx_to_fitting_verts`` mapped through the variant's vertex
order: fit mean / p95 (mm, :func:`bench_heads._measures`), flipped triangles among
them, part vertices through the skin (ICT's parts table mapped, sign of the
signed distance to the skin changed from the aligned template), the landmark
error (mm), the distance to the truth where there is one, the vertices whose role
(:mod:`facewrap.wrapping.roles`) differs from the run as published, and the time.
A robust method gives the same figures for every variant up to noise (the
identity and the cut heads differ by what they are).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_heads as H  # noqa: E402
from facewrap.geometry import flipped_triangles  # noqa: E402
from facewrap.mesh import Mesh  # noqa: E402
from facewrap.wrapping import WrapSettings, wrap  # noqa: E402
from facewrap.wrapping.follow import side_changes  # noqa: E402
from facewrap.wrapping.roles import CAVITY, PART  # noqa: E402

#: ICT's polygon ranges (data README): eyeballs from here, and the face region
EYEBALL_POLYGONS = (21496, 24692)
LASH_POLYGONS_END = 26384
FACE_POLYGONS_END = 9230
#: the two ICT identities scanned with a truth, and the identity used as a template
SCANNED = ("identity001", "identity002")
OTHER_TEMPLATE = "identity010"


def _rebuilt(mesh: Mesh, vertices, faces, face_order, vertex_order=None) -> Mesh:
    """``mesh`` with new positions, its polygons in ``face_order`` and its vertices
    in ``vertex_order`` (new id i is old vertex ``vertex_order[i]``); UVs,
    materials and groups carried along."""
    n = mesh.n_vertices
    order = np.arange(n) if vertex_order is None else np.asarray(vertex_order)
    new_id = np.empty(n, np.int64)
    new_id[order] = np.arange(n)
    offsets, indices = faces
    sizes = np.diff(offsets)[face_order]
    starts = offsets[:-1][face_order]
    corners = np.repeat(starts, sizes) + (np.arange(sizes.sum())
                                         - np.repeat(np.cumsum(sizes) - sizes, sizes))
    new_offsets = np.r_[0, np.cumsum(sizes)]
    kw = {}
    if mesh.uvs is not None:
        uv_corner = (mesh.face_uvs if len(indices) == len(mesh.face_indices)
                     else mesh.triangle_uvs.ravel())
        kw.update(uvs=mesh.uvs, face_uvs=(new_offsets, uv_corner[corners]))
    per_face = (np.arange(mesh.n_faces) if len(offsets) - 1 == mesh.n_faces
                else mesh.triangle_faces)
    if mesh.face_materials is not None:
        kw.update(face_materials=mesh.face_materials[per_face][face_order],
                  materials=mesh.materials)
    if mesh.face_groups is not None:
        kw.update(face_groups=mesh.face_groups[per_face][face_order], groups=mesh.groups)
    return Mesh(np.asarray(vertices)[order], (new_offsets, new_id[indices[corners]]),
                mtllib=mesh.mtllib, **kw)


def _variants(head: Mesh, kit) -> list:
    """(name, template, vertex map: new id -> ICT id) of every variant."""
    n, V = head.n_vertices, head.vertices
    same = np.arange(n)
    polys = (head.face_offsets, head.face_indices)
    z_up = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0.]])     # +y -> +z
    turned = np.diag([-1.0, -1.0, 1.0])                      # 180° about z
    tri = head.triangles
    parts_first = np.r_[np.arange(H.SKIN_END, n), np.arange(H.SKIN_END)]
    poly_parts_first = np.r_[np.arange(14034, head.n_faces), np.arange(14034)]
    teeth_only, teeth_map = head.submesh(np.r_[0:EYEBALL_POLYGONS[0],
                                               LASH_POLYGONS_END:head.n_faces])
    face_eyes, face_eyes_map = head.submesh(np.r_[0:FACE_POLYGONS_END,
                                                  EYEBALL_POLYGONS[0]:EYEBALL_POLYGONS[1]])
    return [
        ("(a) as published (cm)", head, same),
        ("(b) mm", head.with_vertices(10.0 * V), same),
        ("(b) metres", head.with_vertices(0.01 * V), same),
        ("(c) Z-up", head.with_vertices(V @ z_up.T), same),
        ("(c) Z-up, turned 180°", head.with_vertices(V @ z_up.T @ turned.T), same),
        ("(d) triangulated", _rebuilt(head, V, (np.arange(0, 3 * len(tri) + 1, 3),
                                                tri.ravel()), np.arange(len(tri))), same),
        ("(e) parts first, skin last", _rebuilt(head, V, polys, poly_parts_first,
                                                parts_first), parts_first),
        (f"(f) {OTHER_TEMPLATE} as template",
         head.with_vertices(kit.shape(OTHER_TEMPLATE)), same),
        ("(g) teeth only (no eyeballs, lashes)", teeth_only, teeth_map),
        ("(g) face region + eyeballs", face_eyes, face_eyes_map),
    ]


def _scans(fitting):
    import _head_scans
    _, _, (james, james_lm), (demo, demo_lm) = H._inputs()
    out = [("james", james, james_lm, None, None),
           ("MeshMonk demo", demo, demo_lm, H.MESHMONK_IBUG, None)]
    for identity in SCANNED:
        try:
            scan, lm, truth = _head_scans.scanned_head(identity)
        except ValueError:       # libigl's decimation gave up: bench_heads says so too
            continue
        out.append((identity, scan, lm, None, truth))
    return out


def _one(template, vmap, ids, scan, scan_lm, truth, fitting, base_roles) -> dict:
    """One wrap of a variant and its measures, or the error it raised."""
    new_id = np.full(max(int(vmap.max()) + 1, len(fitting)), -1)
    new_id[vmap] = np.arange(len(vmap))
    lm = type(scan_lm).from_vertices(new_id[ids])
    fit_v = fitting[vmap]
    t = time.perf_counter()
    try:
        r = wrap(template, scan, lm, scan_lm, WrapSettings())
    except Exception as exc:  # noqa: BLE001 - a crash is a result here
        return {"error": f"{type(exc).__name__}: {exc}"[:160]}
    seconds = time.perf_counter() - t
    out = H._measures(r, template, scan, fit_v)
    # parts by ICT's table mapped through the variant, whatever the template holds
    T = template.triangles
    aligned = r.transform.apply(template.vertices)
    truth_roles = np.where(vmap >= H.SKIN_END, PART, 0).astype(np.int8)
    out["through"] = int(side_changes(T, aligned, r.vertices, truth_roles).sum())
    out["part_flips"] = int(flipped_triangles(r.vertices, aligned, T)[
        (vmap[T] >= H.SKIN_END).all(axis=1)].sum())
    out.update(time=seconds, landmarks=r.metrics["landmark_mean"],
               part_as_skin=int(((vmap >= H.SKIN_END) & (r.roles != PART)).sum()),
               skin_as_part=int(((vmap < H.SKIN_END) & (r.roles == PART)).sum()),
               cavity=int((r.roles[fit_v] == CAVITY).sum()),
               roles_changed=int((r.roles != base_roles[vmap]).sum())
               if base_roles is not None else 0, roles=r.roles)
    if truth is not None:
        e = np.linalg.norm(r.vertices - truth[vmap], axis=1)
        inner = fit_v & (base_roles[vmap] == CAVITY) if base_roles is not None else (
            fit_v & (r.roles == CAVITY))
        part = vmap >= H.SKIN_END
        out.update(truth_mean=float(e[fit_v].mean()),
                   truth_p95=float(np.percentile(e[fit_v], 95)),
                   inner_lips=float(e[inner].mean()),
                   parts_max=float(e[part].max()) if part.any() else float("nan"))
    return out


def run(only=None) -> dict:
    if not (H.ICT / "generic_neutral_mesh.obj").is_file():
        return {"scans": [], "notes": ["skipped: ../shared/data is absent"]}
    import _nicp_cases as C
    head, profile, _, _ = H._inputs()
    fitting = np.zeros(head.n_vertices, bool)
    fitting[profile.fitting] = True
    ibug = profile.landmarks.vertex
    variants = _variants(head, C.ict_kit())
    out = {"scans": [], "notes": []}
    for scan_name, scan, scan_lm, subset, truth in _scans(fitting):
        ids = ibug if subset is None else ibug[list(subset)]
        rows, base = {}, None
        for name, template, vmap in variants:
            if only and not any(o in name for o in only):
                continue
            r = _one(template, vmap, ids, scan, scan_lm, truth, fitting, base)
            if base is None and "roles" in r:
                base = r["roles"]
            r.pop("roles", None)
            rows[name] = r
            print(f"{scan_name:14s} {name:38s} " + _line(r), file=sys.stderr, flush=True)
        out["scans"].append({"name": scan_name, "landmarks": len(ids), "rows": rows,
                             "truth": truth is not None})
    return out


def _line(x) -> str:
    if "error" in x:
        return f"crash: {x['error']}"
    truth = (f"{x['truth_mean']:.3f} / {x['truth_p95']:.3f} | {x['inner_lips']:.3f} | "
             f"{x['parts_max']:.1f}" if "truth_mean" in x else "– | – | –")
    return (f"{x['fit_mean']:.3f} / {x['fit_p95']:.3f} | {truth} | {x['flipped']} | "
            f"{x['through']} | {x['part_flips']} | {x['landmarks']:.2f} | "
            f"{x['part_as_skin']} / "
            f"{x['skin_as_part']} | {x['roles_changed']} | {x['time']:.1f}")


def markdown(r: dict) -> str:
    L = ["### Production-head variants, landmarks only", "",
         "ICT-FaceKit's full head changed as studios and exporters change heads, each "
         "wrapped with only its landmark ids (no profile beside it, model auto → graph). "
         "Over ICT's fitting vertices mapped through the variant: fit mean / p95 (mm, "
         "off the scan's border), truth mean / p95 (mm, identities scanned by "
         "`benchmarks/_head_scans.py`; inner lips: the fitting vertices that are "
         "cavities in the run as published; parts: ICT's parts table), flipped "
         "triangles among them, through = part vertices (ICT's parts table) on the "
         "other side of the skin than on the template, part flips = flipped part "
         "triangles, landmark mean error (mm), parts taken as skin / skin taken as "
         "parts (vertices), roles changed = vertices whose role differs from the run "
         "as published. One run each.", ""]
    L += [f"{n}" for n in r.get("notes", [])]
    for s in r["scans"]:
        L += [f"**onto {s['name']}** ({s['landmarks']} landmarks)", "",
              "| variant | fit mean / p95 (mm) | truth mean / p95 (mm) | inner lips to "
              "the truth (mm) | parts to the truth, max (mm) | flipped | through | part "
              "flips | landmarks (mm) | parts as skin / skin as parts (v) | roles "
              "changed (v) | time (s) |", "|---|" + "---:|" * 11]
        L += [f"| {name} | " + _line(x) + " |" for name, x in s["rows"].items()]
        L.append("")
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    print(markdown(run(sys.argv[1:] or None)))
