"""Benchmark: deformation transfer (Sumner 2004) and landmark-guided avatar
blendshapes (Onizuka 2019) on ../shared/data, plus a synthetic case that always
runs.  Writes only the pictures ``docs/images/avatar_<name>.png`` (a few key shapes
per avatar, plain vs landmark-guided); every other output goes to a temporary
folder."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from _timing import best_of
from facewrap.geometry.similarity import similarity_transform
from facewrap.geometry import face_areas, face_normals
from facewrap.sample import make_scan, make_template
from facewrap.avatar import AvatarTransfer
from facewrap.transfer import DeformationTransfer, find_correspondence

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
IMAGES = Path(__file__).resolve().parents[1] / "docs" / "images"


#: measured once (session 3, by sweeping w_I on cat -> lion and ICT -> Oldman)
# Evidence from benchmarks/studies/cat_lion_oracle (sensitivity.py, oracle_vertex.py).
_OUT_OF_REACH = (
    " **Why ≤ 0.5 % is out of reach without Sumner's own cat–lion markers** "
    "(`benchmarks/studies/cat_lion_oracle/`): (1) correspondences that do not look at "
    "the ground truth (other w_I, more closest-point iterations, deforming the lion "
    "instead, five markers left out, soft Gaussian partners) land at 1.12–1.58 % raw "
    "and lie 0.19–0.87 % (median 0.47 %) from *each other*: two valid "
    "correspondences disagree by about the aim. (2) Half the raw error sits in 10 % "
    "of the lion, the lower flanks and belly where the cat's skin folds between legs "
    "and body: the lion's own gradients in those four regions alone give 0.69 % raw, "
    "in eight regions 0.47 %. (3) Partners chosen with the ground truth (weights "
    "over the 16 nearest cat triangles, rounded to 0/1 pairs) give 0.34 % raw "
    "(0.48 % through `DeformationTransfer`); sliding our lion centroids by those "
    "partners' offset, "
    "smoothed over one lion edge, recovers most of it (0.70 %), over four edges "
    "less (1.10 %). Sumner's correspondence differs from ours by a slide of a few "
    "edge lengths in the flanks, which is what marker placement decides; the 55 "
    "markers here are a third party's (Sumner published his horse–camel markers, "
    "not his cat–lion ones).")
_STIFF_IDENTITY = (" A much stiffer identity term (w_I = 10 instead of 0.001) is the one change that helps: 1.26 % raw / 0.63 % aligned, flat from there on; it is not the default because on ICT → Oldman it raises the plain solve's new flips from 140 to 210 and the unmatched target triangles from 604 to 883.")


def _ambiguity_text(a: dict) -> str:
    return (f"**Where to add markers** (`facewrap transfer --ambiguity`, "
            f"`transfer.partner_ambiguity`, {a['seconds']:.2f} s): the spread of the "
            "pose gradients over each lion triangle's 8 candidate cat partners ranks "
            "the error of the transferred gradients against Sumner's with Spearman "
            f"ρ = {a['spearman']:.2f}; the 10 % most ambiguous triangles carry "
            f"{a['ratio']:.1f}× the error of the rest, and {a['hints_in_flanks']} of "
            f"the {a['hints']} suggested marker places lie in the lower flanks and "
            "belly, where the study found half of the error.")


def _flips(X, mesh) -> int:
    n0 = face_normals(mesh.vertices, mesh.triangles)
    return int(np.sum(np.einsum("ij,ij->i", face_normals(X, mesh.triangles), n0) < 0))


def _new_flips(out, target, shapes, source, corr) -> int:
    """Flipped target triangles none of whose source partners flip in the source
    shape ``P``: flips the transfer made, not ones it copied (a lid rolling over
    the eye, lips pressed through each other turn source triangles past 90° too)."""
    from facewrap.transfer import complete_pairs, pair_matrix
    pairs, _ = complete_pairs(pair_matrix(corr), target.triangles)
    n0 = face_normals(target.vertices, target.triangles)
    s0 = face_normals(source.vertices, source.triangles)
    count = 0
    for X, P in zip(out, shapes):
        flipped = np.einsum("ij,ij->i", face_normals(X, target.triangles), n0) < 0
        src = np.einsum("ij,ij->i", face_normals(P, source.triangles), s0) < 0
        count += int(np.sum(flipped & ~((pairs @ src.astype(np.float64)) > 0)))
    return count


def _folds(X, V0, T) -> int:
    """Edge-adjacent triangle pairs facing apart (dot < 0) in X but not in V0: folds,
    a rotation-independent flip count for whole-body poses."""
    from facewrap.transfer import adjacent_triangle_pairs
    pairs = adjacent_triangle_pairs(T)
    def apart(P):
        n = face_normals(P, T)
        return np.einsum("ij,ij->i", n[pairs[:, 0]], n[pairs[:, 1]]) < 0
    return int(np.sum(apart(X) & ~apart(V0)))


def synthetic() -> dict:
    tpl = make_template(64)
    face, vmap = tpl.mesh.submesh(tpl.mesh.face_groups == 0)
    scan = make_scan(tpl, weights={}, resolution=90, noise=0, holes=0, crop=False,
                     transform=False, texture_size=8)
    markers = (tpl.landmarks.vertex,
               cKDTree(scan.mesh.vertices).query(scan.landmarks.points)[1])
    t = time.perf_counter()
    corr = find_correspondence(face, scan.mesh, markers)
    dt = DeformationTransfer().fit(face, scan.mesh, corr)
    fit = time.perf_counter() - t
    P = np.stack([v[vmap] for v in tpl.blendshapes.values()])
    per = best_of(lambda: dt.transfer(P))[0] / len(P)
    return {"case": f"sample face ({face.n_vertices:,} v, quads) → scan "
                    f"({scan.mesh.n_vertices:,} v, triangles)",
            "fit": fit, "per_pose": per, "poses": len(P)}


def cat_lion() -> dict:
    from facewrap.datasets import load_sumner_pair
    p = load_sumner_pair(DATA / "sumner2004" / "cat-lion" / "markers-cat-lion.yml")
    s, t = p.source, p.target
    t0 = time.perf_counter()
    corr = find_correspondence(s.reference, t.reference, p.markers)
    t1 = time.perf_counter()
    dt = DeformationTransfer(anchor=t.reference.n_vertices - 1).fit(s.reference,
                                                                    t.reference, corr)
    out = dt.transfer(np.stack(s.poses))
    t2 = time.perf_counter()
    diag = t.reference.scale()
    err, rigid, shift, at_anchor = [], [], [], []
    a = t.reference.n_vertices - 1
    for X, G in zip(out, t.poses):
        err.append(100 * np.linalg.norm(X - G, axis=1).mean() / diag)
        shift.append(100 * np.linalg.norm(X + (G - X).mean(0) - G, axis=1).mean() / diag)
        R = similarity_transform(X, G, scale=False)
        e = np.linalg.norm(R.apply(X) - G, axis=1)
        rigid.append(100 * e.mean() / diag)
        at_anchor.append(100 * e[a] / diag)
    return {"corr": t1 - t0, "fit_and_poses": t2 - t1, "err": err, "rigid": rigid,
            "shift": shift, "at_anchor": at_anchor, "pairs": len(corr),
            "names": s.names, "ambiguity": _ambiguity_check(s, t, corr, out)}


def _ambiguity_check(s, t, corr, out) -> dict:
    """Does :func:`partner_ambiguity` point where the transfer is wrong?  Rank
    correlation with the error of the transferred lion gradients against Sumner's
    poses, the error ratio of the 10 % most ambiguous triangles, and how many
    marker hints lie in the lower flanks and belly (the study's five worst regions:
    within 0.08 of their centres, lion units)."""
    from scipy.stats import spearmanr
    from facewrap.transfer import ambiguity_summary, partner_ambiguity
    from facewrap.transfer import gradient_operator
    from facewrap.transfer import source_gradient_blocks
    L = t.reference
    t0 = time.perf_counter()
    amb = partner_ambiguity(corr, s.reference, L, np.stack(s.poses))
    seconds = time.perf_counter() - t0
    op = gradient_operator(L.vertices, L.triangles)
    err = np.sqrt(((source_gradient_blocks(op, out)
                    - source_gradient_blocks(op, np.stack(t.poses))) ** 2).sum(-1)).mean(0)
    ok = np.isfinite(amb)
    top = ok & (amb > np.nanpercentile(amb, 90))
    hints = ambiguity_summary(amb, L)["marker_hints"]
    flanks = np.array([[-0.05, 0.25, -0.14], [0.0, 0.24, 0.02], [0.05, 0.23, -0.17],
                       [-0.06, 0.21, 0.15], [0.06, 0.2, 0.16]])
    near = np.linalg.norm(L.vertices[hints][:, None] - flanks[None], axis=2).min(1) < 0.08
    return {"seconds": seconds, "spearman": float(spearmanr(amb[ok], err[ok]).correlation),
            "ratio": float(err[top].mean() / err[ok & ~top].mean()),
            "hints": len(hints), "hints_in_flanks": int(near.sum())}


def horse_camel() -> dict:
    from facewrap.datasets import load_pose_set
    from facewrap.io import read_mesh
    from facewrap.io.landmarks import read_markers
    root = DATA / "sumner2004" / "horse-camel"
    src = load_pose_set(root / "horse_ref.obj",
                        [root / f"horse-{i:02d}.obj" for i in range(1, 11)])
    camel = read_mesh(root / "camel_ref.obj")
    markers = read_markers(root / "horse_camel.cons")
    t0 = time.perf_counter()
    corr = find_correspondence(src.reference, camel, markers)
    t1 = time.perf_counter()
    dt = DeformationTransfer().fit(src.reference, camel, corr)
    t2 = time.perf_counter()
    out = dt.transfer(np.stack(src.poses))
    t3 = time.perf_counter()
    unfolded = dt.repairs_["found"]
    one = best_of(lambda: dt.transfer(src.poses[3]))[0]
    dt.fix_flips = False
    one_plain = best_of(lambda: dt.transfer(src.poses[3]))[0]
    folds_plain = [_folds(X, camel.vertices, camel.triangles)
                   for X in dt.transfer(np.stack(src.poses))]
    dt.fix_flips = True
    a0 = face_areas(camel.vertices, camel.triangles)
    ratios = np.concatenate([face_areas(X, camel.triangles) / np.maximum(a0, 1e-300)
                             for X in out])
    return {"corr": t1 - t0, "fit": t2 - t1, "poses": t3 - t2, "one": one,
            "one_plain": one_plain, "folds_plain": folds_plain,
            "total": t3 - t0,
            "folds": [_folds(X, camel.vertices, camel.triangles) for X in out],
            "source_folds": [_folds(P, src.reference.vertices, src.reference.triangles)
                             for P in src.poses],
            "area_p1_p99": np.percentile(ratios, [1, 99]).tolist(),
            "unfolded": unfolded.tolist(),
            "unmatched": corr.stats["unmatched_target"], "n_tri": len(camel.triangles)}


def _per_eye_gap(X, lm):
    """Upper-to-lower lid distance of each eye (51-point layout)."""
    def g(a, b):
        return np.linalg.norm(X[..., lm[a], :] - X[..., lm[b], :], axis=-1)
    return np.stack([(g(20, 24) + g(21, 23)) / 2, (g(26, 30) + g(27, 29)) / 2], axis=-1)


def _mouth(X, lm):
    """Inner-lip opening (51-point 45 ↔ 49) over mouth width (31 ↔ 37)."""
    return (np.linalg.norm(X[..., lm[45], :] - X[..., lm[49], :], axis=-1)
            / np.linalg.norm(X[..., lm[31], :] - X[..., lm[37], :], axis=-1))


def _smile(X, lm):
    """Rise of the mouth corners (51-point 31, 37) toward the brows plus their
    spread, over mouth width: large for a smile."""
    up = X[..., lm[:10], :].mean(axis=-2) - X[..., lm[31:51], :].mean(axis=-2)
    up = up / np.linalg.norm(up, axis=-1, keepdims=True)
    corners = (X[..., lm[31], :] + X[..., lm[37], :]) / 2 - X[..., lm[31:51], :].mean(axis=-2)
    width = np.linalg.norm(X[..., lm[31], :] - X[..., lm[37], :], axis=-1)
    return (np.einsum("...i,...i->...", corners, up) + 0.5 * width) / width


def _face_view(mesh, lm, size):
    """How to look at a face from its landmarks: (frame, view, centre, pixel size).

    Up is from the mouth to the brows, image x from the subject's right eye to the
    left; the camera turns toward the subject's left until it faces the left eye's
    surface (a horse's eyes look sideways, a person's forward), by 15° to 60°."""
    from facewrap.geometry import vertex_normals
    from facewrap.report import frame_from_axes
    P = mesh.vertices[lm]
    up = P[:10].mean(0) - P[31:51].mean(0)
    right = P[25:31].mean(0) - P[19:25].mean(0)
    frame = frame_from_axes(up=up, front=np.cross(right, up))
    N = vertex_normals(mesh.vertices, mesh.triangles) @ frame.T
    left, right = N[lm[25:31]].sum(0), N[lm[19:25]].sum(0)
    side = (np.arctan2(left[0], left[2]) - np.arctan2(right[0], right[2])) / 2
    view = (float(np.clip(np.degrees(side), 15, 60)), 5.0)
    from facewrap.report import view_rotation
    Q = P @ view_rotation(view, frame)[:2].T
    return frame, view, P.mean(0), 1.45 * np.ptp(Q, axis=0).max() / size


def _avatar_picture(name, av, la, rows, picks, path, size=220) -> None:
    """Neutral and a few key shapes, one row per method, one view and scale; shapes
    coloured by how far each vertex moved (one colour range per shape, so the two
    methods compare)."""
    from facewrap.report import image_grid, render_mesh, robust_clim, save_png
    frame, view, centre, px = _face_view(av, la, size)
    clim = {k: robust_clim(np.concatenate([np.linalg.norm(out[k] - av.vertices, axis=1)
                                           for _, out in rows]), 99.5)
            for _, k in picks}
    images, labels = [], []
    for method, out in rows:
        for label, k in [("neutral", None), *picks]:
            V = av.vertices if k is None else out[k]
            scalars = None if k is None else np.linalg.norm(V - av.vertices, axis=1)
            images.append(render_mesh((V, av.triangles), scalars=scalars,
                                      clim=clim.get(k),
                                      frame=frame, view=view, center=centre,
                                      pixel_size=px, size=(size, size)))
            labels.append(f"{method}: {label}")
    save_png(path, image_grid(
        images, labels, columns=1 + len(picks), gap=6, font_size=13,
        title=f"{name}: template shapes transferred (colour: distance moved, "
              "one scale per column)"))


def onizuka(pictures: bool = True) -> dict:
    from facewrap.io import read_mesh
    from facewrap.io.landmarks import read_vertex_indices
    from facewrap.io.obj import read_obj_vertices
    root = DATA / "onizuka2019"
    src = read_mesh(root / "blendshapes" / "Neutralm.obj")
    shapes = np.stack([read_obj_vertices(root / "blendshapes" / f"{i:02d}m.obj",
                                         src.n_vertices) for i in range(48)])
    ls = read_vertex_indices(root / "landmarks" / "SOURCE" / "FACIAL_LANDMARKS.txt").vertex
    src_gap = _per_eye_gap(shapes, ls) / _per_eye_gap(src.vertices, ls)
    blink = src_gap < 0.3                                          # (48, 2)
    src_mouth = _mouth(shapes, ls) - _mouth(src.vertices, ls)
    opens = np.argsort(-src_mouth)[:3]
    both = int(np.argmin(src_gap.min(axis=1)))             # an eye shut the most
    smile = _smile(shapes, ls) - _smile(src.vertices, ls)
    smile[opens[0]] = -np.inf
    picks = [(f"blink ({both:02d}m)", both), (f"mouth open ({opens[0]:02d}m)", int(opens[0])),
             (f"smile ({int(np.argmax(smile)):02d}m)", int(np.argmax(smile)))]
    images = {}
    rows = []
    src_flips = int(sum(_flips(P, src) for P in shapes))
    for name in ("Horse", "Mario", "Oldman"):
        av = read_mesh(root / "avatars" / f"{name}.ply")
        la = read_vertex_indices(root / "landmarks" / f"landmarks_{name}.txt").vertex
        t0 = time.perf_counter()
        guided = AvatarTransfer().fit(src, ls, av, la)
        t1 = time.perf_counter()
        og = guided.transfer(shapes)
        t2 = time.perf_counter()
        plain = AvatarTransfer(landmark_guided=False).fit(
            src, ls, av, la, correspondence=guided.correspondence_)
        op = plain.transfer(shapes)
        if pictures:
            path = IMAGES / f"avatar_{name.lower()}.png"
            _avatar_picture(name, av, la, [("plain", op), ("guided", og)], picks, path)
            images[name] = path.name
        for label, model, out, fit, solve in (
                ("plain (Sumner)", plain, op, None, None),
                ("landmark-guided", guided, og, t1 - t0, t2 - t1)):
            gap = _per_eye_gap(out, la) / _per_eye_gap(av.vertices, la)
            mouth = _mouth(out, la) - _mouth(av.vertices, la)
            rows.append({"avatar": f"{name} ({av.n_vertices:,} v)", "method": label,
                         "gap": float(gap[blink].mean()),
                         "gap_src": float(src_gap[blink].mean()),
                         "mouth": float(mouth[opens].mean()),
                         "mouth_src": float(src_mouth[opens].mean()),
                         "flips": int(sum(_flips(X, av) for X in out)),
                         "new_flips": _new_flips(out, av, shapes, src,
                                                 guided.correspondence_),
                         "flipped_shapes": int(sum(_flips(X, av) > 0 for X in out)),
                         "unfolded": int(model.repairs_["found"].sum()),
                         "unfolded_shapes": int(np.sum(model.repairs_["found"] > 0)),
                         "fit": fit, "solve": solve})
    return {"rows": rows, "blink_shapes": int(blink.any(axis=1).sum()),
            "open_shapes": [f"{i:02d}m" for i in opens], "images": images,
            "source_flips": src_flips}


def ict_to_oldman() -> dict:
    from facewrap.datasets import ICTFaceKit, cache_dir, expand_ict_facekit
    from facewrap.io import read_mesh
    from facewrap.io.gltf import read_gltf_morphs, write_gltf_morphs
    from facewrap.io.landmarks import read_vertex_indices
    folder = expand_ict_facekit(DATA / "ict-facekit", cache_dir("ict-facekit"))
    kit = ICTFaceKit(folder)
    face = kit.part_mesh("face")
    n = face.n_vertices
    names = kit.expression_names
    shapes = np.stack([kit.shape(k)[:n] for k in names])
    ls = np.asarray(kit.indices["idx_to_landmark_verts"])[17:]
    root = DATA / "onizuka2019"
    old = read_mesh(root / "avatars" / "Oldman.ply")
    la = read_vertex_indices(root / "landmarks" / "landmarks_Oldman.txt").vertex
    t0 = time.perf_counter()
    corr = find_correspondence(face, old, (ls, la))
    t1 = time.perf_counter()
    dt = DeformationTransfer().fit(face, old, corr)
    t2 = time.perf_counter()
    out = dt.transfer(shapes)
    t3 = time.perf_counter()
    repairs = dt.repairs_
    dt.fix_flips = False
    unrepaired = best_of(lambda: dt.transfer(shapes), 1)[0]
    dt.fix_flips = True
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "oldman_arkit.glb"
        write_gltf_morphs(path, old, dict(zip(names, out)), scale=0.001)
        t4 = time.perf_counter()
        size = path.stat().st_size
        back = read_gltf_morphs(path)
        ok = list(back.shapes) == names
    return {"corr": t1 - t0, "fit": t2 - t1, "shapes": t3 - t2, "glb": t4 - t3,
            "n": len(names), "glb_mb": size / 1e6, "names_ok": ok,
            "flips": int(sum(_flips(X, old) for X in out)), "target": old.n_vertices,
            "new_flips": _new_flips(out, old, shapes, face, corr),
            "unfolded": int(repairs["found"].sum()),
            "unfolded_shapes": int(np.sum(repairs["found"] > 0)),
            "shapes_unrepaired": unrepaired,
            "source_flips": int(sum(_flips(P, face) for P in shapes)),
            "source": n}


def run() -> dict:
    result = {"synthetic": synthetic()}
    if (DATA / "sumner2004").is_dir():
        result["cat_lion"] = cat_lion()
        result["horse_camel"] = horse_camel()
    if (DATA / "onizuka2019").is_dir():
        result["onizuka"] = onizuka()
    if (DATA / "ict-facekit").is_dir() and (DATA / "onizuka2019").is_dir():
        result["ict"] = ict_to_oldman()
    return result


def markdown(r: dict) -> str:
    s = r["synthetic"]
    lines = ["### transfer: deformation transfer and avatar blendshapes", "",
             f"Synthetic ({s['case']}): correspondence + factor {s['fit']:.2f} s, "
             f"{1000 * s['per_pose']:.1f} ms per pose ({s['poses']} poses solved "
             "together).", ""]
    if "cat_lion" in r:
        c = r["cat_lion"]
        lines += ["**cat → lion** (Sumner's lion poses are ground truth; 55 markers; "
                  "translation fixed at the last lion vertex as in Sumner's data). Mean "
                  "vertex error, % of the lion's bounding-box diagonal:", "",
                  "| pose | " + " | ".join(n[-2:] for n in c["names"]) + " | mean |",
                  "|---|" + "---:|" * (len(c["names"]) + 1),
                  "| error | " + " | ".join(f"{e:.2f}" for e in c["err"])
                  + f" | {np.mean(c['err']):.2f} |",
                  "| after best translation | " + " | ".join(
                      f"{e:.2f}" for e in c["shift"]) + f" | {np.mean(c['shift']):.2f} |",
                  "| after best rigid alignment | " + " | ".join(
                      f"{e:.2f}" for e in c["rigid"]) + f" | {np.mean(c['rigid']):.2f} |",
                  "| anchor vertex, after rigid alignment | " + " | ".join(
                      f"{e:.2f}" for e in c["at_anchor"])
                  + f" | {np.mean(c['at_anchor']):.2f} |",
                  "", "Sumner fixed one vertex, not the markers: the last lion vertex is "
                  "the only one that never moves in his poses (every marker moves). "
                  "The gap between the raw and aligned rows is almost all translation, "
                  "and it is the local error *at that vertex* (lower flank by the hind "
                  "leg, where folded legs press on the belly) carried to the whole body: "
                  "the solve does not drift." + _OUT_OF_REACH + _STIFF_IDENTITY, "",
                  _ambiguity_text(c["ambiguity"]), "", f"Correspondence {c['corr']:.2f} s ({c['pairs']:,} triangle pairs); "
                  f"factor + 9 poses {c['fit_and_poses']:.2f} s.", ""]
    if "horse_camel" in r:
        h = r["horse_camel"]
        lines += [f"**horse → camel** (107 markers, 10 poses; no ground truth): "
                  f"correspondence {h['corr']:.2f} s, factor {h['fit']:.2f} s, 10 poses "
                  f"{h['poses']:.2f} s, **total {h['total']:.2f} s** (target ≤ 10 s); one "
                  f"further pose {1000 * h['one']:.0f} ms (target ≤ 100 ms). Folds "
                  f"(adjacent triangles turned to face apart) per camel pose "
                  f"{h['folds']} of {h['n_tri']:,} triangles (the horse poses themselves: "
                  f"{h['source_folds']}); triangle area "
                  f"ratio p1/p99 {h['area_p1_p99'][0]:.2f}/{h['area_p1_p99'][1]:.2f}; "
                  f"{h['unmatched']} camel triangles without a partner (they follow "
                  "their neighbours).  The flip repair (default) unfolded "
                  f"{h['unfolded']} new flips of the plain solve per pose (turned past "
                  "90° while no horse partner flips and the transferred gradient does "
                  "not turn them past 95°); without it: folds "
                  f"{h['folds_plain']}, one further pose "
                  f"{1000 * h['one_plain']:.0f} ms.", ""]
    if "onizuka" in r:
        o = r["onizuka"]
        lines += ["**Onizuka 2019 template (48 expressions) → avatars**, 51 landmarks. "
                  f"Eyelid gap / neutral gap on the {o['blink_shapes']} blink shapes "
                  "(eyes the source closes below 30 %); mouth opening gain (inner lips "
                  f"over mouth width) on {', '.join(o['open_shapes'])}; flipped "
                  "triangles (normal turned > 90°) summed over the 48 shapes (shapes "
                  "with any), and of those the *new* ones, whose source partners do "
                  "not flip: the template's own shapes turn "
                  f"{o['source_flips']} triangles past 90° (eyelids rolling over the "
                  "eye), and their partners legitimately follow.  Both methods run "
                  "with the flip repair (`fix_flips=True`, the default): *unfolded* "
                  "counts the new flips of the plain least-squares solves that it "
                  "removed (shapes re-solved); the other shapes are the plain solve.",
                  "", "| avatar | method | lid gap (source) | mouth gain (source) | "
                  "flips (shapes) | new flips | unfolded (shapes) | fit (s) | "
                  "48 shapes (s) |",
                  "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
        for x in o["rows"]:
            fit = "" if x["fit"] is None else f"{x['fit']:.2f}"
            solve = "" if x["solve"] is None else f"{x['solve']:.2f}"
            lines.append(f"| {x['avatar']} | {x['method']} | {x['gap']:.2f} "
                         f"({x['gap_src']:.2f}) | {x['mouth']:.2f} ({x['mouth_src']:.2f}) "
                         f"| {x['flips']} ({x['flipped_shapes']}) | {x['new_flips']} "
                         f"| {x['unfolded']} ({x['unfolded_shapes']}) | {fit} | {solve} |")
        lines.append("")
        for name, file in o.get("images", {}).items():
            lines += [f"![{name}: neutral, blink, mouth open and smile, plain (top) and "
                      f"landmark-guided (bottom)](images/{file})", ""]
    if "ict" in r:
        i = r["ict"]
        lines += [f"**ICT-FaceKit face ({i['source']:,} v) → Oldman ({i['target']:,} v)**,"
                  f" {i['n']} ARKit shapes, 51 landmarks as markers: correspondence "
                  f"{i['corr']:.2f} s, factor {i['fit']:.2f} s, {i['n']} shapes "
                  f"{i['shapes']:.2f} s ({i['shapes_unrepaired']:.2f} s without the flip "
                  f"repair; fit + shapes {i['fit'] + i['shapes']:.2f} s), "
                  f"GLB with named morph targets {i['glb_mb']:.1f} MB in {i['glb']:.2f} s "
                  f"(names round-trip: {i['names_ok']}); {i['flips']} flipped triangles "
                  f"over all shapes, {i['new_flips']} of them new (the ICT shapes "
                  f"themselves flip {i['source_flips']} triangles, e.g. mouthClose "
                  "presses the lips through each other); the repair unfolded "
                  f"{i['unfolded']} new flips of the plain solve in "
                  f"{i['unfolded_shapes']} shapes.", ""]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown(run()))
