"""Hostile inputs of a sweep of every subcommand: one test per bug class it found.

Each input broke a rule for bad input — one line naming the file and the problem
with exit status 2 (never a hang, a traceback or a bare library message), nothing
implausible fitted silently, every distance with its unit — and each test checks
the rule now holds.  Inputs are the built-in sample at its smallest, so the file
runs in seconds.
"""

from __future__ import annotations

import contextlib
import json
import os
import threading
from pathlib import Path

import numpy as np
import pytest

from facewrap.landmarks import Landmarks
from conftest import facewrap
# the fixture: the built-in sample at its smallest (template 24, scan 40), as files
from test_hostile_more import sample  # noqa: F401


def wrap_argv(p: dict, out: Path, *more) -> list:
    return ["wrap", p["template"], p["scan"], "--template-landmarks", p["template_landmarks"],
            "--scan-landmarks", p["scan_landmarks"], "--model", "rbf", "-q", "-o", out, *more]


def error_line(capsys, rc: int, *needles: str) -> str:
    """Status 2 and one ``facewrap: error:`` line holding every needle."""
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2, err
    assert len(err) == 1 and err[0].startswith("facewrap: error: "), err
    for needle in needles:
        assert needle in err[0], err[0]
    return err[0]


def warning_lines(capsys, rc: int, *needles: str) -> list:
    """Status 0 and a ``facewrap: warning:`` line holding every needle."""
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 0, err
    hits = [ln for ln in err if ln.startswith("facewrap: warning: ")
            and all(n in ln for n in needles)]
    assert hits, err
    return hits


@contextlib.contextmanager
def fifo(path: Path):
    """A fifo at ``path`` whose writer, should a reader ever open it, closes at once
    (so a reader that opens it sees an empty file instead of waiting forever)."""
    os.mkfifo(path)

    def writer():
        with open(path, "wb"):
            pass
    t = threading.Thread(target=writer, daemon=True)
    t.start()
    try:
        yield path
    finally:   # a read end that does not wait lets a writer still waiting finish
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
        t.join()
        os.close(fd)


# -- a fifo where a file is expected: named, never opened -------------------------------
def test_a_fifo_texture_is_named_not_opened(sample, tmp_path, capsys):
    with fifo(tmp_path / "t.png") as t:
        rc = facewrap(*wrap_argv(sample, tmp_path / "out.obj", "--texture", t))
    error_line(capsys, rc, "t.png: is a fifo, not a regular file")
    assert not (tmp_path / "out.obj").exists()


def test_a_fifo_start_texture_of_animate_is_named(sample, tmp_path, capsys):
    smile = Path(sample["template"]).parent / "blendshapes" / "smile.obj"
    with fifo(tmp_path / "a.png") as a:
        rc = facewrap("animate", sample["template"], smile, "-o", tmp_path / "an",
                      "--textures", a, sample["scan_texture"])
    error_line(capsys, rc, "a.png: is a fifo, not a regular file")


def test_a_fifo_ground_truth_is_named(sample, tmp_path, capsys):
    with fifo(tmp_path / "g.npy") as g:
        rc = facewrap("evaluate", sample["template"], sample["scan"], "-q",
                      "--ground-truth", g)
    error_line(capsys, rc, "g.npy: is a fifo, not a regular file")


# -- files whose content a library rejects in its own words -----------------------------
def test_a_ply_of_no_vertices_is_named(tmp_path, capsys):
    p = tmp_path / "m.ply"
    p.write_text("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
                 "property float y\nproperty float z\nend_header\n")
    error_line(capsys, facewrap("info", p), "m.ply: holds no vertices")


def test_an_integer_of_5000_digits_in_landmark_json_is_named(sample, tmp_path, capsys):
    p = tmp_path / "tl.json"
    p.write_text('{"format": "facewrap.landmarks", "version": 1, "landmarks": '
                 '[{"vertex": 1' + "0" * 5000 + "}]}")
    rc = facewrap(*wrap_argv({**sample, "template_landmarks": p}, tmp_path / "o.obj"))
    line = error_line(capsys, rc, "tl.json: invalid JSON", "digits")
    assert "sys.set_int_max_str_digits" not in line


@pytest.mark.parametrize("value, problem", [
    ("[" * 5000 + "]" * 5000, "nested too deeply"),
    ("1" + "0" * 5000, "digits")])
