"""Hostile inputs of a sixth sweep: the commands other than ``wrap``.

Classes:

- ``--units`` (or a job's ``units``) that the data contradict by a decade or more
  (``--units m`` on a scan in millimetres: a head 0.16 km across) was taken as
  given by every command, and every distance shown was off by that factor without
  a word; ``wrap``, ``run``, ``batch``, ``rig``, ``track``, ``info``,
  ``evaluate``, ``report`` and ``landmarks`` now say so in one line naming the
  file (:func:`facewrap.units.units_conflict`);
- a batch summary's distances (``fit_mean`` ... ``landmark_max``) carried no unit,
  and the jobs of one batch may be in different units; each row now says its
  ``units`` (CSV and JSON, and a resumed job's from its done-record).

Inputs are the built-in sample at its smallest.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from conftest import facewrap
# the fixture: the built-in sample at its smallest (template 24, scan 40), as files
from test_hostile_more import sample  # noqa: F401
from test_hostile_sweep import warning_lines, wrap_argv


# -- a given unit the data contradict -------------------------------------------------------
@pytest.mark.parametrize("unit", ["m", "cm", "in"])
def test_wrap_says_a_given_unit_the_head_contradicts(sample, tmp_path, capsys, unit):
    argv = wrap_argv(sample, tmp_path / "fit.obj", "--units", unit)
    warning_lines(capsys, facewrap(*argv), str(sample["scan"]), f"--units {unit} makes",
                  "its size says mm")


def test_a_given_unit_that_fits_is_not_said(sample, tmp_path, capsys):
    assert facewrap(*wrap_argv(sample, tmp_path / "fit.obj", "--units", "mm")) == 0
    assert "--units" not in capsys.readouterr().err


def test_info_evaluate_report_say_a_given_unit_the_head_contradicts(sample, tmp_path,
                                                                    capsys):
    warning_lines(capsys, facewrap("info", sample["scan"], "--units", "m"),
                  str(sample["scan"]), "--units m makes the head")
    fit, run = tmp_path / "fit.obj", tmp_path / "run.json"
    assert facewrap(*wrap_argv(sample, fit, "--report", run)) == 0
    capsys.readouterr()
    warning_lines(capsys, facewrap("evaluate", fit, sample["scan"], "--units", "cm"),
                  str(fit), "--units cm makes the head")
    rc = facewrap("report", run, "-o", tmp_path / "page", "--units", "m")
    warning_lines(capsys, rc, str(fit), "--units m makes the head")
    assert "--units m makes the head" in (tmp_path / "page" / "index.html").read_text()


def test_track_says_a_given_unit_once(sample, tmp_path, capsys):
    seq = tmp_path / "seq"
    seq.mkdir()
    for k in range(2):
        (seq / f"f{k}.obj").write_bytes(Path(sample["scan"]).read_bytes())
    rc = facewrap("track", sample["template"], seq, "--template-landmarks",
                  sample["template_landmarks"], "--scan-landmarks", sample["scan_landmarks"],
                  "--model", "rigid", "-q", "-o", tmp_path / "out", "--units", "m")
    hits = warning_lines(capsys, rc, "--units m makes the head")
    assert len(hits) == 1 and "f0.obj" in hits[0]


# -- a batch summary's units ---------------------------------------------------------------
def test_a_batch_summary_says_each_jobs_units(sample, tmp_path, capsys):
    (tmp_path / "shared.toml").write_text(
        f'[inputs]\ntemplate = "{sample["template"]}"\n'
        f'template_landmarks = "{sample["template_landmarks"]}"\n[wrap]\nmodel = "rbf"\n')
    (tmp_path / "m.csv").write_text(
        "scan,scan_landmarks,output,units\n"
        f"{sample['scan']},{sample['scan_landmarks']},a.obj,\n"
        f"{sample['scan']},{sample['scan_landmarks']},b.obj,cm\n")
    argv = ("batch", tmp_path / "m.csv", "--job", tmp_path / "shared.toml", "--workers", 1,
            "-q")
    for status in ("done", "skipped"):      # a resumed job's unit from its record
        assert facewrap(*argv) == 0
        rows = list(csv.DictReader((tmp_path / "m.summary.csv").open()))
        assert [(r["status"], r["units"]) for r in rows] == [(status, "mm"),
                                                             (status, "cm")]
        assert int(rows[1]["warnings"]) == 1      # the given unit contradicted
        jobs = json.loads((tmp_path / "m.summary.json").read_text())["jobs"]
        assert [j["units"] for j in jobs] == ["mm", "cm"]
    capsys.readouterr()
