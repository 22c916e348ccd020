"""Deformation models: Jacobians against finite differences, invariants."""

import numpy as np
import pytest
import scipy.sparse as sp

from facewrap.wrapping.models.affine import AffineModel
from facewrap.wrapping.models.base import rotation_exp, skew
from facewrap.wrapping.models.blendshape import (BlendshapeModel, BlendshapeParams, RigidModel,
                                        blendshape_basis)
from facewrap.wrapping.models.graph import GraphModel, GraphParams, build_graph
from facewrap.wrapping.models.hybrid import HybridModel, HybridParams
from facewrap.solve.block_jacobian import BlockJacobian


@pytest.fixture(scope="module")
def face():
    from facewrap.sample import make_template
    t = make_template(resolution=24)
    V = t.mesh.vertices
    c = V.mean(0)
    size = np.linalg.norm(np.ptp(V, axis=0))
    base = (V - c) / size
    shapes = {k: (v - c) / size for k, v in t.blendshapes.items()}
    D, names = blendshape_basis(base, shapes)
    graph = build_graph(base, t.mesh.triangles, spacing=0.08)
    return t, base, D, names, graph


def dense(J):
    return BlockJacobian.of(J).toarray()


def check_jacobian(model, params, rng, eps=1e-6, tol=1e-6):
    """Central differences of vertices and regularisers along random increments."""
    Jv = dense(model.jacobian(params))
    regs = {k: (r, dense(J)) for k, (r, J) in model.regularizers(params).items()}
    for _ in range(3):
        d = rng.normal(size=model.n_params)
        plus, minus = model.update(params, eps * d), model.update(params, -eps * d)
        fd = (model.vertices(plus) - model.vertices(minus)).ravel() / (2 * eps)
        assert np.allclose(Jv @ d, fd, atol=tol * max(1, np.abs(fd).max()))
        rp, rm = model.regularizer_residuals(plus), model.regularizer_residuals(minus)
        for name, (r, J) in regs.items():
            fd_r = (rp[name] - rm[name]) / (2 * eps)
            assert np.allclose(J @ d, fd_r, atol=tol * max(1, np.abs(fd_r).max())), name
            assert np.allclose(model.regularizer_residuals(params)[name], r)


def random_graph_params(m, rng):
    return GraphParams(rotation_exp(rng.normal(0, 0.3, (m, 3))), rng.normal(0, 0.05, (m, 3)))


def test_rotation_helpers_are_consistent():
    rng = np.random.default_rng(0)
    w = rng.normal(size=(5, 3))
    R = rotation_exp(w)
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1)
    assert np.allclose(rotation_exp(np.zeros(3)), np.eye(3))
    a, b = rng.normal(size=3), rng.normal(size=3)
    assert np.allclose(skew(a) @ b, np.cross(a, b))


def test_graph_nodes_cover_the_mesh_and_weights_are_a_partition(face):
    t, base, _, _, graph = face
    assert graph.vertex_weights.shape == graph.vertex_nodes.shape
    assert np.allclose(graph.vertex_weights.sum(1), 1)
    assert (graph.vertex_weights >= 0).all()
    # every node has an edge, both directions are present
    assert set(np.unique(graph.edges)) == set(range(graph.n_nodes))
    pairs = {tuple(e) for e in graph.edges.tolist()}
    assert all((k, j) in pairs for j, k in pairs)


def folded_strip(n=60, gap=0.02):
    """A strip folded back on itself like closed lips: two sheets ``gap`` apart in
    space, joined by a half-turn at x = 1, so they are ~2 apart on the surface."""
    u = np.linspace(0, 2 + np.pi * gap / 2, 2 * n + 1)
    w = np.linspace(0, 0.2, 5)
    U, W = np.meshgrid(u, w, indexing="ij")
    U, W = U.ravel(), W.ravel()
    turn = np.clip((U - 1) / (np.pi * gap / 2), 0, 1) * np.pi
    x = np.where(U < 1, U, np.where(turn < np.pi, 1 + gap / 2 * np.sin(turn),
                                    1 - (U - 1 - np.pi * gap / 2)))
    z = np.where(U < 1, 0.0, np.where(turn < np.pi, gap / 2 * (1 - np.cos(turn)) * -1,
                                      -gap))
    V = np.stack([x, W, z], 1)
    i, j = np.meshgrid(np.arange(len(u) - 1), np.arange(len(w) - 1), indexing="ij")
    a = (i * len(w) + j).ravel()
    T = np.concatenate([np.stack([a, a + len(w), a + 1], 1),
                        np.stack([a + 1, a + len(w), a + len(w) + 1], 1)])
    return V, T


