"""Shared cases of the avatar tests: a template face with its 51 landmarks and
another face, scaled, turned and moved."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from facewrap.geometry import Similarity
from facewrap.sample import make_scan, make_template


R90 = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0.0]])   # 90° about y
MOVE = Similarity(R90, np.array([100.0, -20, 3]), 2.5)


@pytest.fixture(scope="module")
def template():
    tpl = make_template(32)
    face, vmap = tpl.mesh.submesh(tpl.mesh.face_groups == 0)
    lm51 = tpl.landmarks.vertex[17:]             # iBUG-68 without the jaw line
    shapes = {k: v[vmap] for k, v in tpl.blendshapes.items()}
    return face, lm51, shapes


@pytest.fixture(scope="module")
def avatar(template):
    """Another face in another topology, scaled, turned and moved."""
    face, lm51, _ = template
    tpl = make_template(32)
    scan = make_scan(tpl, weights={}, identity_seed=3, resolution=40, noise=0, holes=0,
                     crop=False, transform=False, texture_size=8)
    ids = cKDTree(scan.mesh.vertices).query(scan.landmarks.points[17:])[1]
    return scan.mesh.with_vertices(MOVE.apply(scan.mesh.vertices)), ids
