"""Alignment (facewrap.wrapping.align): the landmark similarity and rigid ICP."""

import numpy as np
import pytest

from facewrap.geometry import ClosestPointTree, vertex_normals
from facewrap.geometry.similarity import Similarity, similarity_transform
from facewrap.mesh import Mesh
from facewrap.wrapping.align import rigid_icp

from geometry_meshes import quad_ellipsoid


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def test_umeyama_recovers_similarity_and_never_reflects():
    rng = np.random.default_rng(3)
    P = rng.normal(size=(30, 3))
    R = random_rotation(rng)
    T = similarity_transform(P, 1.7 * P @ R.T + [3, -2, 5])
    assert np.allclose(T.rotation, R) and np.isclose(T.scale, 1.7)
    assert np.allclose(T.apply(P), 1.7 * P @ R.T + [3, -2, 5])
    assert np.allclose(T.inverse().apply(T.apply(P)), P)
    assert np.allclose(Similarity.from_matrix(T.matrix).rotation, R)
    mirrored = P * [-1, 1, 1]
    M = similarity_transform(P, mirrored)
    assert np.isclose(np.linalg.det(M.rotation), 1.0)
    rigid = similarity_transform(P, 2 * P, scale=False)
    assert rigid.scale == 1.0


def test_umeyama_rejects_bad_input():
    with pytest.raises(ValueError, match="both be"):
        similarity_transform(np.zeros((3, 3)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="weights"):
        similarity_transform(np.eye(3), np.eye(3), weights=[-1, 1, 1])


def test_rigid_icp_recovers_a_small_motion():
    V, Q = quad_ellipsoid()
    mesh = Mesh(V, Q)
    tree = ClosestPointTree(V, mesh.triangles)
    rng = np.random.default_rng(0)
    small = Similarity(random_rotation(rng) * 0 + np.eye(3), np.zeros(3))
    angle = np.radians(6)
    R = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0],
                  [0, 0, 1]])
    moved = Similarity(R, np.array([0.05, -0.03, 0.02])).apply(V)
    res = rigid_icp(moved, tree, init=small, trim=1.0, iterations=60)
    assert np.sqrt(np.mean((res.transform.apply(moved) - V) ** 2)) < 1e-3
    assert res.history[-1]["rms"] < res.history[0]["rms"]


def test_rigid_icp_weights_keep_a_moved_region_from_pulling_the_pose():
    """Points on a bulge the target does not have (an expression) pull an
    unweighted fit off; weighted down, they leave the rigid pose to the rest."""
    V, Q = quad_ellipsoid()
    tree = ClosestPointTree(V, Mesh(V, Q).triangles)
    source = V.copy()
    bulge = V[:, 0] > 0.6 * V[:, 0].max()
    source[bulge] += [0.0, 0.08, 0.0]                 # moved along the surface
    kw = dict(trim=1.0, iterations=60)
    plain = rigid_icp(source, tree, **kw).transform
    weights = np.where(bulge, 1e-6, 1.0)
    weighted = rigid_icp(source, tree, weights=weights, **kw).transform
    off = lambda T: np.abs(T.apply(V[~bulge]) - V[~bulge]).max()
    assert off(weighted) < 1e-3 < off(plain)
    with pytest.raises(ValueError, match="weights"):
        rigid_icp(source, tree, weights=np.ones(3))
    with pytest.raises(ValueError, match="weights"):
        rigid_icp(source, tree, weights=np.ones(len(V)), scale=True)


def test_rigid_icp_rejects_far_and_flipped_pairs_and_trims():
    V, Q = quad_ellipsoid()
    mesh = Mesh(V, Q)
    tree = ClosestPointTree(V, mesh.triangles)
    normals = vertex_normals(V, mesh.triangles)
    moved = V + [0.01, 0.0, 0.0]
    res = rigid_icp(moved, tree, normals, trim=0.8, iterations=1, max_distance=1.0)
    assert res.history[0]["inliers"] == res.inliers.sum() <= int(0.8 * len(V)) + 1
    # every normal reversed: no pair passes the normal test, nothing moves
    res = rigid_icp(moved, tree, -normals, iterations=3)
    assert res.history == [] and not res.inliers.any()
