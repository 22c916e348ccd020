"""Landmark-guided avatar blendshapes (Onizuka et al. 2019)."""

import json

import numpy as np
import pytest
from scipy.spatial import cKDTree

from conftest import needs_data, DATA
from facewrap.errors import InputError
from facewrap.geometry import Similarity, face_normals, vertex_normals
from facewrap.sample.face import make_scan, make_template
from facewrap.avatar import (IBUG51_PARTS, AvatarTransfer, FacePart, part_frame, part_motions,
                             read_parts)
from facewrap.geometry import flipped_triangles
from facewrap.transfer import complete_pairs, pair_matrix

R90 = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0.0]])   # 90° about y
MOVE = Similarity(R90, np.array([100.0, -20, 3]), 2.5)


@pytest.fixture(scope="module")
def template():
    tpl = make_template(32)
    face, vmap = tpl.mesh.submesh(tpl.mesh.face_groups == 0)
    lm51 = tpl.landmarks.vertex[17:]             # iBUG-68 without the jaw line
    shapes = {k: v[vmap] for k, v in tpl.blendshapes.items()}
    return face, lm51, shapes


@pytest.fixture(scope="module")
def avatar(template):
    """Another face in another topology, scaled, turned and moved."""
    face, lm51, _ = template
    tpl = make_template(32)
    scan = make_scan(tpl, weights={}, identity_seed=3, resolution=40, noise=0, holes=0,
                     crop=False, transform=False, texture_size=8)
    ids = cKDTree(scan.mesh.vertices).query(scan.landmarks.points[17:])[1]
    return scan.mesh.with_vertices(MOVE.apply(scan.mesh.vertices)), ids


def test_default_parts_cover_the_51_points_once():
    owned = np.concatenate([p.landmarks for p in IBUG51_PARTS])
    assert sorted(owned.tolist()) == list(range(51))
    assert [p.name for p in IBUG51_PARTS if p.is_mouth] == ["mouth"]


def test_part_frame_is_a_rotation_with_outward_normal(template):
    face, lm51, _ = template
    P = face.vertices[lm51]
    N = vertex_normals(face.vertices, face.triangles)[lm51]
    for part in IBUG51_PARTS:
        R, extent = part_frame(P, N, part)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) > 0
        assert R[2] @ N[list(part.landmarks)].mean(axis=0) > 0
        assert np.all(extent >= 0)


def test_part_motion_of_a_similar_copy_is_the_similarity(template):
    face, lm51, _ = template
    P = face.vertices[lm51]
    N = vertex_normals(face.vertices, face.triangles)[lm51]
    M, owner, info = part_motions(P, N, MOVE.apply(P), MOVE.apply_vectors(N))
    for k, part in enumerate(IBUG51_PARTS):
        if part.is_mouth:       # z ratio fixed to 1: only in-plane motion scales
            np.testing.assert_allclose(info[k]["ratio"][:2], MOVE.scale, rtol=1e-9)
            continue
        np.testing.assert_allclose(M[k], MOVE.scale * R90, atol=1e-9)
    assert (owner >= 0).all()


def test_self_transfer_reproduces_shapes(template):
    """An avatar that is a similar copy of the source gets the source's shapes."""
    face, lm51, shapes = template
    copy = face.with_vertices(MOVE.apply(face.vertices))
    P = np.stack([shapes["jaw_open"], shapes["blink"]])
    expect = MOVE.apply(P.reshape(-1, 3)).reshape(P.shape)
    tol = 1e-4 * copy.scale()
    exact = AvatarTransfer(smoothness_weight=0, identity_weight=0).fit(face, lm51, copy, lm51)
    np.testing.assert_allclose(exact.transfer(P), expect, atol=tol)
    plain = AvatarTransfer(landmark_guided=False).fit(
        face, lm51, copy, lm51, correspondence=exact.correspondence_)
    np.testing.assert_allclose(plain.transfer(P), expect, atol=tol)
    np.testing.assert_allclose(plain.transfer(face.vertices), copy.vertices, atol=tol)


