"""Two standards held on the command line, as a user meets them.

* "An implausible input is refused or warned about, never measured silently":
  ``facewrap evaluate`` names a scan landmark file that matches the result's only
  in a mirror image (left and right swapped, or the scan mirrored) or whose
  landmarks are mis-paired (shuffled, two swapped); normal landmarks stay silent.
* "Inputs are sacred; outputs appear whole or not at all": ``facewrap sample OUT``
  replaces no file already in OUT unless ``--overwrite`` is given.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
import pytest

from facewrap.cli.evaluate import landmarks_mispaired
from facewrap.detection.backend import IBUG68_MIRROR
from facewrap.evaluate import evaluate, landmark_errors
from facewrap.io import read_mesh
from facewrap.io.landmarks import read_landmarks
from facewrap.landmarks import IBUG68_NAMES, Landmarks
from facewrap.sample import make_scan, make_template, sample_paths, write_sample
from conftest import facewrap, write_mirrored_obj


def digest(folder: Path) -> dict:
    """Every file under ``folder`` (relative path) -> its SHA-256."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def stderr_lines(capsys) -> list[str]:
    return capsys.readouterr().err.strip().splitlines()


# -- evaluate: mirrored and mis-paired landmark files -------------------------------------

@pytest.fixture(scope="module")
def fitted(tmp_path_factory) -> dict:
    """The sample at its smallest (template 24, scan 40) and the rbf wrap of it."""
    folder = tmp_path_factory.mktemp("sample")
    template = make_template(24)
    paths = write_sample(folder, template, make_scan(template, resolution=40,
                                                     texture_size=16))
    fit = folder / "fit.obj"
    assert facewrap("wrap", paths["template"], paths["scan"], "--template-landmarks",
                    paths["template_landmarks"], "--scan-landmarks",
                    paths["scan_landmarks"], "--model", "rbf", "-q", "-o", fit) == 0
    return {**paths, "fit": fit}


def evaluate_argv(p: dict, scan_landmarks, scan=None, *more) -> list:
    return ["evaluate", p["fit"], scan or p["scan"], "--result-landmarks",
            p["template_landmarks"], "--scan-landmarks", scan_landmarks, *more]


def renumbered(p: dict, folder: Path, name: str, order) -> Path:
    """The scan's landmark file with its points in ``order`` (a relabelling)."""
    path = folder / name
    np.savetxt(path, np.loadtxt(p["scan_landmarks"])[order])
    return path


def test_normal_landmarks_give_no_warning(fitted, tmp_path, capsys):
    out = tmp_path / "e.json"
    before = digest(fitted["scan"].parent)
    assert facewrap(*evaluate_argv(fitted, fitted["scan_landmarks"], None,
                                   "--json", out)) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    summary = json.loads(out.read_text())
    assert "warnings" not in summary and summary["landmark_count"] == 68
    assert " mm" in captured.out
    assert digest(fitted["scan"].parent) == before


def test_the_template_before_fitting_gives_no_warning(fitted, capsys):
    # an unfitted template (another face, no expression) is a poor fit, not a
    # mis-paired one: poor numbers, but nothing to warn about
    assert facewrap("evaluate", fitted["template"], fitted["scan"], "-q",
                    "--result-landmarks", fitted["template_landmarks"],
                    "--scan-landmarks", fitted["scan_landmarks"]) == 0
    assert stderr_lines(capsys) == []


def test_a_mirrored_landmark_file_is_named(fitted, tmp_path, capsys):
    mirrored = renumbered(fitted, tmp_path, "mirrored.txt", IBUG68_MIRROR)
    out = tmp_path / "e.json"
    assert facewrap(*evaluate_argv(fitted, mirrored, None, "--json", out)) == 0
    captured = capsys.readouterr()
    warned = captured.err.strip().splitlines()
    assert len(warned) == 1, warned
    assert warned[0].startswith(f"facewrap: warning: {mirrored}: ")
    assert "mirror image" in warned[0] and "left and right" in warned[0]
    assert str(fitted["template_landmarks"]) in warned[0]
    # measured all the same (the numbers are what the user asked for), and said so
    summary = json.loads(out.read_text())
    assert summary["warnings"] == [warned[0].removeprefix("facewrap: warning: ")]
    assert "landmarks mean" in captured.out


def test_a_mirrored_scan_is_named(fitted, tmp_path, capsys):
    """The scan and its landmarks mirrored (x -> -x): the fit's landmarks match them
    only mirrored back."""
    scan = write_mirrored_obj(fitted["scan"], tmp_path / "mirrored.obj")
    landmarks = tmp_path / "mirrored_landmarks.txt"
    np.savetxt(landmarks, np.loadtxt(fitted["scan_landmarks"]) * [-1.0, 1.0, 1.0])
    assert facewrap(*evaluate_argv(fitted, landmarks, scan, "-q")) == 0
    warned = [w for w in stderr_lines(capsys) if "mirror image" in w]
    assert len(warned) == 1 and warned[0].startswith(f"facewrap: warning: {landmarks}: ")


def test_a_shuffled_landmark_file_is_named(fitted, tmp_path, capsys):
    order = np.random.default_rng(3).permutation(68)
    shuffled = renumbered(fitted, tmp_path, "shuffled.txt", order)
    out = tmp_path / "e.json"
    assert facewrap(*evaluate_argv(fitted, shuffled, None, "-q", "--json", out)) == 0
    warned = stderr_lines(capsys)
    assert len(warned) == 1, warned
    assert warned[0].startswith(f"facewrap: warning: {shuffled}: ")
    assert "mis-paired" in warned[0] and " %" in warned[0]
    assert len(json.loads(out.read_text())["warnings"]) == 1