def test_graph_skinning_follows_the_surface_not_space():
    """Vertices that touch in space but are far apart on the surface (upper and
    lower lip, upper and lower lid) must not be moved by the same nodes."""
    V, T = folded_strip()
    graph = build_graph(V, T, spacing=0.1)
    top = np.flatnonzero((V[:, 2] == 0) & (V[:, 0] < 0.7))
    bottom = np.flatnonzero((V[:, 2] < -0.015) & (V[:, 0] < 0.7))
    assert len(top) and len(bottom)
    shared = np.intersect1d(graph.vertex_nodes[top], graph.vertex_nodes[bottom])
    assert len(shared) == 0
    # Euclidean nearest nodes would have mixed the sheets
    from scipy.spatial import cKDTree
    _, j = cKDTree(V[graph.nodes]).query(V[top], k=4)
    assert np.isin(j, graph.vertex_nodes[bottom]).any()


def test_graph_skins_each_vertex_by_its_nearest_nodes_along_the_surface():
    """Every vertex's nodes are its k nearest by surface distance (within the
    graph's reach), nearest first, the lower node first among equals: a regular
    grid, full of equal distances."""
    from scipy.sparse.csgraph import dijkstra
    from facewrap.geometry import edges as mesh_edges
    V, T = folded_strip()
    spacing, k = 0.1, 4
    graph = build_graph(V, T, spacing=spacing, k=k)
    E = mesh_edges(T)
    length = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    G = sp.coo_matrix((np.r_[length, length], (np.r_[E[:, 0], E[:, 1]],
                                                np.r_[E[:, 1], E[:, 0]])), shape=(len(V),) * 2)
    D = dijkstra(G.tocsr(), directed=False, indices=graph.nodes, limit=4 * spacing).T
    assert np.isfinite(np.sort(D, axis=1)[:, k - 1]).all()    # every vertex in reach
    j = np.broadcast_to(np.arange(len(graph.nodes)), D.shape)
    want = np.lexsort((j, D), axis=1)[:, :k]                   # nearest, lower first
    np.testing.assert_array_equal(graph.vertex_nodes, want)


def test_graph_identity_and_rigid_motion(face):
    _, base, _, _, graph = face
    model = GraphModel(base, graph)
    p = model.initial_params()
    assert np.allclose(model.vertices(p), base)
    R = rotation_exp([0.3, -0.2, 0.1])
    t = np.array([0.1, 0.2, -0.3])
    X = base[graph.nodes]
    # the same rigid motion at every node: t_j = R x_j + t - x_j
    rigid = GraphParams(np.broadcast_to(R, (graph.n_nodes, 3, 3)).copy(), X @ R.T + t - X)
    assert np.allclose(model.vertices(rigid), base @ R.T + t)
    assert np.allclose(model.regularizer_residuals(rigid)["smooth"], 0, atol=1e-12)


def test_graph_jacobian_matches_finite_differences(face):
    rng = np.random.default_rng(1)
    _, base, _, _, graph = face
    model = GraphModel(base, graph)
    check_jacobian(model, random_graph_params(graph.n_nodes, rng), rng)


def test_hybrid_is_the_blend_when_the_graph_rests(face):
    _, base, D, _, graph = face
    model = HybridModel(base, D, graph)
    w = np.linspace(-0.5, 1.0, D.shape[1])
    p = HybridParams(GraphParams.identity(graph.n_nodes), w)
    assert np.allclose(model.vertices(p), base + (D @ w).reshape(-1, 3))
    # nodes follow the blend: no smoothness cost for any expression
    assert np.allclose(model.regularizer_residuals(p)["smooth"], 0, atol=1e-12)
    assert np.allclose(model.regularizer_residuals(p)["blend"], w)


