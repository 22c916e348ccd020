"""facewrap.geometry.checks: every public function checks its arguments at the door."""

from __future__ import annotations

import numpy as np
import pytest

import facewrap.geometry as geo

from geometry_meshes import icosphere


@pytest.mark.parametrize("fn", [geo.face_normals, geo.face_areas, geo.vertex_normals,
                                geo.cotangent_laplacian, geo.mass_matrix])
def test_vertex_functions_validate(fn):
    with pytest.raises(ValueError, match="V"):
        fn(np.zeros((3, 4)), [[0, 1, 2]])
    with pytest.raises(ValueError, match="T"):
        fn(np.zeros((3, 3)), [[0, 1, 5]])
    with pytest.raises(ValueError, match="T"):
        fn(np.zeros((3, 3)), [[0, 1]])


def test_functions_do_not_mutate_inputs():
    V, T = icosphere(2, noise=0.1)
    V.setflags(write=False)
    T.setflags(write=False)
    for fn in (geo.face_normals, geo.face_areas, geo.vertex_normals,
               geo.cotangent_laplacian, geo.mass_matrix, geo.closest_points):
        fn(V, T) if fn is not geo.closest_points else fn(V, T, V[:5])
    for fn in (geo.edges, geo.triangle_adjacency, geo.boundary_edges,
               geo.boundary_loops):
        fn(T)
    geo.sample_surface(V, T, 10)
    geo.farthest_point_sampling(V, 5)
    geo.poisson_disk_vertices(V, 0.3)


@pytest.mark.parametrize("call, match", [
    (lambda: geo.edges([[0, 1, 2.5]]), "T"),
    (lambda: geo.edges([[0, -1, 2]]), "negative"),
    (lambda: geo.edges([[True, False, True]]), "T"),
    (lambda: geo.boundary_vertices([[0, 1, 2]], True), "n"),
    (lambda: geo.connected_components([[0, 1, 2]], 2), "T"),
    (lambda: geo.edges_of_polygons([[0, 3]], [0, 1, 2]), "offsets"),
    (lambda: geo.edges_of_polygons([0, 3], [0, -1, 2]), "indices"),
    (lambda: geo.uniform_laplacian([[0, 1]], 1), "T_or_edges"),
    (lambda: geo.sample_surface(np.zeros((3, 3)), [[0, 1, 2]], 2.5), "count"),
])
def test_index_validation(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_empty_inputs():
    assert geo.edges(np.zeros((0, 3), int)).shape == (0, 2)
    assert geo.triangle_adjacency(np.zeros((0, 3), int)).shape == (0, 3)
    assert geo.boundary_edges([]).shape == (0, 2)
    assert geo.vertex_adjacency([], 3).nnz == 0
    assert geo.connected_components([], 3).tolist() == [0, 1, 2]
    assert geo.uniform_laplacian([], 2).nnz == 0
    assert geo.mass_matrix(np.zeros((2, 3)), []).shape == (2, 2)
