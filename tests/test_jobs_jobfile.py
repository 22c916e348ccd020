"""Job files (facewrap.jobs.jobfile, reading; .jobfile_writer, writing) and ``facewrap run``."""

from __future__ import annotations

import dataclasses
import re
import os
from pathlib import Path
from unittest import mock

import pytest
from hypothesis import given, settings as hsettings, strategies as st

from facewrap.errors import InputError
from facewrap.wrapping import Stage
from facewrap.io import read_mesh
from facewrap.sample import make_scan, make_template, write_sample
from facewrap.jobs import JOB_KINDS, WRAP, WrapJob, job_to_toml, load_job, read_job_tables, write_job
from facewrap.jobs.jobfile import job_keys, settings_keys
from facewrap.wrapping import WrapSettings
from conftest import facewrap


@pytest.fixture(scope="module")
def sample(tmp_path_factory) -> dict:
    tpl = make_template(24)
    folder = tmp_path_factory.mktemp("sample")
    return write_sample(folder, tpl, make_scan(tpl, resolution=40, texture_size=16))


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def sample_job(sample, folder: Path, wrap: str = 'model = "rbf"\n') -> Path:
    d = sample["template"].parent
    return write(folder / "job.toml", f"""
[inputs]
template = "{d / 'template.obj'}"
template_landmarks = "{d / 'template_landmarks.txt'}"
scan = "{d / 'scan.obj'}"
scan_landmarks = "{d / 'scan_landmarks.txt'}"
[outputs]
output = "out/fitted.obj"
report = "out/report.json"
[wrap]
{wrap}""")


# -- format ----------------------------------------------------------------------------
def test_template_round_trips_and_resolves_paths(tmp_path, monkeypatch):
    monkeypatch.chdir("/")
    p = tmp_path / "jobs" / "job.toml"
    write_job(p)
    job, s = load_job(p)
    assert job.scan == str(tmp_path / "jobs" / "scan.obj")
    assert job.output == str(tmp_path / "jobs" / "out" / "fitted.obj")
    assert s == WrapSettings()
    text = p.read_text()
    for key in settings_keys():  # every setting is in the template, set or commented
        assert f"\n{key} = " in text or f"# {key} = " in text or f"wrap.{key}" in text


def test_job_to_toml_round_trips_every_value(tmp_path):
    # (the backslash in an input: in an output it is refused, a Windows path)
    job = WrapJob(template=str(tmp_path / "a b" / "t.obj"),
                  scan=str(tmp_path / 'we"ird\\name.ply'),
                  template_landmarks=str(tmp_path / "t.json"),
                  scan_landmarks=str(tmp_path / "s.txt"),
                  output=str(tmp_path / "out" / 'we"ird name.obj'),
                  blendshapes=str(tmp_path / "shapes"), texture_size=256,
                  report=str(tmp_path / "r.json"))
    s = WrapSettings(model="graph", smoothing=0.25, max_distance=1e-7, blend_order=1,
                     pca_components=3, project=False,
                     stages=[Stage(iterations=3, landmark_weight=10.0), Stage()])
    p = tmp_path / "job.toml"
    p.write_text(job_to_toml(job, s, relative_to=tmp_path))
    assert load_job(p) == (job, s)
    # settings switched off where their default is on come back off
    off = WrapSettings(weight_range=None, landmark_pull=False, landmark_tolerance=0.0)
    p.write_text(job_to_toml(job, off, relative_to=tmp_path))
    assert load_job(p) == (job, off)


@dataclasses.dataclass
class Inner:
    radius: float = 1.0


@dataclasses.dataclass
class Grown(WrapSettings):
    """Settings as they might grow: a scalar, a nested table, a list."""
    new_knob: float = 1.0
    inner: Inner | None = None
    names: list[str] = dataclasses.field(default_factory=list)


def test_new_settings_become_keys_by_introspection(tmp_path):
    with mock.patch.dict(JOB_KINDS, wrap=dataclasses.replace(WRAP, settings_class=Grown)):
        p = write(tmp_path / "j.toml", '[wrap]\nnew_knob = 2\nnames = ["a", "b"]\n'
                                       '[wrap.inner]\nradius = 3\n')
        values = read_job_tables(p).settings
        assert values == {"new_knob": 2.0, "names": ["a", "b"], "inner": Inner(3.0)}
        assert "new_knob = 1.0" in job_to_toml(
            WrapJob("t.obj", "s.obj", scan_landmarks="s.txt", output="o.obj",
                    template_landmarks="t.txt"), Grown())
        bad = write(tmp_path / "k.toml", "[wrap.inner]\nradius = 3\ncolour = 1\n")
        with pytest.raises(InputError, match="unknown key 'colour'"):
            read_job_tables(bad)


def test_every_wrap_option_has_a_key(capsys):
    with pytest.raises(SystemExit):
        facewrap("wrap", "--help")
    options = set(re.findall(r"--([a-z][a-z-]*)", capsys.readouterr().out))
    assert {"model", "robust", "no-project", "texture-size"} <= options
    keys = set(job_keys()) | set(settings_keys())
    for option in options - {"help", "quiet"}:
        dest = option.replace("-", "_")
        assert dest in keys or dest.removeprefix("no_") in keys, option


