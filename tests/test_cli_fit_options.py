"""The fitting options of ``facewrap wrap`` / ``track`` (facewrap.cli.fit_options)."""

from __future__ import annotations

import argparse
import dataclasses

import pytest

from facewrap.cli.fit_options import add_fit_options, option_name, wrap_settings_from_args
from facewrap.errors import InputError
from facewrap.params import choices_of
from facewrap.wrapping import WrapSettings


def parse(*argv):
    p = argparse.ArgumentParser()
    add_fit_options(p)
    return p.parse_args(list(argv))


def test_no_option_given_is_the_default_settings():
    assert wrap_settings_from_args(parse()) == WrapSettings()


@pytest.mark.parametrize("option, field", [("--model", "model"), ("--robust", "robust"),
                                           ("--kernel", "kernel"),
                                           ("--blend-order", "blend_order")])
def test_choices_are_the_settings_table(option, field, capsys):
    for value in choices_of(WrapSettings, field):
        assert getattr(wrap_settings_from_args(parse(option, str(value))), field) == value
    with pytest.raises(SystemExit):
        parse(option, "9")
    assert "invalid choice" in capsys.readouterr().err


def test_options_map_to_settings():
    s = wrap_settings_from_args(parse("--no-project", "--no-weight-range", "--smoothing",
                                      "0.5", "--no-landmark-pull", "--rigid-refine"))
    changed = {f.name for f in dataclasses.fields(s)
               if getattr(s, f.name) != getattr(WrapSettings(), f.name)}
    assert changed == {"project", "weight_range", "smoothing", "landmark_pull",
                       "rigid_refine"}


def test_values_the_settings_refuse_name_the_option():
    with pytest.raises(InputError, match="^--node-spacing: must be .*; got -1.0$"):
        wrap_settings_from_args(parse("--node-spacing", "-1"))


def test_every_settings_field_has_its_option():
    """option_name names a flag the parser knows, for every field an option sets."""
    p = argparse.ArgumentParser()
    add_fit_options(p)
    flags = {s for a in p._actions for s in a.option_strings}
    fields = {f.name for f in dataclasses.fields(WrapSettings)}
    checked = 0
    for action in p._actions:
        field = action.dest.removeprefix("no_")
        if field in fields:
            assert option_name(field) in flags, field
            checked += 1
    assert checked >= 15


def test_alignment_and_matching_options_map_to_settings():
    s = wrap_settings_from_args(parse("--no-scale", "--max-normal-angle", "45",
                                      "--point-weight", "0.5"))
    assert (s.scale, s.max_normal_angle, s.point_weight) == (False, 45.0, 0.5)


@pytest.mark.parametrize("option, field, value", [
    ("--max-normal-angle", "max_normal_angle", "0"),
    ("--max-normal-angle", "max_normal_angle", "181"),
    ("--point-weight", "point_weight", "-0.1"),
    ("--point-weight", "point_weight", "nan")])
def test_values_outside_the_settings_table_name_the_option(option, field, value):
    with pytest.raises(InputError, match=f"^{option}: must be"):
        wrap_settings_from_args(parse(option, value))


def test_help_states_the_allowed_range_from_the_table(capsys):
    p = argparse.ArgumentParser()
    add_fit_options(p)
    with pytest.raises(SystemExit):
        p.parse_args(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    for field in ("max_normal_angle", "point_weight"):
        assert WrapSettings.constraints[field].describe() in text


def test_output_frame_choices_are_the_jobs():
    from facewrap.jobs.wrap_job import OUTPUT_FRAMES, WrapJob
    assert parse().output_frame == WrapJob.output_frame == "scan"
    assert {parse("--output-frame", f).output_frame for f in OUTPUT_FRAMES} == {
        "scan", "template"}
    with pytest.raises(SystemExit):
        parse("--output-frame", "world")


@pytest.fixture(scope="module")
def sample_files(tmp_path_factory):
    from facewrap.sample import make_scan, make_template, write_sample
    tpl = make_template(24)
    return write_sample(tmp_path_factory.mktemp("sample"), tpl,
                        make_scan(tpl, resolution=40, texture_size=16))


def _wrap(paths, out, *extra):
    from conftest import facewrap
    return facewrap("wrap", paths["template"], paths["scan"], "-o", out, "--model", "rbf",
                    "--template-landmarks", paths["template_landmarks"], "--scan-landmarks",
                    paths["scan_landmarks"], "--report", out.with_suffix(".json"), "-q",
                    *extra)


def test_output_in_the_template_frame_overlays_the_template(sample_files, tmp_path):
    import json
    import numpy as np
    from facewrap.geometry.similarity import Similarity
    from facewrap.io import read_mesh
    on_scan, on_template = tmp_path / "scan.obj", tmp_path / "template.obj"
    assert _wrap(sample_files, on_scan) == 0
    assert _wrap(sample_files, on_template, "--output-frame", "template") == 0
    report = json.loads(on_template.with_suffix(".json").read_text())
    assert report["output_frame"] == "template"
    assert json.loads(on_scan.with_suffix(".json").read_text())["output_frame"] == "scan"
    back = Similarity.from_matrix(np.asarray(report["transform"])).inverse()
    V_scan, V_tpl = read_mesh(on_scan).vertices, read_mesh(on_template).vertices
    template = read_mesh(sample_files["template"])
    size = template.scale()
    # the same fit, mapped back by the inverse of the landmark similarity ...
    assert np.abs(back.apply(V_scan) - V_tpl).max() < 1e-6 * size
    # ... lies over the template (another identity: close, not equal), the scan-frame
    # result does not (the sample's scan is moved and turned)
    assert np.linalg.norm(V_tpl - template.vertices, axis=1).mean() < 0.03 * size
    assert np.linalg.norm(V_scan - template.vertices, axis=1).mean() > 0.1 * size
    assert np.array_equal(read_mesh(on_template).face_indices, template.face_indices)


def test_a_job_file_output_frame_is_checked_at_the_door(sample_files, tmp_path, capsys):
    from conftest import facewrap
    p = sample_files
    job = tmp_path / "job.toml"
    job.write_text("[inputs]\n" + "".join(f'{k} = "{p[k]}"\n' for k in (
        "template", "template_landmarks", "scan", "scan_landmarks"))
        + '[outputs]\noutput = "out/fitted.obj"\noutput_frame = "world"\n'
          '[wrap]\nmodel = "rbf"\n')
    capsys.readouterr()
    assert facewrap("run", job) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "output_frame" in err[0] and "'template'" in err[0]
    assert not (tmp_path / "out").exists()


def test_no_scale_keeps_the_template_size(sample_files, tmp_path):
    import json
    import numpy as np
    from facewrap.geometry.similarity import Similarity

    def scale(*extra):
        out = tmp_path / f"s{len(extra)}.obj"
        assert _wrap(sample_files, out, *extra) == 0
        report = json.loads(out.with_suffix(".json").read_text())
        assert report["settings"]["scale"] is not bool(extra)
        return Similarity.from_matrix(np.asarray(report["transform"])).scale

    assert scale("--no-scale") == pytest.approx(1.0, abs=1e-9)
    assert abs(scale() - 1.0) > 1e-3  # the sample's scan is of another size
