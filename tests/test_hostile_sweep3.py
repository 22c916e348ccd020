"""Hostile inputs of a third sweep: one test per bug class it found.

Each input broke a rule for bad input — one line naming the file and the problem
with exit status 2, outputs whole or absent (also when the run is killed), nothing
implausible fitted silently — and each test checks the rule now holds.  Inputs are
the built-in sample at its smallest; the few tests that need a process of their own
(what happens at its exit, signals) start ``python -m facewrap.cli``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from conftest import facewrap
# the fixture: the built-in sample at its smallest (template 24, scan 40), as files
from test_hostile_more import sample  # noqa: F401
from test_hostile_sweep import error_line, warning_lines, wrap_argv


def run_cli(*argv, cwd=None, prelude: str = "") -> subprocess.CompletedProcess:
    """``facewrap ARGV`` as a process of its own (after ``prelude``, Python run in it
    first), as a user's shell starts it."""
    code = prelude + "\nimport sys\nfrom facewrap.cli import main\nsys.exit(main())\n"
    return subprocess.run([sys.executable, "-c", code, *map(str, argv)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def listing(folder: Path) -> list:
    """Every entry under ``folder``, hidden ones too."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def uv_edited(src: Path, dst: Path, move) -> Path:
    """``src``'s OBJ text with every ``vt u v`` line mapped by ``move(u, v)``."""
    lines = []
    for ln in Path(src).read_text().splitlines():
        if ln.startswith("vt "):
            u, v = move(*(float(t) for t in ln.split()[1:3]))
            ln = f"vt {u!r} {v!r}"
        lines.append(ln)
    dst.write_text("\n".join(lines) + "\n")
    return dst


# -- a failed run's exit: one line, not a library's leak report --------------------------
def test_a_texture_no_reader_takes_fails_in_one_line_at_exit(sample, tmp_path):
    """The texture decodes on a thread beside the meshes' reading; its error came
    back through a future whose traceback held the scan's AABB tree in a cycle, and
    the collector (frozen at exit) never freed it: nanobind then printed ~50 lines of
    'leaked instance / type / function' after the error line."""
    bad = tmp_path / "t.png"
    bad.write_text("not an image")
    r = run_cli(*wrap_argv(sample, tmp_path / "o.obj", "--texture", bad))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert lines[0].startswith("facewrap: error: ") and "t.png" in lines[0]


# -- a killed run: staged outputs removed, outputs whole or absent ------------------------
KILL_BEFORE_COMMIT = """
import os, signal
from facewrap.io import paths
_commit = paths.StagedOutputs.commit
def commit(self):   # every output written (staged), none moved into place yet
    os.kill(os.getpid(), signal.{sig})
    _commit(self)
paths.StagedOutputs.commit = commit
"""

KILL_MID_COMMIT = """
import os, signal
from facewrap.io import paths
_commit, _replace, moves = paths.StagedOutputs.commit, os.replace, []
def commit(self):
    moves.append(0)
    _commit(self)
def replace(a, b):   # the signal arrives between the commit's first two moves
    _replace(a, b)
    if len(moves) == 1:
        moves.append(os.kill(os.getpid(), signal.SIGTERM))
paths.StagedOutputs.commit, paths.os.replace = commit, replace
"""


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGHUP"])
def test_a_run_ended_by_sigterm_or_sighup_leaves_no_staged_files(sample, sig, tmp_path):
    """``kill``, ``timeout``, a cluster's scheduler or a closed terminal ended the
    process where it stood: the staged outputs (hidden ``.facewrap-staged-*`` files)
    stayed in the output folder."""
    out = tmp_path / "out"
    r = run_cli(*wrap_argv(sample, out / "fit.obj", "--report", out / "r.json"),
                prelude=KILL_BEFORE_COMMIT.format(sig=sig))
    assert r.returncode == 128 + getattr(signal, sig), r.stderr
    assert r.stderr.strip() == f"facewrap: terminated ({sig})"
    assert not out.exists() or listing(out) == [], listing(out)


def test_a_sigterm_during_the_moves_waits_for_the_last(sample, tmp_path):
    """Outputs appear whole: a signal between two moves of a commit takes effect
    after the last one."""
    out = tmp_path / "out"
    r = run_cli(*wrap_argv(sample, out / "fit.obj", "--report", out / "r.json",
                           "--texture", sample["scan_texture"], "--texture-size", "16"),
                prelude=KILL_MID_COMMIT)
    assert r.returncode == 143, r.stderr
    assert listing(out) == ["fit.mtl", "fit.obj", "fit.png", "r.json"]


def test_a_process_started_ignoring_sighup_keeps_ignoring_it(sample, tmp_path):
    """``nohup facewrap ...`` must survive its terminal closing."""
    out = tmp_path / "out"
    r = run_cli(*wrap_argv(sample, out / "fit.obj"),
                prelude="import signal; signal.signal(signal.SIGHUP, signal.SIG_IGN)\n"
                + KILL_BEFORE_COMMIT.format(sig="SIGHUP"))
    assert r.returncode == 0, r.stderr
    assert listing(out) == ["fit.obj"]


# -- folders of files: frames in their numbers' order, hidden files left out --------------
def test_track_takes_frames_numbered_without_zeros_in_order(sample, tmp_path, capsys):
    """A folder f_1, f_2, f_10 was tracked in string order f_1, f_10, f_2: frames
    out of order, silently."""
    seq = tmp_path / "seq"
    seq.mkdir()
    for k in (1, 2, 10):
        (seq / f"f_{k}.obj").write_bytes(Path(sample["scan"]).read_bytes())
    out = tmp_path / "out"
    rc = facewrap("track", sample["template"], seq, "--template-landmarks",
                  sample["template_landmarks"], "--scan-landmarks", sample["scan_landmarks"],
                  "--model", "rbf", "-q", "-o", out)
    assert rc == 0, capsys.readouterr().err
    scans = json.loads((out / "track.json").read_text())["scans"]
    assert [Path(s).name for s in scans] == ["f_1.obj", "f_2.obj", "f_10.obj"]


APPLE_DOUBLE = b"\x00\x05\x16\x07\x00\x02\x00\x00Mac OS X        \x00\x02"


def test_macos_resource_forks_in_a_shape_folder_are_left_out(sample, tmp_path, capsys):
    """A folder copied from a Mac onto a foreign disk holds ``._smile.obj`` beside
    ``smile.obj``: it was read as a shape and refused as binary data."""
    shapes = tmp_path / "shapes"
    shapes.mkdir()
    for name in ("smile", "blink"):
        (shapes / f"{name}.obj").write_bytes(
            Path(sample[f"blendshapes/{name}"]).read_bytes())
        (shapes / f"._{name}.obj").write_bytes(APPLE_DOUBLE)
    rc = facewrap(*wrap_argv(sample, tmp_path / "o.obj", "--blendshapes", shapes,
                             "--model", "hybrid"))
    assert rc == 0, capsys.readouterr().err


def test_macos_resource_forks_in_a_frame_folder_are_left_out(sample, tmp_path, capsys):
    seq = tmp_path / "seq"
    seq.mkdir()
    (seq / "f_0.obj").write_bytes(Path(sample["scan"]).read_bytes())
    (seq / "._f_0.obj").write_bytes(APPLE_DOUBLE)
    rc = facewrap("track", sample["template"], seq, "--template-landmarks",
                  sample["template_landmarks"], "--scan-landmarks", sample["scan_landmarks"],
                  "--model", "rbf", "-q", "-o", tmp_path / "out")
    assert rc == 0, capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "out").glob("*.obj")) == ["frame_0000.obj"]


