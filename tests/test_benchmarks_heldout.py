"""The held-out benchmark's own pieces (``benchmarks/bench_heldout.py``): the face
regions and the seeded expressions; and the crease count it reports
(:func:`facewrap.geometry.new_creases`)."""

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import bench_heldout as heldout  # noqa: E402
from facewrap.geometry import new_creases  # noqa: E402

DATA = ROOT.parent / "shared" / "data"
ICT = DATA / "ict-facekit" / "FaceXModel" / "vertex_indices.json"


def _strip(n=6):
    """A flat strip of 2 (n - 1) triangles in the z = 0 plane, all facing +z."""
    x = np.arange(n, dtype=float)
    V = np.c_[np.r_[x, x], np.r_[np.zeros(n), np.ones(n)], np.zeros(2 * n)]
    T = np.array([t for i in range(n - 1)
                  for t in ([i, i + 1, n + i], [i + 1, n + i + 1, n + i])])
    return V, T


def test_new_creases_counts_only_the_folds_the_result_made():
    V, T = _strip()
    folded = V.copy()
    folded[[4, 5, 10, 11], 0] = 6.0 - folded[[4, 5, 10, 11], 0]   # folded back at x = 3
    folded[[4, 5, 10, 11], 2] = 0.1
    made = new_creases(folded, V, T)
    assert len(made) > 0 and (made[:, 0] < made[:, 1]).all()
    # the fold is the template's own when the template has it: nothing new
    assert len(new_creases(folded, folded, T)) == 0
    # a similarity of either mesh changes nothing
    R = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.]])
    assert new_creases(2.5 * folded @ R.T + 3.0, V, T).tolist() == made.tolist()
    # a smooth bend below 90 degrees is no crease
    bent = V.copy()
    bent[:, 2] = 0.2 * bent[:, 0] ** 2
    assert len(new_creases(bent, V, T)) == 0


def test_expressions_are_seeded_and_follow_the_rules():
    names = ["jawOpen", "mouthClose", "eyeBlink_L", "eyeBlink_R", "mouthSmile_L",
             "mouthFunnel", "cheekPuff_L", "browDown_L"]
    a, b = heldout.expressions(names, 8), heldout.expressions(names, 8)
    assert a == b and len(a) == 8 and all(len(rows) == 5 for rows in a)
    for rows in a:
        kinds = [k for k, _ in rows]
        assert kinds == ["extreme", "single", "pair", "three", "four"]
        for kind, expr in rows[1:]:
            if kind in ("single", "pair"):
                assert set(expr.values()) == {1.0}
            else:
                assert all(0.5 <= w <= 1.0 for w in expr.values())
            if "mouthClose" in expr:
                assert expr["jawOpen"] >= expr["mouthClose"]


@pytest.mark.skipif(not ICT.is_file(), reason="../shared/data/ict-facekit is absent")
def test_face_regions_put_landmarks_in_their_own_groups():
    import json

    from facewrap.io import read_mesh
    lm = json.loads(ICT.read_text())["idx_to_landmark_verts"]
    V = read_mesh(ICT.parent / "generic_neutral_mesh.obj").vertices[:9409]
    regions = heldout.face_regions(V, lm)
    names = np.array(heldout.REGIONS)[regions[lm]]
    assert (names[48:68] == "lips").all() and (names[36:48] == "eyelids").all()
    assert (names[31:36] == "nostrils").all() and (names[17:27] == "brows").all()
    assert set(np.array(heldout.REGIONS)[np.unique(regions)]) == set(heldout.REGIONS)