def test_guided_transfer_moves_landmarks_and_keeps_orientation(template, avatar):
    face, lm51, shapes = template
    mesh, ids = avatar
    model = AvatarTransfer().fit(face, lm51, mesh, ids)
    P = np.stack([shapes[k] for k in ("jaw_open", "blink", "smile")])
    out = model.transfer(P)
    assert out.shape == (3, mesh.n_vertices, 3) and np.isfinite(out).all()
    neutral = model.transfer(face.vertices)
    np.testing.assert_allclose(neutral, mesh.vertices, atol=1e-6 * mesh.scale())
    # landmarks reach their per-part targets (w_l = 100 dominates)
    goal = model.landmark_targets(P)
    aligned = model.alignment_.apply(out.reshape(-1, 3)).reshape(out.shape)
    moved = np.linalg.norm(goal - model.alignment_.apply(mesh.vertices[ids]), axis=2)
    miss = np.linalg.norm(aligned[:, ids] - goal, axis=2)
    assert miss.mean() < 0.1 * moved.mean()
    # hardly any flipped triangles (the sample's lids fold a little when shut)
    n0 = face_normals(mesh.vertices, mesh.triangles)
    for X in out:
        flips = np.sum(np.einsum("ij,ij->i", face_normals(X, mesh.triangles), n0) < 0)
        assert flips < 0.005 * len(n0)


def test_guided_closes_the_eyes_better_than_plain(template, avatar):
    face, lm51, shapes = template
    mesh, ids = avatar
    guided = AvatarTransfer().fit(face, lm51, mesh, ids)
    plain = AvatarTransfer(landmark_guided=False).fit(
        face, lm51, mesh, ids, correspondence=guided.correspondence_)

    def gap(X, lm):   # upper lid (51-index 20, 21, 26, 27) to lower lid (24, 23, 30, 29)
        return np.linalg.norm(X[lm[[20, 21, 26, 27]]] - X[lm[[24, 23, 30, 29]]],
                              axis=1).mean()
    src = gap(shapes["blink"], lm51) / gap(face.vertices, lm51)
    g = gap(guided.transfer(shapes["blink"]), ids) / gap(mesh.vertices, ids)
    p = gap(plain.transfer(shapes["blink"]), ids) / gap(mesh.vertices, ids)
    assert abs(g - src) <= abs(p - src) + 0.05
    assert g < 0.5


def test_read_parts_round_trip_and_errors(tmp_path):
    items = []
    for p in IBUG51_PARTS:
        it = {"name": p.name, "landmarks": [[p.landmarks[0], p.landmarks[-1]]],
              "frame": list(p.frame), "axis": list(p.axis)}
        if p.is_mouth:
            it["mouth"] = {"nose_bottom": p.nose_bottom, "lower_lip": list(p.lower_lip)}
        items.append(it)
    f = tmp_path / "parts.json"
    f.write_text(json.dumps({"format": "facewrap.parts", "version": 1, "parts": items}))
    assert read_parts(f) == IBUG51_PARTS
    f.write_text(json.dumps({"format": "facewrap.parts", "parts": [
        {"name": "eye", "landmarks": [[3, 1]], "axis": [0, 1]}]}))
    with pytest.raises(InputError, match="parts.json.*range"):
        read_parts(f)
    f.write_text("{")
    with pytest.raises(InputError, match="parts.json:1"):
        read_parts(f)


def test_bad_landmarks_raise(template):
    face, lm51, _ = template
    with pytest.raises(InputError, match="lm.txt"):
        AvatarTransfer().fit(face, lm51, face, np.r_[lm51[:-1], 10 ** 7],
                             landmarks_path="lm.txt")
    with pytest.raises(InputError, match="only 10 landmarks"):
        AvatarTransfer().fit(face, lm51[:10], face, lm51[:10])
    with pytest.raises(ValueError):
        FacePart("x", (0, 1, 2), (0, 0))


@needs_data
def test_onizuka_horse_blinks():
    from facewrap.io import read_mesh
    from facewrap.io.landmarks import read_vertex_indices
    from facewrap.io.obj import read_obj_vertices
    root = DATA / "onizuka2019"
    src = read_mesh(root / "blendshapes" / "Neutralm.obj")
    ls = read_vertex_indices(root / "landmarks" / "SOURCE" / "FACIAL_LANDMARKS.txt").vertex
    horse = read_mesh(root / "avatars" / "Horse.ply")
    la = read_vertex_indices(root / "landmarks" / "landmarks_Horse.txt").vertex
    blink = read_obj_vertices(root / "blendshapes" / "00m.obj", src.n_vertices)
    out = AvatarTransfer().fit(src, ls, horse, la).transfer(blink)

    def gaps(X, lm):
        return np.linalg.norm(X[lm[[20, 21, 26, 27]]] - X[lm[[24, 23, 30, 29]]], axis=1)
    src_ratio = gaps(blink, ls) / gaps(src.vertices, ls)
    ratio = gaps(out, la) / gaps(horse.vertices, la)
    closed = src_ratio < 0.3
    assert closed.any() and np.all(ratio[closed] < 0.4)