# -- two shapes of one name: one of them lost ---------------------------------------------
def _markers(sample, tmp_path) -> Path:
    markers = tmp_path / "markers.txt"
    ids = sample["template_landmarks"].read_text().split()[:12]
    markers.write_text("".join(f"{i} {i}\n" for i in ids))
    return markers


def _transfer(sample, tmp_path, *sources):
    return facewrap("transfer", sample["template"], sample["template"], "--markers",
                    _markers(sample, tmp_path), "--source-shapes", *sources, "-o",
                    tmp_path / "out", "-q")


def test_two_source_shapes_of_one_name_are_refused(sample, tmp_path, capsys):
    """``--source-shapes a b`` with a smile in each: b's took a's place (one
    smile.obj written), silently."""
    other = tmp_path / "more"
    other.mkdir()
    V = np.loadtxt([ln[2:] for ln in Path(sample["blendshapes/smile"]).read_text()
                    .splitlines() if ln.startswith("v ")])
    (other / "smile.obj").write_text("".join(f"v {x} {y} {z + 1.0}\n"
                                             for x, y, z in V))
    rc = _transfer(sample, tmp_path, Path(sample["blendshapes/smile"]).parent, other)
    error_line(capsys, rc, "more/smile.obj: two source shapes are named 'smile'",
               "rename one")
    assert not (tmp_path / "out").exists()


