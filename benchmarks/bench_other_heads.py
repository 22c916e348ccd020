"""Benchmark: production heads not made from ICT-FaceKit, landmarks only.

Every other head benchmark wraps ICT's head or variants of it.  Here the skins are
MeshMonk's face template (a mask), Onizuka et al.'s generic head (its own mouth
socket, a neck) and facewrap's built-in sample head, each dressed by
:mod:`_other_heads` with the parts production heads have (eyeballs, corneas, teeth,
gums, a tongue, a mouth bag separate from or welded to the lips, eye-occlusion
bands, lashes outside the skin) and exported the ways studios export them (quads or
triangles, parts before the skin, mm or cm).  Each is wrapped as a user does with
only landmark ids (:func:`facewrap.wrapping.wrap`, model graph; hybrid for the
sample head, whose expressions the skin carries) onto menpo's ``james`` (68
landmarks), MeshMonk's demo face (5) and an ICT identity scanned as a face scanner
does (:mod:`_head_scans`, 68), and once through ``facewrap wrap``.

Measures, against the parts as built: part vertices on the other side of the skin
than on the aligned template ("through", as :mod:`bench_heads` counts it; the skin is
every vertex of the skin's own surface, a welded bag included), welded-bag vertices
through the outer skin, flipped triangles of the seen skin and of the parts, fit
mean / p95 over the skin an outside camera sees (mm, off the scan's border), the
landmark mean error (mm), and the roles: parts taken as skin (pulled), skin taken
as a part, welded-bag vertices pulled onto the scan, cavities.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _other_heads as O  # noqa: E402
from facewrap.evaluate import surface_distances  # noqa: E402
from facewrap.geometry import flipped_triangles  # noqa: E402
from facewrap.geometry.visibility import outside_views  # noqa: E402
from facewrap.landmarks import Landmarks  # noqa: E402
from facewrap.wrapping import WrapSettings, wrap  # noqa: E402
from facewrap.wrapping.follow import side_changes  # noqa: E402
from facewrap.wrapping.roles import CAVITY, FITTED, PART  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: where the pictures go (not committed: a benchmark run makes them again)
PICTURES = Path(tempfile.gettempdir()) / "facewrap-other-heads"


def heads() -> list:
    """(name, head, labels, {iBUG index: vertex id}, blendshapes or None)."""
    mm, mm_labels, mm_ibug = O.meshmonk_head("separate")
    mw, mw_labels, mw_ibug = O.meshmonk_head("welded")
    oz, oz_labels, oz_ibug = O.onizuka_head("none")
    sw, sw_labels, sw_ibug = O.sample_head("welded")
    ss, ss_labels, ss_ibug = O.sample_head("separate")
    from facewrap.sample import make_template
    shapes = make_template().blendshapes
    n0 = len(next(iter(shapes.values())))
    # the dressed sample: its skin moves by the expression, the added parts stay
    dressed = {k: np.vstack([v, sw.vertices[n0:]]) for k, v in shapes.items()}
    return [
        ("MeshMonk mask, bag separate (mm, triangles)", mm, mm_labels, mm_ibug, None),
        ("MeshMonk mask, bag welded, parts first, cm",
         *O.variant(mw, mw_labels, mw_ibug, parts_first=True, scale=0.1), None),
        ("Onizuka head, own socket (mm, triangles)", oz, oz_labels, oz_ibug, None),
        ("Onizuka head, parts first, cm",
         *O.variant(oz, oz_labels, oz_ibug, parts_first=True, scale=0.1), None),
        ("sample head, bag welded (mm, quads)", sw, sw_labels, sw_ibug, None),
        ("sample head, bag welded, hybrid", sw, sw_labels, sw_ibug, dressed),
        ("sample head, bag separate, triangulated, cm",
         *O.variant(ss, ss_labels, ss_ibug, triangles=True, scale=0.1), None),
    ]


def scans() -> list:
    """(name, scan, {iBUG index: position})."""
    import _head_scans
    from facewrap.io import read_mesh
    from facewrap.io.landmarks import read_landmarks, read_ljson
    james = read_ljson(O.DATA / "scans/james/james.ljson")
    mm = O.DATA / "scans/meshmonk"
    demo = read_landmarks(mm / "DemoFaceLandmarks.csv")
    out = [("james", read_mesh(O.DATA / "scans/james/james.obj"),
            dict(enumerate(james.points))),
           ("MeshMonk demo", read_mesh(mm / "DemoFace_10K.obj"),
            dict(zip(O.FIVE, demo.points)))]
    try:
        scan, lm, _ = _head_scans.scanned_head("identity001")
        out.append(("ICT identity001 scanned", scan, dict(enumerate(lm.points))))
    except ValueError:          # libigl's decimation gave up: bench_heads says so too
        pass
    return out


def paired(ibug: dict, targets: dict):
    """Template and scan landmarks of the iBUG points both have, in one order."""
    common = [k for k in targets if k in ibug]
    return (Landmarks.from_vertices([ibug[k] for k in common]),
            Landmarks.from_points(np.array([targets[k] for k in common])))


def measures(result, head, labels, scan, seen) -> dict:
    """What a judge measures of one wrap (see the module docstring)."""
    T = head.triangles
    labels = np.asarray(labels)
    aligned = result.transform.apply(head.vertices)
    X = result.vertices
    piece = labels > O.SOCKET
    roles = np.where(piece, PART, 0).astype(np.int8)
    through = side_changes(T, aligned, X, roles)
    outer = np.where(labels != O.SKIN, PART, 0).astype(np.int8)
    bag_through = side_changes(T, aligned, X, outer)[labels[outer == PART] == O.SOCKET]
    flips = flipped_triangles(X, aligned, T)
    fit = surface_distances(X, scan, mask=seen).summary("")
    r = result.roles
    return {"fit_mean": fit["mean"], "fit_p95": fit["p95"],
            "flipped": int((flips & seen[T].all(axis=1)).sum()),
            "through": int(through.sum()), "bag_through": int(bag_through.sum()),
            "part_flips": int(flips[piece[T].all(axis=1)].sum()),
            "landmarks": float(result.metrics["landmark_mean"]),
            "part_as_skin": int((piece & (r != PART)).sum()),
            "pulled_parts": int((piece & (r == FITTED)).sum()),
            "skin_as_part": int((~piece & (r == PART)).sum()),
            "bag_pulled": int(((labels == O.SOCKET) & (r == FITTED)).sum()),
            "cavity": int((~piece & (r == CAVITY)).sum()),
            "through_by": _by_label(labels[piece], through)}


def _by_label(labels, flags) -> str:
    counts = np.bincount(labels[flags], minlength=len(O.LABELS))
    return ", ".join(f"{O.LABELS[k]} {c}" for k, c in enumerate(counts) if c)


def seen_skin(head, labels) -> np.ndarray:
    """(n,) bool: skin vertices a camera outside the skin alone sees (the parts
    and a welded bag hide nothing a scanner records)."""
    skin = (np.asarray(labels) == O.SKIN)
    T = head.triangles
    own = skin[T].all(axis=1)
    return outside_views(head.vertices, T, occluders=own) & skin


def _picture(name, head, labels, result) -> str:
    from facewrap.io.images import save_png
    from facewrap.report.figures import render_views, side_by_side
    V = result.transform.inverse().apply(result.vertices)
    colors = np.tile([0.86, 0.80, 0.74], (head.n_vertices, 1))
    colors[result.roles == CAVITY] = [0.95, 0.55, 0.25]
    colors[result.roles == PART] = [0.35, 0.55, 0.90]
    colors[(np.asarray(labels) > O.SOCKET) & (result.roles != PART)] = [0.9, 0.1, 0.1]
    images = render_views((V, head.triangles), ["front", "left", (0, -35)],
                          size=(360, 420), colors=colors)
    PICTURES.mkdir(parents=True, exist_ok=True)
    path = PICTURES / (name.split(",")[0].replace(" ", "_") + f"_{len(labels)}.png")
    save_png(path, side_by_side(images, ["front", "side", "below the nose"]))
    return str(path)


def _one(head, labels, ibug, shapes, scan, targets, seen) -> dict:
    lm, scan_lm = paired(ibug, targets)
    settings = WrapSettings(model="hybrid" if shapes else "graph")
    t = time.perf_counter()
    try:
        r = wrap(head, scan, lm, scan_lm, settings, blendshapes=shapes)
    except Exception as exc:  # noqa: BLE001 - a crash is a result here
        return {"error": f"{type(exc).__name__}: {exc}"[:160]}
    out = measures(r, head, labels, scan, seen)
    out.update(time=time.perf_counter() - t, result=r)
    return out


def cli_run(head, labels, ibug, seen) -> dict:
    """The first head onto MeshMonk's demo face through ``facewrap wrap``."""
    from facewrap.io import read_mesh, write_mesh
    mm = O.DATA / "scans/meshmonk"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        write_mesh(tmp / "head.obj", head)
        (tmp / "ids.txt").write_text("\n".join(str(ibug[k]) for k in O.FIVE) + "\n")
        t = time.perf_counter()
        subprocess.run([sys.executable, "-m", "facewrap.cli", "wrap", str(tmp / "head.obj"),
                        str(mm / "DemoFace_10K.obj"), "--template-landmarks",
                        str(tmp / "ids.txt"), "--scan-landmarks",
                        str(mm / "DemoFaceLandmarks.csv"), "-o", str(tmp / "out.obj"),
                        "--output-frame", "scan", "-q"], check=True)
        seconds = time.perf_counter() - t
        out = read_mesh(tmp / "out.obj").vertices
    r = wrap(head, read_mesh(mm / "DemoFace_10K.obj"),
             *paired(ibug, dict(zip(O.FIVE, _demo_points()))), WrapSettings(model="graph"))
    r.mesh = r.mesh.with_vertices(out)           # the CLI's vertices, the library's roles
    x = measures(r, head, labels, read_mesh(mm / "DemoFace_10K.obj"), seen)
    x.update(time=seconds, same_as_library=float(np.abs(out - r.mesh.vertices).max()))
    return x


