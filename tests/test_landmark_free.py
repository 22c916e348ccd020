"""Wraps with no scan landmark file (issue 18): job files, manifests, ``facewrap run``,
``batch`` and ``track`` detect them, and the report draws them apart from given ones.

The tests that detect need the optional extra ``facewrap[landmarks]`` (dlib) and
skip without it; the others build what a detection leaves in a run report by hand.
"""

from __future__ import annotations

import base64
import csv
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest

from facewrap.batch import read_manifest
from facewrap.jobs import WrapJob, load_job, run_wrap_job
from facewrap.landmarks import Landmarks, snap_to_surface
from facewrap.io import read_mesh, write_mesh
from facewrap.io.landmarks import read_landmarks
from facewrap.report.landmark_figure import landmark_picture
from facewrap.report.page import build_report_page
from facewrap.report.viewer_data import FLAGGED_COLOR, POINT_COLORS, PointSet, viewer_data
from facewrap.sample import make_scan, make_template, write_sample
from facewrap.wrapping import WrapSettings
from conftest import facewrap
from test_report_html import CHROMIUM, Browser, needs_chromium
from test_report_run_page import page_data, table_rows


def overview(path: Path) -> dict:
    """The page's Overview table as ``{key: value}``."""
    return table_rows(path)["Overview"]


def pictures(path: Path) -> dict:
    """The page's pictures, ``{caption: (H, W, 3) uint8}``."""
    from PIL import Image
    found = re.findall(r'<img src="data:image/png;base64,([^"]+)" alt="([^"]*)"',
                       path.read_text(encoding="utf-8"))
    return {alt: np.asarray(Image.open(io.BytesIO(base64.b64decode(b))).convert("RGB"))
            for b, alt in found}


# ---------------------------------------------------------------------------------
# The field is optional everywhere (no detection needed to check that)
# ---------------------------------------------------------------------------------
def test_a_wrap_job_may_leave_the_scan_landmarks_out():
    job = WrapJob("t.obj", "s.obj", output="o.obj")
    assert job.scan_landmarks is None and job.output == "o.obj"
    with pytest.raises(TypeError):   # an old positional call fails loudly, never shifts
        WrapJob("t.obj", "s.obj", "s.txt", "o.obj")
    with pytest.raises(TypeError, match="output"):
        WrapJob("t.obj", "s.obj")


def test_job_files_and_manifests_without_scan_landmarks(tmp_path):
    (tmp_path / "job.toml").write_text('[inputs]\ntemplate = "t.obj"\nscan = "s.obj"\n'
                                       '[outputs]\noutput = "out/o.obj"\n')
    job, _ = load_job(tmp_path / "job.toml")
    assert job.scan_landmarks is None and job.scan == str(tmp_path / "s.obj")
    (tmp_path / "shared.toml").write_text('[inputs]\ntemplate = "t.obj"\n')
    (tmp_path / "jobs.csv").write_text("scan,output,scan_landmarks\n"
                                       "a.obj,out/a.obj,\nb.obj,out/b.obj,b.txt\n")
    rows = read_manifest(tmp_path / "jobs.csv", tmp_path / "shared.toml")
    assert [r.job.scan_landmarks for r in rows] == [None, str(tmp_path / "b.txt")]
    facewrap("run", "--write-template", tmp_path / "t.toml")
    text = " ".join(w for w in (tmp_path / "t.toml").read_text().split() if w != "#")
    assert "left out (None), the 68 iBUG points are detected on the scan" in text


# ---------------------------------------------------------------------------------
# The viewer's markers and the pictures
# ---------------------------------------------------------------------------------
def test_point_sets_carry_their_marker_and_are_checked():
    P = np.zeros((3, 3))
    data = viewer_data({}, points={"landmarks: scan": P,
                                   "landmarks: scan (detected)": PointSet(P, "diamond"),
                                   "flagged": PointSet(P[:1], "ring", FLAGGED_COLOR)})
    assert [(p["marker"], p["count"]) for p in data["points"]] == [
        ("ball", 3), ("diamond", 3), ("ring", 1)]
    # a detected set takes its set's colour (the scan's), a flagged one its own
    assert data["points"][1]["color"] == data["points"][0]["color"] == POINT_COLORS["scan"]
    assert data["points"][2]["color"] == FLAGGED_COLOR
    with pytest.raises(ValueError, match="marker must be one of"):
        viewer_data({}, points={"x": PointSet(P, "star")})
    with pytest.raises(ValueError, match="color must be"):
        viewer_data({}, points={"x": PointSet(P, "ring", "red")})