def _new_flips(out, shapes, source, avatar, corr):
    """Flipped avatar triangles none of whose source partners flips (the benchmark's
    definition)."""
    pairs, _ = complete_pairs(pair_matrix(corr), avatar.triangles)
    src = flipped_triangles(shapes, source.vertices, source.triangles)
    copied = (pairs @ src.T.astype(float)).T > 0
    return (flipped_triangles(out, avatar.vertices, avatar.triangles) & ~copied).sum(axis=1)


def test_guided_repair_unfolds_the_lids_and_keeps_them_closing(template, avatar):
    """The landmark term pulls the sample avatar's lids shut and folds a few
    triangles there; the repair unfolds them, the eyes still close, and shapes
    without such flips are the plain solve bit for bit."""
    face, lm51, shapes = template
    mesh, ids = avatar
    P = np.stack([shapes[k] for k in ("blink", "jaw_open", "smile")])
    plain = AvatarTransfer(fix_flips=False).fit(face, lm51, mesh, ids)
    fixed = AvatarTransfer().fit(face, lm51, mesh, ids,
                                 correspondence=plain.correspondence_)
    before, after = plain.transfer(P), fixed.transfer(P)
    corr = plain.correspondence_
    assert _new_flips(before, P, face, mesh, corr)[0] > 0
    np.testing.assert_array_equal(_new_flips(after, P, face, mesh, corr), 0)
    np.testing.assert_array_equal(after[1:], before[1:])
    assert fixed.repairs_["found"][0] > 0 and fixed.repairs_["remaining"][0] == 0

    def gap(X, lm):
        return np.linalg.norm(X[lm[[20, 21, 26, 27]]] - X[lm[[24, 23, 30, 29]]],
                              axis=1).mean()
    g_plain = gap(before[0], ids) / gap(mesh.vertices, ids)
    g_fixed = gap(after[0], ids) / gap(mesh.vertices, ids)
    assert g_fixed < 0.5 and abs(g_fixed - g_plain) < 0.1


@pytest.mark.slow
@needs_data
def test_onizuka_repair_leaves_no_new_flips():
    """Mario has no lid geometry, so the guided transfer folds the skin around his
    eyes when the template blinks; the horse's mouth corners fold when the plain
    transfer opens its mouth.  Repaired: no new flips, and Mario's eyes still
    close."""
    from facewrap.io import read_mesh
    from facewrap.io.landmarks import read_vertex_indices
    from facewrap.io.obj import read_obj_vertices
    root = DATA / "onizuka2019"
    src = read_mesh(root / "blendshapes" / "Neutralm.obj")
    ls = read_vertex_indices(root / "landmarks" / "SOURCE" / "FACIAL_LANDMARKS.txt").vertex
    shapes = np.stack([read_obj_vertices(root / "blendshapes" / f"{i:02d}m.obj",
                                         src.n_vertices) for i in range(48)])

    def gaps(X, lm):
        return np.linalg.norm(X[..., lm[[20, 21, 26, 27]], :]
                              - X[..., lm[[24, 23, 30, 29]], :], axis=-1)
    blink = gaps(shapes, ls) / gaps(src.vertices, ls) < 0.3
    for name, guided in (("Mario", True), ("Horse", False)):
        av = read_mesh(root / "avatars" / f"{name}.ply")
        la = read_vertex_indices(root / "landmarks" / f"landmarks_{name}.txt").vertex
        model = AvatarTransfer(landmark_guided=guided).fit(src, ls, av, la)
        out = model.transfer(shapes)
        assert model.repairs_["found"].sum() > 0, name
        np.testing.assert_array_equal(
            _new_flips(out, shapes, src, av, model.correspondence_), 0)
        if guided:
            ratio = gaps(out, la) / gaps(av.vertices, la)
            assert ratio[blink].mean() < 0.35
