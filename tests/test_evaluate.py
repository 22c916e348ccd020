"""Evaluation: surface distances, landmark and ground-truth errors, the summary, the CLI."""

import argparse
import json

import numpy as np
import pytest

from facewrap.errors import InputError
from facewrap.evaluate import (VERTEX_ROLE_NAMES, evaluate, ground_truth_errors,
                               landmark_errors, role_codes, surface_distances)
from facewrap.geometry import ClosestPointTree
from facewrap.landmarks import Landmarks

from geometry_meshes import flat_square


@pytest.fixture(scope="module")
def sample():
    from facewrap.sample import make_scan, make_template
    from facewrap.wrapping.stages import WrapSettings, wrap
    tpl = make_template(24)
    scan = make_scan(tpl, resolution=40, texture_size=8)
    res = wrap(tpl.mesh, scan.mesh, tpl.landmarks, scan.landmarks,
               WrapSettings(model="rbf"))
    return tpl, scan, res


# -- surface distances ------------------------------------------------------------------

def test_distance_of_a_mesh_to_itself_is_zero():
    V, T = flat_square()
    d = surface_distances(V, (V, T), exclude_border=False)
    assert np.allclose(d.distances, 0, atol=1e-12)
    assert d.coverage == 1.0 and d.summary()["max"] < 1e-12


def test_known_offset_gives_known_signed_distance():
    V, T = flat_square()
    inner = (V[:, 0] > 2) & (V[:, 0] < 8) & (V[:, 1] > 2) & (V[:, 1] < 8)
    P = V[inner] + [0, 0, 0.7]
    Q = V[inner] - [0, 0, 0.3]
    d = surface_distances(np.vstack([P, Q]), (V, T))
    k = len(P)
    assert np.allclose(d.distances[:k], 0.7) and np.allclose(d.distances[k:], 0.3)
    assert np.allclose(d.signed[:k], 0.7) and np.allclose(d.signed[k:], -0.3)
    assert d.covered.all()                      # closest points are inside, not on border


def test_points_beyond_the_border_are_not_covered():
    V, T = flat_square()
    P = np.array([[5.0, 5.0, 1.0], [15.0, 5.0, 0.0], [-3.0, -3.0, 0.0]])
    d = surface_distances(P, (V, T))
    assert d.covered.tolist() == [True, False, False]
    s = d.summary()
    assert s["mean"] == pytest.approx(1.0) and s["coverage"] == pytest.approx(1 / 3)
    assert np.isnan(d.values()[1]) and d.values()[0] == pytest.approx(1.0)
    every = surface_distances(P, (V, T), exclude_border=False)
    assert every.covered.all() and every.summary()["max"] == pytest.approx(5.0)
    masked = surface_distances(P, (V, T), mask=[1, 2])
    assert not masked.covered.any()
    assert masked.summary()["coverage"] == 0.0    # statistics fall back to all points


def test_fit_summary_matches_wrap_fit_metrics(sample):
    from facewrap.wrapping.stages import fit_metrics
    tpl, scan, res = sample
    tree = ClosestPointTree(scan.mesh.vertices, scan.mesh.triangles)
    mask = np.ones(tpl.mesh.n_vertices, bool)
    mask[tpl.parts["eyeball_left"]] = False
    old = fit_metrics(res.vertices, tree, mask=mask)
    new = surface_distances(res.vertices, tree, mask=mask).summary("fit_")
    for key in ("fit_mean", "fit_p95", "fit_max"):
        assert new[key] == pytest.approx(old[key], rel=1e-12, abs=1e-12)
    # coverage is the covered share of the masked (fitted) vertices: vertices left
    # out by the mask are not in its denominator (issue 17)
    on_scan = ~tree.boundary_triangles[tree.query(res.vertices).triangles]
    assert new["fit_coverage"] == pytest.approx((on_scan & mask).sum() / mask.sum())
    assert new["fit_coverage"] > (on_scan & mask).sum() / len(mask)


def test_coverage_counts_only_masked_vertices():
    V, T = flat_square()
    # the masked points all sit above the square's middle, the others reach its rim
    inner = (V[:, 0] > 2) & (V[:, 0] < 8) & (V[:, 1] > 2) & (V[:, 1] < 8)
    P = V + [0.0, 0.0, 0.1]
    d = surface_distances(P, (V, T), mask=inner)
    assert d.coverage == pytest.approx(1.0)
    assert d.summary()["coverage"] == pytest.approx(1.0)
    assert surface_distances(P, (V, T)).coverage < 1.0


def test_role_codes_read_report_ranges():
    codes = role_codes({"fitted": [[0, 4]], "part": [[4, 6]], "cavity": [],
                        "excluded": [[6, 7]], "pinned": [[7, 8]]}, 8)
    assert [VERTEX_ROLE_NAMES[c] for c in codes] == (
        ["fitted"] * 4 + ["part"] * 2 + ["excluded", "pinned"])
    for bad, match in [({"fitted": [[0, 7]]}, "vertex 7 has no role"),
                       ({"fitted": [[0, 8]], "part": [[2, 3]]}, "in two ranges"),
                       ({"fitted": [[0, 9]]}, "0 <= start < stop <= 8"),
                       ({"fitted": [[3, 3]], "part": [[0, 8]]}, "start < stop"),
                       ({"skin": [[0, 8]]}, "unknown role 'skin'"),
                       ([[0, 8]], "must map role names")]:
        with pytest.raises(ValueError, match=match):
            role_codes(bad, 8)


def test_surface_distances_validates_points():
    V, T = flat_square(3)
    with pytest.raises(ValueError, match="points"):
        surface_distances(np.zeros((2, 2)), (V, T))
    with pytest.raises(ValueError, match="mask"):
        surface_distances(np.zeros((2, 3)), (V, T), mask=np.ones(3, bool))


