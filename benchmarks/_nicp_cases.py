"""Ground-truth registration cases for ``bench_nicp`` (helpers, no timing here).

ICT-FaceKit cases: the template is ICT's neutral face region (9,409 vertices, cm);
the scan is ICT's neutral + an identity shape + an extreme expression, remeshed to
another topology (midpoint-subdivided twice, decimated by edge collapse with
libigl, vertices snapped back onto the true surface), with normal noise and a
hole, converted to mm and moved by a random rigid motion.  The truth for each
template vertex is its position in the deformed ICT mesh (same units, same motion).

Cases are pure functions of their arguments (fixed seeds) and cached as ``.npz``
in a temporary folder.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facewrap.geometry import ClosestPointTree
from facewrap.landmarks import IBUG68_NAMES, Landmarks
from facewrap.mesh import Mesh

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
ICT_COMPACT = DATA / "ict-facekit"
CACHE = Path(tempfile.gettempdir()) / "facewrap-bench-nicp"
N_FACE = 9409          # ICT face region: vertices 0..9408


@dataclass
class Case:
    name: str
    template: Mesh                 # template mesh (its own units)
    landmarks: Landmarks           # on the template
    blendshapes: dict | None       # name -> (n, 3) positions in the template's topology
    scan: Mesh                     # scan (mm)
    scan_landmarks: Landmarks      # free points on the scan (mm)
    truth: np.ndarray              # (n, 3) where each template vertex belongs (mm)
    mask: np.ndarray               # (n,) bool: vertices the error is measured on
    note: str = ""


# -- ICT-FaceKit --------------------------------------------------------------------
_KIT = None


def ict_available() -> bool:
    return (ICT_COMPACT / "expand.py").is_file()


def ict_kit():
    """The expanded ICT-FaceKit (expanded once into facewrap's cache folder, and
    again if that folder went: a benchmark with a temporary cache removes it)."""
    global _KIT
    if _KIT is None or not Path(_KIT.folder).is_dir():
        from facewrap.datasets import ICTFaceKit, expand_ict_facekit
        folder = expand_ict_facekit(ICT_COMPACT)
        _KIT = ICTFaceKit(folder)
    return _KIT


def ict_template():
    """(face Mesh in cm, 68 landmarks, {expression: (9409, 3) positions})."""
    kit = ict_kit()
    face = kit.part_mesh("face")
    shapes = {n: np.asarray(kit.shape(n)[:N_FACE]) for n in kit.expression_names}
    return face, kit.landmarks, shapes


def _rotation(rng) -> np.ndarray:
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = np.radians(rng.uniform(10, 25))
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def remesh(V, F, n_triangles: int):
    """Another triangulation of the surface (V, F): midpoint subdivision to at
    least 2x ``n_triangles``, then edge-collapse decimation (libigl, shortest edge
    first, midpoint placement) to ``n_triangles``; vertices are then snapped back
    onto (V, F) so they lie on the true surface."""
    import igl
    import trimesh
    V2, F2 = np.asarray(V, float), np.asarray(F, np.int64)
    while len(F2) < 1.4 * n_triangles:
        V2, F2 = trimesh.remesh.subdivide(V2, F2)
    U, G = igl.decimate(np.asfortranarray(V2), np.asfortranarray(F2), int(n_triangles))[:2]
    used = np.unique(G)
    remap = np.full(len(U), -1)
    remap[used] = np.arange(len(used))
    U, G = U[used], remap[G]
    cp = ClosestPointTree(np.asarray(V, float), np.asarray(F, np.int64)).query(U)
    return cp.points, G


def _vertex_normals(V, F):
    N = np.zeros_like(V)
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    for k in range(3):
        np.add.at(N, F[:, k], fn)
    return N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-30)


def _seen_mask(scan: Mesh, truth, tol=1.0):
    """Truth points on the scan (within ``tol`` mm) whose closest scan triangle
    is not on its border (hole, outline) — the demo's "seen" rule."""
    tree = ClosestPointTree(scan.vertices, scan.triangles)
    ok = np.isfinite(truth).all(axis=1)
    mask = np.zeros(len(truth), dtype=bool)
    cp = tree.query(truth[ok])
    mask[ok] = ~tree.boundary_triangles[cp.triangles] & (cp.distances < tol)
    return mask


def save_npz(path: Path, **arrays) -> None:
    """Write a cached case whole: to a file of this process's own, then renamed (two
    benchmarks building one case at once each wrote the same temporary file, and the
    second rename found it gone)."""
    tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
    np.savez_compressed(tmp, **arrays)
    tmp.replace(path)


