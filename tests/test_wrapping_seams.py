"""Templates split at their seams (facewrap.wrapping.seams): fitted as one surface."""

import numpy as np
import pytest

from facewrap.mesh import Mesh
from facewrap.wrapping import WrapSettings, wrap
from facewrap.wrapping.seams import seam_weld


@pytest.fixture(scope="module")
def sample():
    from facewrap.sample import make_scan, make_template
    template = make_template(resolution=24)
    return template, make_scan(template, resolution=40)


def split_down_the_middle(template):
    """The template's triangles with those right of x = 0 given copies of the
    vertices they share with the left: a seam as an exporter cuts it."""
    V, T = template.mesh.vertices, template.mesh.triangles
    right = V[T].mean(axis=1)[:, 0] > 0
    shared = np.intersect1d(T[right].ravel(), T[~right].ravel())
    remap = np.arange(len(V))
    remap[shared] = np.arange(len(V), len(V) + len(shared))
    T2 = T.copy()
    T2[right] = remap[T[right]]
    return Mesh(np.r_[V, V[shared]], T2), shared, remap[shared]


@pytest.mark.parametrize("model", ["hybrid", "graph"])
def test_a_split_template_does_not_crack_and_fits_as_the_whole_one(sample, model):
    template, scan = sample
    split, originals, copies = split_down_the_middle(template)
    assert len(copies) > 10
    shapes = template.blendshapes if model == "hybrid" else None
    split_shapes = None if shapes is None else {
        k: np.r_[v, v[originals]] for k, v in shapes.items()}
    res = wrap(split, scan.mesh, template.landmarks, scan.landmarks,
               WrapSettings(model=model), blendshapes=split_shapes)
    V = res.mesh.vertices
    # every copy where its vertex went (it opened by 0.8 mm (hybrid), 3.2 (graph))
    assert np.array_equal(V[originals], V[copies])
    assert res.mesh.n_vertices == split.n_vertices
    assert np.array_equal(res.mesh.face_indices, split.face_indices)
    assert res.metrics["seam_copies_welded"] == len(copies)
    assert len(res.roles) == split.n_vertices and len(res.projection.projected) == len(V)
    whole = wrap(Mesh(template.mesh.vertices, template.mesh.triangles), scan.mesh,
                 template.landmarks, scan.landmarks, WrapSettings(model=model),
                 blendshapes=shapes)
    np.testing.assert_allclose(V[:template.mesh.n_vertices], whole.mesh.vertices,
                               rtol=0, atol=1e-9)


def test_copies_that_part_in_a_shape_or_carry_other_materials_stay_apart():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0], [0, 1, 0.]])
    T = [[0, 1, 2], [4, 3, 5]]
    assert seam_weld(Mesh(V, T)).merged == 2
    opened = V.copy()
    opened[4] += [0, -0.1, 0]               # a lip: the same point only at rest
    assert seam_weld(Mesh(V, T), {"open": opened}) is None   # no cut edge is left
    parts = Mesh(V, T, materials=["skin", "occlusion"], face_materials=[0, 1])
    assert seam_weld(parts) is None         # parts that touch are not a cut


def test_inputs_given_on_copies_reach_the_welded_vertex(sample):
    template, scan = sample
    split, originals, copies = split_down_the_middle(template)
    weld = seam_weld(split)
    excluded = weld.vertex_set(copies[:5])          # ids of copies
    assert excluded.sum() == 5 and excluded[weld.inverse[originals[:5]]].all()
    mask = np.zeros(split.n_vertices, bool)
    mask[copies[:3]] = True                         # a boolean mask
    assert weld.vertex_set(mask).sum() == 3
    from facewrap.landmarks import Landmarks
    lm = weld.landmarks(Landmarks.from_vertices(copies[:2], names=["a", "b"]))
    assert lm.vertex.tolist() == weld.inverse[originals[:2]].tolist()