@pytest.mark.parametrize("text, match, line", [
    ("[wrap]\nsmoothing = 0.1\nsmothing = 2\n", "unknown key 'smothing' in \\[wrap\\]", 3),
    ("[inputs]\noutput = 'a.obj'\n", "'output'.*belongs in \\[outputs\\]", 2),
    ("[wrapp]\nmodel = 'rbf'\n", "unknown table 'wrapp'", 1),
    ("[wrap]\nsmoothing = 'high'\n", "'smoothing' must be a number", 2),
    ("[wrap]\nproject = 1\n", "'project' must be a boolean", 2),
    ("[wrap]\nblend_order = 1.5\n", "'blend_order' must be an integer", 2),
    ("[wrap]\nsmoothing = nan\n", "finite", 2),
    ("[wrap]\nmodel = 'magic'\n", "'model' must be one of auto, rigid, rbf", 2),
    ("[wrap]\nproject = true\nnode_spacing = -1.0\n",
     r"\[wrap\] WrapSettings.node_spacing must be a real number in \(0, 1\]; got -1.0", 3),
    ("[wrap]\nblend_order = 7\n", "'blend_order' must be one of 1, 2; got 7", 2),
    ("[wrap]\n[[wrap.stages]]\niterations = 0\n",
     r"stages\[0\]: Stage.iterations must be an integer in \[1, inf\)", 2),
    ("[wrap]\n[[wrap.stages]]\niterations = 3\n[[wrap.stages]]\nstifness = 1\n",
     "unknown key 'stifness' in stages\\[1\\]", 4),
    ("[wrap]\nstages = 3\n", "'stages' must be an array of \\[\\[...\\]\\] tables", 2),
    ("[wrap]\nmodel = 'rbf'\n[wrap]\n", "invalid TOML", 3),
    ("version = 7\n", "unknown job-file version 7", 1),
    ("[outputs]\noutput = 'x.obj'\n", "missing 'template' in \\[inputs\\]", None),
    ("[inputs]\ntemplate='t.obj'\nscan='s.obj'\ntemplate_landmarks='t.txt'\n"
     "scan_landmarks='s.txt'\n[outputs]\noutput='t.obj'\n", "also an input", None),
    ("[inputs]\ntemplate='t.obj'\nscan='s.obj'\ntemplate_landmarks='t.txt'\n"
     "scan_landmarks='s.txt'\n[outputs]\noutput='t.stl'\n", "unknown mesh format", None),
])
def test_bad_job_files_name_file_line_and_key(tmp_path, text, match, line):
    p = write(tmp_path / "job.toml", text)
    with pytest.raises(InputError, match=match) as err:
        load_job(p)
    assert err.value.path == str(p)
    assert err.value.line == line


@hsettings(max_examples=150, deadline=None)
@given(st.text(max_size=300))
def test_any_text_is_a_job_or_an_input_error(tmp_path_factory, text):
    p = tmp_path_factory.getbasetemp() / "fuzz.toml"
    p.write_text(text, encoding="utf-8")
    try:
        read_job_tables(p)
    except InputError as exc:
        assert str(p) in str(exc) and "\n" not in exc.problem


# -- facewrap run ----------------------------------------------------------------------------
def test_run_writes_the_fitted_mesh(sample, tmp_path, capsys):
    p = sample_job(sample, tmp_path)
    assert facewrap("run", p) == 0
    fitted = read_mesh(tmp_path / "out" / "fitted.obj")
    template = read_mesh(sample["template"])
    assert fitted.n_vertices == template.n_vertices
    assert (tmp_path / "out" / "report.json").is_file()
    assert "wrote" in capsys.readouterr().out


def test_run_dry_run_writes_nothing_and_prints_a_loadable_job(sample, tmp_path, capsys):
    p = sample_job(sample, tmp_path, 'model = "rbf"\nsmoothing = 0.5\n')
    assert facewrap("run", p, "--dry-run") == 0
    assert not (tmp_path / "out").exists()
    printed = write(tmp_path / "again" / "job.toml", capsys.readouterr().out)
    job, s = load_job(printed)
    assert (job, s) == load_job(p) and s.smoothing == 0.5


def test_run_write_template_then_refuses_to_overwrite(tmp_path, capsys):
    p = tmp_path / "new.toml"
    assert facewrap("run", "--write-template", p) == 0
    assert facewrap("run", "--write-template", p) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("facewrap: error:") and str(p) in err and "\n" not in err
    assert facewrap("run", "--write-template", "--force", p) == 0


def test_run_missing_input_is_one_line_exit_2(sample, tmp_path, capsys):
    p = sample_job(sample, tmp_path)
    p.write_text(p.read_text().replace("scan.obj", "nope.obj"))
    assert facewrap("run", p, "--dry-run") == 2
    assert facewrap("run", p) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("nope.obj" in e for e in err)
    assert not (tmp_path / "out" / "fitted.obj").exists()


def test_run_relative_paths_follow_the_job_file(sample, tmp_path, monkeypatch):
    d = sample["template"].parent
    p = write(d / "jobs" / "rel.toml", """
[inputs]
template = "../template.obj"
template_landmarks = "../template_landmarks.txt"
scan = "../scan.obj"
scan_landmarks = "../scan_landmarks.txt"
[outputs]
output = "%s"
[wrap]
model = "rbf"
""" % (tmp_path / "rel.obj"))
    monkeypatch.chdir(tmp_path)
    job, _ = load_job(p)
    assert job.scan == os.path.normpath(d / "scan.obj")
    assert facewrap("run", "-q", p) == 0 and (tmp_path / "rel.obj").is_file()
