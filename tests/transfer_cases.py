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


def face_scan_markers(template_resolution: int, scan_resolution: int):
    """``(template, face, vmap, scan, markers)``: the sample template's face (quads,
    UVs; ``vmap`` its vertices in the template), a clean neutral scan of another face
    and topology, and the 68 landmarks as (face vertex, scan vertex) markers."""
    tpl = make_template(template_resolution)
    face, vmap = tpl.mesh.submesh(tpl.mesh.face_groups == 0)
    scan = make_scan(tpl, weights={}, resolution=scan_resolution, noise=0, holes=0,
                     crop=False, transform=False, texture_size=8)
    markers = (tpl.landmarks.vertex,
               cKDTree(scan.mesh.vertices).query(scan.landmarks.points)[1])
    return tpl, face, vmap, scan, markers


@pytest.fixture(scope="module")
def pair():
    """Template face (quads, UVs) and a neutral scan of another face and topology,
    with the 68 landmarks as markers."""
    tpl, face, vmap, scan, markers = face_scan_markers(32, 40)
    shapes = {k: v[vmap] for k, v in tpl.blendshapes.items()}
    corr = find_correspondence(face, scan.mesh, markers)
    return face, scan.mesh, markers, shapes, corr