def test_one_shape_given_twice_is_one_shape(sample, tmp_path, capsys):
    folder = Path(sample["blendshapes/smile"]).parent
    assert _transfer(sample, tmp_path, folder, sample["blendshapes/smile"]) == 0, \
        capsys.readouterr().err


def test_two_files_of_one_shape_name_in_a_folder_are_refused(sample, tmp_path, capsys):
    shapes = tmp_path / "shapes"
    shapes.mkdir()
    for name in ("smile.obj", "smile.OBJ"):
        (shapes / name).write_bytes(Path(sample["blendshapes/smile"]).read_bytes())
    rc = facewrap(*wrap_argv(sample, tmp_path / "o.obj", "--blendshapes", shapes,
                             "--model", "hybrid"))
    error_line(capsys, rc, "shapes: two files hold the shape 'smile'")


# -- texture coordinates a bake cannot use ------------------------------------------------
def test_a_template_laid_out_outside_every_tile_is_refused(sample, tmp_path, capsys):
    """Template UVs moved to u < 0: every triangle in no UDIM tile, a black texture
    baked and written, exit 0."""
    template = uv_edited(sample["template"], tmp_path / "template.obj",
                         lambda u, v: (u - 5.0, v))
    rc = facewrap(*wrap_argv({**sample, "template": template}, tmp_path / "o.obj",
                             "--texture", sample["scan_texture"], "--texture-size", "16"))
    error_line(capsys, rc, "template.obj: no triangle's texture coordinates lie in a UDIM "
               "tile")
    assert list(tmp_path.glob("o.*")) == []


def test_a_template_partly_outside_the_tiles_is_said(sample, tmp_path, capsys):
    template = uv_edited(sample["template"], tmp_path / "template.obj",
                         lambda u, v: (u if u < 0.5 else u - 5.0, v))
    rc = facewrap(*wrap_argv({**sample, "template": template}, tmp_path / "o.obj",
                             "--texture", sample["scan_texture"], "--texture-size", "16"))
    warning_lines(capsys, rc, "template.obj: ", "template triangles have texture "
                  "coordinates outside the UDIM tiles", "left out of the baked texture")


def test_scan_uvs_beyond_its_image_are_said(sample, tmp_path, capsys):
    """A scan laid out in UDIM tile 1002 (u in [1, 2]) with its one image: every
    texel read the image's border column, a smeared texture, exit 0 and silent."""
    scan = uv_edited(sample["scan"], tmp_path / "scan.obj", lambda u, v: (u + 1.0, v))
    (tmp_path / "scan.mtl").write_bytes(Path(sample["scan_mtl"]).read_bytes())
    rc = facewrap(*wrap_argv({**sample, "scan": scan}, tmp_path / "o.obj",
                             "--texture", sample["scan_texture"], "--texture-size", "16"))
    warning_lines(capsys, rc, "scan.obj: ", "scan triangles have texture coordinates "
                  "outside [0, 1]")


def test_a_scan_laid_out_in_its_image_says_nothing(sample, tmp_path, capsys):
    rc = facewrap(*wrap_argv(sample, tmp_path / "o.obj", "--texture",
                             sample["scan_texture"], "--texture-size", "16"))
    err = capsys.readouterr().err
    assert rc == 0 and "texture coordinates" not in err, err


# -- a setting's error named as the output's ----------------------------------------------
def test_a_texture_size_out_of_range_names_the_option_not_the_output(sample, tmp_path,
                                                                     capsys):
    """``--texture-size 0`` was reported as 'OUT.obj: texture_size must be...', as
    if the output file were at fault."""
    rc = facewrap(*wrap_argv(sample, tmp_path / "o.obj", "--texture-size", "0"))
    line = error_line(capsys, rc, "(--texture-size) must be an integer in [1, 16384]")
    assert "o.obj" not in line
