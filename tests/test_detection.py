"""Landmark detection (issue 18) on the built-in sample, and on real scans.

Oracles: the sample's own landmarks (its template's vertex ids, its scan's points),
the same mesh turned and scaled (the answer must turn and scale with it), a sphere
(no face), the manual landmarks of the real scans.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from facewrap.cli import main
from facewrap.detection import DetectionSettings, detect_landmarks, mesh_texture
from facewrap.detection.fuse import fuse_views
from facewrap.detection.views import Camera, SceneArrays, render_view, skin_triangles
from facewrap.errors import InputError
from facewrap.geometry.visibility import sphere_directions
from facewrap.io import read_mesh
from facewrap.io.landmarks import read_landmarks, read_ljson
from facewrap.landmarks import IBUG68_NAMES
from facewrap.mesh import Mesh

from conftest import ROOT, needs_data

pytestmark = pytest.mark.slow
pytest.importorskip("dlib", reason="the optional extra facewrap[landmarks] is absent")

GROUPS = {"jaw": slice(0, 17), "brows": slice(17, 27), "nose": slice(27, 36),
          "eyes": slice(36, 48), "mouth": slice(48, 68)}


@pytest.fixture(scope="module")
def sample(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sample")
    assert main(["sample", str(folder)]) == 0
    scan = read_mesh(folder / "scan.obj")
    found = detect_landmarks(scan, mesh_texture(folder / "scan.obj", scan))
    return folder, scan, found


def test_the_sample_scan_gives_68_named_points_on_its_surface(sample):
    folder, scan, found = sample
    assert found.landmarks.names == IBUG68_NAMES
    assert found.positions.shape == (68, 3)
    assert np.allclose(found.landmarks.positions(scan), found.positions)
    assert np.all((found.confidence >= 0) & (found.confidence <= 1))
    assert np.array_equal(found.low_confidence, found.confidence < 0.5)
    assert any(v["found"] for v in found.views) and found.views[0]["yaw"] == 0
    truth = read_landmarks(folder / "scan_landmarks.txt", kind="points").points
    err = np.linalg.norm(found.positions - truth, axis=1)
    # measured (bench_detection): nose 2.3 mm, eyes 3.6 mm, brows 4.1 mm, jaw
    # 7.6 mm, all 68 5.0 mm (in mm)
    assert err[GROUPS["nose"]].mean() < 3.5 and err[GROUPS["eyes"]].mean() < 5.0
    assert err[GROUPS["brows"]].mean() < 6.0 and err[GROUPS["jaw"]].mean() < 11.0
    assert err.mean() < 7.0


def _moved_back(scan, image, found, R, scale):
    """Distances between ``found`` and the landmarks of the scan turned by ``R`` and
    scaled, with the transform undone; and which points both call confident."""
    moved = Mesh(scale * scan.vertices @ R.T, (scan.face_offsets, scan.face_indices),
                 uvs=scan.uvs, face_uvs=(scan.face_offsets, scan.face_uvs))
    again = detect_landmarks(moved, image)
    back = (again.positions / scale) @ R
    return (np.linalg.norm(back - found.positions, axis=1),
            ~found.low_confidence & ~again.low_confidence)


def test_the_answer_turns_and_scales_with_the_mesh(sample):
    folder, scan, found = sample
    R = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])          # 90 degrees about x
    dist, ok = _moved_back(scan, mesh_texture(folder / "scan.obj", scan), found, R, 10.0)
    assert ok.sum() >= 20
    assert dist[ok].mean() < 1.5   # mm


def test_a_sphere_has_no_face(tmp_path):
    V = sphere_directions(600) * 100.0
    from scipy.spatial import ConvexHull
    T = ConvexHull(V).simplices
    with pytest.raises(InputError, match="ball.obj: no face found"):
        detect_landmarks((V, T), source="ball.obj",
                         settings=DetectionSettings(search_size=128))


def test_fusing_keeps_agreeing_views_and_scores_the_others_low():
    rng = np.random.default_rng(0)
    truth = rng.normal(size=(68, 3)) * 30
    lifts = truth + rng.normal(scale=0.2, size=(3, 68, 3))
    lifts[2, :10] += 20.0                       # one view wrong on the first ten
    lifts[1:, 60:] = np.nan                     # two views do not see the last eight
    fused = fuse_views(lifts, radius=5.0)
    assert np.linalg.norm(fused.points[10:60] - truth[10:60], axis=1).max() < 1.0
    assert np.linalg.norm(fused.points[:10] - truth[:10], axis=1).max() < 1.0
    assert np.all(fused.confidence[:10] < fused.confidence[10:60].min())
    assert np.all(fused.confidence[60:] < 0.5) and np.all(fused.seen[60:] == 1)


def _skin_and_lash():
    """A 2 x 2 sheet of skin at z = 0 (a 10 x 10 grid) and, 0.1 in front of it, a
    small open strip (a lash): two pieces, the strip not skin."""
    g = np.linspace(-1.0, 1.0, 11)
    V = np.array([[x, y, 0.0] for y in g for x in g])
    i = np.arange(10)[:, None] * 11 + np.arange(10)[None, :]
    q = np.stack([i, i + 1, i + 12, i + 11], axis=-1).reshape(-1, 4)
    T = np.r_[q[:, [0, 1, 2]], q[:, [0, 2, 3]]]
    strip = np.array([[-.2, -.05, .1], [.2, -.05, .1], [.2, .05, .1], [-.2, .05, .1]])
    return np.r_[V, strip], np.r_[T, len(V) + np.array([[0, 1, 2], [0, 2, 3]])], len(T)


def test_a_lift_looks_through_an_open_piece_in_front_of_the_skin():
    V, T, n_skin = _skin_and_lash()
    skin = skin_triangles(V, T)
    assert skin is not None and np.array_equal(skin, np.arange(n_skin))
    scene = SceneArrays.of(V, T, skin=skin)
    view = render_view(scene, Camera(np.eye(3), np.zeros(3), 0.02, (128, 128)))
    centre = [[63.5, 63.5]]
    point, tri = view.lift(scene, centre)
    assert tri[0] < n_skin and abs(point[0, 2]) < 1e-9      # on the skin, not the strip
    everything = SceneArrays.of(V, T)                        # without the rule: the strip
    point, tri = render_view(everything, view.camera).lift(everything, centre)
    assert tri[0] >= n_skin and abs(point[0, 2] - 0.1) < 1e-9


def test_a_point_just_off_the_edge_lifts_from_the_nearest_covered_pixel():
    V = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0.]])
    scene = SceneArrays.of(V, [[0, 1, 2], [0, 2, 3]])
    view = render_view(scene, Camera(np.eye(3), np.zeros(3), 0.05, (64, 64)))
    # the square covers columns 12..51; 3 pixels right of it, then 10
    near, far = [[54.0, 31.5]], [[61.0, 31.5]]
    assert np.isnan(view.lift(scene, near)[0]).all()
    point, tri = view.lift(scene, near, reach=4.0)
    assert tri[0] >= 0 and abs(point[0, 0] - 1.0) < 0.05
    assert np.isnan(view.lift(scene, far, reach=4.0)[0]).all()


def test_points_on_surface_turned_from_the_front_are_less_sure(sample):
    """The grazing rule: no confident point where the surface meets the frontal view
    at more than 72 degrees (|cos| < 0.3)."""
    folder, scan, found = sample
    from facewrap.geometry.normals import vertex_normals
    lm = found.landmarks
    normals = vertex_normals(scan.vertices, scan.triangles, "angle")
    corners = normals[scan.triangles[lm.triangle]]
    n = np.einsum("kj,kjd->kd", lm.barycentric, corners)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    front = np.array(found.views[0]["direction"])
    facing = np.abs(n @ front)
    assert np.all(found.low_confidence[facing < 0.3])
    assert np.any(facing >= 0.3) and not found.low_confidence[facing >= 0.9].all()


def test_without_the_extra_the_command_names_it(tmp_path):
    code = ("import sys; sys.modules['dlib'] = None\n"
            "from facewrap.cli import main\n"
            f"sys.exit(main(['landmarks', {str(tmp_path / 'x.obj')!r}, '-o', "
            f"{str(tmp_path / 'x.json')!r}]))")
    (tmp_path / "x.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env)
    assert run.returncode == 2
    assert run.stderr.count("\n") == 1 and "facewrap[landmarks]" in run.stderr
    assert not (tmp_path / "x.json").exists()


def _james(data_dir):
    """Landmarks detected on the textured james scan, and their errors (mm)."""
    path = data_dir / "scans" / "james" / "james.obj"
    scan = read_mesh(path)
    found = detect_landmarks(scan, mesh_texture(path, scan), source=path)
    manual = read_ljson(data_dir / "scans" / "james" / "james.ljson").points
    return found, np.linalg.norm(found.positions - manual, axis=1)


@needs_data
@pytest.mark.shared_data
def test_james_landmarks_against_the_manual_ones(data_dir):
    found, err = _james(data_dir)
    ok = ~found.low_confidence
    # measured (bench_detection): eyes 3.0 mm, mouth 2.0 mm, confident points
    # 2.6 mm mean (47 of them), no confident point more than 8 mm off
    assert err[GROUPS["eyes"]].mean() < 4.0 and err[GROUPS["mouth"]].mean() < 3.0
    assert err[ok].mean() < 3.5 and ok.sum() >= 40
    assert not np.any((err > 8.0) & ok)


@needs_data
@pytest.mark.shared_data
@pytest.mark.xfail(reason="issue 18's 2.5 mm mean over all 68: dlib's jaw contour on our "
                          "renders is 11 mm off james's (4.75 mm mean over all, 2.6 mm "
                          "over the confident points)", strict=True)
def test_james_meets_the_issue_18_acceptance(data_dir):
    found, err = _james(data_dir)
    assert err.mean() < 2.5 and not np.any((err > 8.0) & ~found.low_confidence)


@needs_data
@pytest.mark.shared_data
def test_james_turned_upside_down_in_metres_gives_the_same_landmarks(data_dir):
    path = data_dir / "scans" / "james" / "james.obj"
    scan = read_mesh(path)
    image = mesh_texture(path, scan)
    R = np.diag([-1.0, 1.0, -1.0])                       # 180 degrees about y
    dist, ok = _moved_back(scan, image, detect_landmarks(scan, image), R, 0.001)
    # issue 18: within 0.5 mm after undoing the transform (measured 0.27 mm)
    assert ok.sum() >= 40
    assert dist[ok].mean() < 0.5


@needs_data
@pytest.mark.shared_data
@pytest.mark.parametrize("shape", [None, "identity000"])
def test_ict_eyes_are_found_on_the_skin_and_far_points_are_flagged(ict_folder, shape):
    """ICT's lashes and eye occlusion shells lie in front of the eyelids: lifts look
    through them (eyes were 7.5 mm off on the template before, lifted onto them);
    the grazing jaw and the shaded brows are flagged (issue 18: no unflagged point
    more than 8 mm off)."""
    from facewrap.datasets import ICTFaceKit
    kit = ICTFaceKit(ict_folder)
    mesh = kit.neutral if shape is None else kit.neutral.with_vertices(kit.shape(shape))
    found = detect_landmarks(mesh)
    err = 10.0 * np.linalg.norm(found.positions - kit.landmarks.positions(mesh), axis=1)
    # measured: eyes 2.8 mm, mouth 1.9-2.0 mm, the 32 confident points 2.3-2.4 mm
    ok = ~found.low_confidence
    assert err[GROUPS["eyes"]].mean() < 4.0 and err[GROUPS["mouth"]].mean() < 3.0
    assert err[ok].mean() < 3.0 and ok.sum() >= 25
    assert not np.any((err > 8.0) & ok)


def test_a_lash_strip_in_front_of_the_eye_is_looked_through(sample):
    """The sample scan, shaded, with a small open strip (a lash) 2 mm in front of its
    right upper lid: no landmark lands on the strip, the eye stays where it was."""
    folder, scan, found = sample
    V, T = scan.vertices, scan.triangles
    plain = detect_landmarks((V, T))
    front = np.array(plain.views[0]["direction"])
    lid = plain.positions[[36, 37, 38, 39]]
    along = lid[3] - lid[0]
    up = np.cross(front, along)
    up *= 3.0 / np.linalg.norm(up)
    a, b = lid[0] - 0.15 * along + 2.0 * front, lid[3] + 0.15 * along + 2.0 * front
    strip = np.array([a - up, b - up, b + up, a + up])
    quad = len(V) + np.array([[0, 1, 2], [0, 2, 3]])
    lashed = detect_landmarks((np.r_[V, strip], np.r_[T, quad]))
    assert np.all(lashed.landmarks.triangle < len(T))
    moved = np.linalg.norm(lashed.positions[36:42] - plain.positions[36:42], axis=1)
    assert moved.max() < 3.0     # mm (the strip changes the picture a little)


def test_open_eye_holes_still_frame_the_face(sample):
    """A face region without its eyeballs (ICT's face-region template and the scans
    made from it) shows the background through the eye openings: the lid margins'
    points lift from the nearest lid pixel, so the face frame is found (it was not:
    "no face found" on two of four held-out ICT scans)."""
    from facewrap.sample import make_template
    tpl = make_template()
    face, _ = tpl.mesh.submesh(tpl.mesh.face_groups == 0)         # no eyeballs
    found = detect_landmarks(face)
    truth = face.vertices[tpl.landmarks.vertex]
    err = np.linalg.norm(found.positions - truth, axis=1)
    assert err[GROUPS["eyes"]].mean() < 8.0 and err[GROUPS["nose"]].mean() < 8.0


def test_detected_landmarks_weigh_less_than_clicked_ones(sample):
    """A wrap from detected landmarks trusts the surface over their millimetres of
    offset: on the sample the fit is nearer the truth with the detected weighting
    (:data:`~facewrap.detection.for_wrap.DETECTED_LANDMARK_SCALE`, no pull) than at
    full weight."""
    from facewrap.detection.for_wrap import confident_landmarks, detected_landmark_settings
    from facewrap.sample import make_scan, make_template
    from facewrap.wrapping import WrapSettings, wrap
    tpl = make_template()
    scan = make_scan(tpl, seed=1, weights={"smile": 0.6})
    tl, sl = confident_landmarks(tpl.landmarks, detect_landmarks(scan.mesh, scan.texture))
    ok = np.isfinite(scan.ground_truth).all(axis=1)
    errors = {}
    for name, settings in (("full", WrapSettings(model="hybrid")),
                           ("detected", detected_landmark_settings(
                               WrapSettings(model="hybrid")))):
        r = wrap(tpl.mesh, scan.mesh, tl, sl, settings, blendshapes=tpl.blendshapes)
        errors[name] = np.linalg.norm(r.vertices - scan.ground_truth, axis=1)[ok].mean()
    # measured: 3.99 mm at full weight, 0.7-0.9 mm with the detected weighting
    assert errors["detected"] < 0.5 * errors["full"], errors