def test_hybrid_jacobian_matches_finite_differences(face):
    rng = np.random.default_rng(2)
    _, base, D, _, graph = face
    model = HybridModel(base, D, graph)
    p = HybridParams(random_graph_params(graph.n_nodes, rng), rng.normal(0, 0.5, D.shape[1]))
    check_jacobian(model, p, rng)


def test_blendshape_and_rigid_jacobians(face):
    rng = np.random.default_rng(3)
    _, base, D, _, _ = face
    model = BlendshapeModel(base, D)
    p = BlendshapeParams(rotation_exp([0.2, 0.1, -0.3]), np.array([0.1, 0, 0.2]), 1.1,
                         rng.normal(size=D.shape[1]))
    check_jacobian(model, p, rng)
    rigid = RigidModel(base)
    pr = BlendshapeParams(rotation_exp([0.1, 0.4, 0.0]), np.array([0.0, 0.3, 0.1]), 0.9,
                          np.zeros(0))
    check_jacobian(rigid, pr, rng)
    assert rigid.regularizers(pr) == {}


def test_stretching_pose_jacobians_and_what_it_stretches(face):
    rng = np.random.default_rng(5)
    _, base, D, _, _ = face
    stretch = np.array([0.05, -0.08, 0.03])
    model = BlendshapeModel(base, D, stretch=True)
    assert model.n_params == 10 + D.shape[1]
    p = BlendshapeParams(rotation_exp([0.2, -0.1, 0.3]), np.array([0.1, 0, -0.1]), 1.05,
                         rng.normal(0, 0.3, D.shape[1]), stretch)
    check_jacobian(model, p, rng)                  # vertices and the "stretch" term
    rigid = RigidModel(base, stretch=True)
    check_jacobian(rigid, BlendshapeParams(np.eye(3), np.zeros(3), 1.0, np.zeros(0),
                                           stretch), rng)
    assert list(rigid.regularizers(p)) == ["stretch"]
    # the stretch scales the centred base along its principal axes by exp(λ)
    still = BlendshapeParams(np.eye(3), np.zeros(3), 1.0, np.zeros(0), stretch)
    Q, c = rigid.axes, base.mean(0)
    got = (rigid.vertices(still) - c) @ Q
    np.testing.assert_allclose(got, ((base - c) @ Q) * np.exp(stretch), atol=1e-12)
    # the posed deltas are what the pose does to the weighted shapes
    w = rng.normal(0, 0.3, D.shape[1])
    pw = BlendshapeParams(p.R, p.t, p.s, w, stretch)
    p0 = BlendshapeParams(p.R, p.t, p.s, np.zeros_like(w), stretch)
    np.testing.assert_allclose(model.vertices(pw) - model.vertices(p0),
                               (model.posed_deltas(pw) @ w).reshape(-1, 3), atol=1e-12)
    # no scale, no stretch: a pose that may not scale may not stretch either
    assert not BlendshapeModel(base, D, scale=False, stretch=True).stretch


def test_affine_jacobian_and_identity():
    rng = np.random.default_rng(4)
    V, T = folded_strip(n=8)   # small: the dense Jacobian check is (3n, 12n)
    base = V
    model = AffineModel(base, T)
    X = model.initial_params()
    assert np.allclose(model.vertices(X), base)
    assert np.allclose(model.regularizer_residuals(X)["smooth"], 0)
    check_jacobian(model, X + rng.normal(0, 0.1, X.shape), rng)


def test_pca_basis_spans_the_shapes(face):
    _, base, D, _, _ = face
    shapes = {f"s{k}": base + D[:, k].reshape(-1, 3) for k in range(D.shape[1])}
    P, names = blendshape_basis(base, shapes, components=D.shape[1])
    assert names[0] == "pc0" and P.shape == D.shape
    # every raw shape is a combination of the components
    coef, *_ = np.linalg.lstsq(P, D, rcond=None)
    assert np.allclose(P @ coef, D, atol=1e-10)