def test_a_job_file_value_no_parser_takes_is_named(sample, value, problem, tmp_path,
                                                   capsys):
    job = tmp_path / "job.toml"
    job.write_text(f'[inputs]\ntemplate = "{sample["template"]}"\n'
                   f'[outputs]\noutput = "o.obj"\n[wrap]\nx = {value}\n')
    error_line(capsys, facewrap("run", job), "job.toml: invalid TOML", problem)


def test_a_report_section_of_the_wrong_type_is_named(sample, tmp_path, capsys):
    report = tmp_path / "r.json"
    assert facewrap(*wrap_argv(sample, tmp_path / "f.obj", "--report", report)) == 0
    run = json.loads(report.read_text())
    run["timings"] = [1, 2]
    report.write_text(json.dumps(run))
    capsys.readouterr()
    rc = facewrap("report", report, "-o", tmp_path / "page")
    error_line(capsys, rc, "r.json: 'timings' must be an object, got list")
    assert not (tmp_path / "page").exists()


# -- landmark files ---------------------------------------------------------------------
def test_a_template_vertex_id_listed_twice_is_named(sample, tmp_path, capsys):
    ids = Path(sample["template_landmarks"]).read_text().split()
    ids[3] = ids[2]
    p = tmp_path / "tl.txt"
    p.write_text("\n".join(ids) + "\n")
    rc = facewrap(*wrap_argv({**sample, "template_landmarks": p}, tmp_path / "o.obj"))
    error_line(capsys, rc, "tl.txt: landmarks 2 and 3 are at the same position")


def test_a_float_id_is_named_with_its_line(sample, tmp_path, capsys):
    ids = Path(sample["template_landmarks"]).read_text().split()
    ids[2] = "12.0"
    p = tmp_path / "tl.txt"
    p.write_text("\n".join(ids) + "\n")
    rc = facewrap(*wrap_argv({**sample, "template_landmarks": p}, tmp_path / "o.obj"))
    error_line(capsys, rc, "tl.txt:3:", "'12.0'")


@pytest.mark.parametrize("bary", [[5, -7, 1e300], [0.5, 0.5, 0.5]])
def test_barycentric_coordinates_off_the_triangle_are_named(sample, bary, tmp_path,
                                                            capsys):
    items = [{"triangle": 5 + i, "barycentric": bary} for i in range(68)]
    p = tmp_path / "tl.json"
    p.write_text(json.dumps({"format": "facewrap.landmarks", "version": 1,
                             "landmarks": items}))
    rc = facewrap(*wrap_argv({**sample, "template_landmarks": p}, tmp_path / "o.obj"))
    error_line(capsys, rc, "tl.json: landmark 0: 'barycentric' must be 3 numbers in [0, 1]")


def test_names_that_pair_with_nothing_are_said(sample, tmp_path, capsys):
    ids = Path(sample["template_landmarks"]).read_text().split()
    rows = [r.split() for r in Path(sample["scan_landmarks"]).read_text().splitlines()
            if r.strip()]
    tl, sl = tmp_path / "tl.json", tmp_path / "sl.json"
    tl.write_text(json.dumps({"format": "facewrap.landmarks", "version": 1, "landmarks": [
        {"name": f"n{i}", "vertex": int(v)} for i, v in enumerate(ids)]}))
    sl.write_text(json.dumps({"format": "facewrap.landmarks", "version": 1, "landmarks": [
        {"name": f"n{i}" if i < 20 else f"typo{i}", "point": [float(x) for x in r]}
        for i, r in enumerate(rows)]}))
    rc = facewrap(*wrap_argv({**sample, "template_landmarks": tl, "scan_landmarks": sl},
                             tmp_path / "o.obj"))
    warning_lines(capsys, rc, "sl.json: 48 of 68 scan landmarks pair with no landmark",
                  "'typo20'")


def test_landmarks_off_the_scan_are_said_with_their_unit(sample, tmp_path, capsys):
    rows = [np.array(r.split(), float) for r in
            Path(sample["scan_landmarks"]).read_text().splitlines() if r.strip()]
    p = tmp_path / "sl.txt"
    p.write_text("".join(" ".join(repr(float(x) + 30.0) for x in r) + "\n" for r in rows))
    rc = facewrap(*wrap_argv({**sample, "scan_landmarks": p}, tmp_path / "o.obj"))
    warning_lines(capsys, rc, "sl.txt:", "lie off the scan surface", " mm away",
                  "scan size ", " mm)")


def test_a_name_given_twice_is_said():
    with pytest.raises(ValueError, match="'b' is given twice"):
        Landmarks.from_vertices([0, 1, 2], names=["a", "b", "b"])


