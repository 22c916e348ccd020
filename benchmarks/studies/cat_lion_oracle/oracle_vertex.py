"""Vertex-error oracles: weights over K candidate cat triangles per lion triangle,
optimised for the transferred vertices' error (not for the per-triangle gradient
fit).  Sumner's GT lion gradients carry the LS residual of his solve, so fitting
them per triangle is the wrong target; this fits what the solve produces."""
import sys
import tempfile
import time
import numpy as np
from pathlib import Path
from scipy.spatial import cKDTree
from scipy.optimize import minimize
from common import load, relative_errors
from facewrap.solve import factorize
from facewrap.transfer import find_correspondence
from facewrap.transfer import gradient_operator
from facewrap.transfer import source_gradient_blocks

p, s, t, S_ref, L_ref, P, GT, k, n, a, diag = load()

def errors(out):
    return relative_errors(out, GT, diag)

def report(name, out, extra=""):
    r, g = errors(out)
    print(f"{name:62s} raw {r.mean():.3f}  rigid {g.mean():.3f}  {extra}", flush=True)
    print("    raw/pose  " + " ".join(f"{x:.2f}" for x in r), flush=True)
    print("    rig/pose  " + " ".join(f"{x:.2f}" for x in g), flush=True)

corr = find_correspondence(S_ref, L_ref, p.markers)
sop = gradient_operator(S_ref.vertices, S_ref.triangles)
lop = gradient_operator(L_ref.vertices, L_ref.triangles)
Sg = source_gradient_blocks(sop, P)     # (k, ts, 9)
Lg = source_gradient_blocks(lop, GT)
ts, tl = Sg.shape[1], Lg.shape[1]
G = lop.matrix.tocsr(); N = G.shape[1]
fidx = np.setdiff1d(np.arange(N), [a])
H = (G.T @ G).tocsr()
Hff = H[fidx][:, fidx]
Hfa = np.asarray(H[fidx][:, [a]].todense()).ravel()
F = factorize(Hff)
Gf = G[:, fidx].tocsr()
xa = np.tile(L_ref.vertices[a], k)
isvert = fidx < n                       # free unknowns that are real vertices
GTm = GT.transpose(1, 0, 2).reshape(n, 3 * k)[fidx[isvert]] / diag
c0 = (Hfa[:, None] * xa[None, :])

def B2m(B):
    return B.reshape(k, tl, 3, 3).transpose(1, 2, 0, 3).reshape(3 * tl, 3 * k)
def m2B(M):
    return M.reshape(tl, 3, k, 3).transpose(2, 0, 1, 3).reshape(k, tl, 9)
def forward(B):
    return F.solve(G.T[fidx] @ B2m(B) - c0)
def to_X(xf):
    x = np.empty((N, 3 * k)); x[fidx] = xf; x[a] = xa
    return x[:n].reshape(n, k, 3).transpose(1, 0, 2)

cd = corr.deformed[S_ref.triangles].mean(1)
cl = L_ref.vertices[L_ref.triangles].mean(1)
_, NB = cKDTree(cd).query(cl, k=64)

TRAIN = np.ones(k, bool)
def run(K, convex, per_pose, iters=600, mu=None):
    C = NB[:, :K]
    SC = Sg[:, C]                                 # (k, tl, K, 9)
    shape = (k, tl, K) if per_pose else (tl, K)
    def Bof(w):
        w = w.reshape(shape)
        if per_pose:
            return np.einsum("pic,picd->pid", w, SC)
        return np.einsum("ic,picd->pid", w, SC)
    mu_ = mu if mu is not None else 1.0
    def f(w):
        xf = forward(Bof(w))
        e = np.zeros_like(xf); e[isvert] = xf[isvert] / diag - GTm
        e[:, ~np.repeat(TRAIN, 3)] = 0
        val = 0.5 * (e ** 2).sum() / k
        lam = F.solve(e) / diag / k
        dB = m2B(Gf @ lam)                        # (k, tl, 9)
        if per_pose:
            g = np.einsum("pid,picd->pic", dB, SC)
        else:
            g = np.einsum("pid,picd->ic", dB, SC)
        w2 = w.reshape(shape)
        if convex:
            r = w2.sum(-1) - 1
            val += 0.5 * mu_ * (r ** 2).sum()
            g = g + mu_ * r[..., None]
        return val, g.ravel()
    w0 = np.full(shape, 1.0 / K)
    # warm start: nearest candidate
    w0[...] = 0; w0[..., 0] = 1
    tt = time.perf_counter()
    res = minimize(f, w0.ravel(), jac=True, method="L-BFGS-B",
                   bounds=[(0, None)] * w0.size, options={"maxiter": iters, "maxfun": 2 * iters})
    w = res.x.reshape(shape)
    dev = np.abs(w.sum(-1) - 1)
    if convex:
        w = w / np.maximum(w.sum(-1, keepdims=True), 1e-12)
    X = to_X(forward(Bof(w)))
    tag = f"{'convex' if convex else 'nonneg'} K={K} {'per-pose' if per_pose else 'shared'}"
    report(f"V {tag} (vertex-err fit)", X,
           f"it {res.nit} {time.perf_counter()-tt:.0f}s |sum-1| med {np.median(dev):.3f} p99 {np.percentile(dev,99):.3f}")
    if not TRAIN.all():
        r, g = errors(X)
        print(f"    held-out poses {np.flatnonzero(~TRAIN)+1}: raw {r[~TRAIN].mean():.3f} rigid {g[~TRAIN].mean():.3f};"
              f" train raw {r[TRAIN].mean():.3f} rigid {g[TRAIN].mean():.3f}", flush=True)
    if convex and not per_pose:
        # round to an unweighted pair subset (a plain Sumner correspondence)
        for thr in (0.5, 0.25):
            keep = w >= thr * w.max(-1, keepdims=True)
            wr = keep / keep.sum(-1, keepdims=True)
            ii, cc = np.nonzero(keep)
            np.savez(str(Path(tempfile.gettempdir()) / f"pairs_K{K}_{'holdout' if not TRAIN.all() else 'all'}_thr{thr}.npz"),
                     target=ii, source=C[ii, cc])
            Xr = to_X(forward(Bof(wr.ravel())))
            report(f"    rounded: 0/1 pairs w>={thr}*max (mean {keep.sum(-1).mean():.2f}/tri)", Xr)
            if not TRAIN.all():
                r, g = errors(Xr)
                print(f"    held-out raw {r[~TRAIN].mean():.3f} rigid {g[~TRAIN].mean():.3f}", flush=True)
    return w

todo = sys.argv[1:]
ITERS = 600
for job in todo:
    if job.startswith("it="):
        ITERS = int(job[3:]); continue
    if job == "holdout":
        TRAIN[:] = np.arange(k) % 2 == 0; continue
    K = int(job[:-2]); convex = job[-2] == "c"; per_pose = job[-1] == "p"
    run(K, convex, per_pose, iters=ITERS)
