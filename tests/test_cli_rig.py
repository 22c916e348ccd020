"""``facewrap rig`` (facewrap.cli.rig): the command on the built-in sample."""

from __future__ import annotations

import contextlib
import io
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from facewrap.io.gltf import read_gltf_morphs
from conftest import facewrap


@pytest.fixture(scope="module")
def sample(tmp_path_factory) -> Path:
    """``facewrap sample`` written once (template, blendshapes, textured scan)."""
    folder = tmp_path_factory.mktemp("cli_rig") / "sample"
    assert facewrap("sample", folder) == 0
    return folder


def rig_args(s: Path, out: Path, *more) -> list:
    return ["rig", s / "scan.obj", "--template", s / "template.obj", "--blendshapes",
            s / "blendshapes", "--template-landmarks", s / "template_landmarks.txt",
            "--scan-landmarks", s / "scan_landmarks.txt", "-o", out, *more]


@pytest.fixture(scope="module")
def textured(sample, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cli_rig_out") / "rig"
    assert facewrap(*rig_args(sample, out, "--texture", sample / "scan_texture.png",
                              "--texture-size", 64, "-q")) == 0
    return out


@pytest.fixture(scope="module")
def plain(sample, tmp_path_factory) -> tuple[Path, str]:
    """A rig without texture, by displacements, units given: (folder, what it printed)."""
    out = tmp_path_factory.mktemp("cli_rig_plain") / "anna"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert facewrap(*rig_args(sample, out, "--method", "delta", "--units", "mm")) == 0
    return out, printed.getvalue()


def test_rig_writes_the_rig_and_one_summary_line_with_units(plain):
    out, printed = plain
    lines = printed.splitlines()
    assert len(lines) == 1, lines   # units given: no note on how they were inferred
    assert lines[0].startswith(f"wrote {out}: ") and "5 shapes (delta)" in lines[0]
    assert " mm" in lines[0] and lines[0].endswith(" s")
    report = json.loads((out / "rig.json").read_text())
    assert report["method"] == "delta" and report["units_source"] == "given"
    names = sorted(p.stem for p in (out / "shapes").iterdir())
    assert sorted(read_gltf_morphs(out / "rig.glb").shapes) == names == report["shapes"]


def test_rig_takes_the_wraps_fitting_options(sample, tmp_path):
    out = tmp_path / "graph"
    assert facewrap(*rig_args(sample, out, "--model", "graph", "--node-spacing", 0.06,
                              "-q")) == 0
    settings = json.loads((out / "rig.json").read_text())["settings"]
    assert settings["model"] == "graph" and settings["node_spacing"] == 0.06
    # a value the settings refuse names the option
    assert facewrap(*rig_args(sample, tmp_path / "x", "--node-spacing", -1)) == 2
    assert not (tmp_path / "x").exists()


def test_bad_input_is_one_line_exit_2_and_writes_nothing(sample, tmp_path):
    bad = tmp_path / "landmarks.txt"
    bad.write_text("not numbers\n")
    out = tmp_path / "out"
    for args in (rig_args(sample, out, "--scan-landmarks", bad),
                 rig_args(sample, out, "--method", "wobble"),
                 rig_args(sample, out)[:5] + ["-o", out]):   # no --blendshapes
        r = subprocess.run([sys.executable, "-m", "facewrap.cli", *map(str, args)],
                           capture_output=True, text=True)
        assert r.returncode == 2, r.stderr
        assert r.stderr.startswith("facewrap: error: ") and r.stderr.count("\n") == 1, \
            r.stderr
    assert not out.exists()


def test_an_output_folder_inside_an_input_is_refused(sample, capsys):
    inside = sample / "blendshapes" / "rig"
    assert facewrap(*rig_args(sample, inside)) == 2
    err = capsys.readouterr().err
    assert "lies in the input folder" in err and "inputs are never overwritten" in err
    assert not inside.exists()


def test_a_rig_job_file_runs_with_facewrap_run(sample, tmp_path, capsys):
    job = tmp_path / "rig.toml"
    job.write_text(f'[inputs]\ntemplate = "{sample / "template.obj"}"\n'
                   f'scan = "{sample / "scan.obj"}"\n'
                   f'scan_landmarks = "{sample / "scan_landmarks.txt"}"\n'
                   f'template_landmarks = "{sample / "template_landmarks.txt"}"\n'
                   f'blendshapes = "{sample / "blendshapes"}"\n'
                   '[outputs]\noutput = "anna"\n[rig]\n')
    assert facewrap("run", job) == 0
    assert capsys.readouterr().out.startswith(f"wrote {tmp_path / 'anna'}: ")
    assert (tmp_path / "anna" / "rig.glb").is_file()


def _validator() -> str | None:
    """Node.js with the Khronos ``gltf-validator`` package (found on NODE_PATH)."""
    node = shutil.which("node")
    if node is None:
        return None
    found = subprocess.run([node, "-e", "require.resolve('gltf-validator')"],
                           capture_output=True)
    return node if found.returncode == 0 else None


_VALIDATE = """
const v = require("gltf-validator");
const bytes = new Uint8Array(require("fs").readFileSync(process.argv[1]));
v.validateBytes(bytes).then(r => console.log(JSON.stringify(r.issues)),
                            e => { console.error(String(e)); process.exit(1); });
"""


@pytest.mark.skipif(_validator() is None, reason="Node.js with gltf-validator not found "
                    "(npm install gltf-validator; NODE_PATH=.../node_modules)")
@pytest.mark.parametrize("which", ["textured", "plain"])
def test_the_glb_passes_the_khronos_validator(textured, plain, which):
    glb = (textured if which == "textured" else plain[0]) / "rig.glb"
    r = subprocess.run([_validator(), "-e", _VALIDATE, str(glb)], capture_output=True,
                       text=True, check=True)
    issues = json.loads(r.stdout)
    assert (issues["numErrors"], issues["numWarnings"]) == (0, 0), issues["messages"]


def test_expression_scans_on_the_command_line(tmp_path, capsys):
    from facewrap.sample import make_scan, make_template, write_sample
    tpl = make_template(24)
    n = write_sample(tmp_path / "neutral", tpl, make_scan(tpl, weights={}, resolution=40,
                                                           texture_size=16, seed=1))
    x = write_sample(tmp_path / "smile", tpl, make_scan(tpl, weights={"smile": 1.0},
                                                         resolution=40, texture_size=16,
                                                         seed=2))
    base = ["rig", n["scan"], x["scan"], "--template", n["template"], "--blendshapes",
            tmp_path / "neutral" / "blendshapes", "--template-landmarks",
            n["template_landmarks"], "--scan-landmarks", n["scan_landmarks"]]
    out = tmp_path / "rig"
    # two landmark files for one expression scan: one line, exit 2, nothing written
    assert facewrap(*base, "--expression-landmarks", x["scan_landmarks"],
                    n["scan_landmarks"], "-o", out) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "2 expression landmark file(s)" in err
    assert not out.exists()
    assert facewrap(*base, "--expression-landmarks", x["scan_landmarks"], "-o", out,
                    "--units", "mm") == 0
    line = capsys.readouterr().out.strip()
    assert "1 expression scan(s) reproduced to mean " in line and "neutral-only rig" in line
    examples = json.loads((out / "rig.json").read_text())["examples"]
    assert examples[0]["weights"]["smile"] == pytest.approx(1.0, abs=0.1)