def _colour_near(image, xy, colour, radius=7) -> int:
    """How many pixels around ``xy`` have ``colour`` (within 40 per channel)."""
    x, y = xy
    rgb = np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)])
    patch = image[y - radius:y + radius + 1, x - radius:x + radius + 1].astype(int)
    return int((np.abs(patch - rgb).max(axis=2) < 40).sum())


def test_the_picture_marks_what_the_camera_sees_and_leaves_hidden_points_out():
    # two squares, the front one (z = 1) covering the left half of the back one (z = 0)
    V = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0],
                  [-1, -1, 1], [0, -1, 1], [0, 1, 1], [-1, 1, 1.]])
    T = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    points = [[-0.5, 0.0, 0.0],    # on the back square, behind the front one: hidden
              [0.5, 0.0, 0.0],     # on the back square, in the open: a diamond
              [-0.5, 0.5, 1.0]]    # on the front square, flagged: a ring
    img = landmark_picture((V, T), points, [False, False, True], size=(200, 200))
    # the squares span the picture (6 % margin): x = -1..1 -> 12..188 px
    px = lambda x, y: (int(round(100 + 88 * x)), int(round(100 - 88 * y)))  # noqa: E731
    assert _colour_near(img, px(0.5, 0.0), POINT_COLORS["scan"]) > 20
    assert _colour_near(img, px(-0.5, 0.0), POINT_COLORS["scan"]) == 0
    assert _colour_near(img, px(-0.5, 0.5), FLAGGED_COLOR) > 10
    with pytest.raises(ValueError, match="one entry per point"):
        landmark_picture((V, T), points, [True])


# ---------------------------------------------------------------------------------
# The report of a run whose scan landmarks were detected, built by hand
# ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def detected_run(tmp_path_factory) -> dict:
    """A quick wrap run, its report rewritten as a detection leaves it: no scan
    landmark file, the sample's true scan landmarks as the "detected" ones (surface
    points), the jaw flagged low-confidence."""
    d = tmp_path_factory.mktemp("run")
    tpl = make_template(24)
    paths = write_sample(d / "in", tpl, make_scan(tpl, resolution=32, texture_size=32))
    job = WrapJob(template=str(paths["template"]), scan=str(paths["scan"]),
                  template_landmarks=str(paths["template_landmarks"]),
                  scan_landmarks=str(paths["scan_landmarks"]),
                  output=str(d / "wrapped.obj"), report=str(d / "run.json"))
    run_wrap_job(job, WrapSettings(model="rbf"))
    scan = read_mesh(paths["scan"])
    points = read_landmarks(paths["scan_landmarks"], kind="points")
    on, _ = snap_to_surface(points, scan.vertices, scan.triangles)
    names = list(tpl.landmarks.names)
    report = json.loads((d / "run.json").read_text())
    del report["job"]["scan_landmarks"]
    report["scan_landmarks_source"] = "detected"
    report["detected_landmarks"] = {"scan": {
        "names": names, "triangles": on.triangle.tolist(),
        "barycentric": on.barycentric.tolist(),
        "positions": on.positions(scan.vertices, scan.triangles).tolist(),
        "confidence": dict.fromkeys(names, 0.9), "low_confidence": names[:17],
        "views": [{"found": True}] * 3, "eye_distance": 60.0,
        "timings": {"total": 1.25}}}
    (d / "detected.json").write_text(json.dumps(report))
    return {"dir": d, "report": d / "detected.json", "scan": scan,
            "truth": on.positions(scan.vertices, scan.triangles)}


def test_the_page_draws_detected_landmarks_apart_and_says_so(detected_run, tmp_path):
    page = build_report_page(detected_run["report"], tmp_path / "html")
    data = page_data(page)
    sets = {p["name"]: p for p in data["points"]}
    assert list(sets) == ["landmarks: template", "landmarks: scan (detected)",
                          "landmarks: scan (low confidence)", "landmarks: result"]
    assert sets["landmarks: scan (detected)"]["marker"] == "diamond"
    low = sets["landmarks: scan (low confidence)"]
    assert low["marker"] == "ring" and low["color"] == FLAGGED_COLOR
    assert low["count"] == 17 and sets["landmarks: scan (detected)"]["count"] == 51
    # the flagged ones are where the detection put the jaw
    shown = np.frombuffer(base64.b64decode(low["positions"]), "<f4").reshape(-1, 3)
    assert np.abs(shown - detected_run["truth"][:17]).max() < 1e-3
    # the wrap paired only the confident ones: the template's and the result's too
    assert sets["landmarks: template"]["count"] == sets["landmarks: result"]["count"] == 51
    assert overview(page)["scan landmarks"] == "detected (51 confident of 68)"
    detected = table_rows(page)["Landmarks detected"]
    assert detected["scan › confident"] == "51 of 68"
    assert detected["scan › low confidence (left out)"].startswith("jaw_0, jaw_1, ")
    assert detected["scan › eye distance"] == "60.00 mm"
    text = page.read_text()
    assert '"triangles"' not in text.split('id="facewrap-data"')[0]  # no raw dump
    caption, = [c for c in pictures(page) if c.startswith("scan landmarks:")]
    assert "detected (51 confident of 68)" in caption
    img = pictures(page)[caption]
    assert _count(img, POINT_COLORS["scan"]) > 100 and _count(img, FLAGGED_COLOR) > 50


