"""Benchmark: a real scan degraded the ways real scanners deliver them.

ICT-FaceKit's face (9,409 v, cm, 68 landmarks, 53 expression shapes) onto menpo's
``james`` scan (mm), set up as :mod:`bench_realscan` does, with the scan or its
landmarks spoiled in one way per row: faces wound the wrong way (all, or half at
random), floating debris, a background plane, spikes, a hole over an eye, the
chin cut off, a million triangles, an unwelded triangle soup, non-manifold fins,
metres or centimetres, a mirror image, noisy or one grossly wrong landmark.

Each row is judged against the *clean* scan, as a user would judge it: fit p95
over ICT's fitting vertices on the undegraded scan's surface (away from its
borders), triangles of the fitting set turned past 90 degrees (from the aligned
template for the graph model; from the fit's own expression, the aligned
template plus its fitted shapes, for the hybrid: ICT's expressions turn
triangles of the neutral), landmark error against the clean landmarks, time,
and the warnings the wrap gave.  A degradation must give a result close to the
clean one, or refuse (a mirror image) with one clear line; a silently worse fit
is a bug.  Results in other units or mirrored are mapped back to the clean
scan's frame before they are measured.

A few rows also run the command line (``facewrap wrap``, graph model) on files,
to see its messages and exit status.  Skipped when ``../shared/data`` is absent.
"""

from __future__ import annotations

import contextlib
import io
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_nicp as nicp  # noqa: E402
import bench_realscan as realscan  # noqa: E402
from facewrap.geometry import ClosestPointTree, turned_triangles, vertex_normals  # noqa: E402
from facewrap.landmarks import Landmarks  # noqa: E402
from facewrap.mesh import Mesh  # noqa: E402
from facewrap.wrapping import WrapSettings, wrap  # noqa: E402

SEED = 7


@dataclass
class Degraded:
    """A spoiled scan and its landmarks, and the map of a result back to the
    clean scan's frame (units, mirror)."""
    scan: Mesh
    points: np.ndarray                       # (68, 3) scan landmarks, spoiled frame
    names: tuple | None = None
    back: Callable = staticmethod(lambda V: V)
    refuse: bool = False                     # the right answer is a refusal
    note: str = ""
    kept: np.ndarray | None = field(default=None)   # landmarks given (None: all)


# -- degradations: (scan, landmark points, rng) -> Degraded ---------------------------
def _clean(scan, P, rng):
    return Degraded(scan, P)


def _reversed_all(scan, P, rng):
    return Degraded(Mesh(scan.vertices, scan.triangles[:, ::-1]), P)


def _reversed_half(scan, P, rng):
    T = scan.triangles.copy()
    flip = rng.random(len(T)) < 0.5
    T[flip] = T[flip, ::-1]
    return Degraded(Mesh(scan.vertices, T), P)


def _append(scan, V, T) -> Mesh:
    """``scan`` with more vertices ``V`` and triangles ``T`` (indices into ``V``)."""
    return Mesh(np.vstack([scan.vertices, V]),
                np.vstack([scan.triangles, np.asarray(T) + scan.n_vertices]))


