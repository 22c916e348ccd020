"""The non-rigid ICP engine: terms, solver, correspondences, and wraps with
ground truth on the built-in sample (jaw open, eyes shut, another identity)."""

import json

import numpy as np
import pytest
import scipy.sparse as sp

from facewrap.geometry import ClosestPointTree
from facewrap.wrapping.icp.engine import NonRigidICP, Stage, default_schedule, find_correspondences
from facewrap.solve.factor import gauss_newton_step
from facewrap.solve.block_jacobian import BlockJacobian
from facewrap.wrapping.icp.terms import (landmark_rows, landmark_term, point_to_plane,
                                         point_to_point, robust_weights)
from facewrap.wrapping.stages import WrapSettings, wrap


def grid(n=21, size=2.0, z=0.0):
    u = np.linspace(-size / 2, size / 2, n)
    X, Y = np.meshgrid(u, u, indexing="ij")
    V = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], 1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    T = np.concatenate([np.stack([a, a + n, a + 1], 1), np.stack([a + 1, a + n, a + n + 1], 1)])
    return V, T


# -- terms and solver ---------------------------------------------------------------
@pytest.mark.parametrize("kind", ["welsch", "huber", "geman_mcclure", "none"])
def test_robust_weights_are_one_at_zero_and_decrease(kind):
    d = np.linspace(0, 10, 50)
    w = robust_weights(d, 1.0, kind)
    assert w[0] == 1 and ((w >= 0) & (w <= 1)).all()
    assert (np.diff(w) <= 1e-15).all()
    if kind != "none":
        assert w[-1] < 0.2


def test_robust_weights_reject_unknown_norm():
    with pytest.raises(ValueError, match="unknown robust norm"):
        robust_weights([1.0], 1.0, "cauchyish")


@pytest.mark.parametrize("method", ["cg", "direct"])
def test_gauss_newton_step_solves_the_linear_least_squares(method):
    rng = np.random.default_rng(0)
    S1 = sp.random(40, 12, density=0.3, random_state=3, format="csr") + sp.eye(40, 12)
    D1 = rng.normal(size=(40, 2))
    r1 = rng.normal(size=40)
    S2 = sp.eye(14, 12, format="csr")
    r2 = rng.normal(size=14)
    rw = rng.random(40)
    terms = [(0.7, r1, BlockJacobian(S1, D1), rw),
             (0.3, r2, BlockJacobian(S2, np.zeros((14, 2))), None)]
    delta = gauss_newton_step(terms, damping=0.0, method=method, block=3)
    A = np.vstack([np.sqrt(0.7 * rw)[:, None] * np.hstack([S1.toarray(), D1]),
                   np.sqrt(0.3) * np.hstack([S2.toarray(), np.zeros((14, 2))])])
    b = np.concatenate([np.sqrt(0.7 * rw) * r1, np.sqrt(0.3) * r2])
    expected = -np.linalg.lstsq(A, b, rcond=None)[0]
    assert np.allclose(delta, expected, atol=1e-5)


def test_both_factor_back_ends_and_refactorize_solve_exactly():
    """cholespy ("many" solves) and CHOLMOD ("few"), vectors and blocks; a
    refactorisation on the same pattern reuses the analysis; indefinite matrices
    still get a finite answer."""
    from facewrap.solve.factor import factorize, refactorize
    rng = np.random.default_rng(5)
    n = 60
    L = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    A = (L @ L + 0.1 * sp.identity(n)).tocsr()
    B = rng.normal(size=(n, 4))
    for solves, method in (("many", "cholesky"), ("few", "cholmod")):
        f = factorize(A, solves=solves)
        assert f.method == method
        np.testing.assert_allclose(A @ f.solve(B), B, atol=1e-9)
        np.testing.assert_allclose(A @ f.solve(B[:, 0]), B[:, 0], atol=1e-9)
    f = factorize(A, solves="few")
    A2 = (A + sp.diags(rng.uniform(0, 5, n))).tocsr()      # same pattern
    g = refactorize(f, A2)
    assert g is f and g.method == "cholmod"
    np.testing.assert_allclose(A2 @ g.solve(B), B, atol=1e-9)
    indefinite = sp.diags([1.0, -1.0, 2.0]).tocsr()
    f = factorize(indefinite, solves="few")
    assert f.method == "lu" and np.allclose(f.solve([1.0, 1.0, 1.0]), [1, -1, 0.5])
    with pytest.raises(ValueError, match="solves"):
        factorize(A, solves="some")


