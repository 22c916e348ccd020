"""facewrap.avatar.shapes: landmark-guided avatar key shapes (Onizuka et al. 2019)."""

import numpy as np
import pytest

from conftest import needs_data, DATA
from facewrap.errors import InputError
from facewrap.avatar import AvatarTransfer, FacePart
from facewrap.geometry import face_normals, flipped_triangles
from facewrap.transfer import complete_pairs, pair_matrix
from avatar_cases import MOVE, avatar, template


def test_self_transfer_reproduces_shapes(template):
    """An avatar that is a similar copy of the source gets the source's shapes."""
    face, lm51, shapes = template
    copy = face.with_vertices(MOVE.apply(face.vertices))
    P = np.stack([shapes["jaw_open"], shapes["blink"]])
    expect = MOVE.apply(P.reshape(-1, 3)).reshape(P.shape)
    tol = 1e-4 * copy.scale()
    exact = AvatarTransfer(smooth_weight=0, identity_weight=0).fit(face, lm51, copy, lm51)
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
