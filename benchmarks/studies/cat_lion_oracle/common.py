"""Shared by the cat → lion oracle scripts: the error measures of bench_transfer."""
from pathlib import Path

import numpy as np

from facewrap.align import similarity_transform
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
