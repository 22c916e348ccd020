"""Plausibility checks of a wrap's inputs (issue 16): each check alone on points with
a known answer, then on the built-in sample through ``wrap`` and the command line."""

import hashlib
import json

import numpy as np
import pytest

from facewrap.cli import main
from facewrap.geometry import ClosestPointTree
from facewrap.io import write_mesh
from facewrap.io.landmarks import write_points
from facewrap.landmarks import Landmarks
from facewrap.mesh import Mesh
from facewrap.sample import make_scan, make_template, write_sample
from facewrap.wrapping import WrapSettings, wrap
from facewrap.wrapping.plausibility import (check_landmark_residuals, check_reflection,
                                            check_scale, checked_scan,
                                            duplicated_landmarks, robust_similarity,
                                            swapped_pairs, unique_faces)

MIRROR = np.array([-1.0, 1.0, 1.0])


def _blob(seed=0, k=30):
    return np.random.default_rng(seed).normal(size=(k, 3)) * [3.0, 2.0, 1.0]


# -- each check alone ---------------------------------------------------------------
def test_reflection_refused_only_when_the_mirror_fits_clearly_better():
    X = _blob()
    Y = 2.0 * X + [5, 0, 0]
    assert check_reflection(X, Y) == []
    with pytest.raises(ValueError, match="mirror"):
        check_reflection(X, Y * MIRROR)
    assert "mirror" in check_reflection(X, Y * MIRROR, allow_mirrored=True)[0]
    # planar landmarks: the mirror image fits exactly as well, nothing to refuse
    flat = X * [1, 1, 0]
    assert check_reflection(flat, flat * [1, 1, -1]) == []


def test_robust_similarity_keeps_outliers_large_and_the_rest_close():
    X = _blob(1)
    Y = 0.5 * X
    Y[:3] += 20.0
    similarity, residuals = robust_similarity(X, Y)
    # Cauchy weights never reach zero: the outliers keep a trace of a pull
    assert abs(similarity.scale - 0.5) < 1e-3
    assert (residuals[:3] > 1).all() and residuals[3:].max() < 1e-3


def test_swapped_pairs_finds_the_swap_and_nothing_in_a_common_shift():
    X = _blob(2)
    Y = X.copy()
    Y[[4, 9]] = X[[9, 4]]
    assert swapped_pairs(X, Y, 1.0).tolist() == [[4, 9]]
    moved = X.copy()
    moved[:6] += [0, -1.5, 0]  # neighbours moving alike (an open jaw) are no swap
    assert len(swapped_pairs(X, moved, 1.0)) == 0


def test_residual_warning_names_the_worst_landmarks():
    X = _blob(3)
    names = [f"p{i}" for i in range(len(X))]
    lm = Landmarks.from_points(X, names)
    assert check_landmark_residuals(X, X + 1, lm) == []
    Y = X.copy()
    Y[[0, 7]] = X[[7, 0]]
    (note,) = check_landmark_residuals(X, Y, lm)
    assert "p0" in note and "p7" in note and "nearest p7's place" in note
    assert "%" in note


def test_duplicated_landmarks_and_faces():
    P = _blob(4, 5)
    P[3] = P[1]
    lm = Landmarks.from_points(P, ["a", "b", "c", "d", "e"])
    (note,) = duplicated_landmarks(P, lm, "scan")
    assert "b and d" in note
    assert duplicated_landmarks(_blob(4, 5), lm, "scan") == []
    keep = unique_faces([[0, 1, 2], [2, 0, 1], [0, 2, 1], [1, 2, 3]])
    assert keep.tolist() == [True, False, False, True]


def test_scale_check():
    assert check_scale(10.0) == []  # cm -> mm is fine
    assert "same units" in check_scale(1000.0)[0]
    assert "same units" in check_scale(0.001)[0]


# -- through wrap on the built-in sample ---------------------------------------------
@pytest.fixture(scope="module")
def sample():
    template = make_template(resolution=40)
    return template, make_scan(template, resolution=60)


def _wrap(template, scan_mesh, scan_landmarks, **settings):
    return wrap(template.mesh, scan_mesh, template.landmarks, scan_landmarks,
                WrapSettings(model="rbf", **settings))


