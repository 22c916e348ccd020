"""Ground-truth scans of ICT-FaceKit's full heads, made as a face scanner makes them.

A scanner records only what its cameras see, and its reconstruction closes the lips
over the mouth (as menpo's ``james`` is closed), so the inner lips that ICT counts
among its fitting vertices have no surface of their own on the scan.  These cases
ask what the measure "fit over ICT's fitting vertices" rewards there: a wrap that
lets the unseen inner lips follow the skin, or one that pulls them onto the bridge.

One case: an ICT identity's neutral head (26,719 v, cm); the skin triangles an
outside camera sees (:func:`facewrap.geometry.visibility.outside_views`), the front
of the head only, the mouth's boundary loop filled with a fan; another triangulation
(``_nicp_cases.remesh``), 0.2 mm of noise along the normal, mm; 68 landmarks with
0.5 mm of noise.  The truth is the identity's head itself, every vertex.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

import _nicp_cases as C
from facewrap.geometry.visibility import outside_views
from facewrap.landmarks import IBUG68_NAMES, Landmarks
from facewrap.mesh import Mesh

SKIN_END = 14062          # ICT's parts table: skin with its sockets, parts from here
N_TRIANGLES = 30000
_VERSION = 2


def _large_components(V, F, smallest: int = 2000):
    """``F`` without the islands of fewer than ``smallest`` triangles (specks
    the visibility test leaves inside the ears and nostrils)."""
    n = len(V)
    A = sp.coo_matrix((np.ones(3 * len(F)), (F.ravel(), np.roll(F, 1, axis=1).ravel())),
                      shape=(n, n))
    _, label = connected_components(A, directed=False)
    of_triangle = label[F[:, 0]]
    return F[np.bincount(of_triangle)[of_triangle] >= smallest]


def _mouth_closed(V, F, mouth):
    """The boundary loop nearest ``mouth`` (3,) filled with a fan to its centre,
    oriented as its neighbours (a boundary edge (a, b) of the surface becomes the
    fan's edge (b, a))."""
    import igl
    loops = igl.boundary_loop_all(np.asarray(F, dtype=np.int64))
    loop = np.asarray(min(loops, key=lambda L: np.linalg.norm(V[L].mean(axis=0) - mouth)))
    centre = len(V)
    fan = np.c_[np.roll(loop, -1), loop, np.full(len(loop), centre)]
    return np.vstack([V, V[loop].mean(axis=0)]), np.vstack([F, fan])


def _compact(V, F):
    used = np.unique(F)
    remap = np.full(len(V), -1)
    remap[used] = np.arange(len(used))
    return V[used], remap[F]


def _seen_remeshed(P, T, front, seen):
    """The seen front skin in another triangulation.  libigl's decimation gives up
    on some surfaces (it returns nothing): the front skin is remeshed whole and
    then cut where the original is seen, or, when that fails, the cut is
    remeshed."""
    from facewrap.geometry.closest import ClosestPointTree
    try:
        S, G = C.remesh(*_compact(P, T[front]), N_TRIANGLES)
        nearest = ClosestPointTree(P, T[front]).query(S[G].mean(axis=1)).triangles
        G = G[seen[front][nearest]]
    except ValueError:
        S, G = C.remesh(*_compact(P, T[seen]), N_TRIANGLES)
    return _compact(S, _large_components(S, G))


def scanned_head(identity: str, seed: int = 0):
    """(scan Mesh in mm, 68 scan Landmarks, truth (26719, 3) mm), cached.

    Raises ``ValueError`` from the remeshing when libigl's decimation cannot
    handle the surface (the caller skips the case and says so).
    """
    key = json.dumps(["scanned-head", identity, seed, N_TRIANGLES, _VERSION])
    C.CACHE.mkdir(parents=True, exist_ok=True)
    path = C.CACHE / f"head-{hashlib.sha1(key.encode()).hexdigest()[:12]}.npz"
    if path.is_file():
        d = np.load(path)
        return (Mesh(d["scan_v"], d["scan_f"]),
                Landmarks.from_points(d["landmarks"], names=IBUG68_NAMES), d["truth"])
    kit = C.ict_kit()
    head = kit.neutral
    T = head.triangles
    P = head.vertices + (kit.shape(identity) - kit.neutral.vertices)
    z = P[T][:, :, 2].mean(axis=1)
    front = (z > P[:, 2].min() + 0.45 * np.ptp(P[:, 2])) & (T < SKIN_END).all(axis=1)
    seen = outside_views(P, T)
    seen_triangle = seen[T].all(axis=1) & front
    S, G = _seen_remeshed(P, T, front, seen_triangle)
    lmv = np.asarray(kit.indices["idx_to_landmark_verts"])
    S, G = _mouth_closed(S, G, P[lmv[48:68]].mean(axis=0))
    rng = np.random.default_rng(seed)
    S = S + rng.normal(scale=0.02, size=(len(S), 1)) * C._vertex_normals(S, G)
    truth = 10.0 * P
    landmarks = truth[lmv] + rng.normal(scale=0.5, size=(len(lmv), 3))
    C.save_npz(path, scan_v=10.0 * S, scan_f=G, landmarks=landmarks, truth=truth)
    return (Mesh(10.0 * S, G), Landmarks.from_points(landmarks, names=IBUG68_NAMES),
            truth)