# -- landmarks and ground truth -----------------------------------------------------------

def test_landmark_errors_known_values_and_summary():
    e = landmark_errors([[0, 0, 0], [1, 0, 0], [0, 0, 0]], [[0, 3, 4], [1, 0, 0], [0, 0, 1]],
                        names=["a", "b", "c"])
    assert e.errors.tolist() == [5.0, 0.0, 1.0]
    s = e.summary()
    assert s["landmark_worst"] == "a" and s["landmark_max"] == 5.0
    assert s["landmark_errors"] == {"a": 5.0, "b": 0.0, "c": 1.0}
    with pytest.raises(ValueError, match="match"):
        landmark_errors(np.zeros((2, 3)), np.zeros((3, 3)))


def test_ground_truth_errors_skip_nan_truth_and_masked_vertices():
    V = np.zeros((4, 3))
    G = np.array([[0, 0, 1.0], [np.nan, 0, 0], [0, 2, 0], [3, 0, 0]])
    e = ground_truth_errors(V, G, mask=[0, 1, 2])
    assert np.isnan(e.errors[[1, 3]]).all() and e.errors[[0, 2]].tolist() == [1.0, 2.0]
    assert e.count == 2 and e.summary()["correspondence_mean"] == 1.5
    with pytest.raises(ValueError, match="ground_truth"):
        ground_truth_errors(V, G[:3])


# -- everything, and the command ------------------------------------------------------------

def test_evaluate_sample_summary_is_json(sample):
    tpl, scan, res = sample
    ev = evaluate(res.mesh, scan.mesh, ground_truth=scan.ground_truth,
                  result_landmarks=tpl.landmarks, scan_landmarks=scan.landmarks,
                  reference=tpl.mesh, mask=tpl.parts["face"])
    s = ev.summary()
    json.dumps(s, allow_nan=False)
    assert s["landmark_count"] == 68 and s["correspondence_count"] > 0
    assert 0 < s["fit_coverage"] < 1 and s["fit_mean"] >= 0
    assert s["triangles_count"] == len(tpl.mesh.triangles)
    # the wrap moves template vertices onto the scan: ground-truth error is sane
    assert s["correspondence_mean"] < 0.05 * scan.mesh.scale()
    vals = ev.vertex_values()
    assert set(vals) >= {"fit", "correspondence", "area_ratio", "stretch", "flipped"}
    assert all(v.shape == (tpl.mesh.n_vertices,) for v in vals.values())


def test_evaluate_pairs_named_landmarks_by_name():
    V, T = flat_square()
    lm_r = Landmarks.from_vertices([0, 5, 60], names=["a", "b", "c"])
    lm_s = Landmarks.from_points(V[[60, 0]] + [0, 0, 2.0], names=["c", "a"])
    ev = evaluate((V, T), (V, T), result_landmarks=lm_r, scan_landmarks=lm_s)
    assert ev.landmarks.names == ("a", "c") and np.allclose(ev.landmarks.errors, 2.0)
    with pytest.raises(ValueError, match="both"):
        evaluate((V, T), (V, T), result_landmarks=lm_r)


def _cli(argv):
    from facewrap.cli.evaluate import register
    p = argparse.ArgumentParser()
    register(p.add_subparsers(), "summary")
    args = p.parse_args(argv)
    return args.func(args)


@pytest.fixture(scope="module")
def files(sample, tmp_path_factory):
    from facewrap.io import write_mesh
    from facewrap.io.landmarks import write_points, write_vertex_indices
    tpl, scan, res = sample
    d = tmp_path_factory.mktemp("evaluate")
    write_mesh(d / "fit.obj", res.mesh)
    write_mesh(d / "scan.obj", scan.mesh)
    write_mesh(d / "template.obj", tpl.mesh)
    write_vertex_indices(d / "tpl_lm.txt", tpl.landmarks)
    write_points(d / "scan_lm.txt", scan.landmarks.points)
    np.save(d / "gt.npy", scan.ground_truth)
    return d


def test_cli_writes_json_and_heatmap(files, capsys):
    from facewrap.texture import load_image
    d = files
    rc = _cli(["evaluate", str(d / "fit.obj"), str(d / "scan.obj"),
               "--ground-truth", str(d / "gt.npy"), "--reference", str(d / "template.obj"),
               "--result-landmarks", str(d / "tpl_lm.txt"),
               "--scan-landmarks", str(d / "scan_lm.txt"),
               "--json", str(d / "out.json"), "--heatmap", str(d / "heat.png"),
               "--heatmap-of", "correspondence"])
    assert rc == 0
    s = json.loads((d / "out.json").read_text())
    assert s["units"] == "mm" and s["landmark_count"] == 68 and "triangles_flipped" in s
    assert load_image(d / "heat.png").shape[2] == 3
    assert "fit mean" in capsys.readouterr().out


def test_cli_input_errors(files):
    d = files
    with pytest.raises(InputError, match="go together"):
        _cli(["evaluate", str(d / "fit.obj"), str(d / "scan.obj"),
              "--result-landmarks", str(d / "tpl_lm.txt")])
    with pytest.raises(InputError, match="topology"):
        _cli(["evaluate", str(d / "fit.obj"), str(d / "scan.obj"),
              "--reference", str(d / "scan.obj"), "-q"])
    with pytest.raises(InputError, match="needs --reference"):
        _cli(["evaluate", str(d / "fit.obj"), str(d / "scan.obj"), "--heatmap",
              str(d / "x.png"), "--heatmap-of", "stretch"])
    assert not (d / "x.png").exists()