def _blob(centre, radius, rng):
    """A small closed blob: an octahedron with its corners jittered."""
    d = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1.]])
    V = centre + radius * d * rng.uniform(0.6, 1.4, (6, 1))
    T = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4],
                  [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    return V, T


def _debris(scan, P, rng):
    """300 pieces: 200 loose triangles (1-4 mm) and 100 blobs (radius 1-4 mm);
    half 3-30 mm off the face (either side), half anywhere within 300 mm."""
    V0 = scan.vertices
    lo, hi = V0.min(axis=0), V0.max(axis=0)
    Vs, Ts, n = [], [], 0
    for k in range(300):
        if k % 2:
            i = rng.integers(len(V0))
            d = rng.normal(size=3)
            c = V0[i] + rng.uniform(3, 30) * d / np.linalg.norm(d)
        else:
            c = rng.uniform(lo - 150, hi + 150)
        if k < 200:
            V, T = c + rng.uniform(1, 4) * rng.normal(size=(3, 3)), np.array([[0, 1, 2]])
        else:
            V, T = _blob(c, rng.uniform(1, 4), rng)
        Vs.append(V)
        Ts.append(T + n)
        n += len(V)
    return Degraded(_append(scan, np.vstack(Vs), np.vstack(Ts)), P)


def _grid(corner, u, v, k: int):
    """A (k x k)-quad grid spanned by ``u`` and ``v`` from ``corner``, its
    triangles wound to face ``u x v``."""
    s = np.linspace(0, 1, k + 1)
    a, b = np.meshgrid(s, s, indexing="ij")
    V = corner + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    i = np.arange(k)[:, None] * (k + 1) + np.arange(k)[None]
    i = i.ravel()
    T = np.vstack([np.stack([i, i + k + 1, i + 1], 1),
                   np.stack([i + 1, i + k + 1, i + k + 2], 1)])
    return V, T


def _background(scan, P, rng):
    """A 700 x 700 mm wall 30 mm behind the scan's back, facing the camera (+z)."""
    V0 = scan.vertices
    c = V0.mean(axis=0)
    z = V0[:, 2].min() - 30
    V, T = _grid(np.array([c[0] - 350, c[1] - 350, z]), np.array([700.0, 0, 0]),
                 np.array([0, 700.0, 0]), 40)
    return Degraded(_append(scan, V, T), P)


def _spikes(scan, P, rng):
    V = scan.vertices.copy()
    n = vertex_normals(V, scan.triangles)
    i = rng.choice(len(V), size=len(V) // 100, replace=False)
    V[i] += (rng.choice([-1, 1], len(i)) * rng.uniform(5, 20, len(i)))[:, None] * n[i]
    return Degraded(Mesh(V, scan.triangles), P)


def _without(scan, drop) -> Mesh:
    """``scan`` without the triangles ``drop`` (unused vertices stay)."""
    return Mesh(scan.vertices, scan.triangles[~drop])


def _eye_hole(scan, P, rng):
    """Every triangle with a corner within 15 mm of the right eye's centre (iBUG
    36-41) gone: the eye and its lids (landmarks kept where they were)."""
    c = P[36:42].mean(axis=0)
    near = np.linalg.norm(scan.vertices - c, axis=1) < 15
    return Degraded(_without(scan, near[scan.triangles].any(axis=1)), P)


def _chin_cut(scan, P, rng):
    """Everything below halfway from the lower lip (iBUG 57) to the chin (8) cut;
    the landmarks now off the scan (more than 1 mm) are not given."""
    y = 0.5 * (P[57, 1] + P[8, 1])
    cut = _without(scan, (scan.vertices[scan.triangles, 1] < y).any(axis=1))
    d = ClosestPointTree(cut.vertices, cut.triangles).query(P).distances
    return Degraded(cut, P, kept=np.flatnonzero(d < 1.0),
                    note=f"{int((d >= 1).sum())} landmarks not given")


def _dense(scan, P, rng):
    import trimesh
    V, T = scan.vertices, scan.triangles
    while len(T) < 700_000:
        V, T = trimesh.remesh.subdivide(V, T)
    return Degraded(Mesh(V, T), P)


def _soup(scan, P, rng):
    T = scan.triangles
    return Degraded(Mesh(scan.vertices[T.reshape(-1)], np.arange(T.size).reshape(-1, 3)), P)


def _fins(scan, P, rng):
    """300 fins: a triangle on an edge of the scan, 3-10 mm high, making the
    edge non-manifold."""
    T = scan.triangles
    t = rng.choice(len(T), 300, replace=False)
    a, b = T[t, 0], T[t, 1]
    V = scan.vertices
    n = vertex_normals(V, T)[a]
    tip = 0.5 * (V[a] + V[b]) + rng.uniform(3, 10, (300, 1)) * n
    k = np.arange(300) + len(V)
    return Degraded(Mesh(np.vstack([V, tip]), np.vstack([T, np.stack([a, b, k], 1)])), P)


def _units(factor):
    def degrade(scan, P, rng):
        return Degraded(Mesh(scan.vertices * factor, scan.triangles), P * factor,
                        back=lambda V: V / factor)
    return degrade


def _mirrored(scan, P, rng):
    """x -> -x for the scan and its landmark points (labels kept), triangles
    re-wound so they still face out: a mirrored scan and landmark file."""
    M = np.array([-1.0, 1, 1])
    return Degraded(Mesh(scan.vertices * M, scan.triangles[:, ::-1]), P * M,
                    back=lambda V: V * M, refuse=True)


def _noisy(size):
    def degrade(scan, P, rng):
        # isotropic, ``size`` mm root-mean-square in 3D
        return Degraded(scan, P + rng.normal(scale=size / np.sqrt(3), size=P.shape))
    return degrade


def _one_wrong(scan, P, rng):
    """The inner corner of the right eye (iBUG 39) 20 mm off, along the face."""
    Q = P.copy()
    Q[39] += np.array([20.0, 0, 0])
    return Degraded(scan, Q)


DEGRADATIONS = [
    ("clean", _clean), ("all faces reversed", _reversed_all),
    ("half the faces reversed", _reversed_half), ("floating debris", _debris),
    ("background wall", _background), ("spikes (1 % of vertices)", _spikes),
    ("hole over the right eye (r 15 mm)", _eye_hole), ("chin cut off", _chin_cut),
    ("subdivided to ~0.8M triangles", _dense), ("triangle soup (unwelded)", _soup),
    ("non-manifold fins", _fins), ("in metres", _units(0.001)), ("in cm", _units(0.1)),
    ("mirrored (scan and landmarks)", _mirrored), ("landmark noise 2 mm", _noisy(2.0)),
    ("landmark noise 5 mm", _noisy(5.0)), ("one landmark 20 mm off", _one_wrong),
]


def degrade(case, how) -> Degraded:
    P = case.scan_landmarks.positions(case.scan.vertices, case.scan.triangles)
    d = how(case.scan, P, np.random.default_rng(SEED))
    d.names = case.scan_landmarks.names
    return d


def _scan_landmarks(d: Degraded) -> Landmarks:
    lm = Landmarks.from_points(d.points, d.names)
    return lm if d.kept is None else lm.subset(d.kept)


# -- one row -------------------------------------------------------------------------
def flipped_in_fitting_set(res, case, V) -> int:
    """Triangles of ICT's fitting set turned past 90 degrees from the fit's rest:
    the aligned template plus its fitted shapes (the aligned template alone for
    a model without shapes), in the clean scan's frame when ``V`` is."""
    T = case.template.triangles
    rest = case.template.vertices
    if res.weights is not None and case.blendshapes:
        rest = rest + sum(w * (case.blendshapes[n] - case.template.vertices)
                          for n, w in zip(res.shape_names, res.weights))
    return int(turned_triangles(V, res.transform.apply(rest), T)[
        case.mask[T].all(axis=1)].sum())


def run_row(case, name, how, model: str) -> dict:
    d = degrade(case, how)
    t = time.perf_counter()
    res = wrap(case.template, d.scan, case.landmarks, _scan_landmarks(d),
               WrapSettings(model=model),
               blendshapes=case.blendshapes if model == "hybrid" else None)
    seconds = time.perf_counter() - t
    V = d.back(res.vertices)
    aligned = d.back(res.transform.apply(case.template.vertices))
    m = realscan.measures(V, case, aligned)
    # flips against the rest pose, measured in the degraded frame (a mirror turns
    # every triangle of both alike)
    return {"row": name, "model": model, "time": seconds, "fit_p95": m["fit_p95"],
            "flipped": flipped_in_fitting_set(res, case, res.vertices),
            "landmark_mean": m["landmark_mean"], "landmark_max": m["landmark_max"],
            "warnings": list(res.warnings), "triangles": len(d.scan.triangles),
            "refuse": d.refuse, "note": d.note}


def safe_row(case, name, how, model) -> dict:
    out = nicp._safe(run_row, case, name, how, model, method=name)
    if "error" in out:
        kind = out["error"].split(":")[0]
        out.update(row=name, model=model, refuse=dict(DEGRADATIONS)[name] is _mirrored,
                   refused=kind in ("ValueError", "InputError"))
    return out


# -- the command line ----------------------------------------------------------------
#: rows also run through ``facewrap wrap`` (graph model)
CLI_ROWS = ("clean", "all faces reversed", "triangle soup (unwelded)", "in metres",
            "mirrored (scan and landmarks)", "floating debris")


def run_cli(case, name, how, folder: Path) -> dict:
    """``facewrap wrap`` on files of the degraded scan: exit status, the error or
    warning lines, the fit measured as for the library rows."""
    from facewrap.cli import main
    from facewrap.io import read_mesh, write_mesh
    from facewrap.io.landmarks_json import write_landmarks_json
    d = degrade(case, how)
    template = folder / "ict_face.obj"
    if not template.exists():
        write_mesh(template, case.template)
        write_landmarks_json(folder / "ict_face_landmarks.json", case.landmarks)
    scan = folder / f"scan_{abs(hash(name))}.obj"
    write_mesh(scan, d.scan)
    write_landmarks_json(folder / "scan_landmarks.json", _scan_landmarks(d))
    out = folder / "out.obj"
    out.unlink(missing_ok=True)
    err, std = io.StringIO(), io.StringIO()
    t = time.perf_counter()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(std):
        try:
            status = main(["wrap", str(template), str(scan), "-o", str(out),
                           "--template-landmarks", str(folder / "ict_face_landmarks.json"),
                           "--scan-landmarks", str(folder / "scan_landmarks.json"),
                           "--template-profile", "none", "--model", "graph"])
        except Exception as exc:   # a traceback is a bug: say so in the row
            status, err = "traceback", io.StringIO(f"{type(exc).__name__}: {exc}")
    row = {"row": name, "status": status, "time": time.perf_counter() - t,
           "stderr": [s for s in err.getvalue().splitlines() if s.strip()],
           "stdout": [s for s in std.getvalue().splitlines() if s.strip()]}
    if status == 0:
        V = d.back(read_mesh(out).vertices[:case.template.n_vertices])
        m = realscan.measures(V, case)
        row.update(fit_p95=m["fit_p95"], landmark_mean=m["landmark_mean"])
    return row


def run(models=("graph", "hybrid"), rows=None, cli: bool = True) -> dict:
    out = {"rows": [], "cli": [], "notes": []}
    found = [c for c, _ in realscan._cases() if c.name.startswith("ICT")]
    if not found:
        out["notes"].append("skipped: ../shared/data (ICT-FaceKit, scans/james) is absent")
        return out
    case = found[0]
    chosen = [(n, h) for n, h in DEGRADATIONS if rows is None or n in rows]
    for name, how in chosen:
        for model in models:
            r = safe_row(case, name, how, model)
            print(_line(r), file=sys.stderr, flush=True)
            out["rows"].append(r)
    if cli:
        with tempfile.TemporaryDirectory() as tmp:
            for name, how in chosen:
                if name in CLI_ROWS:
                    r = nicp._safe(run_cli, case, name, how, Path(tmp), method=name)
                    out["cli"].append(r)
                    print(r, file=sys.stderr, flush=True)
    return out


def _verdict(r: dict, clean: dict | None) -> str:
    """ok / refused / WORSE / FAILED, against the clean row of the same model."""
    if "error" in r:
        if r.get("refused"):
            return "refused" + ("" if r.get("refuse") else " (wrongly)")
        return "FAILED"
    if r.get("refuse"):
        return "fitted (should refuse)" + (", warned" if r["warnings"] else ", SILENT")
    if clean is None or r is clean:
        return "ok"
    worse = (r["fit_p95"] > 1.5 * clean["fit_p95"] or r["flipped"] > clean["flipped"] + 2
             or r["landmark_mean"] > 1.5 * clean["landmark_mean"] + 0.5)
    return ("WORSE" + (", warned" if r["warnings"] else ", silent")) if worse else "ok"


def _line(r: dict) -> str:
    if "error" in r:
        return f"{r['row']} [{r['model']}]: {r['error']}"
    return (f"{r['row']} [{r['model']}]: p95 {r['fit_p95']:.2f} mm, flipped "
            f"{r['flipped']}, landmarks {r['landmark_mean']:.2f} mm, {r['time']:.1f} s, "
            f"{len(r['warnings'])} warning(s)")


def markdown(r: dict) -> str:
    L = ["### Degraded real scans: ICT face → james, one spoiling per row", "",
         "Fit p95 over ICT's fitting vertices, measured on the clean scan's surface "
         "(away from its borders), mm; flipped = fitting-set triangles turned past "
         "90° from the fit's rest pose (aligned template, plus the fitted shapes for "
         "the hybrid); landmarks = mean distance to the clean scan's landmarks, mm; "
         "time of `wrap` in s; verdict against the clean row (worse: p95 > 1.5×, "
         "more than 2 new flips, or landmarks > 1.5× + 0.5 mm).", ""]
    L += r.get("notes", [])
    if r["rows"]:
        L += ["| scan | model | fit p95 (mm) | flipped | landmarks mean / max (mm) | "
              "time (s) | warnings | verdict |", "|---|---|---:|---:|---:|---:|---|---|"]
        clean = {x["model"]: x for x in r["rows"] if x["row"] == "clean" and "error" not in x}
        for x in r["rows"]:
            v = _verdict(x, clean.get(x["model"]))
            if "error" in x:
                L.append(f"| {x['row']} | {x['model']} | — | — | — | — | "
                         f"{x['error'][:160]} | {v} |")
                continue
            w = "; ".join(s[:90] for s in x["warnings"]) or "none"
            L.append(f"| {x['row']} | {x['model']} | {x['fit_p95']:.2f} | {x['flipped']} | "
                     f"{x['landmark_mean']:.2f} / {x['landmark_max']:.2f} | "
                     f"{x['time']:.1f} | {w} | {v} |")
        L.append("")
    if r["cli"]:
        L += ["`facewrap wrap` (graph model) on the same files: exit status, what it "
              "printed to standard error, fit p95 (mm).", "",
              "| scan | exit | stderr | fit p95 (mm) |", "|---|---:|---|---:|"]
        for x in r["cli"]:
            if "error" in x:
                L.append(f"| {x['method']} | — | {x['error']} | — |")
                continue
            e = "<br>".join(s[:140] for s in x["stderr"]) or "—"
            p = f"{x['fit_p95']:.2f}" if "fit_p95" in x else "—"
            L.append(f"| {x['row']} | {x['status']} | {e} | {p} |")
        L.append("")
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    import argparse
    ap = argparse.ArgumentParser()
    ap.add_argument("--rows", nargs="*", help="only these rows (names as in the table)")
    ap.add_argument("--models", nargs="*", default=["graph", "hybrid"])
    ap.add_argument("--no-cli", action="store_true")
    ap.add_argument("--json", help="also write the raw rows here")
    a = ap.parse_args()
    result = run(tuple(a.models), a.rows, not a.no_cli)
    if a.json:
        import json
        Path(a.json).write_text(json.dumps(result, indent=1, default=str))
    print(markdown(result))
