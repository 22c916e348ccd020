"""facewrap.sample.scan: synthetic scans, their damage (holes, crop, noise) and their
truth (ground truth, landmarks), checked against brute-force oracles.
"""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from facewrap.sample import EXPRESSIONS, LANDMARK_NAMES, make_scan, make_template
from facewrap.sample.layout import MOUTH_HALF_WIDTH, MOUTH_T, st_from_uv

from sample_oracles import boundary_loops


def closest_point_distances(P, V, T, candidates=24):
    """Exact distance from each point to the nearest of its ``candidates`` triangles
    (by centroid); an upper bound of the distance to the whole mesh."""
    _, cand = cKDTree(V[T].mean(axis=1)).query(P, k=candidates)
    a, b, c = (V[T[cand, k]] for k in range(3))             # (n, k, 3)
    p = P[:, None, :]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    bp, cp = p - b, p - c
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    den = np.where(va + vb + vc == 0, 1e-300, va + vb + vc)
    q = a + ab * (vb / den)[..., None] + ac * (vc / den)[..., None]

    def put(mask, value):
        q[mask] = value[mask]

    def safe(x):
        return np.where(x == 0, 1e-300, x)
    put((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + ab * (d1 / safe(d1 - d3))[..., None])
    put((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + ac * (d2 / safe(d2 - d6))[..., None])
    w = (d4 - d3) / safe((d4 - d3) + (d5 - d6))
    put((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b + (c - b) * w[..., None])
    put((d1 <= 0) & (d2 <= 0), a)
    put((d3 >= 0) & (d4 <= d3), b)
    put((d6 >= 0) & (d5 <= d6), c)
    return np.linalg.norm(q - p, axis=-1).min(axis=1)


def to_canonical(scan, X):
    M = np.linalg.inv(scan.transform)
    return X @ M[:3, :3].T + M[:3, 3]


@pytest.fixture(scope="module")
def tpl():
    return make_template()


@pytest.fixture(scope="module")
def scan(tpl):
    return make_scan(tpl)


# -- helpers are right --------------------------------------------------------------------
def test_closest_point_oracle_on_a_square():
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.]])
    T = np.array([[0, 1, 2], [0, 2, 3]])
    P = np.array([[0.2, 0.7, 0.5], [2.0, 0.5, 0.0], [-1.0, -1.0, 0.0], [0.5, 0.5, -2.0]])
    d = closest_point_distances(P, V, T, candidates=2)
    np.testing.assert_allclose(d, [0.5, 1.0, np.sqrt(2.0), 2.0])


def test_boundary_loops_of_a_square_with_a_hole():
    # 4x4 grid of quads split into triangles, centre quad removed
    i, j = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")
    ids = np.arange(25).reshape(5, 5)
    quads = [(ids[a, b], ids[a + 1, b], ids[a + 1, b + 1], ids[a, b + 1])
             for a, b in zip(i.ravel(), j.ravel()) if (a, b) != (1, 1)]
    T = np.array([t for q in quads for t in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))])
    assert boundary_loops(T) == 2


def test_scan_is_deterministic_and_seeded(tpl):
    kw = dict(resolution=40, texture_size=32, landmark_noise=0.5)
    a, b = make_scan(tpl, seed=5, **kw), make_scan(tpl, seed=5, **kw)
    for x, y in [(a.mesh.vertices, b.mesh.vertices), (a.mesh.face_indices, b.mesh.face_indices),
                 (a.mesh.uvs, b.mesh.uvs), (a.texture, b.texture),
                 (a.landmarks.points, b.landmarks.points), (a.transform, b.transform)]:
        assert np.array_equal(x, y)
    assert np.array_equal(a.ground_truth, b.ground_truth, equal_nan=True)
    c = make_scan(tpl, seed=6, **kw)
    assert c.mesh.n_vertices != a.mesh.n_vertices or not np.array_equal(
        c.mesh.vertices, a.mesh.vertices)


