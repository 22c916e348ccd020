"""4D tracking on a synthetic expression ramp (ground truth known per frame)."""

import csv
import json

import numpy as np
import pytest

from facewrap.geometry import ClosestPointTree
from facewrap.wrapping.track import track
from facewrap.wrapping import wrap

PEAK = {"jaw_open": 0.8, "blink": 1.0, "smile": 0.3}


@pytest.fixture(scope="module")
def ramp():
    from facewrap.sample import make_sequence, make_template
    template = make_template(resolution=32)
    return template, make_sequence(template, frames=10, peak=PEAK, resolution=48)


def seen_error(template, scan, vertices):
    face = template.parts["face"]
    tree = ClosestPointTree(scan.mesh.vertices, scan.mesh.triangles)
    on = tree.query(np.nan_to_num(scan.ground_truth[face]))
    seen = face[~tree.boundary_triangles[on.triangles] & (on.distances < 1.0)]
    return np.linalg.norm(vertices[seen] - scan.ground_truth[seen], axis=1)


@pytest.mark.slow
def test_track_recovers_every_frame_within_single_frame_accuracy(ramp):
    template, seq = ramp
    result = track(template.mesh, [s.mesh for s in seq], template.landmarks,
                   [s.landmarks for s in seq], blendshapes=template.blendshapes)
    assert len(result.frames) == 10 and result.landmarks_given.all()
    # single-frame accuracy: independent wraps of the first and last frames
    single = [seen_error(template, seq[i], wrap(template.mesh, seq[i].mesh,
                                                template.landmarks, seq[i].landmarks,
                                                blendshapes=template.blendshapes).vertices
                         ).mean() for i in (0, 9)]
    bound = 1.15 * max(single)
    for scan, frame in zip(seq, result.frames):
        assert seen_error(template, scan, frame.vertices).mean() < bound
    # the expression ramp is recovered: weights rise with the frame number
    names = result.shape_names
    jaw = result.weights[:, names.index("jaw_open")]
    assert np.all(np.diff(jaw) > 0)
    assert jaw[-1] == pytest.approx(PEAK["jaw_open"], abs=0.1)
    assert result.weights[-1, names.index("blink")] == pytest.approx(1.0, abs=0.15)


def test_track_cli_writes_sequence_weights_and_report(ramp, tmp_path):
    from facewrap.cli import main
    from facewrap.io import read_mesh, write_mesh
    from facewrap.sample import write_sample
    template, seq = ramp
    paths = write_sample(tmp_path / "in", template, seq[0])
    scans = tmp_path / "scans"
    scans.mkdir()
    for i, s in enumerate(seq[:3]):
        write_mesh(scans / f"take_{i:02d}.obj", s.mesh)
    out = tmp_path / "out"
    rc = main(["track", str(paths["template"]), str(scans), "-o", str(out),
               "--template-landmarks", str(paths["template_landmarks"]),
               "--scan-landmarks", str(paths["scan_landmarks"]),
               "--blendshapes", str(paths["blendshapes/blink"].parent), "-q"])
    assert rc == 0
    frames = sorted(out.glob("frame_*.obj"))
    assert [f.name for f in frames] == ["frame_0000.obj", "frame_0001.obj", "frame_0002.obj"]
    assert read_mesh(frames[-1]).n_vertices == template.mesh.n_vertices
    rows = list(csv.reader((out / "weights.csv").open()))
    assert rows[0][0] == "frame" and set(rows[0][1:]) == set(template.blendshapes)
    assert len(rows) == 4
    report = json.loads((out / "track.json").read_text())
    assert [f["landmarks_given"] for f in report["frames"]] == [True, False, False]
    assert all(f["fit_mean"] < 1.0 for f in report["frames"])


def test_track_needs_first_frame_landmarks(ramp):
    template, seq = ramp
    with pytest.raises(ValueError, match="first frame needs landmarks"):
        track(template.mesh, [seq[0].mesh], template.landmarks, [None])
    with pytest.raises(ValueError, match="landmark entries"):
        track(template.mesh, [seq[0].mesh, seq[1].mesh], template.landmarks,
              [seq[0].landmarks])


@pytest.mark.slow
def test_track_without_later_landmarks_keeps_up_with_the_expression(ramp):
    """Landmarks on frame 0 only: the carried-over landmarks are predicted at
    their last velocity, so the fit does not lag behind the ramp."""
    template, seq = ramp
    result = track(template.mesh, [s.mesh for s in seq], template.landmarks,
                   [seq[0].landmarks] + [None] * (len(seq) - 1),
                   blendshapes=template.blendshapes)
    assert not result.landmarks_given[1:].any()
    names = result.shape_names
    jaw = result.weights[:, names.index("jaw_open")]
    assert jaw[-1] == pytest.approx(PEAK["jaw_open"], abs=0.1)
    assert np.all(np.diff(jaw) > 0)
    for scan, frame in zip(seq, result.frames):
        assert seen_error(template, scan, frame.vertices).mean() < 1.0
    # predicted landmarks guide the fit but never pull it (first frame: given ones)
    assert "landmark_pull" in result.frames[0].metrics
    assert not any("landmark_pull" in f.metrics for f in result.frames[1:])