def test_block_jacobian_algebra():
    rng = np.random.default_rng(5)
    S = sp.random(12, 7, density=0.3, random_state=1, format="csr")
    Dn = rng.normal(size=(12, 2))
    J = BlockJacobian(S, Dn)
    full = J.toarray()
    x = rng.normal(size=9)
    assert np.allclose(J @ x, full @ x)
    w = rng.random(12)
    assert np.allclose(J.scale_rows(w).toarray(), w[:, None] * full)
    M = sp.random(4, 12, density=0.5, random_state=2, format="csr")
    assert np.allclose(J.left(M).toarray(), M @ full)
    assert np.allclose(J.rows([3, 1]).toarray(), full[[3, 1]])
    with pytest.raises(ValueError):
        BlockJacobian(S, Dn[:5])


def test_nearest_rotations_remove_scale_shear_and_reflection():
    from facewrap.wrapping.models.base import nearest_rotations
    rng = np.random.default_rng(4)
    R = rotation_exp(rng.normal(size=(6, 3)))
    assert np.allclose(nearest_rotations(R * rng.uniform(0.5, 2, (6, 1, 1))), R)
    M = rng.normal(size=(50, 3, 3))
    Q = nearest_rotations(M)
    assert np.allclose(Q @ Q.transpose(0, 2, 1), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(Q), 1.0)
    # no rotation is closer than the polar one (a few random competitors)
    for i in range(5):
        other = rotation_exp(rng.normal(size=(200, 3))) @ Q[i]
        best = np.linalg.norm(M[i] - Q[i])
        assert (np.linalg.norm(M[i] - other, axis=(1, 2)) >= best - 1e-12).all()


def test_coarse_to_fine_resampling_keeps_the_deformation(face):
    """A fine graph continuing a coarse one translates each node where the coarse
    graph moved it; a rigid motion carries over exactly, a smooth bend closely;
    the hybrid keeps its weights."""
    from facewrap.wrapping.models.base import nearest_rotations
    _, base, D, _, fine = face
    t = face[0]
    coarse = build_graph(base, t.mesh.triangles, spacing=0.16)
    assert coarse.n_nodes < fine.n_nodes / 2
    X = base[coarse.nodes]
    gm = GraphModel(base, coarse)
    # rigid: R x + c at every node
    R0 = rotation_exp([0.2, -0.4, 0.1])
    rigid = GraphParams(np.broadcast_to(R0, (len(X), 3, 3)).copy(),
                        X @ R0.T + [0.05, 0.0, -0.02] - X)
    fm, fp = gm.on_graph(fine, rigid)
    assert fm.graph is fine and fp.R.shape == (fine.n_nodes, 3, 3)
    assert np.allclose(fm.vertices(fp), gm.vertices(rigid), atol=1e-12)
    # smooth bend f(x) = x + a (y², 0, 0): node rotations from its gradient
    a = 0.3

    def bend_params(Y):
        grad = np.broadcast_to(np.eye(3), (len(Y), 3, 3)).copy()
        grad[:, 0, 1] = 2 * a * Y[:, 1]
        return GraphParams(nearest_rotations(grad), np.c_[a * Y[:, 1] ** 2, 0 * Y[:, :2]])
    bend = bend_params(X)
    fm, fp = gm.on_graph(fine, bend)
    V0, V1 = gm.vertices(bend), fm.vertices(fp)
    assert np.allclose(base[fine.nodes] + fp.t, V0[fine.nodes], atol=1e-12)
    # the handover costs nothing against the true field (the graphs only
    # interpolate it: here 17 % of the motion for the coarse graph)
    f = base + np.c_[a * base[:, 1] ** 2, 0 * base[:, :2]]
    assert np.abs(V1 - f).max() <= 1.05 * np.abs(V0 - f).max()
    motion = np.abs(f - base).max()
    assert np.abs(V1 - V0).max() < 0.15 * motion
    w = np.random.default_rng(5).normal(0, 0.3, D.shape[1])
    hm = HybridModel(base, D, coarse)
    hm2, hp = hm.on_graph(fine, HybridParams(bend_params(hm.blended(w)[coarse.nodes]), w))
    assert np.array_equal(hp.w, w)
    H0 = hm.vertices(HybridParams(bend_params(hm.blended(w)[coarse.nodes]), w))
    assert np.abs(hm2.vertices(hp) - H0).max() < 0.15 * motion


