"""Deformation transfer: gradient operators, correspondence, transfer, CLI."""

import argparse
import json

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.spatial import cKDTree

from conftest import needs_data, DATA
from facewrap.errors import InputError
from facewrap.geometry import closest_points, face_normals, flipped_triangles
from facewrap.io import read_mesh, write_obj
from facewrap.sample.face import make_scan, make_template
from facewrap.transfer import (Correspondence, CorrespondenceSettings,
                               CorrespondenceStage, DeformationTransfer,
                               adjacent_triangle_pairs, complete_pairs,
                               deformation_gradients, find_correspondence,
                               fourth_vertices, gradient_operator, match_triangles,
                               nearest_proper_maps, pair_matrix, source_gradient_blocks,
                               triangle_smoothness_operator, untethered_vertices)


def _random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.fixture(scope="module")
def pair():
    """Template face (quads, UVs) and a neutral scan of another face and topology,
    with the 68 landmarks as markers."""
    tpl = make_template(32)
    face, vmap = tpl.mesh.submesh(tpl.mesh.face_groups == 0)
    scan = make_scan(tpl, weights={}, resolution=40, noise=0, holes=0, crop=False,
                     transform=False, texture_size=8)
    markers = (tpl.landmarks.vertex,
               cKDTree(scan.mesh.vertices).query(scan.landmarks.points)[1])
    shapes = {k: v[vmap] for k, v in tpl.blendshapes.items()}
    corr = find_correspondence(face, scan.mesh, markers)
    return face, scan.mesh, markers, shapes, corr


# -- gradients ----------------------------------------------------------------------
def test_operator_matches_direct_formula():
    rng = np.random.default_rng(1)
    V = rng.normal(size=(30, 3))
    T = np.array([rng.choice(30, 3, replace=False) for _ in range(40)])
    X = V + 0.3 * rng.normal(size=V.shape)
    op = gradient_operator(V, T)
    Q = op.gradients(X)
    for i in (0, 7, 39):
        a, b, c = T[i]

        def edges(P):
            n = np.cross(P[b] - P[a], P[c] - P[a])
            return np.column_stack([P[b] - P[a], P[c] - P[a], n / np.sqrt(np.linalg.norm(n))])
        np.testing.assert_allclose(Q[i], edges(X) @ np.linalg.inv(edges(V)), atol=1e-9)
    assert op.matrix.shape == (3 * len(T), len(V) + len(T))
    np.testing.assert_allclose(np.asarray(op.matrix.sum(axis=1)).ravel(), 0, atol=1e-9)


def test_gradient_of_similarity_and_affine_map():
    rng = np.random.default_rng(2)
    mesh = make_template(20).mesh
    V, T = mesh.vertices, mesh.triangles
    R = _random_rotation(rng)
    Q, degenerate = deformation_gradients(V, 1.7 * V @ R.T + [1, 2, 3], T)
    assert not degenerate.any()
    np.testing.assert_allclose(Q, np.broadcast_to(1.7 * R, Q.shape), atol=1e-9)
    A = rng.normal(size=(3, 3)) + 3 * np.eye(3)        # general affine: edges map as A
    Q, _ = deformation_gradients(V, V @ A.T, T)
    E = V[T[:, 1]] - V[T[:, 0]]
    np.testing.assert_allclose(np.einsum("tij,tj->ti", Q, E), E @ A.T, atol=1e-9)


def test_degenerate_triangles_are_finite_and_reported():
    V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [5, 5, 5.]])
    T = np.array([[0, 1, 3], [0, 1, 2], [4, 4, 4], [1, 2, 3]])  # collinear, a point
    op = gradient_operator(V, T)
    assert op.degenerate.tolist() == [False, True, True, False]
    assert np.isfinite(op.matrix.data).all()
    assert np.isfinite(fourth_vertices(V, T)).all()
    Q = op.gradients(V)
    assert np.isfinite(Q).all()
    np.testing.assert_allclose(Q[~op.degenerate], np.broadcast_to(np.eye(3), (2, 3, 3)),
                               atol=1e-12)


def test_smoothness_operator_vanishes_on_rigid_motion():
    mesh = make_template(20).mesh
    op = gradient_operator(mesh.vertices, mesh.triangles)
    D = triangle_smoothness_operator(op, adjacent_triangle_pairs(mesh.triangles))
    R = _random_rotation(np.random.default_rng(3))
    X = op.extend(mesh.vertices @ R.T + 5)
    assert np.abs(D @ X).max() < 1e-9
    assert np.abs(op.matrix @ X - np.tile(R.T, (op.n_triangles, 1))).max() < 1e-9