def test_data_and_landmark_terms_match_their_definitions():
    rng = np.random.default_rng(1)
    V = rng.normal(size=(6, 3))
    Jv = sp.identity(18, format="csr")  # vertices are the parameters
    verts = np.array([1, 4])
    targets, normals = rng.normal(size=(2, 3)), np.array([[0, 0, 1.0], [1, 0, 0]])
    r, J = point_to_point(V, Jv, verts, targets)
    assert np.allclose(r, (V[verts] - targets).ravel()) and J.shape == (6, 18)
    r, J = point_to_plane(V, Jv, verts, targets, normals)
    assert np.allclose(r, [V[1, 2] - targets[0, 2], V[4, 0] - targets[1, 0]])
    assert np.allclose(J.toarray()[0, 3:6], [0, 0, 1])
    from facewrap.landmarks import Landmarks
    T = np.array([[0, 1, 2], [3, 4, 5]])
    lm = Landmarks.from_barycentric([1], [[0.2, 0.3, 0.5]])
    L = landmark_rows(lm, 6, T)
    r, J = landmark_term(V, Jv, L, np.zeros((1, 3)))
    assert np.allclose(r, 0.2 * V[3] + 0.3 * V[4] + 0.5 * V[5])
    with pytest.raises(ValueError, match="free points"):
        landmark_rows(Landmarks.from_points([[0, 0, 0.0]]), 6, T)


# -- correspondences ----------------------------------------------------------------
def test_correspondences_reject_far_flipped_and_border_points():
    V, T = grid(21, 2.0)                                  # the scan: z = 0, |x|,|y| <= 1
    tree = ClosestPointTree(V, T)
    inside, TP = grid(5, 0.5, z=0.05)                     # 25 points above the interior
    far = inside + [0, 0, 1.0]                            # 25 points too far above
    edge = inside + [1.3, 0, -0.05]                       # 25 points beside the border
    P = np.vstack([inside, far, edge])
    TT = np.vstack([TP, TP + 25, TP + 50])
    c = find_correspondences(P, TT, tree, np.arange(75), center=np.zeros(3), size=1.0,
                             max_distance=0.6, max_normal_angle=60)
    assert c.vertices.tolist() == list(range(25))
    assert c.rejected == {"distance": 25, "normal": 0, "border": 25}
    assert np.allclose(c.points[:, 2], 0) and np.allclose(c.distances, 0.05)
    # a patch facing the other way finds no compatible normals
    c2 = find_correspondences(inside, TP[:, ::-1], tree, np.arange(25),
                              center=np.zeros(3), size=1.0, max_distance=0.3)
    assert len(c2.vertices) == 0 and c2.rejected["normal"] == 25
    # the frame: the same query in a scaled, shifted frame gives the same answer
    c3 = find_correspondences((P - 1.0) / 2.0, TT, tree, np.arange(75), center=np.ones(3),
                              size=2.0, max_distance=0.3)
    assert c3.vertices.tolist() == list(range(25))
    assert np.allclose(c3.distances, 0.025)


def test_graph_icp_bends_a_sheet_onto_a_cylinder():
    from facewrap.wrapping.models.graph import GraphModel, build_graph
    V, T = grid(25, 1.0)
    # the scan: a cylinder of radius 1 around the y axis, below the sheet's centre
    a = np.linspace(-0.8, 0.8, 61)
    y = np.linspace(-0.7, 0.7, 41)
    A, Y = np.meshgrid(a, y, indexing="ij")
    S = np.stack([np.sin(A).ravel(), Y.ravel(), (np.cos(A) - 1).ravel()], 1)
    _, TS = grid(61, 1.0)
    TS = TS.copy()
    # reuse the grid triangulation pattern for a 61 x 41 grid
    i, j = np.meshgrid(np.arange(60), np.arange(40), indexing="ij")
    q = (i * 41 + j).ravel()
    TS = np.concatenate([np.stack([q, q + 41, q + 1], 1),
                         np.stack([q + 1, q + 41, q + 42], 1)])
    tree = ClosestPointTree(S, TS)
    model = GraphModel(V, build_graph(V, T, spacing=0.15))
    icp = NonRigidICP([Stage(iterations=15, stiffness=1.0, landmark_weight=0,
                             robust_scale=0.2),
                       Stage(iterations=15, stiffness=0.1, landmark_weight=0,
                             robust_scale=0.05),
                       Stage(iterations=15, stiffness=0.01, landmark_weight=0,
                             robust_scale=0.01)],
                      max_distance=0.3).fit(model, T, tree, center=np.zeros(3), size=1.0)
    d = tree.query(icp.vertices_).distances
    assert d.max() < 0.01 and np.median(d) < 0.001
    assert len(icp.history_) > 2 and "data_rms" in icp.history_[-1]


