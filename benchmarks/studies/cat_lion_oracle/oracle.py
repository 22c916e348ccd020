"""Oracle bounds for cat->lion deformation transfer (Sumner formulation)."""
import tempfile
import time
import numpy as np, scipy.sparse as sp
from pathlib import Path
from scipy.spatial import cKDTree
from scipy.optimize import nnls
from common import gradient_solver, load, relative_errors
from facewrap.geometry import face_normals
from facewrap.transfer import DeformationTransfer, find_correspondence
from facewrap.transfer import gradient_operator
from facewrap.transfer import source_gradient_blocks, pair_matrix, complete_pairs

T0 = time.perf_counter()
p, s, t, S_ref, L_ref, P, GT, k, n, a, diag = load()
print("anchor moves in GT:", np.abs(GT[:, a] - L_ref.vertices[a]).max())

def errors(out):
    return relative_errors(out, GT, diag)

rows = []
def report(name, out, extra=""):
    r, g = errors(out)
    rows.append((name, r, g, extra))
    print(f"{name:58s} raw {r.mean():.3f}  rigid {g.mean():.3f}  {extra}", flush=True)
    print("    raw/pose  " + " ".join(f"{x:.2f}" for x in r), flush=True)
    print("    rig/pose  " + " ".join(f"{x:.2f}" for x in g), flush=True)

# ---------- baseline
corr = find_correspondence(S_ref, L_ref, p.markers)
for ff in (False, True):
    dt = DeformationTransfer(anchor=a, fix_flips=ff).fit(S_ref, L_ref, corr)
    report(f"baseline library transfer (fix_flips={ff})", dt.transfer(P))

# ---------- gradients
sop = gradient_operator(S_ref.vertices, S_ref.triangles)
lop = gradient_operator(L_ref.vertices, L_ref.triangles)
Sg = source_gradient_blocks(sop, P)     # (k, ts, 9)
Lg = source_gradient_blocks(lop, GT)    # (k, tl, 9)
ts, tl = Sg.shape[1], Lg.shape[1]

def make_solver(w):
    return gradient_solver(L_ref, a, k, w)

solve = make_solver(np.ones(tl))

# 1. sanity
report("1 lion GT gradients as targets", solve(Lg))

# baseline energy with uniform weights, library pairs averaged (sanity of own solver)
Pm, orph = complete_pairs(pair_matrix(corr), L_ref.triangles)
cnt = np.asarray(Pm.sum(1)).ravel()
avg = sp.diags(1 / cnt) @ Pm
Bavg = np.stack([avg @ Sg[j] for j in range(k)])
solve_cnt = make_solver(cnt)
report("0 library corr, own solver (weights=#pairs, plain)", solve_cnt(Bavg))
report("0 library corr, pair-mean gradient, uniform weights", solve(Bavg))

def gfit(B):  # per-triangle gradient residual, relative
    return np.sqrt(((B - Lg) ** 2).sum((0, 2)).sum() / (Lg ** 2).sum((0, 2)).sum())
print("   grad rel residual library:", gfit(Bavg))

# flatten per lion triangle: (tl, k*9); cat: (ts, k*9)
Lf = Lg.transpose(1, 0, 2).reshape(tl, -1)
Sf = Sg.transpose(1, 0, 2).reshape(ts, -1)

# ---------- 2. best single cat triangle, all poses jointly
# candidates from the correspondence deformation (deformed cat in lion coords)
cd = corr.deformed[S_ref.triangles].mean(1)
cl = L_ref.vertices[L_ref.triangles].mean(1)
nd = face_normals(corr.deformed, S_ref.triangles)
nl = face_normals(L_ref.vertices, L_ref.triangles)
tree = cKDTree(cd)
Kmax = 64
_, NB = tree.query(cl, k=Kmax)

def best_single(cands):
    # cands (tl, K)
    d = ((Sf[cands] - Lf[:, None]) ** 2).sum(-1)
    j = d.argmin(1)
    return cands[np.arange(tl), j]

def best_single_all():
    out = np.empty(tl, int)
    s2 = (Sf ** 2).sum(1)
    for i in range(0, tl, 1000):
        D = s2[None] - 2 * Lf[i:i + 1000] @ Sf.T
        out[i:i + 1000] = D.argmin(1)
    return out

for K in (1, 8, 16, 64):
    pick = best_single(NB[:, :K])
    B = Sg[:, pick]
    report(f"2 best single cat tri, K={K} nearest (deformed cat)", solve(B),
           f"grad res {gfit(B):.3f}")
pick_all = best_single_all()
B = Sg[:, pick_all]
dist_all = np.linalg.norm(cd[pick_all] - cl, axis=1) / np.linalg.norm(np.ptp(L_ref.vertices, 0))
report("2 best single cat tri, ANY cat triangle", solve(B),
       f"grad res {gfit(B):.3f}, partner dist med {np.median(dist_all)*100:.1f}% diag")

# per-pose best single (upper-bound flavour of 2)
def best_single_perpose(cands):
    out = np.empty((k, tl, 9))
    for j in range(k):
        d = ((Sg[j][cands] - Lg[j][:, None]) ** 2).sum(-1)
        out[j] = Sg[j][cands[np.arange(tl), d.argmin(1)]]
    return out
for K in (16, 64):
    B = best_single_perpose(NB[:, :K])
    report(f"2b best single per POSE, K={K}", solve(B), f"grad res {gfit(B):.3f}")

# ---------- 3/4. combinations
def combo(cands, convex, per_pose, lam=1e3):
    K = cands.shape[1]
    out = np.empty((k, tl, 9))
    scale = np.sqrt(lam)
    for i in range(tl):
        c = cands[i]
        if not per_pose:
            A = Sf[c].T; b = Lf[i]
            if convex:
                sc = scale * np.sqrt(k)
                A = np.vstack([A, sc * np.ones(K)]); b = np.r_[b, sc]
            w, _ = nnls(A, b, maxiter=50 * K)
            out[:, i] = np.einsum("k,jkd->jd", w, Sg[:, c])
        else:
            for j in range(k):
                A = Sg[j, c].T; b = Lg[j, i]
                if convex:
                    A = np.vstack([A, scale * np.ones(K)]); b = np.r_[b, scale]
                w, _ = nnls(A, b, maxiter=50 * K)
                out[j, i] = w @ Sg[j, c]
    return out

for per_pose, label in ((False, "3 {} comb K={}, shared over poses"),
                        (True, "4 {} comb K={}, free per pose")):
    for K in (8, 16, 32):
        for convex in (True, False):
            tt = time.perf_counter()
            B = combo(NB[:, :K], convex, per_pose)
            report(label.format("convex" if convex else "nonneg", K), solve(B),
                   f"grad res {gfit(B):.3f} ({time.perf_counter()-tt:.0f}s)")

np.save(str(Path(tempfile.gettempdir()) / "cat_lion_oracle_rows.npy"), np.array([(r[0], r[1].mean(), r[2].mean()) for r in rows], dtype=object), allow_pickle=True)
print("total", time.perf_counter() - T0)