# -- correspondence ---------------------------------------------------------------------
def test_self_correspondence_matches_each_triangle_to_itself():
    full = make_template(20).mesh
    mesh, _ = full.submesh(full.face_groups == 0)
    s, t = match_triangles(mesh.vertices, mesh.triangles, mesh.vertices, mesh.triangles)
    np.testing.assert_array_equal(s, t)
    assert len(s) == len(mesh.triangles)


def test_correspondence_fits_and_round_trips(pair, tmp_path):
    face, scan, markers, _, corr = pair
    assert corr.stats["valid_closest"] > 0.95
    assert len(corr.unmatched_target) == 0
    dist = closest_points(scan.vertices, scan.triangles, corr.deformed).distances
    assert dist.mean() < 2e-3 * scan.scale()
    # markers are hard constraints
    np.testing.assert_allclose(corr.deformed[markers[0]], scan.vertices[markers[1]],
                               atol=1e-9)
    path = tmp_path / "pair.npz"
    corr.save(path)
    back = Correspondence.load(path)
    for name in ("source_triangles", "target_triangles", "markers", "deformed"):
        np.testing.assert_array_equal(getattr(back, name), getattr(corr, name))
    assert back.stats == corr.stats
    back.check(face, scan)
    with pytest.raises(InputError, match="pair.npz"):
        back.check(scan, face, path)


def test_correspondence_file_errors(tmp_path):
    bad = tmp_path / "x.npz"
    np.savez(bad, a=np.zeros(3))
    with pytest.raises(InputError, match="not a facewrap correspondence"):
        Correspondence.load(bad)
    junk = tmp_path / "junk.npz"
    junk.write_text("hello")
    with pytest.raises(InputError, match="junk.npz"):
        Correspondence.load(junk)
    with pytest.raises(InputError, match="no such file"):
        Correspondence.load(tmp_path / "missing.npz")


def test_markers_out_of_range_raise(pair):
    face, scan, markers, _, _ = pair
    with pytest.raises(InputError, match="m.cons.*target vertex 99999"):
        find_correspondence(face, scan, (markers[0], markers[1] * 0 + 99999),
                            markers_path="m.cons")


def test_settings_validate():
    with pytest.raises(ValueError, match="closest_weight"):
        CorrespondenceStage(closest_weight=-1)
    with pytest.raises(ValueError, match="smoothness_weight"):
        CorrespondenceStage(smoothness_weight=0, identity_weight=0)
    with pytest.raises(ValueError, match="deform"):
        CorrespondenceSettings(deform="both")
    with pytest.raises(ValueError, match="anchor"):
        DeformationTransfer(anchor="centre")
    with pytest.raises(ValueError, match="fix_flips"):
        DeformationTransfer(fix_flips=1)


# -- transfer ---------------------------------------------------------------------------
def test_identity_pose_reproduces_target(pair):
    face, scan, _, _, corr = pair
    dt = DeformationTransfer().fit(face, scan, corr)
    np.testing.assert_allclose(dt.transfer(face.vertices), scan.vertices, atol=1e-7)


def test_rigid_source_pose_moves_target_rigidly(pair):
    face, scan, _, _, corr = pair
    dt = DeformationTransfer(anchor=5).fit(face, scan, corr)
    R = _random_rotation(np.random.default_rng(4))
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


# -- CLI ----------------------------------------------------------------------------------
def test_partner_ambiguity_finds_the_crease_and_not_rigid_motion(pair):
    """Candidates agree under a rigid motion (ambiguity ~0) and disagree along a
    crease (half the face hinged by 40°): target triangles there rank highest,
    and the first marker hint lies on it."""
    from facewrap.transfer.ambiguity import ambiguity_summary, partner_ambiguity
    face, scan, _, _, corr = pair
    V = face.vertices
    c = V.mean(axis=0)
    R = _random_rotation(np.random.default_rng(7))
    rigid = partner_ambiguity(corr, face, scan, (V - c) @ R.T + c)
    assert np.nanmax(rigid) < 1e-6
    angle = np.radians(40)
    hinge = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0],
                      [-np.sin(angle), 0, np.cos(angle)]])
    folded = V.copy()
    right = V[:, 0] > c[0]
    folded[right] = (V[right] - c) @ hinge.T + c
    amb = partner_ambiguity(corr, face, scan, folded, neighbours=8)
    T = scan.triangles
    x = scan.vertices[T].mean(axis=1)[:, 0] - c[0]
    edge = np.median(np.linalg.norm(V[face.triangles[:, 0]] - V[face.triangles[:, 1]],
                                    axis=1))
    near, far = np.abs(x) < 1.5 * edge, np.abs(x) > 6 * edge
    assert np.nanmean(amb[near]) > 20 * np.nanmean(amb[far])
    summary = ambiguity_summary(amb, scan, count=5)
    hints = summary["marker_hints"]
    assert 1 <= len(hints) <= 5 and abs(scan.vertices[hints[0], 0] - c[0]) < 2 * edge
    gaps = [np.linalg.norm(scan.vertices[a] - scan.vertices[b])
            for i, a in enumerate(hints) for b in hints[i + 1:]]
    assert min(gaps, default=np.inf) >= 0.05 * scan.scale() - 1e-9
    assert summary["p90"] >= summary["median"] >= 0
    with pytest.raises(ValueError, match="one value per target triangle"):
        ambiguity_summary(amb[:-1], scan)


