"""Shared cases of the transfer tests: a template face and a scan of another
topology, with their correspondence."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from facewrap.sample import make_scan, make_template
from facewrap.transfer import find_correspondence


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.fixture(scope="module")
def pair():
    """Template face (quads, UVs) and a neutral scan of another face and topology,
    with the 68 landmarks as markers."""
    tpl = make_template(32)
    face, vmap = tpl.mesh.submesh(tpl.mesh.face_groups == 0)
    scan = make_scan(tpl, weights={}, resolution=40, noise=0, holes=0, crop=False,
                     transform=False, texture_size=8)
    markers = (tpl.landmarks.vertex,
               cKDTree(scan.mesh.vertices).query(scan.landmarks.points)[1])
    shapes = {k: v[vmap] for k, v in tpl.blendshapes.items()}
    corr = find_correspondence(face, scan.mesh, markers)
    return face, scan.mesh, markers, shapes, corr
