"""The fitting options of ``facewrap wrap`` / ``track`` (facewrap.cli.fit_options)."""

from __future__ import annotations

import argparse
import dataclasses

import pytest

from facewrap.cli.fit_options import add_fit_options, wrap_settings_from_args
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


def test_values_the_settings_refuse_name_the_field():
    with pytest.raises(ValueError, match="WrapSettings.node_spacing"):
        wrap_settings_from_args(parse("--node-spacing", "-1"))
