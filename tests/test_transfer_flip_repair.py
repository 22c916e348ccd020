"""facewrap.transfer.flip_repair: new flips found and unfolded, copied flips kept."""

import numpy as np
import pytest

from facewrap.geometry import face_normals, flipped_triangles
from facewrap.sample import make_template
from facewrap.transfer import (DeformationTransfer, complete_pairs, nearest_proper_maps,
                               pair_matrix)
from transfer_cases import pair


def _new_flips(out, poses, source, target, corr):
    """Oracle (the benchmark's definition): flipped target triangles none of whose
    source partners flips in the source pose."""
    pairs, _ = complete_pairs(pair_matrix(corr), target.triangles)
    n0 = face_normals(target.vertices, target.triangles)
    s0 = face_normals(source.vertices, source.triangles)
    counts = []
    for X, P in zip(out, poses):
        flipped = np.einsum("ij,ij->i", face_normals(X, target.triangles), n0) < 0
        src = np.einsum("ij,ij->i", face_normals(P, source.triangles), s0) < 0
        counts.append(int(np.sum(flipped & ~(pairs @ src.astype(float) > 0))))
    return np.array(counts)


def _pinch(V, centre, radius, scale):
    """Crush the ball around ``centre`` toward it (factor ``scale`` inside ``radius``,
    back to 1 at twice the radius).  Radially monotone: no triangle flips."""
    d = V - centre
    r = np.linalg.norm(d, axis=1, keepdims=True)
    f = np.where(r < radius, scale,
                 np.where(r < 2 * radius, scale + (1 - scale) * (r - radius) / radius, 1.0))
    return centre + d * f


def test_flipped_triangles_against_face_normals():
    """facewrap.geometry.flipped_triangles, the count the flip repair and the
    benchmarks use, against face normals (belongs with the geometry tests)."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    T = np.array([[0, 1, 2]])

    def turned(deg):               # rotate about the x axis (an edge of the triangle)
        a = np.radians(deg)
        R = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
        return V @ R.T
    got = flipped_triangles(np.stack([turned(60), turned(120), V * [1, -1, 1],
                                      V * [1, 0, 1]]), V, T)
    assert got.tolist() == [[False], [True], [True], [False]]   # zero area: not flipped
    mesh = make_template(20).mesh
    rng = np.random.default_rng(5)
    X = mesh.vertices + 0.02 * mesh.scale() * rng.normal(size=(3, *mesh.vertices.shape))
    n0 = face_normals(mesh.vertices, mesh.triangles)
    expect = [np.einsum("ij,ij->i", face_normals(x, mesh.triangles), n0) < 0 for x in X]
    got = flipped_triangles(X, mesh.vertices, mesh.triangles)
    np.testing.assert_array_equal(got, expect)
    assert got.any()
    np.testing.assert_array_equal(flipped_triangles(X[1], mesh.vertices, mesh.triangles),
                                  expect[1])
    with pytest.raises(ValueError, match="vertices"):
        flipped_triangles(X[:, :-1], mesh.vertices, mesh.triangles)
    with pytest.raises(ValueError, match="triangles"):
        flipped_triangles(X, mesh.vertices, mesh.triangles + len(mesh.vertices))


def test_nearest_proper_unfolds_in_the_rest_plane():
    basis = np.tile(np.array([[1.0, 0], [0, 1], [0, 0]]), (3, 1, 1))   # rest plane xy
    F = np.array([[[1.0, 0], [0, -0.5], [0, 0.3]],      # mirrored: flipped
                  [[1.0, 0], [0, 0.01], [0, 0.2]],      # collapsed, not flipped
                  [[0.8, 0.6], [-0.6, 0.8], [0, 0]]])   # a rotation: proper already
    out = nearest_proper_maps(F, basis, 0.1)
    A = out[:, :2]
    s = np.linalg.svd(A, compute_uv=False)
    assert np.all(np.linalg.det(A) > 0)
    assert np.all(s[:, 1] >= 0.1 * s[:, 0] - 1e-12)
    np.testing.assert_allclose(out[:, 2], F[:, 2])       # off the plane: kept
    np.testing.assert_allclose(out[2], F[2], atol=1e-12)


def test_repair_removes_new_flips_and_keeps_other_poses(pair):
    """A crushed mouth corner and the sample's blink fold scan triangles over
    where no source triangle flips; the repair unfolds them, locally, and poses
    without such flips are the plain solve bit for bit."""
    face, scan, markers, shapes, corr = pair
    tpl_corner = face.vertices[markers[0][54]]
    crushed = _pinch(face.vertices, tpl_corner, 0.04 * face.scale(), 0.05)
    P = np.stack([shapes["jaw_open"], crushed, shapes["blink"], shapes["brow_raise"]])
    assert not flipped_triangles(crushed, face.vertices, face.triangles).any()
    plain = DeformationTransfer(fix_flips=False).fit(face, scan, corr)
    dt = DeformationTransfer().fit(face, scan, corr)
    before, after = plain.transfer(P), dt.transfer(P)
    new_before = _new_flips(before, P, face, scan, corr)
    assert new_before[1] > 0 and new_before[2] > 0
    np.testing.assert_array_equal(_new_flips(after, P, face, scan, corr), 0)
    for j in (0, 3):
        assert new_before[j] == 0
        np.testing.assert_array_equal(after[j], before[j])
    r = dt.repairs_
    assert r["found"].tolist() == new_before.tolist()
    assert np.all(r["remaining"] == 0) and np.all(r["repaired"][[1, 2]] > 0)
    assert r["repaired"][0] == r["rounds"][3] == 0
    # local: most of the face keeps the plain solve (up to the marker translation,
    # which follows the repaired markers' centroid)
    shift = after - before
    shift -= np.median(shift, axis=1, keepdims=True)
    moved = np.linalg.norm(shift, axis=2) > 1e-9 * scan.scale()
    assert moved[1].mean() < 0.15 and moved[2].mean() < 0.15


def test_repair_keeps_the_anchor_fixed(pair):
    """The anchor at the crushed mouth corner is a vertex of a flipped triangle:
    the repair keeps it where it is and unfolds around it."""
    face, scan, markers, _, corr = pair
    a = int(markers[1][54])
    crushed = _pinch(face.vertices, face.vertices[markers[0][54]], 0.04 * face.scale(),
                     0.05)
    plain = DeformationTransfer(anchor=a, fix_flips=False).fit(face, scan, corr)
    dt = DeformationTransfer(anchor=a).fit(face, scan, corr)
    before, after = plain.transfer(crushed), dt.transfer(crushed)
    flipped = flipped_triangles(before, scan.vertices, scan.triangles)
    assert flipped[np.any(scan.triangles == a, axis=1)].any()
    assert _new_flips(after[None], crushed[None], face, scan, corr)[0] == 0
    np.testing.assert_array_equal(after[a], scan.vertices[a])