def _demo_points():
    from facewrap.io.landmarks import read_landmarks
    return read_landmarks(O.DATA / "scans/meshmonk/DemoFaceLandmarks.csv").points


def run(only=None) -> dict:
    if not (O.DATA / "scans").is_dir() or not (O.DATA / "onizuka2019").is_dir():
        return {"heads": [], "notes": ["skipped: ../shared/data is absent"]}
    out = {"heads": [], "notes": []}
    every_scan = scans()
    for name, head, labels, ibug, shapes in heads():
        if only and not any(o in name for o in only):
            continue
        seen = seen_skin(head, labels)
        rows = {}
        for scan_name, scan, targets in every_scan:
            if shapes is not None and scan_name != "james":
                continue                 # one hybrid row: the model, not the scans
            x = _one(head, labels, ibug, shapes, scan, targets, seen)
            if scan_name == "james" and "result" in x:
                x["picture"] = _picture(name, head, labels, x["result"])
            x.pop("result", None)
            rows[scan_name] = x
            print(f"{name[:40]:40s} {scan_name:24s} {_line(x)}", file=sys.stderr,
                  flush=True)
        counts = np.bincount(labels, minlength=len(O.LABELS))
        out["heads"].append({"name": name, "vertices": head.n_vertices,
                             "faces": head.n_faces, "rows": rows,
                             "built": {O.LABELS[k]: int(c) for k, c in enumerate(counts)
                                       if c}})
    if not only:
        name, head, labels, ibug, _ = heads()[0]
        out["cli"] = cli_run(head, labels, ibug, seen_skin(head, labels))
    return out