def test_a_good_sample_and_extreme_expressions_raise_no_warning(sample):
    template, scan = sample
    assert _wrap(template, scan.mesh, scan.landmarks).warnings == []
    for weights in ({"jaw_open": 1.0, "smile": 1.0, "blink": 1.0, "brow_raise": 1.0},
                    {"jaw_open": 1.0, "pucker": 1.0, "brow_raise": 1.0}):
        extreme = make_scan(template, resolution=60, weights=weights)
        assert _wrap(template, extreme.mesh, extreme.landmarks).warnings == []


def test_mirrored_scan_is_refused_unless_allowed(sample):
    template, scan = sample
    mirrored = Mesh(scan.mesh.vertices * MIRROR, scan.mesh.triangles)
    points = Landmarks.from_points(scan.landmarks.points * MIRROR, scan.landmarks.names)
    with pytest.raises(ValueError, match="mirrored"):
        _wrap(template, mirrored, points)
    assert any("mirror" in w for w in _wrap(template, mirrored, points,
                                            allow_mirrored=True).warnings)


@pytest.mark.parametrize("named", [True, False])
@pytest.mark.parametrize("damage", ["reversed jaw", "eyes swapped", "shuffled"])
def test_mispaired_landmarks_are_named(sample, damage, named):
    template, scan = sample
    P = scan.landmarks.points.copy()
    if damage == "reversed jaw":
        P[:17] = P[:17][::-1]
    elif damage == "eyes swapped":
        P[36:42], P[42:48] = P[42:48].copy(), P[36:42].copy()
    else:
        P = P[np.random.default_rng(0).permutation(len(P))]
    if named:
        result = _wrap(template, scan.mesh, Landmarks.from_points(P, scan.landmarks.names))
    else:  # paired by order, every pair weighs alike in the similarity
        result = wrap(template.mesh, scan.mesh,
                      Landmarks.from_vertices(template.landmarks.vertex),
                      Landmarks.from_points(P), WrapSettings(model="rbf"))
    notes = [w for w in result.warnings if "wrong order, pairing or a left/right" in w]
    assert len(notes) == 1
    assert ("jaw_0" in notes[0]) == (named and damage == "reversed jaw")
    # the scan faces were not "fixed" on the strength of a mis-paired similarity
    assert not any("flipped" in w for w in result.warnings)


def test_flipped_and_duplicated_scan_faces_are_fixed_for_the_fit(sample):
    template, scan = sample
    good = _wrap(template, scan.mesh, scan.landmarks)
    V, T = scan.mesh.vertices, scan.mesh.triangles
    flipped = _wrap(template, Mesh(V, T[:, ::-1]), scan.landmarks)
    doubled = _wrap(template, Mesh(V, np.vstack([T, T[:, ::-1]])), scan.landmarks)
    assert any("flipped" in w for w in flipped.warnings)
    assert any("duplicated faces" in w for w in doubled.warnings)
    size = template.mesh.scale()
    for fixed in (flipped, doubled):
        assert np.abs(fixed.vertices - good.vertices).max() < 1e-6 * size
        assert abs(fixed.metrics["fit_mean"] - good.metrics["fit_mean"]) < 1e-6 * size


def test_checked_scan_leaves_a_good_scan_and_its_tree_alone(sample):
    template, scan = sample
    tree = ClosestPointTree(scan.mesh.vertices, scan.mesh.triangles)
    aligned = wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks,
                   WrapSettings(model="rigid", project=False)).vertices
    checked, checked_tree, notes = checked_scan(scan.mesh, tree, aligned,
                                                template.mesh.triangles)
    assert checked is scan.mesh and checked_tree is tree and notes == []


# -- the command line ---------------------------------------------------------------
def _digest(folder):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.iterdir()) if p.is_file()}


