"""facewrap.sample.template: the built-in template head, its landmarks and blendshapes."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from facewrap.landmarks import IBUG68_NAMES
from facewrap.sample import EXPRESSIONS, LANDMARK_NAMES, make_template

from sample_oracles import boundary_loops


@pytest.fixture(scope="module")
def tpl():
    return make_template()


# -- determinism and purity -----------------------------------------------------------------
def test_template_is_deterministic():
    a, b = make_template(32), make_template(32)
    assert np.array_equal(a.mesh.vertices, b.mesh.vertices)
    assert np.array_equal(a.mesh.face_indices, b.mesh.face_indices)
    assert np.array_equal(a.mesh.uvs, b.mesh.uvs)
    assert np.array_equal(a.params, b.params, equal_nan=True)
    assert np.array_equal(a.landmarks.vertex, b.landmarks.vertex)
    for k in EXPRESSIONS:
        assert np.array_equal(a.blendshapes[k], b.blendshapes[k])


def test_template_structure(tpl):
    m = tpl.mesh
    assert 4000 <= m.n_vertices <= 8000
    assert m.groups == ("face", "eyeball_left", "eyeball_right")
    sizes = m.face_sizes
    face = m.face_groups == 0
    assert np.all(sizes[face] == 4)                   # the face is all quads
    # eyeballs: quads except the triangle fans around their two poles
    for g in (1, 2):
        eye = m.face_groups == g
        tri = np.flatnonzero(eye & (sizes == 3))
        poles = {int(v) for f in tri for v in m.polygons()[f]}
        n_lon = len(tri) // 2
        assert np.all(sizes[eye] >= 3) and len(poles) == 2 * n_lon + 2
    assert m.uvs.min() >= 0.0 and m.uvs.max() <= 1.0
    assert m.face_uvs is not None and len(m.face_uvs) == len(m.face_indices)
    # params: finite in [0, 1] on the face, NaN on the eyeballs
    f = tpl.parts["face"]
    assert np.all((tpl.params[f] >= 0) & (tpl.params[f] <= 1))
    for name in ("eyeball_left", "eyeball_right"):
        assert np.isnan(tpl.params[tpl.parts[name]]).all()
    assert np.array_equal(np.sort(np.concatenate([tpl.parts[k] for k in
                          ("face", "eyeball_left", "eyeball_right")])),
                          np.arange(m.n_vertices))
    # the face's uvs are its parameters
    np.testing.assert_array_equal(m.uvs[m.face_uvs[np.repeat(face, sizes)]],
                                  tpl.params[m.face_indices[np.repeat(face, sizes)]])


def test_eyeballs_are_closed_separate_and_inside_the_head(tpl):
    m = tpl.mesh
    T, tf = m.triangles, m.triangle_faces
    V = m.vertices
    for g, name in ((1, "eyeball_left"), (2, "eyeball_right")):
        Te = T[m.face_groups[tf] == g]
        assert boundary_loops(Te) == 0                              # closed
        assert set(np.unique(Te).tolist()) == set(tpl.parts[name].tolist())
        centre = V[tpl.parts[name]].mean(axis=0)
        assert np.sign(centre[0]) == (1 if name == "eyeball_left" else -1)
        # behind the eye opening: every eyeball vertex is inside the face surface
        face_T = T[m.face_groups[tf] == 0]
        P = V[tpl.parts[name]]
        front = V[tpl.parts["face"]]
        tree = cKDTree(front)
        _, near = tree.query(P)
        normal_dir = front[near] / np.linalg.norm(front[near], axis=1, keepdims=True)
        assert np.all(((front[near] - P) * normal_dir).sum(axis=1) > 0)
        assert len(face_T)


def test_template_landmarks(tpl):
    lm = tpl.landmarks
    assert lm.names == LANDMARK_NAMES == IBUG68_NAMES and len(lm) == 68
    assert lm.on_mesh and len(np.unique(lm.vertex)) == 68
    assert np.isin(lm.vertex, tpl.parts["face"]).all()
    P = lm.positions(tpl.mesh)
    # iBUG numbering: 17-21 and 36-41 on the subject's right (-x), the others mirrored
    assert P[17:22, 0].max() < 0 < P[22:27, 0].min()
    assert P[36:42, 0].max() < 0 < P[42:48, 0].min()
    assert P[0, 0] < 0 < P[16, 0] and abs(P[8, 0]) < 1e-6
    # plausible layout: brows above eyes above nose tip above mouth above chin
    assert P[19, 1] > P[37, 1] > P[30, 1] > P[62, 1] > P[8, 1]
    assert P[30, 2] == P[:, 2].max()                      # the nose tip sticks out most
    # inner lips are on the two edges of the mouth slit
    assert np.isin(lm.vertex[60:68], tpl.parts["mouth_lips"]).all()
    # head size: about 150 mm wide and 200 mm from chin to top
    face = tpl.mesh.vertices[tpl.parts["face"]]
    assert 140 < np.ptp(face[:, 0]) < 190 and 190 < face[:, 1].max() - P[8, 1] < 230


def test_blendshapes_shape_and_eyeballs_still(tpl):
    assert tuple(tpl.blendshapes) == EXPRESSIONS
    eyes = np.concatenate([tpl.parts["eyeball_left"], tpl.parts["eyeball_right"]])
    for name, B in tpl.blendshapes.items():
        assert B.shape == tpl.mesh.vertices.shape and B.dtype == np.float64
        assert np.array_equal(B[eyes], tpl.mesh.vertices[eyes])
        assert np.linalg.norm(B - tpl.mesh.vertices, axis=1).max() > 3.0, name


def test_jaw_open_drops_the_chin_and_parts_the_lips(tpl):
    V, B, lm = tpl.mesh.vertices, tpl.blendshapes["jaw_open"], tpl.landmarks.vertex
    assert V[lm[8], 1] - B[lm[8], 1] > 15.0                       # chin down
    assert np.linalg.norm(B[lm[8]] - V[lm[8]]) < 30.0
    gap0 = np.linalg.norm(V[lm[62]] - V[lm[66]])
    gap1 = np.linalg.norm(B[lm[62]] - B[lm[66]])
    assert gap0 < 1.0 and gap1 > 15.0                             # lips closed, then apart
    # the upper lip and the nose stay put
    assert np.linalg.norm(B[lm[[30, 33, 51, 62]]] - V[lm[[30, 33, 51, 62]]], axis=1).max() < 0.5


def test_blink_shuts_both_eyes(tpl):
    V, B, lm = tpl.mesh.vertices, tpl.blendshapes["blink"], tpl.landmarks.vertex
    for up, lo in ((37, 41), (38, 40), (43, 47), (44, 46)):
        d0 = np.linalg.norm(V[lm[up]] - V[lm[lo]])
        d1 = np.linalg.norm(B[lm[up]] - B[lm[lo]])
        assert d0 > 6.0 and d1 < 0.2 * d0
    moved = np.linalg.norm(B - V, axis=1) > 1e-9
    assert np.array_equal(np.flatnonzero(moved), tpl.parts["eyelids"])


def test_other_expressions_do_what_they_say(tpl):
    V, lm = tpl.mesh.vertices, tpl.landmarks.vertex
    S = tpl.blendshapes["smile"]
    assert np.all(S[lm[[48, 54]], 1] - V[lm[[48, 54]], 1] > 4.0)            # corners up
    B = tpl.blendshapes["brow_raise"]
    assert np.all(B[lm[17:27], 1] - V[lm[17:27], 1] > 5.0)                  # brows up
    P = tpl.blendshapes["pucker"]
    assert np.all(P[lm[[51, 57, 62, 66]], 2] - V[lm[[51, 57, 62, 66]], 2] > 4.0)
    w0 = np.linalg.norm(V[lm[48]] - V[lm[54]])
    assert np.linalg.norm(P[lm[48]] - P[lm[54]]) < w0 - 8.0                 # narrower


def test_every_combination_of_expressions_stays_a_valid_surface(tpl):
    import itertools

    m = tpl.mesh
    T = m.triangles[m.face_groups[m.triangle_faces] == 0]
    V = m.vertices

    def normals(X):
        return np.cross(X[T[:, 1]] - X[T[:, 0]], X[T[:, 2]] - X[T[:, 0]])
    n0 = normals(V)
    for on in itertools.product([0.0, 1.0], repeat=len(EXPRESSIONS)):
        X = V + sum(w * (tpl.blendshapes[k] - V) for w, k in zip(on, EXPRESSIONS))
        n = normals(X)
        assert np.all((n * n0).sum(axis=1) > 0), dict(zip(EXPRESSIONS, on))


def test_template_faces_point_outward(tpl):
    m = tpl.mesh
    T = m.triangles[m.face_groups[m.triangle_faces] == 0]
    V = m.vertices
    n = np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]])
    assert np.all((n * V[T].mean(axis=1)).sum(axis=1) > 0)


def test_template_resolution_is_checked():
    for bad in (4, 12, 64.0, True, "64"):
        with pytest.raises(ValueError, match="resolution"):
            make_template(bad)
    # the coarsest allowed grid still has 68 distinct landmark vertices
    from facewrap.sample.template import MIN_TEMPLATE_RESOLUTION
    tpl = make_template(MIN_TEMPLATE_RESOLUTION)
    assert len(set(tpl.landmarks.vertex.tolist())) == 68