def _line(x) -> str:
    if "error" in x:
        return f"crash: {x['error']}"
    return (f"{x['fit_mean']:.3f} / {x['fit_p95']:.3f} | {x['landmarks']:.2f} | "
            f"{x['flipped']} | {x['through']} | {x['bag_through']} | {x['part_flips']} | "
            f"{x['part_as_skin']} ({x['pulled_parts']}) / {x['skin_as_part']} | "
            f"{x['bag_pulled']} | {x['cavity']} | {x['time']:.1f}")


def markdown(r: dict) -> str:
    L = ["### Production heads of other makes, landmarks only", "",
         "Skins not made from ICT (MeshMonk's face template, Onizuka et al.'s generic "
         "head, the built-in sample head) dressed in code with eyeballs, corneas, teeth, "
         "gums, a tongue, a mouth bag (its own piece or welded to the lips), eye-"
         "occlusion bands and lashes (`benchmarks/_other_heads.py`), wrapped with only "
         "landmark ids (model graph; hybrid where named). Fit over the skin a camera "
         "sees (mm, off the scan's border); landmarks = mean error (mm); flipped = seen "
         "skin triangles turned past 90°; through = part vertices on the other side "
         "of the skin than on the template; bag through = welded-bag vertices through "
         "the outer skin; parts as skin (of them pulled) / skin as parts, bag pulled "
         "= welded-bag vertices pulled onto the scan, cavities = skin vertices that "
         "follow as cavities (vertices). One run each.", ""]
    L += [f"{n}" for n in r.get("notes", [])]
    L += ["| head | scan | fit mean / p95 (mm) | landmarks (mm) | flipped | through | "
          "bag through | part flips | parts as skin (pulled) / skin as parts | bag "
          "pulled | cavities | time (s) |", "|---|---|" + "---:|" * 10]
    for h in r["heads"]:
        for scan_name, x in h["rows"].items():
            L.append(f"| {h['name']} | {scan_name} | {_line(x)} |")
    L.append("")
    crossed = [f"{h['name']} → {scan_name}: {x['through_by']}" for h in r["heads"]
               for scan_name, x in h["rows"].items() if x.get("through_by")]
    if crossed:
        L += ["Parts through the skin, by part: " + "; ".join(crossed) + ".", ""]
    for h in r["heads"]:
        built = ", ".join(f"{k} {v}" for k, v in h["built"].items())
        L.append(f"- {h['name']}: {h['vertices']:,} v, {h['faces']:,} faces ({built}).")
    if "cli" in r:
        c = r["cli"]
        L += ["", f"Through `facewrap wrap` ({r['heads'][0]['name']} onto the MeshMonk "
              f"demo face): {_line(c)}; largest difference from the library's wrap "
              f"{c['same_as_library']:.2g} mm."]
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    print(markdown(run(sys.argv[1:] or None)))
