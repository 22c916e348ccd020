"""Where the cat → lion error comes from, and how far correspondences that do not
look at the ground truth spread (session 4).  About 1 minute.

1. Blind variants (no ground truth used): their error against Sumner's lion poses,
   and how far their results lie from *each other*.
2. Localisation: the lion's own (ground-truth) gradients put into one body region
   at a time; how much of the error each region carries.
3. Slide oracle (needs the pair file ``oracle_vertex.py 16cs`` writes): lion
   centroids moved by the oracle partners' offset, smoothed over a radius, then
   matched again -- is the difference a smooth slide of the correspondence?
"""
import dataclasses
import sys
import tempfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.cluster.vq import kmeans2
from scipy.spatial import cKDTree

from common import gradient_solver, load, relative_errors
from facewrap.geometry import face_normals
from facewrap.transfer import find_correspondence
from facewrap.transfer import SUMNER_SCHEDULE, CorrespondenceSettings
from facewrap.transfer import gradient_operator
from facewrap.transfer import source_gradient_blocks

p, s, t, S_ref, L_ref, P, GT, k, n, a, diag = load()
Sg = source_gradient_blocks(gradient_operator(S_ref.vertices, S_ref.triangles), P)
ts, tl = Sg.shape[1], len(L_ref.triangles)
cl = L_ref.vertices[L_ref.triangles].mean(1)
nl = face_normals(L_ref.vertices, L_ref.triangles)
plain = gradient_solver(L_ref, a, k)


def blocks(W):
    """Target gradient blocks from (tl, ts) weights, rows normalised; a lion
    triangle without weights keeps its rest gradient (the identity)."""
    W = sp.csr_matrix(W)
    rs = np.asarray(W.sum(1)).ravel()
    W = sp.diags(1 / np.where(rs > 0, rs, 1)) @ W
    B = np.stack([W @ Sg[i] for i in range(k)])
    B[:, rs == 0] = np.eye(3).ravel()
    return B, rs


def sumner_pairs(corr):
    """A library correspondence (nearest centroid both ways) through Sumner's solve,
    which weighs a lion triangle with c partners c times."""
    s_, t_ = corr.source_triangles, corr.target_triangles
    B, rs = blocks(sp.csr_matrix((np.ones(len(t_)), (t_, s_)), shape=(tl, ts)))
    return gradient_solver(L_ref, a, k, np.maximum(rs, 1))(B)


def gaussian(D, query=None, K=32, width=3.0):
    """Soft partners: Gaussian weights (width x the median nearest distance) over
    the K nearest compatible cat centroids."""
    cs, ns = D[S_ref.triangles].mean(1), face_normals(D, S_ref.triangles)
    d, nb = cKDTree(cs).query(cl if query is None else query, k=K)
    ok = np.einsum("ikj,ij->ik", ns[nb], nl) > 0
    h = np.median(d[:, 0]) + 1e-9
    w = np.exp(-(d / (width * h)) ** 2) * ok
    return plain(blocks(sp.csr_matrix((w.ravel(), (np.repeat(np.arange(tl), K),
                                                     nb.ravel())), shape=(tl, ts)))[0])


def line(name, out, ref=GT):
    r, g = relative_errors(out, ref, diag)
    print(f"{name:52s} raw {r.mean():.3f}  rigid {g.mean():.3f}", flush=True)
    return r.mean(), g.mean()


def correspondence(**kw):
    return find_correspondence(S_ref, L_ref, p.markers, CorrespondenceSettings(**kw))


def schedule(**kw):
    return tuple(dataclasses.replace(x, **kw) for x in SUMNER_SCHEDULE)


print("1. blind variants against the ground truth")
C0 = correspondence()
D0 = C0.deformed
src, tgt = p.markers
rng = np.random.default_rng(0)
outs = {"default": sumner_pairs(C0),
        "deform the lion instead": sumner_pairs(correspondence(deform="target")),
        "w_I = 10": sumner_pairs(correspondence(schedule=schedule(identity_weight=10.0))),
        "w_I = 1": sumner_pairs(correspondence(schedule=schedule(identity_weight=1.0))),
        "10 iterations per w_C step": sumner_pairs(correspondence(schedule=tuple(
            dataclasses.replace(x, iterations=10 if x.closest_weight else 1)
            for x in SUMNER_SCHEDULE)))}
for i in range(2):
    keep = np.sort(rng.choice(len(src), len(src) - 5, replace=False))
    outs[f"5 markers left out (draw {i + 1})"] = sumner_pairs(
        find_correspondence(S_ref, L_ref, (src[keep], tgt[keep])))
for name, out in outs.items():
    line(name, out)
line("default, Gaussian partners", gaussian(D0))
line("w_I = 1, Gaussian partners",
     gaussian(correspondence(schedule=schedule(identity_weight=1.0)).deformed))

print("\n   ... and against each other (the same measure, one result as the reference)")
names = list(outs)
spread = [line(f"{names[i]} vs {names[j]}", outs[names[i]], outs[names[j]])[0]
          for i in range(len(names)) for j in range(i + 1, len(names))]
print(f"   pairwise raw: {min(spread):.2f}-{max(spread):.2f} %, median {np.median(spread):.2f} %")

print("\n2. the lion's own gradients put into one region at a time (24 k-means regions)")
cent, lab = kmeans2(L_ref.vertices, 24, minit="++", seed=1)
tlab = lab[L_ref.triangles[:, 0]]
s_, t_ = C0.source_triangles, C0.target_triangles
B0, rs = blocks(sp.csr_matrix((np.ones(len(t_)), (t_, s_)), shape=(tl, ts)))
counted = gradient_solver(L_ref, a, k, np.maximum(rs, 1))
Lg = source_gradient_blocks(gradient_operator(L_ref.vertices, L_ref.triangles), GT)
base = line("default", counted(B0))[0]
gain = []
for j in range(24):
    B = B0.copy()
    B[:, tlab == j] = Lg[:, tlab == j]
    r, _ = relative_errors(counted(B), GT, diag)
    gain.append(base - r.mean())
order = np.argsort(gain)[::-1]
for j in order[:6]:
    print(f"   region {j:2d} at {np.round(cent[j], 2)} ({np.sum(tlab == j)} triangles): "
          f"raw error -{gain[j]:.2f}")
for m in (4, 8):
    sel = np.isin(tlab, order[:m])
    B = B0.copy()
    B[:, sel] = Lg[:, sel]
    line(f"   the {m} regions above together ({sel.sum()} triangles, "
         f"{100 * sel.mean():.0f} %)", counted(B))

pairs = Path(tempfile.gettempdir()) / "pairs_K16_all_thr0.25.npz"
if not pairs.exists():
    sys.exit(f"\n3. skipped: {pairs} missing (run oracle_vertex.py it=400 16cs first)")
print("\n3. slide oracle: lion centroids moved by the oracle partners' smoothed offset")
o = np.load(pairs)
cs0 = D0[S_ref.triangles].mean(1)
cnt = np.bincount(o["target"], minlength=tl)
po = np.zeros((tl, 3))
np.add.at(po, o["target"], cs0[o["source"]])
has = cnt > 0
offset = np.where(has[:, None], po / np.maximum(cnt, 1)[:, None] - cl, 0.0)
tree = cKDTree(cl)
for r in (0.01, 0.02, 0.04):
    near = tree.query_ball_point(cl, r)
    sm = np.array([offset[i].sum(0) / max(has[i].sum(), 1) for i in map(np.asarray, near)])
    line(f"offset smoothed over r = {r} (~{r / 0.011:.0f} lion edges), Gaussian",
         gaussian(D0, query=cl + sm))