def test_cli_refuses_a_mirrored_scan_and_warns_about_a_flipped_one(sample, tmp_path,
                                                                   capsys):
    template, scan = sample
    paths = write_sample(tmp_path / "in", template, scan)
    mirrored, flipped = tmp_path / "in" / "mirrored.obj", tmp_path / "in" / "flipped.obj"
    write_mesh(mirrored, Mesh(scan.mesh.vertices * MIRROR, scan.mesh.triangles))
    write_mesh(flipped, Mesh(scan.mesh.vertices, scan.mesh.triangles[:, ::-1]))
    mirrored_points = tmp_path / "in" / "mirrored.txt"
    write_points(mirrored_points, scan.landmarks.points * MIRROR)
    before = _digest(tmp_path / "in")
    out, report = tmp_path / "out" / "fit.obj", tmp_path / "out" / "r.json"

    def run(scan_path, points, *extra, quiet=True):
        return main(["wrap", str(paths["template"]), str(scan_path), "-o", str(out),
                     "--template-landmarks", str(paths["template_landmarks"]),
                     "--scan-landmarks", str(points), "--model", "rbf",
                     "--report", str(report), *extra, *(["-q"] if quiet else [])])
    capsys.readouterr()
    assert run(mirrored, mirrored_points) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mirror" in err[0] and "Traceback" not in err[0]
    assert err[0].startswith(f"facewrap: error: {mirrored_points}: ")   # names the file
    assert not out.exists()
    # allowed: fitted, with the warning, and the summary line says there were warnings
    assert run(mirrored, mirrored_points, "--allow-mirrored", quiet=False) == 0
    captured = capsys.readouterr()
    assert any("mirror" in w for w in captured.err.splitlines())
    assert "warning(s) above: check the inputs" in captured.out
    out.unlink()
    assert run(flipped, paths["scan_landmarks"]) == 0
    err = capsys.readouterr().err
    (line,) = [w for w in err.splitlines() if "flipped" in w]
    assert line.startswith(f"facewrap: warning: {flipped}: ")
    assert any("flipped" in w for w in json.loads(report.read_text())["warnings"])
    assert _digest(tmp_path / "in") == before


def test_unique_faces_same_answer_for_small_and_huge_vertex_ids():
    from facewrap.wrapping.plausibility import unique_faces
    rng = np.random.default_rng(5)
    T = rng.integers(0, 40, size=(400, 3))
    T[::3] = T[::3][:, ::-1]                      # the same faces, wound the other way
    T = np.r_[T, T[:50]]
    small = unique_faces(T)
    huge = unique_faces(T + 2 ** 22)              # past the packed-key range
    assert np.array_equal(small, huge)
    S = np.sort(T, axis=1)
    assert len(np.unique(S[small], axis=0)) == small.sum() == len(np.unique(S, axis=0))


def test_a_scan_of_another_size_with_scaling_off_is_warned_about(sample):
    template, scan = sample
    assert _wrap(template, scan.mesh, scan.landmarks, scale=False).warnings == []
    bigger = Mesh(1.1 * scan.mesh.vertices, scan.mesh.triangles)
    lm = Landmarks.from_points(1.1 * np.asarray(scan.landmarks.points),
                               names=scan.landmarks.names)
    notes = _wrap(template, bigger, lm, scale=False).warnings
    assert len(notes) == 1 and "1.1 times the template's size" in notes[0], notes
    assert "scaling is off" in notes[0]
    assert _wrap(template, bigger, lm).warnings == []      # with scaling: nothing to say


def test_a_scan_full_of_holes_keeps_its_border_points(sample):
    # half the triangles gone at random: every triangle touches a hole, and rejecting
    # border points would leave the ICP none ("no template vertex found a valid scan
    # point" before)
    template, scan = sample
    keep = np.random.default_rng(0).random(len(scan.mesh.triangles)) > 0.5
    lacy = Mesh(scan.mesh.vertices, scan.mesh.triangles[keep])
    res = wrap(template.mesh, lacy, template.landmarks, scan.landmarks,
               WrapSettings(model="graph"))
    assert len(res.warnings) == 1 and "touch a border" in res.warnings[0], res.warnings
    assert res.settings.reject_boundary is False
    face = template.parts["face"]
    err = np.linalg.norm(res.vertices[face] - scan.ground_truth[face], axis=1)
    assert np.nanmedian(err) < 3.0     # mm; measured 1.3 (hybrid), the whole scan 0.37