def _save(path: Path, case: Case):
    save_npz(path, template_v=case.template.vertices, scan_v=case.scan.vertices,
             scan_f=case.scan.triangles, scan_lm=case.scan_landmarks.positions(case.scan),
             truth=case.truth, mask=case.mask)


def ict_case(name: str, identity: str, expression: dict, *, n_triangles: int = 60000,
             noise_cm: float = 0.02, hole_radius_cm: float = 1.5,
             landmark_noise_mm: float = 0.5, seed: int = 0, person=None,
             rigid=None) -> Case:
    """An ICT-FaceKit ground-truth case (cached).

    ``person`` (9409, 3) cm replaces ICT's identity + expression (a face made
    otherwise, in the template's topology); ``rigid`` ``(R, t)`` replaces the
    random rigid motion (mm).
    """
    extra = [] if person is None and rigid is None else [
        hashlib.sha1(np.ascontiguousarray(person if person is not None else 0.0)).hexdigest(),
        None if rigid is None else np.concatenate([np.ravel(rigid[0]), rigid[1]]).tolist()]
    key = json.dumps([name, identity, sorted(expression.items()), n_triangles, noise_cm,
                      hole_radius_cm, landmark_noise_mm, seed, 2] + extra)
    CACHE.mkdir(parents=True, exist_ok=True)
    path = CACHE / f"ict-{hashlib.sha1(key.encode()).hexdigest()[:12]}.npz"
    face, lms, shapes = ict_template()
    kit = ict_kit()
    note = (f"{identity} + " + " + ".join(f"{k} {w:g}" for k, w in expression.items()))
    if path.is_file():
        d = np.load(path)
        scan = Mesh(d["scan_v"], d["scan_f"])
        return Case(name, face, lms, shapes, scan,
                    Landmarks.from_points(d["scan_lm"], names=IBUG68_NAMES),
                    d["truth"], d["mask"], note)
    rng = np.random.default_rng(seed)
    V0 = face.vertices
    P = V0 + (kit.shape(identity)[:N_FACE] - kit.neutral.vertices[:N_FACE])
    for k, w in expression.items():
        P = P + w * (shapes[k] - V0)
    if person is not None:
        P = np.asarray(person, dtype=np.float64)
    T = face.triangles
    # another topology
    S, G = remesh(P, T, n_triangles)
    # noise along the normal
    S = S + rng.normal(scale=noise_cm, size=(len(S), 1)) * _vertex_normals(S, G)
    # a hole on the left cheek: between the jaw (landmark 13) and the nose (31)
    lmv = np.asarray(kit.indices["idx_to_landmark_verts"])
    centre = 0.5 * (P[lmv[13]] + P[lmv[35]])
    centre = ClosestPointTree(P, T).query(centre[None]).points[0]
    keep = np.linalg.norm(S[G].mean(axis=1) - centre, axis=1) > hole_radius_cm
    G = G[keep]
    used = np.unique(G)
    remap = np.full(len(S), -1)
    remap[used] = np.arange(len(used))
    S, G = S[used], remap[G]
    # mm and a rigid motion
    R = _rotation(rng)
    t = rng.uniform(-50, 50, size=3)
    if rigid is not None:
        R, t = np.asarray(rigid[0], dtype=np.float64), np.asarray(rigid[1], dtype=np.float64)
    scan = Mesh(10.0 * S @ R.T + t, G)
    truth = 10.0 * P @ R.T + t
    lm_pts = truth[lmv] + rng.normal(scale=landmark_noise_mm, size=(len(lmv), 3))
    case = Case(name, face, lms, shapes, scan,
                Landmarks.from_points(lm_pts, names=IBUG68_NAMES), truth,
                _seen_mask(scan, truth), note)
    _save(path, case)
    return case


# -- the built-in synthetic sample -------------------------------------------------
def sample_case() -> Case:
    """The built-in sample (jaw open, eyes shut, smile; noise, holes, crop), its
    template restricted to the face/head skin (eyeballs dropped for every method)."""
    from facewrap.sample import make_scan, make_template
    tpl = make_template()
    scan = make_scan(tpl)
    face = tpl.parts["face"]
    n = len(face)
    F = tpl.mesh.triangles
    F = F[(F < n).all(axis=1)]
    template = Mesh(tpl.mesh.vertices[:n], F)
    shapes = {k: np.asarray(v[:n]) for k, v in tpl.blendshapes.items()}
    truth = scan.ground_truth[:n]
    return Case("sample", template, tpl.landmarks, shapes, scan.mesh, scan.landmarks,
                truth, _seen_mask(scan.mesh, truth),
                "built-in sample: identity 1, jaw_open 0.8 + blink 1 + smile 0.3")