def _count(image, colour) -> int:
    rgb = np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)])
    return int((np.abs(image.astype(int) - rgb).max(axis=2) < 40).sum())


def test_template_landmarks_the_run_detected_are_drawn_too(detected_run, tmp_path):
    # a run with no template landmark file and no profile: they were detected too
    report = json.loads(detected_run["report"].read_text())
    ids = read_landmarks(report["job"].pop("template_landmarks"), kind="auto").vertex
    template = read_mesh(report["job"]["template"])
    T = template.triangles
    tri = np.array([int(np.flatnonzero((T == v).any(axis=1))[0]) for v in ids])
    bary = (T[tri] == ids[:, None]).astype(float)     # the vertex's corner
    names = report["detected_landmarks"]["scan"]["names"]
    report["detected_landmarks"]["template"] = {
        "names": names, "triangles": tri.tolist(), "barycentric": bary.tolist(),
        "low_confidence": []}
    path = detected_run["dir"] / "both.json"
    path.write_text(json.dumps(report))
    sets = {p["name"]: p for p in page_data(build_report_page(path, tmp_path))["points"]}
    assert sets["landmarks: template"]["count"] == 51
    shown = np.frombuffer(base64.b64decode(sets["landmarks: result"]["positions"]),
                          "<f4").reshape(-1, 3)
    result = read_mesh(detected_run["dir"] / "wrapped.obj")
    np.testing.assert_allclose(shown, result.vertices[ids[17:]], atol=1e-3)


def test_a_page_of_a_run_with_a_landmark_file_is_as_before(detected_run, tmp_path):
    page = build_report_page(detected_run["dir"] / "run.json", tmp_path / "html")
    names = [p["name"] for p in page_data(page)["points"]]
    assert names == ["landmarks: template", "landmarks: scan", "landmarks: result"]
    assert all(p["marker"] == "ball" for p in page_data(page)["points"])
    assert overview(page)["scan landmarks"] == "file scan_landmarks.txt"
    assert not [c for c in pictures(page) if c.startswith("scan landmarks:")]


def test_a_malformed_detection_in_a_report_is_one_error(detected_run, tmp_path, capsys):
    report = json.loads(detected_run["report"].read_text())
    report["detected_landmarks"]["scan"]["triangles"] = "three"
    bad = detected_run["dir"] / "bad.json"
    bad.write_text(json.dumps(report))
    assert facewrap("report", bad, "-o", tmp_path / "html") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "detected_landmarks" in err[0] and "bad.json" in err[0]
    assert not (tmp_path / "html").exists()


@needs_chromium
def test_the_viewer_draws_diamonds_and_hollow_rings(detected_run, tmp_path):
    page = build_report_page(detected_run["report"], tmp_path / "html")
    browser = Browser(CHROMIUM)
    try:
        browser.open(page.as_uri(), "window.facewrapViewer && window.facewrapViewer.ready")
        state = browser.evaluate("window.facewrapViewer")
    finally:
        browser.close()
    assert browser.errors == [] and state["error"] is None
    styles = {s["name"]: s for s in state["pointStyles"]}
    assert styles["landmarks: scan (detected)"]["vertices"] == 6      # an octahedron
    assert styles["landmarks: result"]["vertices"] == 12              # an icosahedron
    ring = styles["landmarks: scan (low confidence)"]
    assert ring["wireframe"] and ring["color"] == FLAGGED_COLOR
    assert not styles["landmarks: scan (detected)"]["wireframe"]


# ---------------------------------------------------------------------------------
# With detection (the optional extra)
# ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sample(tmp_path_factory):
    pytest.importorskip("dlib", reason="the optional extra facewrap[landmarks] is absent")
    out = tmp_path_factory.mktemp("sample")
    assert facewrap("sample", out) == 0
    return out


