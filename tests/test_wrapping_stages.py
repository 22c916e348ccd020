"""The staged wrap (facewrap.wrapping.stages): each stage alone, then whole wraps with
ground truth on the built-in sample (jaw open, eyes shut, another identity)."""

import json

import numpy as np
import pytest

from facewrap.cli import main
from facewrap.geometry import ClosestPointTree
from facewrap.io import read_mesh
from facewrap.landmarks import Landmarks
from facewrap.mesh import Mesh
from facewrap.sample import make_scan, make_template, write_sample
from facewrap.wrapping import GraphCache, WrapSettings, fit_metrics, wrap
from facewrap.wrapping.stages import (align, fit_model, prepare_wrap, project,
                                      pull_landmarks)


# -- wraps on the built-in sample, ground truth known --------------------------------
@pytest.fixture(scope="module")
def sample():
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




# -- each stage alone ---------------------------------------------------------------
@pytest.fixture(scope="module")
def problem(sample):
    template, scan, _ = sample
    return prepare_wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks,
                        WrapSettings(model="graph"))


def test_prepare_wrap_resolves_the_model_and_pairs_landmarks(sample, problem):
    template, scan, _ = sample
    assert problem.spec.name == "graph" and problem.settings.model == "graph"
    assert len(problem.sources) == len(problem.targets) >= 3
    # the sample's eyeballs are pieces of their own: they follow, the face is fitted
    eyeballs = np.zeros(template.mesh.n_vertices, dtype=bool)
    eyeballs[np.concatenate([template.parts["eyeball_left"],
                             template.parts["eyeball_right"]])] = True
    assert np.array_equal(problem.excluded, eyeballs)
    everything = prepare_wrap(template.mesh, scan.mesh, template.landmarks,
                              scan.landmarks, WrapSettings(fit_hidden=True))
    assert not everything.excluded.any()
    auto = prepare_wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks,
                        blendshapes=template.blendshapes)
    assert auto.settings.model == "hybrid"
    with pytest.raises(ValueError, match="outside"):
        prepare_wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks,
                     exclude=[template.mesh.n_vertices])


def test_align_brings_the_landmarks_together(problem):
    similarity = align(problem)
    before = np.linalg.norm(problem.sources - problem.targets, axis=1).mean()
    after = np.linalg.norm(similarity.apply(problem.sources) - problem.targets, axis=1)
    assert after.mean() < 0.5 * before


def test_fit_model_closed_form_and_icp(sample, problem):
    template, scan, _ = sample
    similarity = align(problem)
    V = similarity.apply(template.mesh.vertices)
    rigid = prepare_wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks,
                         WrapSettings(model="rigid"))
    fitted = fit_model(rigid, V, similarity)
    np.testing.assert_allclose(fitted.vertices, V, atol=0)
    assert fitted.history == []
    fitted = fit_model(problem, V, similarity)
    assert fitted.history[0]["model"] == "pre-rigid"
    assert fitted.history[-1]["model"] == "graph" and fitted.setup_seconds > 0
    before = fit_metrics(V, problem.tree)["fit_mean"]
    assert fit_metrics(fitted.vertices, problem.tree)["fit_mean"] < 0.5 * before


def test_pull_landmarks_moves_far_landmarks_to_the_tolerance(sample, problem):
    """After the fit, as in a wrap: every landmark left farther than the tolerance
    is pulled to it, none held back."""
    template, _, _ = sample
    similarity = align(problem)
    V = fit_model(problem, similarity.apply(template.mesh.vertices), similarity).vertices
    moved, summary = pull_landmarks(problem, V)
    assert summary["pulled"] > 0 and summary["held_back"] == 0
    lm = problem.landmarks.positions(moved, template.mesh.triangles)
    left = np.linalg.norm(lm - problem.targets, axis=1)
    assert left.max() <= summary["tolerance"] * 1.5