@pytest.mark.slow
def test_track_cli_prints_and_records_each_frames_input_warnings(ramp, tmp_path, capsys):
    from facewrap.cli import main
    from facewrap.io import write_mesh
    from facewrap.mesh import Mesh
    from facewrap.sample import write_sample
    template, seq = ramp
    paths = write_sample(tmp_path / "in", template, seq[0])
    scans = []
    for i, s in enumerate(seq[:3]):
        mesh = s.mesh
        if i == 1:  # every face twice: legal, odd, fixed for the fit with a warning
            mesh = Mesh(mesh.vertices, np.vstack([mesh.triangles, mesh.triangles]))
        scans.append(tmp_path / f"take_{i}.obj")
        write_mesh(scans[-1], mesh)
    out = tmp_path / "out"
    capsys.readouterr()
    rc = main(["track", str(paths["template"]), *map(str, scans), "-o", str(out),
               "--template-landmarks", str(paths["template_landmarks"]),
               "--scan-landmarks", str(paths["scan_landmarks"]), "--model", "graph",
               "--output-frame", "template", "-q"])
    assert rc == 0
    warned = [ln for ln in capsys.readouterr().err.splitlines()
              if ln.startswith("facewrap: warning: ")]
    assert warned and all(ln.startswith(f"facewrap: warning: frame 1 ({scans[1]}): ")
                          for ln in warned)
    assert any("duplicated faces" in ln for ln in warned)
    report = json.loads((out / "track.json").read_text())
    assert report["warnings"] == [ln[len("facewrap: warning: "):] for ln in warned]
    assert [bool(f["warnings"]) for f in report["frames"]] == [False, True, False]
    assert report["output_frame"] == "template"


def test_track_outputs_in_the_template_frame_undo_the_first_similarity(ramp, tmp_path):
    from facewrap.io import read_mesh
    from facewrap.wrapping.track import write_track_outputs
    template, seq = ramp
    result = track(template.mesh, [s.mesh for s in seq[:2]], template.landmarks,
                   [seq[0].landmarks, None], model_settings("rigid"))
    paths = write_track_outputs(tmp_path / "t", result, output_frame="template")
    back = result.frames[0].transform.inverse()
    size = template.mesh.scale()
    for path, frame in zip(paths["meshes"], result.frames):
        assert np.abs(read_mesh(path).vertices - back.apply(frame.vertices)).max() < 1e-6 * size
    with pytest.raises(ValueError, match="output_frame"):
        write_track_outputs(tmp_path / "u", result, output_frame="world")


def model_settings(model):
    from facewrap.wrapping import WrapSettings
    return WrapSettings(model=model)


def test_track_with_a_closed_form_model_fits_every_frame():
    """rbf and rigid have no ICP schedule: later frames are fitted in closed form too
    (this used to fail on the second frame)."""
    from facewrap.sample import make_sequence, make_template
    from facewrap.wrapping import WrapSettings, track
    from facewrap.wrapping.track import tracking_schedule
    assert tracking_schedule("rbf") is None and tracking_schedule("graph")
    tpl = make_template(24)
    seq = make_sequence(tpl, frames=3, resolution=30)
    meshes = [f.mesh for f in seq]
    result = track(tpl.mesh, meshes, tpl.landmarks, [seq[0].landmarks, None, None],
                   WrapSettings(model="rbf"))
    assert len(result.frames) == 3


def test_first_settings_are_the_first_frames_only(ramp):
    """Detected first-frame landmarks weigh less; the frames after carry the fit's
    landmarks over at the sequence's own weight."""
    from facewrap.wrapping import WrapSettings
    from facewrap.wrapping.track import PROPAGATED_LANDMARKS
    template, seq = ramp
    first = WrapSettings(model="hybrid", landmark_scale=0.03, landmark_pull=False)
    result = track(template.mesh, [s.mesh for s in seq[:3]], template.landmarks,
                   [seq[0].landmarks, None, None], WrapSettings(model="hybrid"),
                   blendshapes=template.blendshapes, first_settings=first)
    scales = [f.settings.landmark_scale for f in result.frames]
    assert scales[0] == pytest.approx(0.03) and not result.frames[0].settings.landmark_pull
    assert scales[1:] == pytest.approx([PROPAGATED_LANDMARKS] * 2)


def test_a_frame_that_is_not_the_sequence_is_warned_about(ramp):
    # frames without landmarks of their own follow the fit: a sphere put in as
    # frame 2 was fitted without a word
    import trimesh
    from facewrap.mesh import Mesh
    from facewrap.wrapping import WrapSettings
    template, seq = ramp
    V = seq[0].mesh.vertices
    ball = trimesh.creation.icosphere(3)
    sphere = Mesh(ball.vertices * np.linalg.norm(np.ptp(V, axis=0)) / 3 + V.mean(0),
                  ball.faces)
    res = track(template.mesh, [seq[0].mesh, seq[1].mesh, sphere], template.landmarks,
                [seq[0].landmarks, None, None], WrapSettings(model="rbf"))
    notes = [[n for n in f.warnings if "no landmarks of its own" in n] for f in res.frames]
    assert notes[:2] == [[], []] and len(notes[2]) == 1, notes
    assert "% of the head's size" in notes[2][0]
