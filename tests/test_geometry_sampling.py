"""facewrap.geometry.sampling: surface samples, farthest-point and Poisson-disk subsets."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

import facewrap.geometry as geo

from geometry_meshes import check_barycentric, icosphere, reconstruct


def test_sample_surface():
    V, T = icosphere(2, noise=0.1)
    P, tri, bary = geo.sample_surface(V, T, 2000, seed=3)
    P2, tri2, bary2 = geo.sample_surface(V, T, 2000, seed=3)
    np.testing.assert_array_equal(P, P2)
    np.testing.assert_array_equal(tri, tri2)
    assert not np.array_equal(P, geo.sample_surface(V, T, 2000, seed=4)[0])
    check_barycentric(bary)
    np.testing.assert_allclose(reconstruct(V, T, tri, bary), P, atol=1e-12)
    assert geo.closest_points(V, T, P).distances.max() < 1e-12
    assert tri.dtype == np.int64 and P.shape == (2000, 3)
    assert geo.sample_surface(V, T, 0)[0].shape == (0, 3)


def test_sample_surface_is_area_weighted():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [3, 0, 0], [0, 2, 0],
                  [5, 5, 5], [6, 6, 6], [7, 7, 7.]])
    T = np.array([[5, 6, 7], [0, 1, 2], [0, 3, 4], [5, 6, 7]])   # areas 0, .5, 3, 0
    _, tri, _ = geo.sample_surface(V, T, 20000, seed=0)
    counts = np.bincount(tri, minlength=4)
    assert counts[0] == 0 and counts[3] == 0
    assert counts[1] / 20000 == pytest.approx(0.5 / 3.5, abs=0.01)
    with pytest.raises(ValueError, match="area"):
        geo.sample_surface(V, T[[0]], 10)
    with pytest.raises(ValueError, match="count"):
        geo.sample_surface(V, T, -1)


def _fps_reference(V, count, start):
    chosen = [start]
    for _ in range(count - 1):
        d = np.min(np.linalg.norm(V[:, None] - V[chosen][None], axis=2), axis=1)
        d[chosen] = -1
        chosen.append(int(np.argmax(d)))
    return chosen


def test_farthest_point_sampling():
    V, _ = icosphere(2, noise=0.1)
    idx = geo.farthest_point_sampling(V, 40, start=7)
    assert idx.dtype == np.int64 and idx[0] == 7
    assert idx.tolist() == _fps_reference(V, 40, 7)
    dup = np.vstack([V[:3], V[:3]])
    assert sorted(geo.farthest_point_sampling(dup, 6).tolist()) == list(range(6))
    assert len(geo.farthest_point_sampling(V, 0)) == 0
    with pytest.raises(ValueError, match="count"):
        geo.farthest_point_sampling(V, len(V) + 1)
    with pytest.raises(ValueError, match="start"):
        geo.farthest_point_sampling(V, 3, start=len(V))


def _poisson_reference(V, radius, seed):
    tree = cKDTree(V)
    covered = np.zeros(len(V), dtype=bool)
    kept = []
    for v in np.random.default_rng(seed).permutation(len(V)):
        if not covered[v]:
            kept.append(v)
            covered[tree.query_ball_point(V[v], radius)] = True
    return sorted(kept)


@pytest.mark.parametrize("radius", [0.05, 0.2, 0.7, 5.0])
def test_poisson_disk_vertices(radius):
    V, _ = icosphere(3, noise=0.05)
    idx = geo.poisson_disk_vertices(V, radius, seed=2)
    assert idx.dtype == np.int64
    assert idx.tolist() == _poisson_reference(V, radius, 2)
    if len(idx) > 1:
        assert cKDTree(V[idx]).query(V[idx], k=2)[0][:, 1].min() > radius
    assert cKDTree(V[idx]).query(V)[0].max() <= radius


def test_poisson_disk_vertices_on_many_points_and_validated():
    V = np.random.default_rng(0).uniform(0, 1, (10000, 3))
    idx = geo.poisson_disk_vertices(V, 0.05)
    assert cKDTree(V[idx]).query(V[idx], k=2)[0][:, 1].min() > 0.05
    with pytest.raises(ValueError, match="radius"):
        geo.poisson_disk_vertices(V, 0.0)
