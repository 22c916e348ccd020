"""Run a saved 0/1 pair set through the library's own DeformationTransfer."""
import sys, dataclasses
import numpy as np
from pathlib import Path
from facewrap.datasets import load_sumner_pair
from facewrap.geometry.similarity import similarity_transform
from facewrap.transfer import DeformationTransfer, find_correspondence
p = load_sumner_pair(Path(__file__).resolve().parents[4] / "shared" / "data" / "sumner2004" / "cat-lion" / "markers-cat-lion.yml")
s, t = p.source, p.target
corr = find_correspondence(s.reference, t.reference, p.markers)
GT = np.stack(t.poses); diag = t.reference.scale(); a = t.reference.n_vertices - 1
for f in sys.argv[1:]:
    d = np.load(f)
    pairs = np.unique(np.stack([d["source"], d["target"]], 1), axis=0)
    c = dataclasses.replace(corr, source_triangles=pairs[:, 0], target_triangles=pairs[:, 1])
    for ff in (False, True):
        out = DeformationTransfer(anchor=a, fix_flips=ff).fit(s.reference, t.reference, c).transfer(np.stack(s.poses))
        raw = [100 * np.linalg.norm(X - G, axis=1).mean() / diag for X, G in zip(out, GT)]
        rig = [100 * np.linalg.norm(similarity_transform(X, G, scale=False).apply(X) - G, axis=1).mean() / diag
               for X, G in zip(out, GT)]
        print(f"{f} fix_flips={ff}: {len(pairs)} pairs  raw {np.mean(raw):.3f} rigid {np.mean(rig):.3f}"
              f"  held-out(2,4,6,8) raw {np.mean(raw[1::2]):.3f} rigid {np.mean(rig[1::2]):.3f}")
        print("   raw/pose " + " ".join(f"{x:.2f}" for x in raw))