def test_make_scan_does_not_mutate_its_arguments(tpl):
    weights = {"smile": 0.5}
    M = np.eye(4)
    M[:3, 3] = [1.0, 2.0, 3.0]
    M0 = M.copy()
    before = tpl.mesh.vertices.copy()
    s = make_scan(tpl, weights=weights, transform=M, resolution=30, texture_size=8)
    assert weights == {"smile": 0.5}
    assert np.array_equal(M, M0)
    assert np.array_equal(tpl.mesh.vertices, before)
    assert s.weights == {"smile": 0.5} and s.weights is not weights


def test_default_scan(tpl, scan):
    m = scan.mesh
    assert m.is_triangle_mesh and m.n_vertices != tpl.mesh.n_vertices
    assert 15000 <= m.n_faces <= 30000
    assert m.texture is None and m.uvs.shape == (m.n_vertices, 2)
    assert m.uvs.min() >= 0 and m.uvs.max() <= 1
    assert scan.texture.shape == (512, 512, 3) and scan.texture.dtype == np.uint8
    assert scan.weights == {"jaw_open": 0.8, "blink": 1.0, "smile": 0.3}
    assert scan.ground_truth.shape == tpl.mesh.vertices.shape
    eyes = np.concatenate([tpl.parts["eyeball_left"], tpl.parts["eyeball_right"]])
    assert np.isnan(scan.ground_truth[eyes]).all()
    assert np.isfinite(scan.ground_truth[tpl.parts["face"]]).all()
    # default: mouth open, eyes shut (lid gap small, lips far apart)
    G, lm = scan.ground_truth, tpl.landmarks.vertex
    assert np.linalg.norm(G[lm[62]] - G[lm[66]]) > 15.0
    assert np.linalg.norm(G[lm[37]] - G[lm[41]]) < 2.0


def test_transform_is_a_similarity(scan):
    M = scan.transform
    R = M[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(R), 1.0)
    angle = np.degrees(np.arccos((np.trace(R) - 1) / 2))
    assert 10.0 <= angle <= 20.0 and 10.0 < np.linalg.norm(M[:3, 3]) < 100.0
    np.testing.assert_array_equal(M[3], [0, 0, 0, 1])


def test_given_transform_is_applied(tpl):
    kw = dict(resolution=30, texture_size=8, seed=2)
    plain = make_scan(tpl, transform=False, **kw)
    assert np.array_equal(plain.transform, np.eye(4))
    M = np.eye(4)
    c, s = np.cos(0.5), np.sin(0.5)
    M[:3, :3] = [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]      # 0.5 rad about +y
    M[:3, 3] = [10.0, -5.0, 3.0]
    moved = make_scan(tpl, transform=M, **kw)
    np.testing.assert_allclose(moved.mesh.vertices, plain.mesh.vertices @ M[:3, :3].T
                               + M[:3, 3], atol=1e-9)
    np.testing.assert_allclose(to_canonical(moved, moved.ground_truth),
                               plain.ground_truth, atol=1e-9)
    with pytest.raises(ValueError, match="transform"):
        make_scan(tpl, transform=np.eye(3), **kw)


