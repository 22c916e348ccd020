"""facewrap.texture.uvs: texture coordinates of a template from its scan (SPEC §1.4)."""

import numpy as np
import pytest

from facewrap.geometry import ClosestPointTree
from facewrap.mesh import Mesh
from facewrap.texture import cylindrical_uvs, scan_uvs_at, transfer_uvs

from texture_cases import uv_plane


def test_scan_uvs_at_reproduces_linear_fields_across_a_seam():
    # left half (x < 0.5) and right half map to two islands by different affine maps
    plane = uv_plane(6)
    V = plane.vertices
    faces = plane.faces_array()
    left = V[faces, 0].mean(axis=1) < 0.5

    def f_left(p):
        return np.stack([0.05 + 0.8 * p[:, 0], 0.1 + 0.4 * p[:, 1] + 0.1 * p[:, 0]], 1)

    def f_right(p):
        return np.stack([0.9 - 0.3 * p[:, 1], 0.55 + 0.8 * (p[:, 0] - 0.5)], 1)

    n = len(V)
    face_uvs = np.where(left[:, None], faces, faces + n)
    scan = Mesh(V, faces, uvs=np.vstack([f_left(V), f_right(V)]), face_uvs=face_uvs)
    rng = np.random.default_rng(1)
    tri = rng.integers(0, len(scan.triangles), 500)
    bary = rng.dirichlet([1, 1, 1], 500)
    bary[:50] = [0.5, 0.5, 0.0]                      # points on edges, incl. the seam
    points = np.einsum("kc,kcd->kd", bary, V[scan.triangles[tri]])
    on_left = left[scan.triangle_faces[tri]]
    expected = np.where(on_left[:, None], f_left(points), f_right(points))
    np.testing.assert_allclose(scan_uvs_at(scan, tri, bary), expected, atol=1e-12)
    # the seam is real: the same 3-D point has different UVs on its two sides
    assert np.abs(f_left(points[:1]) - f_right(points[:1])).max() > 0.1


def test_scan_uvs_at_checks_its_arguments():
    plane = uv_plane(2)
    with pytest.raises(ValueError, match="triangles"):
        scan_uvs_at(plane, [len(plane.triangles)], [[1, 0, 0]])
    with pytest.raises(ValueError, match="barycentric"):
        scan_uvs_at(plane, [0, 1], [[1, 0, 0]])
    bare = Mesh(plane.vertices, plane.faces_array())
    with pytest.raises(ValueError, match="scan has no texture"):
        scan_uvs_at(bare, [0], [[1, 0, 0]])


def test_cylindrical_uvs_lie_in_unit_square_and_follow_the_angle():
    rng = np.random.default_rng(2)
    P = rng.normal(size=(1000, 3)) * [1, 3, 1] + [5, -2, 7]
    for axis in [(0, 1, 0), (0, 0, 1), (1, 1, 0)]:
        uv = cylindrical_uvs(P, axis=axis)
        assert uv.shape == (1000, 2)
        assert uv.min() >= 0 and uv.max() <= 1
        assert uv[:, 1].min() == 0 and uv[:, 1].max() == 1
    # default axis y: front (+z) at u = 0.5, +x at 0.75, -x at 0.25
    ring = np.array([[0, 0, 1], [1, 0, 0], [-1, 0, 0], [0, 1, 1.]])
    uv = cylindrical_uvs(ring, center=[0, 0, 0])
    np.testing.assert_allclose(uv[:, 0], [0.5, 0.75, 0.25, 0.5])
    np.testing.assert_allclose(uv[:, 1], [0, 0, 0, 1])
    P_before = P.copy()
    cylindrical_uvs(P)
    np.testing.assert_array_equal(P, P_before)


def test_transfer_uvs_uses_scan_uvs_where_valid_and_cylinder_elsewhere():
    scan = uv_plane(8, uv=lambda xy: 0.1 + 0.8 * xy[:, ::-1])
    rng = np.random.default_rng(3)
    verts = np.column_stack([rng.uniform(0, 1, (200, 2)), rng.normal(0, 0.01, 200)])
    mask = rng.random(200) < 0.7
    uv = transfer_uvs(scan, verts, mask)
    np.testing.assert_allclose(uv[mask], 0.1 + 0.8 * verts[mask][:, [1, 0]], atol=1e-12)
    np.testing.assert_allclose(uv[~mask], cylindrical_uvs(verts)[~mask])
    # the same from a projection made beforehand (with a tree built once)
    tree = ClosestPointTree(scan.vertices, scan.triangles)
    cp = tree.query(verts)
    np.testing.assert_allclose(transfer_uvs(scan, cp, mask, vertices=verts), uv)
    np.testing.assert_allclose(transfer_uvs(scan, verts, mask, tree=tree), uv)
    with pytest.raises(ValueError, match="mask"):
        transfer_uvs(scan, verts, mask[:10])


def test_transfer_uvs_treats_ray_misses_as_unmapped():
    scan = uv_plane(4)
    tree = ClosestPointTree(scan.vertices, scan.triangles)
    origins = np.array([[0.3, 0.6, 1.0], [3.0, 3.0, 1.0]])   # second one misses
    hits = tree.ray_hits(origins, [[0, 0, -1.0]] * 2)
    assert hits.hit.tolist() == [True, False]
    with pytest.raises(ValueError, match="vertices="):
        transfer_uvs(scan, hits)                               # NaN points for the miss
    uv = transfer_uvs(scan, hits, vertices=origins)
    np.testing.assert_allclose(uv[0], [0.3, 0.6])
    np.testing.assert_allclose(uv[1], cylindrical_uvs(origins)[1])