def test_default_schedules_go_from_stiff_to_loose():
    for model in ("affine", "graph", "hybrid"):
        s = default_schedule(model)
        stiff = [st.stiffness for st in s]
        assert stiff == sorted(stiff, reverse=True), model
        assert s[0].data_weight == 0 or model in ("affine", "hybrid")
        # and coarse to fine in node count, ending on the model's own graph
        spacing = [st.node_spacing_factor for st in s]
        assert spacing == sorted(spacing, reverse=True) and spacing[-1] == 1.0, model
    with pytest.raises(ValueError, match="node_spacing_factor"):
        Stage(node_spacing_factor=0.0)


def test_gram_and_bordered_step_match_the_plain_products():
    """The block-sparse Gram of vertex rows (4 node blocks per vertex, columns
    unsorted as the skinning gives them) and the Schur-complement solve equal
    ``SᵀS`` and the dense solve."""
    from facewrap.solve.factor import _bordered_step, _dense_step, _gram, _sparse_gram
    rng = np.random.default_rng(2)
    n, m, k = 300, 30, 4
    nodes = np.stack([rng.choice(m, k, replace=False) for _ in range(n)])
    cols = (6 * nodes)[:, None, :, None] + np.arange(6)
    S = sp.csr_matrix((rng.normal(size=(n, 3, k, 6)).ravel(),
                       np.broadcast_to(cols, (n, 3, k, 6)).ravel(),
                       np.arange(0, 18 * k * n + 1, 6 * k)), shape=(3 * n, 6 * m))
    assert np.allclose(_gram(S), (S.T @ S).toarray(), atol=1e-12)
    assert np.allclose(_sparse_gram(S).toarray(), (S.T @ S).toarray(), atol=1e-12)
    T = sp.random(50, 6 * m, density=0.05, random_state=1, format="csr")
    D = rng.normal(size=(3 * n + 50, 5))
    b = rng.normal(size=3 * n + 50)
    for damping in (0.0, 1e-2):
        x = _bordered_step([S, T], D, b, damping)
        assert np.allclose(x, _dense_step([S, T], D, b, damping), atol=1e-9)
    x0 = _bordered_step([S, T], D[:, :0], b, 0.0)
    assert np.allclose(x0, _dense_step([S, T], D[:, :0], b, 0.0), atol=1e-9)


# -- wraps on the built-in sample, ground truth known --------------------------------
@pytest.fixture(scope="module")
def sample():
    from facewrap.sample.face import make_scan, make_template
    template = make_template(resolution=40)
    scan = make_scan(template, resolution=60)
    tree = ClosestPointTree(scan.mesh.vertices, scan.mesh.triangles)
    face = template.parts["face"]
    on = tree.query(np.nan_to_num(scan.ground_truth[face]))
    seen = face[~tree.boundary_triangles[on.triangles] & (on.distances < 1.0)]
    return template, scan, seen


@pytest.fixture(scope="module")
def fits(sample):
    template, scan, _ = sample
    out = {}
    for model in ("graph", "blendshape", "hybrid"):
        out[model] = wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks,
                          WrapSettings(model=model), blendshapes=template.blendshapes)
    return out


def gt_error(result, sample):
    template, scan, seen = sample
    return np.linalg.norm(result.vertices[seen] - scan.ground_truth[seen], axis=1)


def test_hybrid_beats_graph_and_blendshapes_on_an_extreme_expression(sample, fits):
    e = {k: gt_error(r, sample) for k, r in fits.items()}
    assert e["hybrid"].mean() < 0.6                     # mm, jaw open + eyes shut
    assert e["hybrid"].mean() < 0.6 * e["graph"].mean()
    assert e["hybrid"].mean() < 0.8 * e["blendshape"].mean()
    assert np.percentile(e["hybrid"], 95) < np.percentile(e["graph"], 95)


def test_hybrid_recovers_the_expression_weights(sample, fits):
    template, scan, _ = sample
    r = fits["hybrid"]
    got = dict(zip(r.shape_names, r.weights))
    for name in template.blendshapes:
        assert got[name] == pytest.approx(scan.weights.get(name, 0.0), abs=0.12), name
    # an expression rig's weights stay in [0, 1] (the default weight_range)
    for r in (fits["hybrid"], fits["blendshape"]):
        assert r.weights.min() > -0.01 and r.weights.max() < 1.01


def test_weight_range_setting():
    assert WrapSettings().blend_bounds() == (0.0, 1.0)
    assert WrapSettings(weight_range=[]).blend_bounds() is None
    assert WrapSettings(weight_range=None).blend_bounds() is None
    assert WrapSettings(pca_components=5).blend_bounds() is None   # PCA: unbounded
    assert WrapSettings(weight_range=[-1, 2]).blend_bounds() == (-1.0, 2.0)
    for bad in ([1.0, 0.0], [0.0], [0, 1, 2]):
        with pytest.raises(ValueError, match="weight_range"):
            WrapSettings(weight_range=bad)


