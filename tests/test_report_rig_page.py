"""The rig's page (facewrap.report.rig_page): sliders for its shapes, each example
scan beside the rig at its weights, heatmaps that agree with the examples table."""

from __future__ import annotations

import base64

import numpy as np
import pytest

from facewrap.report.rig_page import reconstruction_errors, write_rig_page
from facewrap.rig import build_rig
from facewrap.sample import make_scan, make_template
from test_report_page import page_data

EXPRESSIONS = [{"smile": 1.0}, {"jaw_open": 0.8}]


def _values(entry) -> np.ndarray:
    return np.frombuffer(base64.b64decode(entry["values"]), dtype=np.float32)


@pytest.fixture(scope="module")
def rigged():
    tpl = make_template(20)
    kw = dict(seed=3, resolution=40, texture_size=8)
    neutral = make_scan(tpl, weights={}, **kw)
    scans = [make_scan(tpl, weights=w, **kw) for w in EXPRESSIONS]
    rig = build_rig(tpl.mesh, neutral.mesh, tpl.landmarks, neutral.landmarks,
                    tpl.blendshapes, expression_scans=[s.mesh for s in scans],
                    expression_landmarks=[s.landmarks for s in scans])
    return tpl, neutral, scans, rig


def test_the_page_plays_the_shapes_and_shows_every_example(rigged, tmp_path):
    tpl, neutral, scans, rig = rigged
    page = write_rig_page(tmp_path, rig, neutral.mesh,
                          expression_scans=[s.mesh for s in scans], units="mm")
    data = page_data(page)
    names = [m["name"] for m in data["meshes"]]
    assert names == ["rig", "neutral scan", "expression 1: scan", "expression 1: rig",
                     "expression 2: scan", "expression 2: rig"]
    assert data["blendshapes"]["mesh"] == "rig"
    assert sorted(s["name"] for s in data["blendshapes"]["shapes"]) == sorted(rig.shapes)
    text = page.read_text()
    assert "Examples" in text and "rig error mean" in text and " mm" in text


def test_heatmaps_and_the_examples_table_agree(rigged, tmp_path):
    """Each heatmap is the error the examples table gives: same vertices, same mean."""
    tpl, neutral, scans, rig = rigged
    data = page_data(write_rig_page(tmp_path, rig, neutral.mesh,
                                    expression_scans=[s.mesh for s in scans], units="mm"))
    maps = {s["name"]: s for s in data["scalars"]}
    for k, error in enumerate(rig.examples.errors, start=1):
        entry = maps[f"expression {k}: rig error"]
        assert entry["units"] == "mm"
        v = _values(entry)
        ok = ~np.isnan(v)
        assert ok.sum() == entry["stats"]["count"] > 0.25 * rig.neutral.n_vertices
        assert v[ok].mean() == pytest.approx(error["mean"], rel=1e-4)
        assert np.percentile(v[ok], 95) == pytest.approx(error["p95"], rel=1e-3)


def test_the_rig_at_an_examples_weights_lies_over_that_scan(rigged):
    """The reconstruction sits on the example's scan moved onto the neutral's pose:
    its distance to that scan is of the order of the table's error, far below the
    neutral's (the expression is there)."""
    from facewrap.evaluate import surface_distances
    tpl, neutral, scans, rig = rigged
    for (rebuilt, example, distance), pose, scan in zip(
            reconstruction_errors(rig), rig.examples.poses, scans):
        moved = (pose.apply(scan.mesh.vertices), scan.mesh.triangles)
        on = ~np.isnan(distance)
        near = surface_distances(rebuilt[on], moved).summary("")["mean"]
        still = surface_distances(rig.neutral.vertices[on], moved).summary("")["mean"]
        assert near < 0.3 * still, (near, still)


def test_a_rig_without_examples_has_sliders_only(rigged, tmp_path):
    tpl, neutral, _, _ = rigged
    rig = build_rig(tpl.mesh, neutral.mesh, tpl.landmarks, neutral.landmarks,
                    tpl.blendshapes)
    data = page_data(write_rig_page(tmp_path, rig, neutral.mesh, units="mm"))
    assert [m["name"] for m in data["meshes"]] == ["rig", "neutral scan"]
    assert not data.get("scalars") and len(data["blendshapes"]["shapes"]) == len(rig.shapes)
    with pytest.raises(ValueError, match="expression_scans"):
        write_rig_page(tmp_path, rigged[3], neutral.mesh, expression_scans=[])
