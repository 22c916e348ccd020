"""facewrap.transfer.marker_deformation: the reused-factorisation path against a
plain solve of the same normal equations, and the free-block assembly."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.spatial import cKDTree

import facewrap.solve.factor
from facewrap.geometry import ClosestPointTree, vertex_normals
from facewrap.geometry.matching import closest_compatible_points
from facewrap.sample import make_scan, make_template
from facewrap.transfer import (SUMNER_SCHEDULE, TETHER_WEIGHT, CorrespondenceStage,
                               adjacent_triangle_pairs, deform_toward,
                               gradient_operator, triangle_smoothness_operator,
                               untethered_vertices)
from facewrap.transfer.marker_deformation import WeightedFreeSystem


@pytest.fixture(scope="module")
def normalised_pair():
    """Template face and a scan of another topology (as tests/test_transfer.py's
    ``pair``), in units of the scan's bounding-box diagonal like
    :func:`find_correspondence` passes them, with the landmarks as markers."""
    tpl = make_template(32)
    face, _ = tpl.mesh.submesh(tpl.mesh.face_groups == 0)
    scan = make_scan(tpl, weights={}, resolution=40, noise=0, holes=0, crop=False,
                     transform=False, texture_size=8)
    lo, hi = scan.mesh.bounding_box()
    centre, unit = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    ids = np.asarray(tpl.landmarks.vertex)
    goal = scan.mesh.vertices[cKDTree(scan.mesh.vertices).query(scan.landmarks.points)[1]]
    uniq, first = np.unique(ids, return_index=True)
    return ((face.vertices - centre) / unit, face.triangles,
            (scan.mesh.vertices - centre) / unit, scan.mesh.triangles,
            uniq, (goal[first] - centre) / unit)


def _reference_deform(moving_V, moving_T, fixed_V, fixed_T, ids, points, schedule,
                      neighbours=16):
    """The textbook loop: build the full normal matrix every step, cut out the free
    block, move the marked columns to the right-hand side, solve with SuperLU."""
    n = len(moving_V)
    op = gradient_operator(moving_V, moving_T)
    N, t = op.n_unknowns, op.n_triangles
    G = op.matrix
    D = triangle_smoothness_operator(op, adjacent_triangle_pairs(moving_T))
    GtG, DtD = (G.T @ G).tocsr(), (D.T @ D).tocsr()
    identity_rhs = np.asarray(G.T @ np.tile(np.eye(3), (t, 1)))
    free = np.setdiff1d(np.arange(N), ids)
    x = op.extend(moving_V)
    x[ids] = points
    loose = np.zeros(N)
    loose[:n] = untethered_vertices(moving_T, n, ids)
    tether = TETHER_WEIGHT * float(GtG.diagonal().mean() + DtD.diagonal().mean()) * loose
    tether_rhs = tether[:, None] * op.extend(moving_V)
    tree = ClosestPointTree(fixed_V, fixed_T)
    kd = cKDTree(fixed_V)
    for stage in schedule:
        for _ in range(stage.iterations):
            w = np.zeros(N)
            rhs = stage.identity_weight * identity_rhs + tether_rhs
            if stage.closest_weight > 0:
                m = closest_compatible_points(tree, x[:n], vertex_normals(x[:n], moving_T),
                                              max_normal_angle=90.0, fallback=kd,
                                              neighbours=neighbours)
                valid = m.accepted.copy()
                cp = x[:n].copy()
                cp[m.index] = m.points
                valid[ids] = False
                w[:n] = stage.closest_weight * valid
                rhs[:n] += w[:n, None] * cp
            H = (stage.smooth_weight * DtD + stage.identity_weight * GtG
                 + sp.diags(tether + w)).tocsc()
            b = rhs[free] - H[free][:, ids] @ x[ids]
            x[free] = spla.spsolve(H[free][:, free].tocsc(), b)
    return x[:n]


@pytest.mark.parametrize("schedule", [
    SUMNER_SCHEDULE,
    # w_I changes between stages (a new factorisation) and a stage repeats
    (CorrespondenceStage(1.0, 0.1, 0.0), CorrespondenceStage(1.0, 0.001, 50.0, 3)),
], ids=["sumner", "changing-weights"])
@pytest.mark.parametrize("backend", ["cholmod", "cholespy"])
def test_deform_toward_equals_reference_solve(normalised_pair, schedule, backend,
                                              monkeypatch):
    """Both ways of solving the steps give the same deformed vertices (to 1e-6) as
    a fresh factorisation of every step: CHOLMOD refactorisations on one symbolic
    analysis, or (cholespy only) reused factors preconditioning CG."""
    if backend == "cholespy":                 # as if cvxopt were not installed
        monkeypatch.setattr(facewrap.solve.factor, "cholmod", None)
    mV, mT, fV, fT, ids, points = normalised_pair
    got, stats = deform_toward(mV, mT, fV, fT, ids, points, schedule)
    want = _reference_deform(mV, mT, fV, fT, ids, points, schedule)
    solves = sum(s.iterations for s in schedule)
    assert stats["solves"] == solves
    if backend == "cholespy":
        # the CG path was taken: fewer factorisations than solves
        assert stats["factorizations"] < solves and stats["cg_iterations"] > 0
    else:
        assert stats["factorizations"] == solves and stats["cg_iterations"] == 0
    scale = np.abs(want).max()
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * scale)
    # and the result is a real fit, not a copy of the input
    assert np.abs(got - mV).max() > 1e-3 * scale


def test_free_system_assembles_the_sliced_matrix():
    """Weighted value arrays on one pattern equal slicing the weighted sum, also
    when the terms' patterns differ and one has explicit zeros."""
    rng = np.random.default_rng(3)
    N = 40
    A = sp.random(N, N, density=0.1, random_state=rng)
    A = (A @ A.T).tocsr()
    A.data[::7] = 0.0                                   # explicit zeros kept
    B = sp.random(N, N, density=0.05, random_state=rng)
    B = (B @ B.T + sp.identity(N)).tocsr()
    fixed = np.zeros(N, dtype=bool)
    fixed[[3, 17, 30]] = True
    P = rng.normal(size=(3, 3))
    system = WeightedFreeSystem(A, B, fixed, P)
    free = np.flatnonzero(~fixed)
    d = rng.uniform(0, 2, size=len(free))
    got = system.matrix(0.7, 2.5, d).toarray()
    full = (0.7 * A + 2.5 * B).toarray()
    want = full[np.ix_(free, free)] + np.diag(d)
    np.testing.assert_allclose(got, want, rtol=1e-14, atol=1e-14)
    # a solve moves the marked columns over
    rhs = rng.normal(size=(len(free), 3))
    x = system.solve(0.7, 2.5, d, rhs, np.zeros_like(rhs))
    expect = np.linalg.solve(want, rhs - full[np.ix_(free, np.flatnonzero(fixed))] @ P)
    np.testing.assert_allclose(x, expect, rtol=0, atol=1e-8 * np.abs(expect).max())
