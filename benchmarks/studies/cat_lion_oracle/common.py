"""Shared by the cat → lion oracle scripts: the error measures of bench_transfer."""
from pathlib import Path

import numpy as np

from facewrap.geometry.similarity import similarity_transform
from facewrap.datasets import load_sumner_pair

MARKERS = (Path(__file__).resolve().parents[4] / "shared" / "data" / "sumner2004" /
           "cat-lion" / "markers-cat-lion.yml")


def load():
    """Sumner's cat (source) and lion (target, poses = ground truth): the pair,
    both pose sets, the lion's diagonal and the anchor (last lion vertex)."""
    p = load_sumner_pair(MARKERS)
    s, t = p.source, p.target
    P, GT = np.stack(s.poses), np.stack(t.poses)
    n = t.reference.n_vertices
    return p, s, t, s.reference, t.reference, P, GT, len(P), n, n - 1, t.reference.scale()


def relative_errors(out, GT, diag):
    """Mean vertex error per pose, % of the lion's diagonal: raw and after the
    best rigid alignment."""
    raw, rig = [], []
    for X, G in zip(out, GT):
        raw.append(100 * np.linalg.norm(X - G, axis=1).mean() / diag)
        R = similarity_transform(X, G, scale=False)
        rig.append(100 * np.linalg.norm(R.apply(X) - G, axis=1).mean() / diag)
    return np.array(raw), np.array(rig)


def gradient_solver(L_ref, anchor, k, row_weight=None):
    """Sumner's transfer solve on the lion with a fixed anchor vertex.

    Returns ``solve(B)``: target gradient blocks ``B`` (k, t, 9), rows as in
    ``G @ X``, to the k transferred poses (k, n, 3).  ``row_weight`` (t,) weighs
    each lion triangle's term (a triangle with c equal pairs weighs c).
    """
    import scipy.sparse as sp
    from facewrap.solve import factorize
    from facewrap.transfer import gradient_operator
    G = gradient_operator(L_ref.vertices, L_ref.triangles).matrix.tocsr()
    tl, N, n = len(L_ref.triangles), G.shape[1], L_ref.n_vertices
    w = np.ones(tl) if row_weight is None else np.asarray(row_weight, float)
    fidx = np.setdiff1d(np.arange(N), [anchor])
    WG = sp.diags(np.repeat(w, 3)) @ G
    H = (G.T @ WG).tocsr()
    F = factorize(H[fidx][:, fidx])
    Hfa = np.asarray(H[fidx][:, [anchor]].todense()).ravel()
    xa = np.tile(L_ref.vertices[anchor], k)

    def solve(B):
        Bm = B.reshape(k, tl, 3, 3).transpose(1, 2, 0, 3).reshape(3 * tl, 3 * k)
        rhs = (WG.T @ Bm)[fidx] - Hfa[:, None] * xa[None, :]
        x = np.empty((N, 3 * k))
        x[fidx], x[anchor] = F.solve(rhs), xa
        return x[:n].reshape(n, k, 3).transpose(1, 0, 2)
    return solve
