"""facewrap.geometry.normals: face and vertex normals, areas, against libigl."""

from __future__ import annotations

import igl
import numpy as np
import pytest

import facewrap.geometry as geo

from geometry_meshes import grid, icosphere, soup


def test_face_normals_and_areas():
    V, T = icosphere(2, noise=0.1)
    N = geo.face_normals(V, T)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0)
    for a, b in ((0, 1), (1, 2)):
        np.testing.assert_allclose(np.einsum("ij,ij->i", N, V[T[:, b]] - V[T[:, a]]),
                                   0, atol=1e-12)
    centroid_dir = V[T].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", N, centroid_dir) > 0)   # outward winding
    A = geo.face_areas(V, T)
    np.testing.assert_allclose(A, 0.5 * np.linalg.norm(
        np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]), axis=1))
    Vg, Tg = grid(4, 3)
    assert geo.face_areas(Vg, Tg).sum() == pytest.approx(6.0)
    Vd, Td = soup(5)
    assert np.all(geo.face_normals(Vd, Td)[1:4] == 0)
    assert np.all(geo.face_areas(Vd, Td)[1:4] == 0)


@pytest.mark.parametrize("weighting", ["angle", "area"])
def test_vertex_normals_match_libigl(weighting):
    V, T = icosphere(3, noise=0.05)
    ours = geo.vertex_normals(V, T, weighting)
    kind = {"angle": "ANGLE", "area": "AREA"}[weighting]
    ref = igl.per_vertex_normals(V, T, getattr(
        igl.PerVertexNormalsWeightingType, f"PER_VERTEX_NORMALS_WEIGHTING_TYPE_{kind}"))
    np.testing.assert_allclose(ours, ref, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(ours, axis=1), 1.0)


def test_vertex_normals_angle_weighting_ignores_retriangulation():
    # apex 0 of a fan; splitting one triangle in two keeps its angle at the apex
    V = np.array([[0, 0, 1.0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0.5],
                  [0.5, 0.5, 0]])
    T1 = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]])
    T2 = np.array([[0, 1, 5], [0, 5, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]])
    np.testing.assert_allclose(geo.vertex_normals(V, T1)[0],
                               geo.vertex_normals(V, T2)[0], atol=1e-12)


def test_vertex_normals_degenerate_and_isolated():
    V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [7, 7, 7.]])
    N = geo.vertex_normals(V, [[0, 1, 2]])
    assert np.all(N == 0)
    with pytest.raises(ValueError, match="weighting"):
        geo.vertex_normals(V, [[0, 1, 2]], weighting="uniform")
    assert geo.vertex_normals(V, np.zeros((0, 3), int)).shape == (4, 3)
