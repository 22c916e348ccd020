"""A rig corrected by expression scans, head motion removed (issue 19, second part).

The person is the built-in sample's identity 1 with a smile 1.4 times stronger on
their left side than the template's (a smooth per-side weighting of the smile's
displacement): no blend of the template's shapes makes it, so only corrected
shapes reproduce it.  Scans of it are made from the sample's own (same topology
for every expression without a blink), moved by random head motions.
"""

import numpy as np
import pytest

from facewrap.geometry import ClosestPointTree
from facewrap.geometry.normals import vertex_normals
from facewrap.geometry.similarity import Similarity
from facewrap.landmarks import Landmarks
from facewrap.mesh import Mesh
from facewrap.params import SettingsError
from facewrap.rig import (ExampleSettings, build_rig, fit_examples, fit_weights,
                          least_moving, stabilise)
from facewrap.rig.stabilise import refine_pose
from facewrap.sample import make_scan, make_template

SEED = 3
EXAMPLES = [{"smile": 1.0}, {"jaw_open": 1.0}, {"smile": 0.6, "jaw_open": 0.4}]
HELD_OUT = [{"smile": 0.5}, {"smile": 0.8, "brow_raise": 0.5}]


def _left_stronger(x):
    """1 on the right of the face, 1.4 on the left, a smooth step between."""
    return 1.0 + 0.4 / (1.0 + np.exp(-np.asarray(x) / 8.0))