@pytest.mark.slow
def test_run_and_batch_detect_when_the_job_has_no_scan_landmarks(sample, tmp_path,
                                                                 capsys):
    (tmp_path / "job.toml").write_text(
        f'[inputs]\ntemplate = "{sample / "template.obj"}"\n'
        f'template_landmarks = "{sample / "template_landmarks.txt"}"\n'
        f'scan = "{sample / "scan.obj"}"\n[outputs]\noutput = "out/o.obj"\n'
        'report = "out/run.json"\n[wrap]\nmodel = "rbf"\n')
    assert facewrap("run", tmp_path / "job.toml") == 0
    said = capsys.readouterr().out
    assert "scan landmarks detected:" in said and "wrote" in said
    report = json.loads((tmp_path / "out" / "run.json").read_text())
    assert report["scan_landmarks_source"] == "detected"
    found = report["detected_landmarks"]["scan"]
    assert len(found["names"]) == len(found["triangles"]) == 68
    # detected landmarks weigh less than clicked ones, and are not pulled to
    from facewrap.detection.for_wrap import DETECTED_LANDMARK_SCALE
    assert report["settings"]["landmark_scale"] == pytest.approx(DETECTED_LANDMARK_SCALE)
    assert report["settings"]["landmark_pull"] is False
    page = build_report_page(tmp_path / "out" / "run.json", tmp_path / "html")
    sets = {p["name"]: p["count"] for p in page_data(page)["points"]}
    low = len(found["low_confidence"])
    assert sets["landmarks: scan (detected)"] == 68 - low
    assert sets.get("landmarks: scan (low confidence)", 0) == low
    assert overview(page)["scan landmarks"] == f"detected ({68 - low} confident of 68)"
    # a batch of one such job: no scan_landmarks column at all
    (tmp_path / "jobs.csv").write_text(f"scan,output\n{sample / 'scan.obj'},b/o.obj\n")
    assert facewrap("batch", tmp_path / "jobs.csv", "--job", tmp_path / "job.toml",
                    "-q") == 0
    with open(tmp_path / "jobs.summary.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["status"], r["scan_landmarks"]) for r in rows] == [("done", "detected")]
    assert json.loads((tmp_path / "b" / "o.obj.done.json").read_text())[
        "scan_landmarks"] == "detected"
    # a re-run skips the finished job and still says how its landmarks came
    assert facewrap("batch", tmp_path / "jobs.csv", "--job", tmp_path / "job.toml",
                    "-q") == 0
    with open(tmp_path / "jobs.summary.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["status"], r["scan_landmarks"]) for r in rows] == [("skipped", "detected")]


@pytest.mark.slow
def test_track_detects_the_first_frame_and_later_frames_follow(sample, tmp_path, capsys):
    from facewrap.sample import make_sequence
    tpl = make_template(resolution=32)
    seq = make_sequence(tpl, frames=3, peak={"jaw_open": 0.4}, resolution=48)
    paths = write_sample(tmp_path / "in", tpl, seq[0])
    frames = tmp_path / "scans"
    frames.mkdir()
    for i, s in enumerate(seq):
        write_mesh(frames / f"take_{i}.obj", s.mesh)
    out = tmp_path / "out"
    assert facewrap("track", paths["template"], frames, "-o", out,
                    "--template-landmarks", paths["template_landmarks"]) == 0
    said = capsys.readouterr().out
    assert re.search(r"frame 0 \(.*take_0\.obj\): 68 landmarks detected, \d+ "
                     r"low-confidence left out; later frames follow the fit", said)
    report = json.loads((out / "track.json").read_text())
    assert report["scan_landmarks_source"] == "detected"
    assert list(report["detected_landmarks"]) == ["frame 0"]
    assert [f["landmarks_given"] for f in report["frames"]] == [True, False, False]
    # the sample's detection is rough, but the fit stays on the scan
    assert all(f["fit_mean"] < 0.5 for f in report["frames"])
    assert len(sorted(out.glob("frame_*.obj"))) == 3


@pytest.mark.slow
def test_track_of_scans_with_no_face_is_one_error(sample, tmp_path, capsys):
    from scipy.spatial import ConvexHull
    from facewrap.mesh import Mesh
    V = np.random.default_rng(3).normal(size=(600, 3))
    V = 90.0 * V / np.linalg.norm(V, axis=1, keepdims=True)
    write_mesh(tmp_path / "ball.obj", Mesh(V, ConvexHull(V).simplices))
    rc = facewrap("track", sample / "template.obj", tmp_path / "ball.obj", "-o",
                  tmp_path / "out", "--template-landmarks",
                  sample / "template_landmarks.txt")
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("facewrap: error: ")
    assert "ball.obj" in err[0] and "no face" in err[0]
    assert not (tmp_path / "out").exists()