def test_wrap_results_keep_topology_and_report_iterations(sample, fits):
    template, _, _ = sample
    for name, r in fits.items():
        assert r.settings.model == name
        assert np.array_equal(r.mesh.face_indices, template.mesh.face_indices)
        assert np.array_equal(r.mesh.uvs, template.mesh.uvs)
        assert r.history and all(np.isfinite(h["energy"]) for h in r.history)
        assert r.metrics["landmark_mean"] < 1.0 and r.metrics["fit_mean"] < 0.5


def test_auto_model_and_determinism(sample, fits):
    template, scan, _ = sample
    again = wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks,
                 blendshapes=template.blendshapes)
    assert again.settings.model == "hybrid"
    assert np.array_equal(again.vertices, fits["hybrid"].vertices)
    with pytest.raises(ValueError, match="needs blendshapes"):
        wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks,
             WrapSettings(model="hybrid"))


def test_excluded_eyeballs_follow_the_face(sample):
    template, scan, _ = sample
    eyes = np.concatenate([template.parts["eyeball_left"], template.parts["eyeball_right"]])
    r = wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks,
             WrapSettings(model="graph", project=False), exclude=eyes)
    # an eyeball moves with its socket (a similarity, nearly): it stays a ball
    V0, V1 = template.mesh.vertices[template.parts["eyeball_left"]], r.vertices[
        template.parts["eyeball_left"]]
    d0 = np.linalg.norm(V0 - V0.mean(0), axis=1)
    d1 = np.linalg.norm(V1 - V1.mean(0), axis=1)
    assert np.abs(d1 / d1.mean() - d0 / d0.mean()).max() < 0.03
    assert 0.9 < d1.mean() / (r.transform.scale * d0.mean()) < 1.1


def test_cli_wrap_with_blendshapes_defaults_to_hybrid(sample, tmp_path):
    from facewrap.cli import main
    from facewrap.io import read_mesh
    from facewrap.sample.face import write_sample
    template, scan, _ = sample
    paths = write_sample(tmp_path / "in", template, scan)
    out, rep = tmp_path / "fit.obj", tmp_path / "r.json"
    rc = main(["wrap", str(paths["template"]), str(paths["scan"]), "-o", str(out),
               "--template-landmarks", str(paths["template_landmarks"]),
               "--scan-landmarks", str(paths["scan_landmarks"]),
               "--blendshapes", str(paths["blendshapes/blink"].parent), "--report", str(rep), "-q"])
    assert rc == 0
    report = json.loads(rep.read_text())
    assert report["settings"]["model"] == "hybrid"
    assert set(report["blend_weights"]) == set(template.blendshapes)
    assert report["iterations"] and "icp" in report["timings"]
    assert read_mesh(out).n_vertices == template.mesh.n_vertices
    assert report["settings"]["weight_range"] == [0.0, 1.0]
    # the weight range from the command line; a reversed one is one clear error
    args = ["wrap", str(paths["template"]), str(paths["scan"]), "-o", str(out),
            "--template-landmarks", str(paths["template_landmarks"]),
            "--scan-landmarks", str(paths["scan_landmarks"]), "--model", "blendshape",
            "--blendshapes", str(paths["blendshapes/blink"].parent), "--report", str(rep),
            "-q"]
    assert main(args + ["--no-weight-range"]) == 0
    assert json.loads(rep.read_text())["settings"]["weight_range"] is None
    assert main(args + ["--weight-range", "1", "0"]) != 0
    # landmark pull: reported by default, can be off, a negative tolerance is an error
    assert "landmark_pull" in report["metrics"]
    assert main(args + ["--no-landmark-pull"]) == 0
    off = json.loads(rep.read_text())
    assert off["settings"]["landmark_pull"] is False
    assert "landmark_pull" not in off["metrics"]
    assert main(args + ["--landmark-tolerance", "-1"]) != 0


def test_template_graph_is_cached_by_content(sample):
    """Batch jobs read the template afresh: an equal mesh reuses the graph, a
    changed one (or another spacing) gets its own."""
    from facewrap.wrapping.stages import _template_graph
    template = sample[0].mesh
    again = template.with_vertices(template.vertices.copy())
    assert again is not template
    g = _template_graph(template, 0.07)
    assert _template_graph(again, 0.07) is g
    assert _template_graph(template, 0.09) is not g
    moved = template.with_vertices(template.vertices * [1.0, 1.0, 1.3])
    assert _template_graph(moved, 0.07) is not g
