import numpy as np
import pytest

from facewrap.mesh import Mesh, polygons_from_list, triangulate_polygons


def test_triangulation_maps_back_to_polygons(mixed_mesh):
    m = mixed_mesh
    assert m.triangles.shape == (5, 3)
    assert m.triangle_faces.tolist() == [0, 0, 1, 1, 2]
    # every triangle corner is a corner of its polygon, in the polygon's own order
    polys = m.polygons()
    for t, f in zip(m.triangles, m.triangle_faces):
        assert set(t) <= set(polys[f].tolist())
    # per-corner UVs follow the same triangulation
    assert m.triangle_uvs[2].tolist() == [4, 5, 7]


def test_triangulate_handles_large_polygons():
    off, idx = polygons_from_list([list(range(6))])
    tri, tf, corners = triangulate_polygons(off, idx)
    assert tri.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]]
    assert (tf == 0).all() and corners.shape == (4, 3)


def test_mesh_copies_and_freezes_inputs():
    V = np.zeros((3, 3))
    F = np.array([[0, 1, 2]])
    m = Mesh(V, F)
    V[0, 0] = 5.0
    F[0, 0] = 2
    assert m.vertices[0, 0] == 0.0 and m.face_indices[0] == 0
    with pytest.raises(ValueError):
        m.vertices[0, 0] = 1.0


def test_with_vertices_keeps_topology_and_uvs(mixed_mesh):
    new = mixed_mesh.with_vertices(mixed_mesh.vertices + 1.0)
    assert np.array_equal(new.face_indices, mixed_mesh.face_indices)
    assert np.array_equal(new.face_uvs, mixed_mesh.face_uvs)
    assert new.uvs is mixed_mesh.uvs and new.normals is None
    assert np.array_equal(mixed_mesh.vertices[0], [0, 0, 0])  # original untouched
    with pytest.raises(ValueError, match="shape"):
        mixed_mesh.with_vertices(np.zeros((2, 3)))


def test_submesh_keeps_order(mixed_mesh):
    sub, vmap = mixed_mesh.submesh([1, 2])
    assert vmap.tolist() == [1, 2, 3, 4, 5, 6]
    assert sub.n_faces == 2 and sub.face_sizes.tolist() == [4, 3]
    assert np.array_equal(sub.vertices, mixed_mesh.vertices[vmap])
    # UVs of the kept corners are the same values as before
    old_uv = mixed_mesh.uvs[mixed_mesh.face_uvs[4:]]
    assert np.array_equal(sub.uvs[sub.face_uvs], old_uv)
    assert sub.materials == mixed_mesh.materials


@pytest.mark.parametrize("kwargs, msg", [
    (dict(vertices=np.zeros((3, 2)), faces=[[0, 1, 2]]), "shape"),
    (dict(vertices=np.zeros((3, 3)), faces=[[0, 1, 3]]), "range"),
    (dict(vertices=np.zeros((3, 3)), faces=[[0, 1]]), "3 corners"),
    (dict(vertices=np.zeros((3, 3)), faces=[[0, 1, 2]], uvs=np.zeros((2, 2))), "face_uvs"),
    (dict(vertices=np.zeros((3, 3)), faces=[[0, 1, 2]], uvs=np.zeros((3, 2)),
          face_uvs=[[0, 1, 5]]), "out of range"),
    (dict(vertices=np.zeros((3, 3)), faces=[[0, 1, 2]], face_materials=[3],
          materials=["a"]), "face_materials"),
])
def test_mesh_rejects_inconsistent_arrays(kwargs, msg):
    V = kwargs.pop("vertices")
    F = kwargs.pop("faces")
    with pytest.raises(ValueError, match=msg):
        Mesh(V, F, **kwargs)


def test_a_mesh_copies_what_it_is_given_unless_handed_over():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    F = np.array([[0, 1, 2]])
    kept = Mesh(V, F)
    V[0, 0] = 5.0                       # the caller's array changes; the mesh does not
    assert kept.vertices[0, 0] == 0.0 and not kept.vertices.flags.writeable
    handed = Mesh(V, (np.array([0, 3]), F.ravel()), uvs=V[:, :2],
                  face_uvs=(np.array([0, 3]), F.ravel()), copy=False)
    assert np.shares_memory(handed.vertices, V)          # taken as it is, read-only now
    assert not V.flags.writeable and not handed.face_uvs.flags.writeable
    with pytest.raises(ValueError):
        V[0, 0] = 1.0
