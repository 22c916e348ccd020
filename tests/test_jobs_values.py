"""Values of job files and manifests (facewrap.jobs.values): checked and converted."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Literal

import pytest

from facewrap.jobs.values import (convert_value, field_types, is_table_list,
                                  optional_inner, parse_text, resolve_path, type_name)


@dataclasses.dataclass
class Knob:
    level: float = 1.0
    count: int = 2

    def __post_init__(self):
        if self.level < 0:
            raise ValueError("Knob.level must be >= 0")


@pytest.mark.parametrize("value, tp, out", [
    (1, float, 1.0), (True, bool, True), (3, int, 3), ("a", str, "a"),
    (2, int | None, 2), ("x", Literal["x", "y"], "x"),
    ([1, 2], list[float], [1.0, 2.0]), ([1, 2], tuple[int, ...], (1, 2)),
    ({"a": 1}, dict[str, float], {"a": 1.0}),
    ({"level": 2}, Knob, Knob(level=2.0)),
])
def test_convert_value(value, tp, out):
    got = convert_value(value, tp, "k")
    assert got == out and type(got) is type(out)


@pytest.mark.parametrize("value, tp, match", [
    ("yes", bool, "'k' must be a boolean"), (1.5, int, "'k' must be an integer"),
    (True, int, "must be an integer"), (float("nan"), float, "finite"),
    ("z", Literal["x", "y"], "one of 'x', 'y'"), (3, list[int], "must be an array"),
    ({"colour": 1}, Knob, "unknown key 'colour' in k"),
    ({"level": -1}, Knob, "k: Knob.level must be >= 0"),
    ([1, "a"], list[int], r"'k\[1\]' must be an integer"),
])
def test_convert_value_says_what_was_expected(value, tp, match):
    with pytest.raises(ValueError, match=match):
        convert_value(value, tp, "k")


def test_parse_text_for_csv_cells():
    assert parse_text("off", bool, "b") is False and parse_text("7", int, "i") == 7
    assert parse_text("0.5", float | None, "f") == 0.5
    for text, tp, match in (("maybe", bool, "true or false"), ("x", int, "integer"),
                            ("x", float, "number"), ("1", list[int], "CSV cell")):
        with pytest.raises(ValueError, match=match):
            parse_text(text, tp, "c")


def test_types_in_words_and_introspection():
    assert type_name(list[Knob]) == "array of [[...]] tables (Knob)"
    assert type_name(int | None) == "integer (optional)"
    assert optional_inner(float | None) == (float, True)
    assert is_table_list(list[Knob] | None) is Knob and is_table_list(list[int]) is None
    assert field_types(Knob) == {"level": float, "count": int}


def test_resolve_path(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    assert resolve_path("~/a.obj", Path("/x")) == str(tmp_path / "a.obj")
    assert resolve_path("../b/./c.obj", Path("/x/y")) == "/x/b/c.obj"
    assert resolve_path("/abs.obj", Path("/x")) == "/abs.obj"
