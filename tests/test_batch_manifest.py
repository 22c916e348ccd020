"""Manifests of batches (facewrap.batch.manifest): CSV and TOML, checked before any job runs."""

from __future__ import annotations

import os

import pytest

from facewrap.batch import read_manifest
from facewrap.errors import InputError
from facewrap.wrapping import Stage
from batch_data import data  # noqa: F401 - a fixture

# -- manifests -------------------------------------------------------------------------------
def test_csv_manifest_overrides_and_paths(data, tmp_path):
    m = tmp_path / "m.csv"
    m.write_text(f"# a comment\nscan,scan_landmarks,output,wrap.smoothing,project,name\n"
                 f"{data}/s1/scan.obj,{data}/s1/scan_landmarks.txt,out/a.obj,0.25,no,A\n"
                 f"{data}/s2/scan.obj,{data}/s2/scan_landmarks.txt,out/b.ply,,,\n")
    a, b = read_manifest(m, data / "shared.toml")
    assert (a.name, a.settings.smoothing, a.settings.project) == ("A", 0.25, False)
    assert (b.settings.smoothing, b.settings.project, b.settings.model) == (0.0, True,
                                                                           "rbf")
    assert a.job.output == str(tmp_path / "out" / "a.obj")
    assert a.job.template == str(data / "s0" / "template.obj")  # from the job file
    assert b.name == os.path.join("out", "b.ply") and a.line == 3 and b.line == 4


def test_toml_manifest_with_job_key_and_stages(data, tmp_path):
    m = tmp_path / "m.toml"
    m.write_text(f'job = "{data}/shared.toml"\n'
                 f'[[jobs]]\nscan = "{data}/s1/scan.obj"\n'
                 f'scan_landmarks = "{data}/s1/scan_landmarks.txt"\noutput = "a.obj"\n'
                 f'[jobs.wrap]\nmodel = "graph"\n[[jobs.wrap.stages]]\niterations = 2\n'
                 f'[[jobs]]\nname = "second"\nscan = "{data}/s2/scan.obj"\n'
                 f'scan_landmarks = "{data}/s2/scan_landmarks.txt"\noutput = "b.obj"\n')
    a, b = read_manifest(m)
    assert a.settings.model == "graph" and a.settings.stages == [Stage(iterations=2)]
    assert b.settings.model == "rbf" and b.name == "second"


@pytest.mark.parametrize("body, match, line", [
    ("scan,scan_landmarks,output,colour\na.obj,a.txt,o.obj,red\n", "unknown column 'colour'", 1),
    ("scan,scan_landmarks,output,smoothing\na.obj,a.txt,o.obj,lots\n",
     "'smoothing' must be a number", 2),
    ("scan,scan_landmarks,output,stages\na.obj,a.txt,o.obj,3\n", "cannot be set in a CSV", 2),
    ("scan,scan_landmarks,output,smoothing\na.obj,a.txt,o.obj,-1\n",
     "job 1: WrapSettings.smoothing must be a real number in \\[0, inf\\)", 2),
    ("scan,scan_landmarks,output\na.obj,a.txt\n", "row has 2 cells", 2),
    ("scan,scan_landmarks\na.obj,a.txt\n", "missing 'output'", 2),
    ("scan,scan_landmarks,output\na.obj,a.txt,o.obj\nb.obj,b.txt,o.obj\n",
     "both write", 3),
    ("scan,scan_landmarks,output\na.obj,a.txt,o.obj\no.obj,b.txt,p.obj\n",
     "an input of job 2", 3),
    ("scan,scan_landmarks,output,output\na.obj,a.txt,o.obj,p.obj\n", "appears twice", 1),
    ("scan,scan_landmarks,output\n", "no jobs", None),
    ("\n\n", "empty file", None),
    ("scan,scan_landmarks,output\na.obj,a.txt,o.txt\n", "unknown mesh format", 2),
])
def test_bad_manifests_name_file_and_line(data, tmp_path, body, match, line):
    m = tmp_path / "m.csv"
    m.write_text(body)
    with pytest.raises(InputError, match=match) as err:
        read_manifest(m, data / "shared.toml")
    assert err.value.path == str(m) and err.value.line == line


def test_a_row_job_file_of_another_kind_is_refused(data, tmp_path):
    (tmp_path / "t.toml").write_text("[transfer]\nfix_flips = false\n")
    m = tmp_path / "m.csv"
    m.write_text(f"scan,scan_landmarks,output,job\n"
                 f"{data}/s1/scan.obj,{data}/s1/scan_landmarks.txt,a.obj,t.toml\n")
    with pytest.raises(InputError, match="is a transfer job but the batch runs wrap"):
        read_manifest(m, data / "shared.toml")
