"""facewrap.transfer.deformation: DeformationTransfer against the textbook solve,
invariants, and Sumner's cat → lion."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from conftest import needs_data, DATA
from facewrap.geometry import closest_points
from facewrap.transfer import (DeformationTransfer, complete_pairs, find_correspondence,
                               gradient_operator, pair_matrix, source_gradient_blocks,
                               untethered_vertices)
from transfer_cases import pair, random_rotation


def test_identity_pose_reproduces_target(pair):
    face, scan, _, _, corr = pair
    dt = DeformationTransfer().fit(face, scan, corr)
    np.testing.assert_allclose(dt.transfer(face.vertices), scan.vertices, atol=1e-7)


def test_rigid_source_pose_moves_target_rigidly(pair):
    face, scan, _, _, corr = pair
    dt = DeformationTransfer(anchor=5).fit(face, scan, corr)
    R = random_rotation(np.random.default_rng(4))
    out = dt.transfer(face.vertices @ R.T + [10, 0, 0])
    expect = (scan.vertices - scan.vertices[5]) @ R.T + scan.vertices[5]
    np.testing.assert_allclose(out, expect, atol=1e-6 * scan.scale())


def test_schur_elimination_equals_full_system(pair):
    """The factor eliminates fourth vertices; compare with the full (n + t) solve."""
    face, scan, _, shapes, corr = pair
    dt = DeformationTransfer(anchor=0).fit(face, scan, corr)
    P = shapes["jaw_open"]
    got = dt.transfer(P)
    S = gradient_operator(face.vertices, face.triangles).gradients(P)
    op = gradient_operator(scan.vertices, scan.triangles)
    rows = (3 * corr.target_triangles[:, None] + np.arange(3)).ravel()
    A = op.matrix[rows]
    b = S[corr.source_triangles].transpose(0, 2, 1).reshape(-1, 3)
    free = np.arange(1, op.n_unknowns)
    H = (A.T @ A).tocsc()
    rhs = A.T @ b - H[:, [0]] @ scan.vertices[[0]]
    x = spla.spsolve(H[free][:, free], rhs[free])
    np.testing.assert_allclose(got[1:], x[:scan.n_vertices - 1], atol=1e-6 * scan.scale())


def test_transfer_follows_the_source_expression(pair):
    face, scan, _, shapes, corr = pair
    dt = DeformationTransfer().fit(face, scan, corr)
    names = ["jaw_open", "brow_raise", "smile"]
    out = dt.transfer(np.stack([shapes[k] for k in names]))
    assert out.shape == (3, scan.n_vertices, 3)
    cp = closest_points(face.vertices, face.triangles, scan.vertices)
    for name, X in zip(names, out):
        D = shapes[name] - face.vertices
        ref = np.einsum("kc,kcd->kd", cp.barycentric, D[face.triangles[cp.triangles]])
        size = np.linalg.norm(ref, axis=1)
        moving = size > 0.05 * size.max()
        err = np.linalg.norm(X - scan.vertices - ref, axis=1)[moving].mean()
        assert err < 0.25 * size[moving].mean(), name


def test_quad_target_keeps_topology_and_uvs(pair):
    face, scan, markers, shapes, _ = pair
    corr = find_correspondence(scan, face, (markers[1], markers[0]))
    dt = DeformationTransfer().fit(scan, face, corr)
    (mesh,) = dt.transfer_meshes(scan.vertices[None])
    assert np.all(mesh.face_sizes == 4)
    np.testing.assert_array_equal(mesh.face_uvs, face.face_uvs)
    np.testing.assert_allclose(mesh.vertices, face.vertices, atol=1e-7)


def test_unmatched_target_triangles_follow_neighbours():
    T = np.array([[0, 1, 2], [1, 3, 2], [3, 4, 2]])
    P = sp.csr_matrix(([1.0], ([0], [5])), shape=(3, 9))
    filled, orphans = complete_pairs(P, T)
    assert filled[1, 5] == 1 and filled[2, 5] == 1 and not orphans.any()


def test_bad_pose_shape_raises(pair):
    face, scan, _, _, corr = pair
    dt = DeformationTransfer().fit(face, scan, corr)
    with pytest.raises(ValueError, match="poses"):
        dt.transfer(np.zeros((3, 3)))


def test_transfer_equals_the_textbook_solve(pair):
    """The factored, reduced system (fourth vertices and anchor eliminated, one
    sparse right-hand-side map) gives the minimiser of the full energy
    ``Σ_t Σ_s M_ts ||T_t − S_s||²`` over vertices and fourth vertices, assembled
    from scratch and solved with the anchor fixed, for a stack of poses and one by
    one."""
    face, scan, _, shapes, corr = pair
    n = scan.n_vertices
    assert not untethered_vertices(scan.triangles, n, [0]).any()  # no tether term
    dt = DeformationTransfer(anchor=0, fix_flips=False).fit(face, scan, corr)
    P = np.stack(list(shapes.values())[:3])
    k = len(P)
    op = gradient_operator(scan.vertices, scan.triangles)
    pairs, orphans = complete_pairs(pair_matrix(corr), scan.triangles)
    counts = np.asarray(pairs.sum(axis=1)).ravel() + orphans
    blocks = source_gradient_blocks(gradient_operator(face.vertices, face.triangles), P)
    B = np.stack([pairs @ b for b in blocks])                        # (k, t, 9)
    B += orphans[None, :, None] * np.eye(3).ravel()
    B = B.reshape(k, op.n_triangles, 3, 3).transpose(1, 2, 0, 3)
    H = (op.matrix.T @ sp.diags(np.repeat(counts, 3)) @ op.matrix).tocsc()
    rhs = np.asarray(op.matrix.T @ B.reshape(3 * op.n_triangles, 3 * k))
    free = np.arange(1, op.n_unknowns)
    xa = np.tile(scan.vertices[0], k)
    x = spla.spsolve(H[free][:, free].tocsc(), rhs[free] - H[free][:, [0]] @ xa[None, :])
    want = np.vstack([xa, x])[:n].reshape(n, k, 3).transpose(1, 0, 2)
    together = dt.transfer(P)
    np.testing.assert_allclose(together, want, atol=1e-6 * scan.scale())
    for j in range(k):
        np.testing.assert_allclose(together[j], dt.transfer(P[j]), atol=1e-9)


@pytest.mark.slow
@needs_data
def test_cat_to_lion_against_sumners_result():
    from facewrap.datasets import load_sumner_pair
    p = load_sumner_pair(DATA / "sumner2004" / "cat-lion" / "markers-cat-lion.yml")
    s, t = p.source, p.target
    corr = find_correspondence(s.reference, t.reference, p.markers)
    # Sumner's lion poses keep the last lion vertex where it was
    dt = DeformationTransfer(anchor=t.reference.n_vertices - 1).fit(s.reference,
                                                                    t.reference, corr)
    out = dt.transfer(np.stack(s.poses))
    err = np.linalg.norm(out - np.stack(t.poses), axis=2).mean(axis=1) / t.reference.scale()
    assert err.max() < 0.035 and err.mean() < 0.02


def test_fix_flips_can_be_switched_between_transfers(pair):
    face, scan, _, shapes, corr = pair
    dt = DeformationTransfer(anchor=0).fit(face, scan, corr)
    P = shapes["jaw_open"]
    dt.fix_flips = False
    plain = dt.transfer(P)
    np.testing.assert_allclose(
        plain, DeformationTransfer(anchor=0, fix_flips=False).fit(face, scan, corr)
        .transfer(P), atol=1e-12)
    with pytest.raises(ValueError, match="fix_flips"):
        dt.fix_flips = "no"
    with pytest.raises(AttributeError):
        dt.anchor = 3