def test_no_triangle_spans_the_open_mouth(tpl):
    sc = make_scan(tpl, weights={"jaw_open": 1.0}, transform=False, noise=0.0, holes=0)
    s, t = st_from_uv(sc.mesh.uvs)
    T = sc.mesh.triangles
    above, below = t > MOUTH_T, t < MOUTH_T
    for a, b in ((0, 1), (1, 2), (2, 0)):
        pa, pb = T[:, a], T[:, b]
        cross = (above[pa] & below[pb]) | (below[pa] & above[pb])
        dt = t[pb] - t[pa]
        sc_ = s[pa] + (MOUTH_T - t[pa]) / np.where(dt == 0, 1, dt) * (s[pb] - s[pa])
        assert not np.any(cross & (np.abs(sc_) < MOUTH_HALF_WIDTH))
    # in 3-D: the lips are far apart and no triangle edge comes close to that gap
    lm = tpl.landmarks.vertex
    gap = np.linalg.norm(sc.ground_truth[lm[62]] - sc.ground_truth[lm[66]])
    V = sc.mesh.vertices
    longest = max(np.linalg.norm(V[T[:, a]] - V[T[:, b]], axis=1).max()
                  for a, b in ((0, 1), (1, 2), (2, 0)))
    assert gap > 20.0 and longest < 0.6 * gap
    # the slit is a hole of the mesh even at rest: outer boundary + mouth
    assert boundary_loops(T) == 2


def test_holes_add_boundary_loops(tpl):
    kw = dict(resolution=50, texture_size=8, seed=1)
    base = boundary_loops(make_scan(tpl, holes=0, **kw).mesh.triangles)
    assert base == 2                                  # outer boundary and the mouth
    for k in (1, 3):
        assert boundary_loops(make_scan(tpl, holes=k, **kw).mesh.triangles) == base + k
    with pytest.raises(ValueError, match="holes"):
        make_scan(tpl, holes=40, **kw)


def test_holes_are_discs_away_from_landmarks(tpl):
    kw = dict(resolution=50, texture_size=8, seed=4, noise=0.0, transform=False)
    full = make_scan(tpl, holes=0, **kw)
    holed = make_scan(tpl, holes=2, hole_radius=8.0, **kw)
    assert holed.mesh.n_vertices < full.mesh.n_vertices
    # vertices that disappeared lie within two discs of radius 8 mm
    kept = cKDTree(holed.mesh.vertices).query(full.mesh.vertices)[0] < 1e-9
    gone = full.mesh.vertices[~kept]
    assert 2 < len(gone)
    far = np.linalg.norm(gone[:, None] - gone[None], axis=2).max()
    assert far > 30.0                                   # two separate places
    # landmarks are not in holes: their nearest scan vertices all survive
    d_full = cKDTree(full.mesh.vertices).query(full.landmarks.points)[0]
    d_holed = cKDTree(holed.mesh.vertices).query(holed.landmarks.points)[0]
    np.testing.assert_allclose(d_holed, d_full, rtol=0, atol=1e-9)  # two code paths


def test_crop_keeps_the_face_only(tpl):
    kw = dict(resolution=40, texture_size=8, holes=0, transform=False)
    full, cropped = make_scan(tpl, crop=False, **kw), make_scan(tpl, crop=True, **kw)
    assert cropped.mesh.n_vertices < 0.8 * full.mesh.n_vertices
    s, t = st_from_uv(cropped.mesh.uvs)
    assert np.abs(s).max() < 150 and t.max() < 90 and t.min() > -112
    # the whole face is there: each landmark's nearest scan vertex survives the crop
    d_full = cKDTree(full.mesh.vertices).query(full.landmarks.points)[0]
    d_crop = cKDTree(cropped.mesh.vertices).query(cropped.landmarks.points)[0]
    np.testing.assert_allclose(d_crop, d_full, rtol=0, atol=1e-9)   # two code paths


def test_ground_truth_lies_on_the_noise_free_scan(tpl):
    kw = dict(weights=None, identity_seed=3, resolution=150, holes=0, crop=False,
              texture_size=8, seed=7)
    noisy = make_scan(tpl, noise=0.3, **kw)
    clean = make_scan(tpl, noise=0.0, **kw)
    # same sampling, truth and pose; the noise only moves vertices along normals
    assert np.array_equal(noisy.mesh.face_indices, clean.mesh.face_indices)
    assert np.array_equal(noisy.ground_truth, clean.ground_truth, equal_nan=True)
    dev = np.linalg.norm(noisy.mesh.vertices - clean.mesh.vertices, axis=1)
    assert 0.15 < np.sqrt(np.mean(dev ** 2)) < 0.45
    face = tpl.parts["face"]
    d = closest_point_distances(clean.ground_truth[face], clean.mesh.vertices,
                                clean.mesh.triangles)
    assert d.max() < 0.5