def _run_cli(argv):
    from facewrap.cli.transfer import register
    p = argparse.ArgumentParser()
    register(p.add_subparsers())
    args = p.parse_args(["transfer", *argv])
    return args.func(args)


def test_cli_transfer_writes_objs_glb_report(pair, tmp_path):
    face, scan, markers, shapes, _ = pair
    write_obj(tmp_path / "src.obj", face)
    write_obj(tmp_path / "tgt.obj", scan)
    (tmp_path / "shapes").mkdir()
    for k in ("jaw_open", "smile"):
        write_obj(tmp_path / "shapes" / f"{k}.obj", face.with_vertices(shapes[k]))
    (tmp_path / "m.txt").write_text(f"{len(markers[0])}\n" + "".join(
        f"{a} {b}\n" for a, b in zip(*markers)))
    argv = [str(tmp_path / "src.obj"), str(tmp_path / "tgt.obj"), "--source-shapes",
            str(tmp_path / "shapes"), "--markers", str(tmp_path / "m.txt"), "-o",
            str(tmp_path / "out"), "--gltf", str(tmp_path / "o.glb"), "--correspondence",
            str(tmp_path / "c.npz"), "--report", str(tmp_path / "r.json"), "-q"]
    assert _run_cli(argv) == 0
    out = read_mesh(tmp_path / "out" / "jaw_open.obj")
    assert out.n_vertices == scan.n_vertices
    np.testing.assert_array_equal(out.face_indices, scan.face_indices)
    assert (tmp_path / "c.npz").is_file() and (tmp_path / "o.glb").is_file()
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["shapes"] == 2
    first = out.vertices
    assert _run_cli(argv) == 0            # second run reuses the correspondence
    np.testing.assert_allclose(read_mesh(tmp_path / "out" / "jaw_open.obj").vertices,
                               first, atol=1e-5)
    assert isinstance(report["flip_repairs"], dict)
    assert report["ambiguity"] is None                 # only when asked for
    assert _run_cli(argv + ["--ambiguity"]) == 0
    amb = json.loads((tmp_path / "r.json").read_text())["ambiguity"]
    assert amb["marker_hints"] and all(0 <= v < scan.n_vertices
                                       for v in amb["marker_hints"])
    # --no-fix-flips: the plain solve (equal here: nothing flips on the sample)
    assert _run_cli(argv + ["--no-fix-flips"]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["flip_repairs"] == {}
    np.testing.assert_allclose(read_mesh(tmp_path / "out" / "jaw_open.obj").vertices,
                               first, atol=1e-5)


def test_cli_bad_inputs_name_the_file(pair, tmp_path):
    face, scan, markers, shapes, _ = pair
    write_obj(tmp_path / "src.obj", face)
    write_obj(tmp_path / "tgt.obj", scan)
    write_obj(tmp_path / "wrong.obj", scan)            # a shape of the wrong topology
    (tmp_path / "m.txt").write_text("0 0\n1 999999\n")
    base = [str(tmp_path / "src.obj"), str(tmp_path / "tgt.obj"), "-o",
            str(tmp_path / "out"), "-q"]
    with pytest.raises(InputError, match="m.txt.*999999"):
        _run_cli(base + ["--source-shapes", str(tmp_path / "src.obj"), "--markers",
                         str(tmp_path / "m.txt")])
    (tmp_path / "m.txt").write_text("0 0\n1 1\n2 2\n")
    with pytest.raises(InputError, match="wrong.obj"):
        _run_cli(base + ["--source-shapes", str(tmp_path / "wrong.obj"), "--markers",
                         str(tmp_path / "m.txt")])


# -- real data ------------------------------------------------------------------------------
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


# -- flip repair ----------------------------------------------------------------------------
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