def _rotation(axis, degrees):
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = np.radians(degrees)
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def _head_motions(count, seed=0):
    """Rotations up to 15 degrees and translations up to 20 mm."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        t = rng.normal(size=3)
        out.append(Similarity(_rotation(rng.normal(size=3), rng.uniform(5, 15)),
                              t * rng.uniform(5, 20) / np.linalg.norm(t), 1.0))
    return out


class Person:
    """Scans and truth of the person (canonical frame unless moved)."""

    def __init__(self, tpl):
        self.tpl = tpl
        kw = dict(seed=SEED, identity_seed=1, transform=False, noise=0.0, holes=0,
                  resolution=60, texture_size=8)
        self.base = make_scan(tpl, weights={}, **kw)
        self.parts = {k: make_scan(tpl, weights={k: 1.0}, **kw)
                      for k in ("smile", "jaw_open", "brow_raise")}

    def truth_and_scan(self, weights, motion=None, noise=0.15):
        X, G = self.base.mesh.vertices.copy(), self.base.ground_truth.copy()
        for k, w in weights.items():
            one = self.parts[k]
            fx = _left_stronger(X[:, 0])[:, None] if k == "smile" else 1.0
            fg = _left_stronger(G[:, 0])[:, None] if k == "smile" else 1.0
            X += w * fx * (one.mesh.vertices - self.base.mesh.vertices)
            G += w * fg * (one.ground_truth - self.base.ground_truth)
        T = self.base.mesh.triangles
        eta = np.random.default_rng(len(weights) + 11).standard_normal((len(X), 1))
        X = X + noise * eta * vertex_normals(X, T)
        lm = G[self.tpl.landmarks.vertex]
        if motion is not None:
            X, G, lm = motion.apply(X), motion.apply(G), motion.apply(lm)
        return G, Mesh(X, T), Landmarks.from_points(lm, names=self.tpl.landmarks.names)


@pytest.fixture(scope="module")
def person():
    return Person(make_template(24))


def _blend(neutral, shapes, weights):
    return neutral + sum(w * (shapes[k] - neutral) for k, w in weights.items())


@pytest.fixture(scope="module")
def built(person):
    tpl = person.tpl
    _, neutral_scan, neutral_lm = person.truth_and_scan({})
    motions = _head_motions(len(EXAMPLES))
    scans = [person.truth_and_scan(w, m) for w, m in zip(EXAMPLES, motions)]
    rig = build_rig(tpl.mesh, neutral_scan, tpl.landmarks, neutral_lm, tpl.blendshapes,
                    expression_scans=[s for _, s, _ in scans],
                    expression_landmarks=[lm for _, _, lm in scans],
                    expression_weights=EXAMPLES)
    return rig, motions, [g for g, _, _ in scans]


def test_the_rig_reproduces_its_examples_better_than_the_neutral_only_rig(built):
    rig, _, _ = built
    fit = rig.examples
    assert fit is not None and len(fit.weights) == len(EXAMPLES)
    for err, prior in zip(fit.errors, fit.prior_errors):
        assert err["mean"] < 0.7 * prior["mean"], (err, prior)
        assert err["p95"] < prior["p95"]


def test_weights_are_in_the_unit_interval_and_find_the_expression_made(built):
    rig, _, _ = built
    for w, meant in zip(rig.examples.weights, EXAMPLES):
        assert set(w) == set(rig.shapes)
        assert all(0.0 <= x <= 1.0 for x in w.values())
        for k, x in meant.items():
            assert abs(w[k] - x) < 0.15, (k, w[k], x)


def test_held_out_expressions_come_closer_to_the_truth(built, person):
    rig, _, _ = built
    face = np.asarray(person.tpl.parts["face"])
    for weights in HELD_OUT:
        truth, _, _ = person.truth_and_scan(weights)
        err = {k: np.linalg.norm(_blend(rig.neutral.vertices, shapes, weights) - truth,
                                 axis=1)[face].mean()
               for k, shapes in (("rig", rig.shapes), ("neutral only", rig.prior))}
        assert err["rig"] < err["neutral only"], (weights, err)


def test_head_motion_is_removed(built, person):
    """The pose found for each example against the truth's (the motion applied):
    vertices a head motion of up to 15 degrees and 20 mm moves by tens of mm end
    within 0.1 mm on average (issue 19's acceptance).  The prediction's vertices are
    trusted less the more it moves them: an 80 % trimmed ICP that trusted them all
    alike left the open jaw at 0.16 mm and the smile with an open jaw at 0.12 mm
    (0.07 and 0.05 now)."""
    rig, motions, truths = built
    face = np.asarray(person.tpl.parts["face"])
    for pose, motion, truth in zip(rig.examples.poses, motions, truths):
        moved = np.linalg.norm(truth[face] - motion.inverse().apply(truth[face]), axis=1)
        off = np.linalg.norm(pose.apply(truth[face]) - motion.inverse().apply(truth[face]),
                             axis=1)
        assert moved.mean() > 10.0
        assert off.mean() < 0.1, off.mean()


def test_stabilisations_beside_the_wraps_give_the_rig_they_give_one_after_another(
        person, monkeypatch):
    """Untextured scans: each expression's stabilisation runs on a thread beside the
    next scan's wrap, or here with one usable thread; the rig is the same."""
    import facewrap.rig.build as build
    tpl = person.tpl
    _, neutral_scan, neutral_lm = person.truth_and_scan({})
    scans = [person.truth_and_scan(w, m)
             for w, m in zip(EXAMPLES, _head_motions(len(EXAMPLES)))]

    def rig(threads):
        monkeypatch.setattr(build, "usable_threads", lambda: threads)
        return build_rig(tpl.mesh, neutral_scan, tpl.landmarks, neutral_lm,
                         tpl.blendshapes, expression_scans=[s for _, s, _ in scans],
                         expression_landmarks=[lm for _, _, lm in scans],
                         expression_weights=EXAMPLES)
    beside, alone = rig(2), rig(1)
    for a, b in zip(beside.examples.poses, alone.examples.poses):
        np.testing.assert_allclose(a.matrix, b.matrix, rtol=0, atol=1e-9)
    for name in beside.shapes:
        np.testing.assert_allclose(beside.shapes[name], alone.shapes[name], atol=1e-9)
    assert beside.timings["stabilise"] > 0 and alone.timings["stabilise"] > 0


def test_refine_pose_trusts_what_the_expression_moves_less(person):
    """The person's smile is 1.4 times stronger on their left than the rig predicts
    (up to 3 mm off at the mouth corner): weighing each vertex by how far the
    prediction moves it puts the skull within 0.1 mm, near half the error
    of trusting every vertex alike (pulled toward the stronger side)."""
    tpl = person.tpl
    face, keep = tpl.mesh.submesh(tpl.mesh.face_groups == 0)       # no eyeballs
    neutral = person.base.ground_truth[keep]
    prediction = neutral + (person.parts["smile"].ground_truth[keep] - neutral)
    moves = np.linalg.norm(prediction - neutral, axis=1)
    motion = _head_motions(1, seed=7)[0]
    truth, scan, _ = person.truth_and_scan({"smile": 1.0}, motion)
    truth = truth[keep]
    assert np.linalg.norm(motion.inverse().apply(truth) - prediction, axis=1).max() > 2.0
    tree = ClosestPointTree(scan.vertices, scan.triangles)
    # the robust fit's pose: off by half a degree and a millimetre or so
    start = Similarity(_rotation([1, 2, 0], 0.5), [0.5, -0.5, 0.3], 1.0).compose(
        motion.inverse())
    ids = np.arange(len(neutral))

    def off(pose):
        return np.linalg.norm(pose.apply(truth) - motion.inverse().apply(truth),
                              axis=1).mean()

    weighted = off(refine_pose(prediction, face.triangles, tree, start, ids, moves))
    alike = off(refine_pose(prediction, face.triangles, tree, start, ids,
                            np.zeros(len(neutral))))
    assert off(start) > 1.0
    assert weighted < 0.1, weighted
    assert weighted < 0.6 * alike, (weighted, alike)
    with pytest.raises(ValueError, match="motion"):
        refine_pose(prediction, face.triangles, tree, start, ids, moves[:-1])
        assert abs(pose.scale - 1.0) < 1e-12


def test_stabilise_is_exact_on_the_truth_and_robust_to_the_expression(person):
    """On the truth itself the pose is exact, though a fifth of the rigid set is
    moved by 3 mm (the robust weights set it aside; a plain fit would not)."""
    tpl = person.tpl
    face = np.asarray(tpl.parts["face"])
    among = np.zeros(tpl.mesh.n_vertices, dtype=bool)
    among[face] = True
    rigid = least_moving(np.stack(list(tpl.blendshapes.values())), tpl.mesh.vertices,
                         among=among)
    neutral, _, _ = person.truth_and_scan({})
    for motion in _head_motions(4, seed=5):
        expr, _, _ = person.truth_and_scan({"smile": 1.0})
        expr[rigid[::5]] += [0.0, 3.0, 0.0]
        out = stabilise(motion.apply(expr), neutral, rigid)
        off = np.linalg.norm(out.pose.apply(motion.apply(neutral)) - neutral, axis=1)
        assert off[face].max() < 1e-3, off[face].max()
        assert out.weights[::5].max() < out.weights.max() * 0.05
        plain = stabilise(motion.apply(expr), neutral, rigid, iterations=0)
        off_plain = np.linalg.norm(plain.pose.apply(motion.apply(neutral)) - neutral, axis=1)
        assert off_plain[face].max() > 100 * off[face].max()


def test_a_scan_without_landmarks_is_aligned_by_rigid_icp(person):
    tpl = person.tpl
    _, neutral_scan, neutral_lm = person.truth_and_scan({})
    motion = _head_motions(1, seed=9)[0]
    # a mild expression: the neutral's landmarks, carried over, guide the wrap only
    # weakly (as for a sequence's frame), so a wide-open jaw needs its own landmarks
    truth, scan, _ = person.truth_and_scan({"jaw_open": 0.3, "smile": 0.5}, motion)
    rig = build_rig(tpl.mesh, neutral_scan, tpl.landmarks, neutral_lm, tpl.blendshapes,
                    expression_scans=[scan], expression_landmarks=[None])
    face = np.asarray(tpl.parts["face"])
    pose = rig.examples.poses[0]
    off = np.linalg.norm(pose.apply(truth[face]) - motion.inverse().apply(truth[face]), axis=1)
    assert off.mean() < 0.6, off.mean()
    assert rig.examples.weights[0]["smile"] > 0.25


def test_fit_examples_on_exact_examples(person):
    """Examples made exactly from the person's shapes (no wrap): they are
    reproduced to a small fraction of the prior's error, a shape no example uses
    keeps the prior, and the smile comes closer to the person's."""
    tpl = person.tpl
    face_ids = np.asarray(tpl.parts["face"])
    face, keep = tpl.mesh.submesh(tpl.mesh.face_groups == 0)
    V = face.vertices
    shapes = {k: np.asarray(v)[keep] for k, v in tpl.blendshapes.items()}
    lean = _left_stronger(V[:, 0])[:, None]
    own = dict(shapes, smile=V + lean * (shapes["smile"] - V))
    examples = [_blend(V, own, w) for w in EXAMPLES]
    fit = fit_examples(face, shapes, examples)
    # the jaw alone is the prior's own (0 error); the smile's correction may touch
    # it by a hundredth of a millimetre
    for err, prior in zip(fit.errors, fit.prior_errors):
        assert err["mean"] < 0.2 * prior["mean"] + 0.01, (err, prior)
    pucker = np.linalg.norm(shapes["pucker"] - V, axis=1).max()
    assert np.linalg.norm(fit.shapes["pucker"] - shapes["pucker"], axis=1).max() < 0.02 * pucker
    before = np.linalg.norm(shapes["smile"] - own["smile"], axis=1).mean()
    after = np.linalg.norm(fit.shapes["smile"] - own["smile"], axis=1).mean()
    assert after < 0.5 * before
    assert len(face_ids) == face.n_vertices


def test_fit_weights_stays_in_bounds():
    rng = np.random.default_rng(1)
    D = rng.normal(size=(60, 4))
    truth = np.array([[0.2, 0.9, 0.0, 0.5]])
    got = fit_weights(D, (D @ truth.T))
    assert np.allclose(got, truth, atol=1e-6)
    far = fit_weights(D, D @ np.array([[2.0, -1.0, 0.5, 0.5]]).T)
    assert far.min() >= 0.0 and far.max() <= 1.0
    held = fit_weights(D, D @ np.array([[1.0, 0.0, 0.0, 0.0]]).T,
                       prior=np.array([[0.0, 0.0, 0.0, 0.0]]), gamma=10.0)
    assert held[0, 0] < 0.5


@pytest.mark.parametrize("dropped", [5, 45])     # the Gram matrix less a few rows, or not
def test_fit_weights_on_some_rows_is_the_fit_of_those_rows(dropped):
    """A fit on the rows a scan saw, from the Gram matrix of all the rows, is the fit
    of those rows alone; the rows dropped cannot pull, however wrong they are."""
    rng = np.random.default_rng(2)
    D = rng.normal(size=(60, 4))
    E = D @ np.array([[0.3, 0.7, 0.1, 0.6], [0.9, 0.0, 0.4, 0.2]]).T
    rows = np.ones(60, dtype=bool)
    rows[rng.choice(60, dropped, replace=False)] = False
    E[~rows] += 100.0
    prior = np.array([[0.0, 1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]])
    alone = fit_weights(D[rows], E[rows], prior=prior, gamma=0.5)
    for gram in (None, D.T @ D):
        got = fit_weights(D, E, prior=prior, gamma=0.5, rows=rows, gram=gram)
        np.testing.assert_allclose(got, alone, rtol=0, atol=1e-9)
    assert np.abs(fit_weights(D, E) - alone).max() > 0.1     # the rows would pull


def test_bad_inputs_are_refused(person):
    tpl = person.tpl
    _, scan, lm = person.truth_and_scan({})
    with pytest.raises(ValueError, match="expression_landmarks"):
        build_rig(tpl.mesh, scan, tpl.landmarks, lm, tpl.blendshapes,
                  expression_scans=[scan, scan], expression_landmarks=[lm])
    with pytest.raises(ValueError, match="rigid_vertices"):
        build_rig(tpl.mesh, scan, tpl.landmarks, lm, tpl.blendshapes,
                  rigid_vertices=[0, 1, 10 ** 9])
    with pytest.raises(SettingsError, match="shape_prior"):
        ExampleSettings(shape_prior=-1.0)
    face, keep = tpl.mesh.submesh(tpl.mesh.face_groups == 0)
    shapes = {k: np.asarray(v)[keep] for k, v in tpl.blendshapes.items()}
    with pytest.raises(ValueError, match="unknown shapes"):
        fit_examples(face, shapes, [face.vertices], weights=[{"grin": 1.0}])