def test_ground_truth_on_the_default_scan_mostly_on_its_surface(tpl):
    clean = make_scan(tpl, noise=0.0, holes=0, crop=False, texture_size=8)
    d = closest_point_distances(clean.ground_truth[tpl.parts["face"]],
                                clean.mesh.vertices, clean.mesh.triangles)
    assert np.median(d) < 0.1 and np.percentile(d, 99) < 0.5


def test_landmarks_are_the_truth_at_landmark_vertices(tpl, scan):
    assert scan.landmarks.names == LANDMARK_NAMES
    assert np.all(scan.landmarks.kinds == "point")
    truth = scan.ground_truth[tpl.landmarks.vertex]
    np.testing.assert_array_equal(scan.landmarks.points, truth)
    noisy = make_scan(tpl, landmark_noise=1.0, resolution=30, texture_size=8)
    clean = make_scan(tpl, landmark_noise=0.0, resolution=30, texture_size=8)
    err = np.linalg.norm(noisy.landmarks.points - clean.landmarks.points, axis=1)
    assert 0.5 < err.mean() < 3.0


def test_truth_is_the_template_and_its_blendshapes_for_identity_zero(tpl):
    face = tpl.parts["face"]
    kw = dict(identity_seed=0, transform=False, resolution=30, texture_size=8)
    rest = make_scan(tpl, weights={}, **kw)
    np.testing.assert_allclose(rest.ground_truth[face], tpl.mesh.vertices[face], atol=1e-9)
    for name in EXPRESSIONS:
        posed = make_scan(tpl, weights={name: 1.0}, **kw)
        np.testing.assert_allclose(posed.ground_truth[face], tpl.blendshapes[name][face],
                                   atol=1e-9)
    # weights combine linearly, like blendshapes
    mix = make_scan(tpl, weights={"smile": 0.5, "jaw_open": 0.25}, **kw)
    V = tpl.mesh.vertices
    expect = (V + 0.5 * (tpl.blendshapes["smile"] - V)
              + 0.25 * (tpl.blendshapes["jaw_open"] - V))
    np.testing.assert_allclose(mix.ground_truth[face], expect[face], atol=1e-9)


def test_identities_differ_but_stay_heads(tpl):
    kw = dict(weights={}, transform=False, resolution=30, texture_size=8)
    faces = [make_scan(tpl, identity_seed=k, **kw).ground_truth[tpl.parts["face"]]
             for k in (1, 2, 3)]
    for a, b in zip(faces, faces[1:]):
        assert np.abs(a - b).max() > 2.0
    for F in faces:
        assert 130 < np.ptp(F[:, 0]) < 200 and 180 < np.ptp(F[:, 1]) < 260


def test_scan_triangles_point_outward(tpl, scan):
    V = to_canonical(scan, scan.mesh.vertices)
    T = scan.mesh.triangles
    n = np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]])
    assert np.mean((n * V[T].mean(axis=1)).sum(axis=1) > 0) > 0.99


@pytest.mark.parametrize("kwargs, match", [
    (dict(weights={"frown": 1.0}), "unknown expression"),
    (dict(weights={"smile": 1.5}), r"\[0, 1\]"),
    (dict(noise=-1.0), "noise"),
    (dict(hole_radius=float("nan")), "hole_radius"),
    (dict(resolution=3), "resolution"),
    (dict(texture_size=0), "texture_size"),
    (dict(holes=-1), "holes"),
])
def test_scan_arguments_are_checked(tpl, kwargs, match):
    with pytest.raises(ValueError, match=match):
        make_scan(tpl, **kwargs)