def test_hybrid_blend_cache_follows_the_weights(face):
    _, base, D, _, graph = face
    hm = HybridModel(base, D, graph)
    w = np.full(D.shape[1], 0.2)
    B1 = hm.blended(w)
    w[0] = 0.9                      # same array, new values: no stale cache
    B2 = hm.blended(w)
    assert not np.allclose(B1, B2)
    assert np.allclose(B2, base + (D @ w).reshape(-1, 3))
    with pytest.raises(ValueError):
        B2[0, 0] = 1.0              # shared result is read-only


def test_weight_bounds_penalty_and_its_jacobian(face):
    """Weights outside [0, 1] are penalised by how far they are out; inside,
    nothing changes; the Jacobians (with the penalty active) match finite
    differences."""
    from facewrap.wrapping.models.blendshape import bound_violation
    _, base, D, _, graph = face
    rng = np.random.default_rng(8)
    w = np.linspace(-0.5, 1.5, D.shape[1])           # some below, some above
    r, d = bound_violation(w, (0.0, 1.0))
    assert np.allclose(r, np.clip(w, None, 0) + np.clip(w - 1, 0, None))
    assert np.array_equal(d, (r != 0).astype(float))
    hm = HybridModel(base, D, graph, bounds=(0.0, 1.0))
    p = HybridParams(random_graph_params(graph.n_nodes, rng), w + 1e-3)
    assert np.allclose(hm.regularizer_residuals(p)["bounds"],
                       bound_violation(w + 1e-3, (0, 1))[0])
    check_jacobian(hm, p, rng)
    bm = BlendshapeModel(base, D, bounds=(0.0, 1.0))
    q = BlendshapeParams(rotation_exp([0.1, 0.2, 0.0]), np.zeros(3), 1.1, w + 1e-3)
    check_jacobian(bm, q, rng)
    assert "bounds" not in HybridModel(base, D, graph).regularizers(p)
    inside = HybridParams(p.graph, np.full(D.shape[1], 0.5))
    assert not hm.regularizer_residuals(inside)["bounds"].any()


def test_graph_cache_keeps_graphs_on_disk_by_content(face, tmp_path, monkeypatch):
    """A new GraphCache (a new process) reads the graph back from disk, equal to a
    fresh build; an entry that does not fit the template is built again; with the
    cache off nothing is written."""
    import facewrap.wrapping.models.graph as graph_module
    from facewrap.geometry.frames import NormalisedFrame
    from facewrap.wrapping.models.graph import GraphCache
    monkeypatch.setenv("FACEWRAP_CACHE_DIR", str(tmp_path))
    t = face[0]
    V, T = t.mesh.vertices, t.mesh.triangles
    first = GraphCache().graph(V, T, 0.1)
    assert len(list(tmp_path.glob("deformation-graph-*.npz"))) == 1
    built = []
    monkeypatch.setattr(graph_module, "build_graph",
                        lambda *a, **k: built.append(1) or build_graph(*a, **k))
    again = GraphCache().graph(V, T, 0.1)
    assert not built                                   # read, not built
    want = build_graph(NormalisedFrame.of(V).to_frame(V), T, spacing=0.1)
    for field in ("nodes", "vertex_nodes", "edges"):
        assert np.array_equal(getattr(again, field), getattr(want, field))
    np.testing.assert_allclose(again.vertex_weights, want.vertex_weights, rtol=0,
                               atol=1e-15)
    assert np.array_equal(again.nodes, first.nodes)
    # another template of the same size: another key, built
    GraphCache().graph(V + 1e-3, T, 0.1)
    assert len(built) == 1
    # a damaged entry (skinning rows that do not match the template) is rebuilt
    entry = next(tmp_path.glob("deformation-graph-*.npz"))
    with np.load(entry) as z:
        arrays = dict(z)
    arrays["vertex_nodes"] = arrays["vertex_nodes"][:-1]
    for e in tmp_path.glob("deformation-graph-*.npz"):
        np.savez(e, **arrays)
    assert np.array_equal(GraphCache().graph(V, T, 0.1).nodes, want.nodes)
    assert len(built) == 2
    monkeypatch.setenv("FACEWRAP_CACHE", "0")
    for e in tmp_path.glob("*.npz"):
        e.unlink()
    GraphCache().graph(V, T, 0.1)
    assert not list(tmp_path.glob("*.npz"))
