"""The page of a wrap run (facewrap.report.page) and ``facewrap report``."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from facewrap.errors import InputError
from facewrap.jobs import WrapJob, run_wrap_job
from facewrap.report.page import build_report_page, load_run_report
from facewrap.sample import make_scan, make_template, write_sample
from facewrap.wrapping import WrapSettings
from conftest import facewrap


def page_data(path: Path) -> dict:
    """The viewer's JSON block of a page."""
    m = re.search(r'<script type="application/json" id="facewrap-data">(.*?)</script>',
                  path.read_text(encoding="utf-8"), re.S)
    return json.loads(m.group(1))


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> dict:
    """A finished wrap run (RBF model: quick) with blendshapes and a baked texture."""
    d = tmp_path_factory.mktemp("run")
    tpl = make_template(24)
    paths = write_sample(d / "in", tpl, make_scan(tpl, resolution=24, texture_size=64))
    job = WrapJob(template=str(paths["template"]), scan=str(paths["scan"]),
                  template_landmarks=str(paths["template_landmarks"]),
                  scan_landmarks=str(paths["scan_landmarks"]),
                  output=str(d / "wrapped.obj"), blendshapes=str(d / "in" / "blendshapes"),
                  texture=str(paths["scan_texture"]), texture_size=64,
                  report=str(d / "run.json"))
    run_wrap_job(job, WrapSettings(model="rbf"))
    return {"dir": d, "paths": paths, "shapes": len(tpl.blendshapes)}


def test_page_of_a_wrap_run(run, tmp_path):
    page = build_report_page(run["dir"] / "run.json", tmp_path / "html",
                             images=[run["paths"]["scan_texture"]], title="a run")
    assert page == tmp_path / "html" / "index.html"
    data = page_data(page)
    # the sample's eyeballs are parts: they follow, and are shown apart
    assert [m["name"] for m in data["meshes"]] == ["template (aligned)", "scan", "result",
                                                   "part (follows)"]
    assert [s["name"] for s in data["scalars"]] == ["distance to scan", "distance to result"]
    assert data["blendshapes"]["mesh"] == "result"
    assert len(data["blendshapes"]["shapes"]) == run["shapes"]
    text = page.read_text()
    assert "a run" in text and "fit mean" in text and "Timings" in text
    assert "Transform" in text
    # the baked texture (a picture and the viewer's) + the image
    assert text.count("data:image/png;base64,") == 3 and len(data["textures"]) == 1


def test_cli_report_prints_the_page(run, tmp_path, capsys):
    assert facewrap("report", run["dir"] / "run.json", "-o", tmp_path / "html") == 0
    assert capsys.readouterr().out.strip() == str(tmp_path / "html" / "index.html")


@pytest.mark.parametrize("content, match", [
    ({"job": {"template": "nope.obj", "scan": "nope.obj", "output": "nope.obj"},
      "metrics": {}}, "nope.obj"),
    ({"metrics": {}}, "not a facewrap wrap report"),
    ("{not json", "not a JSON report"),
])
def test_bad_run_reports_are_input_errors(tmp_path, content, match):
    report = tmp_path / "run.json"
    report.write_text(content if isinstance(content, str) else json.dumps(content))
    with pytest.raises(InputError, match=match):
        build_report_page(report, tmp_path / "html")
    assert not (tmp_path / "html").exists()
    assert facewrap("report", report, "-o", tmp_path / "html") == 2


def test_load_run_report_reads_what_a_wrap_job_writes(run):
    rep = load_run_report(run["dir"] / "run.json")
    assert {"job", "settings", "metrics", "timings", "transform"} <= set(rep)
