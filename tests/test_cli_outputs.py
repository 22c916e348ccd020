"""Every command that writes: no output on an input, a pre-flight, no partial outputs.

Each data-loss case is run as a user runs it: exit status 2, one line naming both
the output and the input, the inputs' bytes unchanged (hashed before and after) and
no output created.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from facewrap.io.obj import read_obj
from facewrap.jobs import WrapJob, run_wrap_job
from facewrap.sample import make_scan, make_template, write_sample
from facewrap.wrapping import WrapSettings
from conftest import facewrap


def digest(folder: Path) -> dict:
    """Name → SHA-256 of every file under ``folder``."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """A small sample, a one-frame sequence, markers and a finished wrap run."""
    d = tmp_path_factory.mktemp("inputs")
    tpl = make_template(24)
    write_sample(d, tpl, make_scan(tpl, resolution=24, texture_size=16))
    (d / "seq").mkdir()
    for name in ("scan.obj", "scan.mtl", "scan_texture.png"):
        shutil.copy(d / name, d / "seq" / ("frame_0000.obj" if name == "scan.obj" else name))
    ids = (d / "template_landmarks.txt").read_text().split()[:12]
    (d / "markers.txt").write_text("".join(f"{i} {i}\n" for i in ids))
    (d / "job.toml").write_text(
        f'[inputs]\ntemplate = "{d / "template.obj"}"\nscan = "{d / "scan.obj"}"\n'
        f'template_landmarks = "{d / "template_landmarks.txt"}"\n'
        f'scan_landmarks = "{d / "scan_landmarks.txt"}"\n'
        f'[outputs]\noutput = "{d / "scan.obj"}"\n[wrap]\nmodel = "rbf"\n')
    (d / "manifest.csv").write_text(
        f"scan,scan_landmarks,blendshapes,output\n{d / 'scan.obj'},"
        f"{d / 'scan_landmarks.txt'},{d / 'blendshapes'},{d / 'blendshapes' / 'fit.obj'}\n")
    (d / "run").mkdir()
    run_wrap_job(WrapJob(template=str(d / "template.obj"), scan=str(d / "scan.obj"),
                         template_landmarks=str(d / "template_landmarks.txt"),
                         scan_landmarks=str(d / "scan_landmarks.txt"),
                         output=str(d / "run" / "out.obj"),
                         report=str(d / "run" / "index.html")), WrapSettings(model="rbf"))
    return d


def wrap_args(d: Path) -> list:
    return ["wrap", d / "template.obj", d / "scan.obj", "--template-landmarks",
            d / "template_landmarks.txt", "--scan-landmarks", d / "scan_landmarks.txt",
            "--model", "rbf", "-q"]


def transfer_args(d: Path, shapes=None) -> list:
    return ["transfer", d / "template.obj", d / "template.obj", "--markers",
            d / "markers.txt", "--source-shapes", shapes or d / "blendshapes", "-q"]


def track_args(d: Path) -> list:
    return ["track", d / "template.obj", d / "seq", "--template-landmarks",
            d / "template_landmarks.txt", "--scan-landmarks", d / "scan_landmarks.txt",
            "--model", "rbf", "-q"]


# (command line, the output and the input the one line must name), d = inputs folder
DATA_LOSS = {
    "convert_onto_itself": lambda d: (["convert", d / "scan.obj", d / "scan.obj"],
                                      d / "scan.obj", d / "scan.obj"),
    "convert_through_dotdot": lambda d: (
        ["convert", d / "scan.obj", d / "seq" / ".." / "scan.obj"],
        d / "seq" / ".." / "scan.obj", d / "scan.obj"),
    "wrap_output_is_the_scan": lambda d: (wrap_args(d) + ["-o", d / "scan.obj"],
                                          d / "scan.obj", d / "scan.obj"),
    "wrap_report_on_landmarks": lambda d: (
        wrap_args(d) + ["-o", d / "new" / "x.obj", "--report", d / "scan_landmarks.txt"],
        d / "scan_landmarks.txt", d / "scan_landmarks.txt"),
    "wrap_output_in_blendshapes": lambda d: (
        wrap_args(d) + ["--blendshapes", d / "blendshapes", "-o",
                        d / "blendshapes" / "fit.obj"],
        d / "blendshapes" / "fit.obj", d / "blendshapes"),
    "run_output_is_the_scan": lambda d: (["run", d / "job.toml"], d / "scan.obj",
                                         d / "scan.obj"),
    "transfer_into_source_shapes": lambda d: (
        transfer_args(d) + ["-o", d / "blendshapes"], d / "blendshapes", d / "blendshapes"),
    "transfer_shape_file_in_out": lambda d: (
        transfer_args(d, d / "blendshapes" / "smile.obj") + ["-o", d / "blendshapes"],
        d / "blendshapes" / "smile.obj", d / "blendshapes" / "smile.obj"),
    "transfer_report_on_markers": lambda d: (
        transfer_args(d) + ["-o", d / "new", "--report", d / "markers.txt"],
        d / "markers.txt", d / "markers.txt"),
    "track_into_scan_folder": lambda d: (track_args(d) + ["-o", d / "seq"],
                                         d / "seq" / "frame_0000.obj", d / "seq"),
    "evaluate_json_on_scan": lambda d: (
        ["evaluate", d / "template.obj", d / "scan.obj", "--json", d / "scan.obj"],
        d / "scan.obj", d / "scan.obj"),
    "evaluate_heatmap_on_scan_texture": lambda d: (
        ["evaluate", d / "template.obj", d / "scan.obj", "--heatmap",
         d / "scan_texture.png"], d / "scan_texture.png", d / "scan.obj"),
    "report_over_run_json": lambda d: (["report", d / "run" / "index.html", "-o", d / "run"],
                                       d / "run" / "index.html", d / "run" / "index.html"),
    "animate_over_start": lambda d: (
        ["animate", d / "seq" / "frame_0000.obj", d / "scan.obj", "--frames", "3", "-o",
         d / "seq"], d / "seq" / "frame_0000.obj", d / "seq" / "frame_0000.obj"),
    "batch_output_in_input_folder": lambda d: (
        ["batch", d / "manifest.csv", "--job", d / "job.toml", "-q"],
        d / "blendshapes" / "fit.obj", d / "blendshapes"),
}


def one_line(capsys) -> list[str]:
    return capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize("name", sorted(DATA_LOSS))
def test_an_output_on_an_input_is_refused(name, inputs, capsys):
    argv, output, inp = DATA_LOSS[name](inputs)
    before = digest(inputs)
    capsys.readouterr()
    assert facewrap(*argv) == 2
    lines = one_line(capsys)
    assert len(lines) == 1 and lines[0].startswith("facewrap: error: "), lines
    assert "never overwritten" in lines[0]
    for path in (output, inp):
        assert str(path) in lines[0], (path, lines[0])
    assert digest(inputs) == before         # same files, same bytes: nothing written
    assert not (inputs / "new").exists()


@pytest.fixture
def a_file(tmp_path) -> Path:
    p = tmp_path / "a_file"
    p.write_text("not a folder")
    return p


# (command line, the output the one line must name), f = a file in the way
PRE_FLIGHT = {
    "wrap_output": lambda d, f: (wrap_args(d) + ["-o", f / "x.obj"], f / "x.obj"),
    "wrap_report": lambda d, f: (wrap_args(d) + ["-o", f.parent / "o" / "x.obj",
                                                 "--report", f / "r.json"], f / "r.json"),
    "wrap_texture": lambda d, f: (
        wrap_args(d) + ["-o", f / "x.obj", "--texture", d / "scan_texture.png"], f / "x.obj"),
    "transfer_out": lambda d, f: (transfer_args(d) + ["-o", f], f),
    "transfer_gltf": lambda d, f: (
        transfer_args(d) + ["-o", f.parent / "shapes", "--gltf", f / "x.glb"], f / "x.glb"),
    "track_out": lambda d, f: (track_args(d) + ["-o", f / "t"], f / "t"),
    "evaluate_heatmap": lambda d, f: (
        ["evaluate", d / "template.obj", d / "scan.obj", "--heatmap", f / "h.png"],
        f / "h.png"),
    "report_out_is_a_file": lambda d, f: (["report", d / "run" / "index.html", "-o", f], f),
    "convert": lambda d, f: (["convert", d / "scan.obj", f / "x.ply"], f / "x.ply"),
    "animate": lambda d, f: (["animate", d / "scan.obj", d / "scan.obj", "-o", f / "a"],
                             f / "a"),
    "sample": lambda d, f: (["sample", f / "s"], f / "s"),
    "demo": lambda d, f: (["demo", "--out", f / "demo", "-q"], f / "demo"),
    "run_write_template": lambda d, f: (["run", f / "job.toml", "--write-template"],
                                        f / "job.toml"),
}


@pytest.mark.parametrize("name", sorted(PRE_FLIGHT))
def test_an_output_that_cannot_be_created_is_refused_before_any_work(
        name, inputs, a_file, capsys):
    argv, output = PRE_FLIGHT[name](inputs, a_file)
    before = digest(a_file.parent)
    capsys.readouterr()
    assert facewrap(*argv) == 2
    lines = one_line(capsys)
    assert len(lines) == 1 and lines[0].startswith("facewrap: error: "), lines
    assert str(output) in lines[0] and ("is a file" in lines[0]), lines[0]
    assert digest(a_file.parent) == before and sorted(os.listdir(a_file.parent)) == ["a_file"]


def test_a_read_only_output_folder_is_refused(inputs, tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        if os.access(ro, os.W_OK):
            pytest.skip("running as root: a read-only mode does not stop writes "
                        "(the path-through-a-file cases cover the pre-flight)")
        capsys.readouterr()
        assert facewrap(*wrap_args(inputs), "-o", ro / "x.obj") == 2
        lines = one_line(capsys)
        assert len(lines) == 1 and "not writable" in lines[0] and str(ro) in lines[0]
    finally:
        ro.chmod(0o755)
    assert list(ro.iterdir()) == []


def test_a_wrap_that_fails_while_writing_leaves_no_outputs(inputs, tmp_path, monkeypatch,
                                                           capsys):
    import facewrap.jobs.wrap_job as wrap_job
    def argv(out):
        return wrap_args(inputs) + ["-o", out / "x.obj", "--report", out / "r.json",
                                    "--texture", inputs / "scan_texture.png",
                                    "--texture-size", "16"]
    out = tmp_path / "out"
    assert facewrap(*argv(out)) == 0
    earlier = digest(out)
    assert sorted(earlier) == ["r.json", "x.mtl", "x.obj", "x.png"]

    def disk_full(*_args, **_kw):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(wrap_job, "save_png", disk_full)
    capsys.readouterr()
    assert facewrap(*argv(out)) == 2         # one line, no traceback
    assert one_line(capsys) == ["facewrap: error: No space left on device"]
    assert digest(out) == earlier           # the earlier run's outputs, untouched
    assert sorted(os.listdir(out)) == sorted(earlier)   # and nothing staged is left
    assert facewrap(*argv(tmp_path / "new" / "deeper")) == 2
    assert not (tmp_path / "new").exists()  # the folders made for it are gone too


def test_a_transfer_that_fails_while_writing_leaves_no_outputs(inputs, tmp_path,
                                                               monkeypatch):
    import facewrap.jobs.transfer_job as transfer_job

    def disk_full(*_args, **_kw):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(transfer_job, "write_gltf_morphs", disk_full)
    assert facewrap(*transfer_args(inputs), "-o", tmp_path / "shapes", "--gltf",
                    tmp_path / "g" / "x.glb") == 2
    assert sorted(os.listdir(tmp_path)) == []


def test_report_uses_the_runs_own_files_before_the_current_folders(inputs, tmp_path,
                                                                   monkeypatch, capsys):
    run = tmp_path / "run"
    run.mkdir()
    for name in ("template.obj", "scan.obj", "scan.mtl", "scan_texture.png"):
        shutil.copy(inputs / name, run / name)
    shutil.copy(inputs / "run" / "out.obj", run / "out.obj")
    report = json.loads((inputs / "run" / "index.html").read_text())
    report["job"].update(template="template.obj", scan="scan.obj", output="out.obj")
    (run / "run.json").write_text(json.dumps(report))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    # another run's files of the same names in the current folder: not a mesh at all
    for name in ("template.obj", "scan.obj", "out.obj"):
        (elsewhere / name).write_text("not this run's mesh\n")
    monkeypatch.chdir(elsewhere)
    assert facewrap("report", run / "run.json", "-o", tmp_path / "page") == 0, \
        capsys.readouterr().err
    assert (tmp_path / "page" / "index.html").is_file()
    V = read_obj(run / "out.obj").vertices
    assert np.isfinite(V).all()
