"""A wrap job from files to files (``facewrap.jobs.wrap_job``): the graph cache a
caller passes is the one the job uses."""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from facewrap.io import read_mesh
from facewrap.jobs import WrapJob, run_wrap_job
from facewrap.sample import make_scan, make_template, write_sample
from facewrap.wrapping import GraphCache, WrapSettings


def _job(folder, name):
    tpl = make_template(24)
    paths = write_sample(folder / "in", tpl, make_scan(tpl, resolution=24, texture_size=16))
    return WrapJob(template=str(paths["template"]), scan=str(paths["scan"]),
                   template_landmarks=str(paths["template_landmarks"]),
                   scan_landmarks=str(paths["scan_landmarks"]),
                   output=str(folder / f"{name}.obj"), report=str(folder / f"{name}.json"),
                   texture=None)


def test_jobs_share_the_graph_cache_they_are_given(tmp_path):
    cache = GraphCache()
    settings = WrapSettings(model="graph")
    first = _job(tmp_path, "first")
    run_wrap_job(first, settings, graph_cache=cache)
    built = len(cache)
    assert built >= 1                                  # the job filled the caller's cache
    second = dataclasses.replace(first, output=str(tmp_path / "second.obj"),
                                 report=str(tmp_path / "second.json"))
    run_wrap_job(second, settings, graph_cache=cache)
    assert len(cache) == built                         # same template: nothing new built
    a, b = read_mesh(first.output), read_mesh(second.output)
    np.testing.assert_allclose(a.vertices, b.vertices, atol=1e-9)
    assert json.loads((tmp_path / "second.json").read_text())["metrics"]["fit_mean"] >= 0
    cache.clear()
    assert len(cache) == 0