@pytest.mark.parametrize("a, b", [(8, 30), (36, 45), (19, 57)])
def test_two_swapped_landmarks_are_named(fitted, tmp_path, capsys, a, b):
    """Chin and nose tip; the outer eye corners; a brow and the lower lip."""
    order = np.arange(68)
    order[[a, b]] = [b, a]
    swapped = renumbered(fitted, tmp_path, "swapped.txt", order)
    assert facewrap(*evaluate_argv(fitted, swapped, None, "-q")) == 0
    warned = stderr_lines(capsys)
    assert len(warned) == 1 and "2 of 68 landmarks" in warned[0], warned
    assert f"landmark {a} " in warned[0] and f"landmark {b} " in warned[0]


def test_named_landmarks_are_checked_in_their_pairing(fitted):
    """Named sets pair by name (in any file order): a file listing the points in
    mirrored order under their own names is no mirror; one whose names are
    swapped left for right is."""
    result = read_mesh(fitted["fit"])
    scan = read_mesh(fitted["scan"])
    on_result = read_landmarks(fitted["template_landmarks"])
    on_result = Landmarks.from_vertices(on_result.vertex, IBUG68_NAMES)
    P = np.loadtxt(fitted["scan_landmarks"])
    reordered = Landmarks.from_points(P[IBUG68_MIRROR],
                                      [IBUG68_NAMES[i] for i in IBUG68_MIRROR])
    swapped = Landmarks.from_points(P[IBUG68_MIRROR], IBUG68_NAMES)
    notes = []
    for on_scan in (reordered, swapped):
        lm = evaluate(result, scan, result_landmarks=on_result,
                      scan_landmarks=on_scan).landmarks
        notes.append(landmarks_mispaired(lm, "scan.txt", "result.txt"))
    assert notes[0] == []
    assert len(notes[1]) == 1 and notes[1][0].startswith("scan.txt: ")


def test_too_few_or_coincident_landmarks_are_not_judged():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(3, 3))
    assert landmarks_mispaired(landmark_errors(X, X[[2, 1, 0]]), "a", "b") == []
    same = np.zeros((6, 3))
    assert landmarks_mispaired(landmark_errors(same, rng.normal(size=(6, 3))),
                               "a", "b") == []


# -- sample: never over a user's files -----------------------------------------------------

def test_sample_into_a_new_folder_then_again(tmp_path, capsys):
    out = tmp_path / "new" / "s"
    assert facewrap("sample", out) == 0
    written = digest(out)
    expected = {p.relative_to(out).as_posix() for p in sample_paths(out).values()}
    assert set(written) == expected
    capsys.readouterr()
    # a second run would replace every file: refused, naming the first
    assert facewrap("sample", out) == 2
    err = stderr_lines(capsys)
    assert err == [f"facewrap: error: {out / 'template.obj'}: already exists and the "
                   "sample would replace it: choose an empty or new folder, or pass "
                   "--overwrite"]
    assert digest(out) == written
    assert facewrap("sample", out, "--overwrite") == 0
    assert set(digest(out)) == expected     # nothing staged is left beside them


def test_sample_keeps_a_users_template(tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "template.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    before = digest(out)
    assert facewrap("sample", out) == 2
    err = stderr_lines(capsys)
    assert len(err) == 1 and err[0].startswith(f"facewrap: error: {out / 'template.obj'}: ")
    assert "--overwrite" in err[0] and "empty or new folder" in err[0]
    assert digest(out) == before and os.listdir(out) == ["template.obj"]


def test_sample_names_a_blendshape_in_the_way(tmp_path, capsys):
    out = tmp_path / "s"
    (out / "blendshapes").mkdir(parents=True)
    (out / "blendshapes" / "smile.obj").write_text("my smile\n")
    assert facewrap("sample", out) == 2
    err = stderr_lines(capsys)
    assert len(err) == 1 and f"{out / 'blendshapes' / 'smile.obj'}: already exists" in err[0]
    assert digest(out) == {"blendshapes/smile.obj": digest(out)["blendshapes/smile.obj"]}


@pytest.mark.parametrize("kind", ["folder_for_a_file", "file_for_a_folder"])
def test_sample_refuses_what_even_overwrite_cannot_replace(tmp_path, capsys, kind):
    out = tmp_path / "s"
    out.mkdir()
    if kind == "folder_for_a_file":
        culprit = out / "scan.obj"
        culprit.mkdir()
    else:
        culprit = out / "blendshapes"
        culprit.write_text("not a folder\n")
    assert facewrap("sample", out, "--overwrite") == 2
    err = stderr_lines(capsys)
    assert len(err) == 1 and err[0].startswith(f"facewrap: error: {culprit}: ")
    assert os.listdir(out) == [culprit.name]


@pytest.mark.parametrize("others", [[], ["notes.txt", "scans/a.obj"]])
def test_sample_into_an_existing_folder_of_other_files(tmp_path, capsys, others):
    out = tmp_path / "s"
    out.mkdir()
    for name in others:
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text(f"the user's {name}\n")
    before = digest(out)
    assert facewrap("sample", out) == 0
    after = digest(out)
    assert {k: after[k] for k in before} == before
    assert set(after) - set(before) == {p.relative_to(out).as_posix()
                                        for p in sample_paths(out).values()}