# -- options and folders that leave nothing to fit --------------------------------------
@pytest.mark.parametrize("option", ["--exclude", "--pin"])
def test_every_vertex_held_is_said(sample, option, tmp_path, capsys):
    n = sum(1 for ln in Path(sample["template"]).read_text().splitlines()
            if ln.startswith("v "))
    ids = tmp_path / "all.txt"
    ids.write_text("".join(f"{i}\n" for i in range(n)))
    rc = facewrap(*wrap_argv(sample, tmp_path / "o.obj", option, ids))
    warning_lines(capsys, rc, "all.txt: every template vertex is excluded or pinned")


def test_a_shape_in_other_units_is_said(sample, tmp_path, capsys):
    shapes = tmp_path / "shapes"
    shapes.mkdir()
    src = Path(sample["template"]).parent / "blendshapes" / "smile.obj"
    (shapes / "smile.obj").write_text("".join(
        "v " + " ".join(repr(float(x) * 1000) for x in ln.split()[1:4]) + "\n"
        if ln.startswith("v ") else ln + "\n" for ln in src.read_text().splitlines()))
    rc = facewrap(*wrap_argv(sample, tmp_path / "o.obj", "--blendshapes", shapes,
                             "--model", "hybrid"))
    warning_lines(capsys, rc, "shapes: 1 shape(s) move a vertex farther than half",
                  "'smile'")


def test_a_folder_of_copies_of_the_neutral_says_so(sample, tmp_path, capsys):
    shapes = tmp_path / "shapes"
    shapes.mkdir()
    for k in range(2):
        (shapes / f"s{k}.obj").write_bytes(Path(sample["template"]).read_bytes())
    rc = facewrap(*wrap_argv(sample, tmp_path / "o.obj", "--blendshapes", shapes,
                             "--model", "hybrid"))
    error_line(capsys, rc, "shapes: no shapes: its 2 OBJ file(s) all equal the neutral")


def test_template_landmark_points_off_the_template_name_their_file(sample, tmp_path,
                                                                     capsys):
    # points for another mesh: one 40 units off the template's surface
    from facewrap.io import read_mesh
    template = read_mesh(sample["template"])
    ids = np.loadtxt(sample["template_landmarks"], dtype=np.int64)
    P = template.vertices[ids]
    P[11] += [0.0, 0.0, 0.2 * template.scale()]
    points = tmp_path / "tl_points.txt"
    np.savetxt(points, P)
    argv = wrap_argv(sample, tmp_path / "out.obj")
    argv[argv.index(sample["template_landmarks"])] = points
    error_line(capsys, facewrap(*argv), "tl_points.txt: ", "landmark 11",
               "template units")


def _transfer_onto(sample, tmp_path, target_vertices):
    """``facewrap transfer`` of the sample's shapes onto the template moved to
    ``target_vertices`` (same topology), 12 landmark ids paired with themselves."""
    from facewrap.io import read_mesh, write_mesh
    template = read_mesh(sample["template"])
    target = tmp_path / "target.obj"
    V = target_vertices(template.vertices)
    write_mesh(target, type(template)(V, template.triangles))
    markers = tmp_path / "markers.txt"
    ids = sample["template_landmarks"].read_text().split()[:12]
    markers.write_text("".join(f"{i} {i}\n" for i in ids))
    return facewrap("transfer", sample["template"], target, "--markers", markers,
                    "--source-shapes", sample["blendshapes/blink"].parent, "-o",
                    tmp_path / "shapes", "-q")


@pytest.mark.parametrize("moved, said", [
    (lambda V: V * [-1.0, 1.0, 1.0], "mirror image of the source"),
    (lambda V: V / 1000.0, "0.001 times the source's size")])
def test_transfer_onto_a_mirrored_or_rescaled_target_is_said(sample, tmp_path, capsys,
                                                              moved, said):
    """transfer ran a mirrored target, or one 1000 times smaller, silently (exit 0)."""
    lines = warning_lines(capsys, _transfer_onto(sample, tmp_path, moved), said)
    assert "markers.txt: " in lines[0]


def test_transfer_onto_a_moved_copy_says_nothing(sample, tmp_path, capsys):
    rc = _transfer_onto(sample, tmp_path, lambda V: 1.5 * V + [10.0, 0.0, 0.0])
    err = capsys.readouterr().err
    assert rc == 0 and "warning" not in err, err
