"""The non-rigid ICP engine (facewrap.wrapping.icp.engine) on synthetic surfaces."""

import numpy as np

from facewrap.geometry import ClosestPointTree
from facewrap.geometry.frames import NormalisedFrame
from facewrap.wrapping.icp.engine import ICPProblem, NonRigidICP
from facewrap.wrapping.icp.schedule import Stage
from facewrap.wrapping.models.graph import GraphModel, build_graph


def grid(n=21, size=2.0, z=0.0):
    u = np.linspace(-size / 2, size / 2, n)
    X, Y = np.meshgrid(u, u, indexing="ij")
    V = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], 1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    T = np.concatenate([np.stack([a, a + n, a + 1], 1), np.stack([a + 1, a + n, a + n + 1], 1)])
    return V, T



def cylinder_scan():
    """A cylinder of radius 1 around the y axis, below a unit sheet's centre."""
    a = np.linspace(-0.8, 0.8, 61)
    y = np.linspace(-0.7, 0.7, 41)
    A, Y = np.meshgrid(a, y, indexing="ij")
    S = np.stack([np.sin(A).ravel(), Y.ravel(), (np.cos(A) - 1).ravel()], 1)
    i, j = np.meshgrid(np.arange(60), np.arange(40), indexing="ij")
    q = (i * 41 + j).ravel()
    TS = np.concatenate([np.stack([q, q + 41, q + 1], 1),
                         np.stack([q + 1, q + 41, q + 42], 1)])
    return ClosestPointTree(S, TS)


def test_graph_icp_bends_a_sheet_onto_a_cylinder():
    V, T = grid(25, 1.0)
    tree = cylinder_scan()
    model = GraphModel(V, build_graph(V, T, spacing=0.15))
    icp = NonRigidICP([Stage(iterations=15, smooth_weight=1.0, landmark_weight=0,
                             robust_scale=0.2),
                       Stage(iterations=15, smooth_weight=0.1, landmark_weight=0,
                             robust_scale=0.05),
                       Stage(iterations=15, smooth_weight=0.01, landmark_weight=0,
                             robust_scale=0.01)],
                      max_distance=0.3).fit(model, T, tree,
                                            frame=NormalisedFrame(np.zeros(3), 1.0))
    d = tree.query(icp.vertices_).distances
    assert d.max() < 0.01 and np.median(d) < 0.001
    assert len(icp.history_) > 2 and "data_rms" in icp.history_[-1]
    # the energy never rises: a step that would raise it is damped or refused
    energies = [h["energy"] for h in icp.history_ if h["stage"] == 0]
    assert all(b <= a * (1 + 1e-9) for a, b in zip(energies, energies[1:]))


def _problem(model, T, tree, frame):
    candidates = np.arange(model.n_vertices)
    return ICPProblem(model, T, tree, frame, candidates, candidates, None, None,
                      np.zeros(0, np.int64))


def test_energy_is_the_weighted_sum_of_the_step_residuals():
    V, T = grid(9, 1.0, z=0.05)
    tree = cylinder_scan()
    model = GraphModel(V, build_graph(V, T, spacing=0.3))
    frame = NormalisedFrame(np.zeros(3), 1.0)
    icp = NonRigidICP(max_distance=0.3)
    stage = Stage(smooth_weight=0.5)
    problem = _problem(model, T, tree, frame)
    p = model.initial_params()
    pairs = icp.scan_pairs(problem, stage, V)
    active = np.arange(model.n_vertices)
    terms = icp.step_terms(problem, stage, pairs, p, V, model.jacobian(p, active), active)
    expected = sum(w * float(((1.0 if rw is None else rw) * r ** 2).sum())
                   for w, r, _, rw in terms)
    np.testing.assert_allclose(icp.energy(problem, stage, pairs, p, V), expected,
                               rtol=1e-12)


def test_scan_pairs_follow_the_frame_and_the_sample():
    V, T = grid(9, 1.0, z=0.05)
    tree = cylinder_scan()
    model = GraphModel(V, build_graph(V, T, spacing=0.3))
    icp = NonRigidICP(max_distance=0.3)
    unit = icp.scan_pairs(_problem(model, T, tree, NormalisedFrame(np.zeros(3), 1.0)),
                          Stage(), V)
    # the same vertices in a frame twice as large and shifted: distances halve
    frame = NormalisedFrame(np.array([0.0, 0.0, 1.0]), 2.0)
    framed = icp.scan_pairs(_problem(model, T, tree, frame), Stage(),
                            frame.to_frame(V))
    assert framed.vertices.tolist() == unit.vertices.tolist()
    np.testing.assert_allclose(framed.matches.distances * 2.0, unit.matches.distances,
                               atol=1e-12)
    problem = _problem(model, T, tree, NormalisedFrame(np.zeros(3), 1.0))
    assert len(icp.scan_pairs(problem, Stage(sample=0.25), V).vertices) <= 21


def test_triangles_around_a_sample_give_its_vertices_the_whole_mesh_normals():
    from facewrap.geometry import vertex_normals
    V, T = grid(15, 1.0)
    V = V + np.random.default_rng(3).normal(0, 0.02, V.shape)     # a bumpy sheet
    model = GraphModel(V, build_graph(V, T, spacing=0.3))
    rng = np.random.default_rng(0)
    candidates = np.arange(model.n_vertices)
    problem = ICPProblem(model, T, cylinder_scan(), NormalisedFrame(np.zeros(3), 1.0),
                         candidates, rng.permutation(candidates), None, None,
                         np.zeros(0, np.int64))
    for fraction in (0.1, 0.3, 1.0):
        used = problem.sampled(fraction)
        around = problem.triangles_around(fraction)
        assert problem.triangles_around(fraction) is around        # found once
        # every triangle with a sampled corner, and none without
        assert set(map(tuple, around)) == {tuple(t) for t in T if np.isin(t, used).any()}
        if fraction < 1:
            assert len(around) < len(T)
        np.testing.assert_allclose(vertex_normals(V, around)[used],
                                   vertex_normals(V, T)[used], rtol=0, atol=1e-12)
