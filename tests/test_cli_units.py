"""Units on the command line (issue 17): every distance printed carries its unit, the
inferred unit is stated, ``--units`` sets it on wrap, track, evaluate and report, job
files take a ``units`` key; evaluate counts coverage over a run's fitted vertices."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from facewrap.evaluate import VERTEX_ROLE_NAMES
from facewrap.jobs import WrapJob, write_job
from facewrap.sample import make_scan, make_template, write_sample
from facewrap.wrapping import WrapSettings
from conftest import facewrap

DISTANCE = r"(?:< )?[\d,]+(?:\.\d+)? "


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict:
    d = tmp_path_factory.mktemp("inputs")
    tpl = make_template(24)
    paths = write_sample(d, tpl, make_scan(tpl, resolution=24, texture_size=8))
    return {"dir": d, "paths": paths, "template": tpl}


def wrap_argv(inputs, out, *extra):
    p = inputs["paths"]
    return ["wrap", p["template"], p["scan"], "--template-landmarks",
            p["template_landmarks"], "--scan-landmarks", p["scan_landmarks"],
            "--model", "rbf", "-o", out / "fit.obj", "--report", out / "run.json", *extra]


def test_wrap_summary_has_units_and_states_the_inferred_one(inputs, tmp_path, capsys):
    assert facewrap(*wrap_argv(inputs, tmp_path)) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert re.search(rf"fit mean {DISTANCE}mm p95 {DISTANCE}mm, landmarks mean "
                     rf"{DISTANCE}mm, ", lines[0]), lines[0]
    assert "scan units" not in lines[0] and "e-" not in lines[0]
    assert lines[1] == "units: mm (inferred from the head's size; --units to set)"
    report = json.loads((tmp_path / "run.json").read_text())
    assert (report["units"], report["units_source"]) == ("mm", "inferred")
    assert report["job"]["units"] == "auto"


def test_wrap_units_given(inputs, tmp_path, capsys):
    assert facewrap(*wrap_argv(inputs, tmp_path, "--units", "cm")) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and re.search(rf"fit mean {DISTANCE}cm p95", out[0])
    report = json.loads((tmp_path / "run.json").read_text())
    assert (report["units"], report["units_source"]) == ("cm", "given")


def test_wrap_rejects_an_unknown_unit(inputs, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        facewrap(*wrap_argv(inputs, tmp_path, "--units", "ft"))
    assert exc.value.code == 2 and "--units" in capsys.readouterr().err
    assert not (tmp_path / "fit.obj").exists()


def test_job_files_take_units_and_refuse_bad_ones(inputs, tmp_path, capsys):
    p = inputs["paths"]
    job = WrapJob(template=str(p["template"]), scan=str(p["scan"]),
                  template_landmarks=str(p["template_landmarks"]),
                  scan_landmarks=str(p["scan_landmarks"]),
                  output=str(tmp_path / "out" / "fit.obj"),
                  report=str(tmp_path / "out" / "run.json"), units="m")
    write_job(tmp_path / "job.toml", job, WrapSettings(model="rbf"))
    text = (tmp_path / "job.toml").read_text()
    assert re.search(r'^units = "m"', text, re.M)
    assert facewrap("run", tmp_path / "job.toml") == 0
    assert " m p95 " in capsys.readouterr().out
    report = json.loads((tmp_path / "out" / "run.json").read_text())
    assert (report["units"], report["units_source"]) == ("m", "given")
    (tmp_path / "bad.toml").write_text(text.replace('units = "m"', 'units = "furlong"'))
    assert facewrap("run", tmp_path / "bad.toml") == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bad.toml" in err and "units" in err
    assert "Traceback" not in err


def test_max_distance_help_says_its_unit(capsys):
    with pytest.raises(SystemExit):
        facewrap("wrap", "--help")
    help_text = " ".join(capsys.readouterr().out.split())
    assert "longest projection move, in scan units" in help_text
    assert "--units {auto,mm,cm,m,in}" in help_text


@pytest.fixture(scope="module")
def wrapped(inputs, tmp_path_factory) -> dict:
    """A wrap run whose report names the left eyeball a part (synthesised roles)."""
    d = tmp_path_factory.mktemp("wrapped")
    assert facewrap(*wrap_argv(inputs, d, "-q")) == 0
    report = json.loads((d / "run.json").read_text())
    tpl = inputs["template"]
    left = tpl.parts["eyeball_left"]
    assert np.array_equal(left, np.arange(left[0], left[-1] + 1))  # one range
    n = tpl.mesh.n_vertices
    report["vertex_roles"] = {"fitted": [[0, int(left[0])], [int(left[-1]) + 1, n]],
                              "part": [[int(left[0]), int(left[-1]) + 1]]}
    (d / "roles.json").write_text(json.dumps(report))
    return {"dir": d, "left": left, "n": n}


def test_evaluate_run_counts_coverage_over_fitted_vertices(inputs, wrapped, capsys):
    d, scan = wrapped["dir"], inputs["paths"]["scan"]
    assert facewrap("evaluate", d / "fit.obj", scan, "--json", d / "all.json") == 0
    capsys.readouterr()
    assert facewrap("evaluate", d / "fit.obj", scan, "--run", d / "roles.json",
                    "--json", d / "fitted.json") == 0
    line = capsys.readouterr().out.splitlines()[0]
    every, fitted = (json.loads((d / f).read_text()) for f in ("all.json", "fitted.json"))
    n, k = wrapped["n"], len(wrapped["left"])
    assert fitted["fit_vertices"] == n - k and every["fit_vertices"] == n
    # the same covered fitted vertices over a smaller denominator
    covered_fitted = fitted["fit_coverage"] * (n - k)
    assert covered_fitted == pytest.approx(round(covered_fitted))
    assert covered_fitted <= every["fit_coverage"] * n + 1e-9
    assert f"of {n - k:,} vertices" in line and re.search(rf"fit mean {DISTANCE}mm", line)
    assert (fitted["units"], fitted["units_source"]) == ("mm", "inferred")


def test_evaluate_units_and_bad_runs(inputs, wrapped, tmp_path, capsys):
    d, scan = wrapped["dir"], inputs["paths"]["scan"]
    assert facewrap("evaluate", d / "fit.obj", scan, "--units", "in") == 0
    out = capsys.readouterr().out
    assert re.search(rf"fit mean {DISTANCE}in p95 {DISTANCE}in max {DISTANCE}in", out)
    assert "inferred" not in out
    assert facewrap("evaluate", d / "fit.obj", scan) == 0
    assert "units: mm (inferred" in capsys.readouterr().out
    no_roles = tmp_path / "old.json"
    no_roles.write_text(json.dumps({"job": {}}))
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"vertex_roles": {"fitted": [[0, 3]]}}))
    for argv, match in [(["--run", no_roles], "old.json: not a wrap report with"),
                        (["--run", bad], "bad.json: vertex_roles: vertex 3 has no role"),
                        (["--run", bad, "--mask", bad], "--mask or --run")]:
        assert facewrap("evaluate", d / "fit.obj", scan, *argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and match in err, err


def test_evaluate_heatmap_caption_in_the_given_unit(inputs, wrapped, tmp_path, capsys):
    d, scan = wrapped["dir"], inputs["paths"]["scan"]
    assert facewrap("evaluate", d / "fit.obj", scan, "--units", "cm", "--run",
                    d / "roles.json", "--heatmap", tmp_path / "h.png") == 0
    assert (tmp_path / "h.png").stat().st_size > 0
    assert " cm" in capsys.readouterr().out


def test_role_names_are_the_interface_table():
    assert VERTEX_ROLE_NAMES == ("fitted", "part", "cavity", "excluded", "pinned")


def test_track_states_and_records_its_units(inputs, tmp_path):
    import os
    import shutil
    import subprocess
    import sys
    d = inputs["dir"]
    seq = tmp_path / "seq"
    seq.mkdir()
    for k in range(2):
        shutil.copy(d / "scan.obj", seq / f"frame_{k:04d}.obj")
    argv = [sys.executable, "-m", "facewrap.cli", "-v", "track", d / "template.obj", seq,
            "--template-landmarks", d / "template_landmarks.txt", "--scan-landmarks",
            d / "scan_landmarks.txt",
            "--model", "rigid"]  # quick; a second frame refuses rbf (no schedule)
    src = str(Path(__file__).resolve().parents[1] / "src")
    env = dict(os.environ, PYTHONPATH=src + os.pathsep + os.environ.get("PYTHONPATH", ""))
    done = subprocess.run([str(a) for a in argv] + ["-o", str(tmp_path / "a")],
                          capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr
    out = done.stdout.splitlines()
    assert out[-1] == "units: mm (inferred from the head's size; --units to set)"
    # the frames' log lines (the sequence repeats its scan: a warning says so too)
    frames = [line for line in done.stderr.splitlines() if line.startswith("INFO: frame ")]
    assert len(frames) == 2 and all(re.search(rf"fit mean {DISTANCE}mm, landmarks mean "
                                              rf"{DISTANCE}mm", f) for f in frames), frames
    report = json.loads((tmp_path / "a" / "track.json").read_text())
    assert (report["units"], report["units_source"]) == ("mm", "inferred")
    assert facewrap(*argv[4:], "-o", tmp_path / "b", "--units", "cm", "-q") == 0
    report = json.loads((tmp_path / "b" / "track.json").read_text())
    assert (report["units"], report["units_source"]) == ("cm", "given")