def test_pull_landmarks_holds_back_pulls_that_would_fold(sample, problem):
    """Straight from the similarity (no fit between), the open jaw's and closed
    eyes' landmarks are many millimetres off: pulled there alone they fold the
    skin; with the guard they are held back and counted, no fitted triangle
    turned over."""
    from facewrap.geometry.quality import turned_triangles
    template, _, _ = sample
    T = template.mesh.triangles
    V = align(problem).apply(template.mesh.vertices)
    free = pull_landmarks(problem, V)[1]
    assert free["held_back"] == 0 and free["turned"] > 0
    moved, summary = pull_landmarks(problem, V, guard=True)
    assert summary["turned"] == 0
    left = np.linalg.norm(problem.landmarks.positions(moved, T) - problem.targets, axis=1)
    short = left > summary["tolerance"] * 1.05   # (a surface landmark moves with
    # its triangle's corners, not exactly as the warp at its own point)
    assert summary["pulled"] > 0 and summary["held_back"] >= short.sum() > 0
    assert summary["held_short"] >= left.max() - summary["tolerance"] - 1e-6
    fitted = ~problem.excluded[T].any(axis=1)
    assert not turned_triangles(moved, V, T)[fitted].any()


def test_project_puts_vertices_on_the_scan(sample, problem):
    template, _, _ = sample
    fitted = fit_model(problem, align(problem).apply(template.mesh.vertices), align(problem))
    projection = project(problem, fitted.vertices)
    d = problem.tree.query(projection.vertices[projection.projected]).distances
    assert projection.projected.mean() > 0.5 and d.max() < 1e-6


def test_wraps_share_a_graph_cache_the_caller_can_clear(sample):
    template, scan, _ = sample
    cache = GraphCache(capacity=2)
    settings = WrapSettings(model="graph", project=False)
    first = wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks, settings,
                 graph_cache=cache)
    assert len(cache) == 2               # the coarse and the fine graph
    again = wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks, settings,
                 graph_cache=cache)
    assert len(cache) == 2
    np.testing.assert_allclose(again.vertices, first.vertices, atol=1e-12)
    cache.clear()
    assert len(cache) == 0


def test_prepare_wrap_keeps_a_clean_scan_and_reports_no_warnings(sample, problem):
    _, scan, _ = sample
    assert problem.warnings == ()
    assert problem.scan is scan.mesh


def test_wrap_result_carries_the_plausibility_warnings(sample):
    template, scan, _ = sample
    P = scan.landmarks.points.copy()
    P[31] = P[30]  # one scan landmark given twice
    result = wrap(template.mesh, scan.mesh, template.landmarks,
                  Landmarks.from_points(P, scan.landmarks.names), WrapSettings(model="rbf"))
    names = scan.landmarks.names
    assert [w for w in result.warnings if f"{names[30]} and {names[31]}" in w]
    with pytest.raises(ValueError, match="mirror"):
        wrap(template.mesh, Mesh(scan.mesh.vertices * [-1, 1, 1], scan.mesh.triangles),
             template.landmarks,
             Landmarks.from_points(scan.landmarks.points * [-1, 1, 1], names),
             WrapSettings(model="rbf"))


def _grid(k=4):
    g = np.stack(np.meshgrid(np.arange(float(k)), np.arange(float(k))), -1).reshape(-1, 2)
    V = np.c_[g, np.zeros(k * k)]
    cells = [i + k * j for j in range(k - 1) for i in range(k - 1)]
    T = np.array([[c, c + 1, c + k + 1] for c in cells] + [[c, c + k + 1, c + k] for c in cells])
    return V, T


def test_folds_a_second_projection_makes_are_put_back_to_the_unfolded_pose():
    from facewrap.geometry import turned_triangles
    from facewrap.wrapping.unfold import step_back_new_folds as _revert_new_folds
    V, T = _grid()
    before = V + [0.0, 0.0, 0.1]                  # upright, moved
    after = before.copy()
    after[5] = [2.7, 2.6, 0.1]                    # pushed past its neighbours: folds
    after[10] = [2.0, 2.0, 0.3]                   # moved, folds nothing on its own
    assert turned_triangles(after, V, T).any()
    out, back = _revert_new_folds(T, V, before, after, np.zeros(len(V), bool))
    assert not turned_triangles(out, V, T).any()
    # vertex 5 went back part of the way (no further than it takes), the rest kept
    # the projection
    assert back[5] and 0 < np.linalg.norm(out[5] - after[5]) < np.linalg.norm(
        before[5] - after[5])
    assert np.array_equal(out[~back], after[~back])
    # a fixed vertex never moves, whatever it folds
    fixed = np.zeros(len(V), bool)
    fixed[5] = True
    out, back = _revert_new_folds(T, V, before, after, fixed)
    assert not back[5] and np.array_equal(out[5], after[5])
    # nothing newly turned: nothing put back
    out, back = _revert_new_folds(T, V, before, before + 0.01, np.zeros(len(V), bool))
    assert not back.any()
