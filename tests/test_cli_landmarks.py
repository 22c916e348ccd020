"""``facewrap landmarks`` and ``facewrap wrap`` without landmark files, as a user runs
them: exit codes, one-line errors, files that read back, inputs untouched."""

from __future__ import annotations

import json

import numpy as np
import pytest

from facewrap.cli import main
from facewrap.io.landmarks import read_landmark_details, read_landmarks_json
from facewrap.landmarks import IBUG68_NAMES

from conftest import needs_data

pytestmark = pytest.mark.slow
pytest.importorskip("dlib", reason="the optional extra facewrap[landmarks] is absent")


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("sample")
    assert main(["sample", str(out)]) == 0
    return out


def test_landmarks_of_the_sample_scan_read_back(folder, tmp_path, capsys):
    out = tmp_path / "lm.json"
    before = (folder / "scan.obj").read_bytes()
    assert main(["landmarks", str(folder / "scan.obj"), "-o", str(out)]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    assert line.startswith(f"wrote {out}: 68 landmarks") and " mm" in line
    lm = read_landmarks_json(out)
    details = read_landmark_details(out)
    assert lm.names == IBUG68_NAMES and len(lm.triangle) == 68 and lm.on_mesh
    assert details["source"] == "detected" and details["confidence"].shape == (68,)
    assert details["low_confidence"].dtype == bool and details["views"]
    assert (folder / "scan.obj").read_bytes() == before


def test_old_landmark_json_still_reads(tmp_path):
    path = tmp_path / "old.json"
    path.write_text(json.dumps({"format": "facewrap.landmarks", "version": 1,
                                "landmarks": [{"name": "a", "vertex": 3}]}))
    assert read_landmarks_json(path).vertex.tolist() == [3]
    assert read_landmark_details(path) == {"confidence": None, "low_confidence": None,
                                           "views": [], "source": None}


@pytest.mark.parametrize("bad", [1.5, "0.5", True, None])
def test_a_bad_confidence_is_one_error_naming_the_file(tmp_path, bad):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"format": "facewrap.landmarks", "version": 1,
                                "landmarks": [{"vertex": 3, "confidence": bad}]}))
    with pytest.raises(ValueError, match="bad.json: landmark 0: 'confidence'"):
        read_landmark_details(path)


def test_the_output_may_not_be_an_input_or_not_json(folder, tmp_path, capsys):
    scan = str(folder / "scan.obj")
    assert main(["landmarks", scan, "-o", scan]) == 2
    assert "inputs are never overwritten" in capsys.readouterr().err
    assert main(["landmarks", scan, "-o", str(tmp_path / "lm.txt")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "lm.txt" in err and ".json" in err
    assert not (tmp_path / "lm.txt").exists()


def test_a_mesh_with_no_face_exits_2(tmp_path, capsys):
    ball = tmp_path / "ball.obj"
    u, v = np.meshgrid(np.linspace(0, np.pi, 12), np.linspace(0, 2 * np.pi, 16))
    P = 50 * np.c_[(np.sin(u) * np.cos(v)).ravel(), (np.sin(u) * np.sin(v)).ravel(),
                   np.cos(u).ravel()]
    from scipy.spatial import ConvexHull
    T = ConvexHull(P).simplices + 1
    ball.write_text("".join(f"v {a} {b} {c}\n" for a, b, c in P)
                    + "".join(f"f {a} {b} {c}\n" for a, b, c in T))
    assert main(["landmarks", str(ball), "-o", str(tmp_path / "lm.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{ball}: no face found" in err
    assert not (tmp_path / "lm.json").exists()


def test_wrap_with_no_landmark_files_detects_them(folder, tmp_path, capsys):
    out, report = tmp_path / "fit.obj", tmp_path / "report.json"
    assert main(["wrap", str(folder / "template.obj"), str(folder / "scan.obj"),
                 "-o", str(out), "--report", str(report), "--model", "rbf"]) == 0
    text = capsys.readouterr().out
    assert "scan landmarks detected" in text and "template landmarks detected" in text
    r = json.loads(report.read_text())
    assert r["scan_landmarks_source"] == "detected"
    assert set(r["detected_landmarks"]) == {"scan", "template"}
    assert len(r["detected_landmarks"]["scan"]["confidence"]) == 68
    assert out.is_file()


@needs_data
@pytest.mark.shared_data
def test_the_sumner_horse_has_no_face(data_dir, tmp_path, capsys):
    horse = data_dir / "sumner2004" / "horse-camel" / "horse_ref.obj"
    assert main(["landmarks", str(horse), "-o", str(tmp_path / "lm.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{horse}: no face found" in err
