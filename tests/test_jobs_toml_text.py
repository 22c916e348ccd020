"""TOML text of job files (facewrap.jobs.toml_text): lines of keys, emitted values."""

from __future__ import annotations

import math
import tomllib

import pytest
from hypothesis import given, settings as hsettings, strategies as st

from facewrap.errors import InputError
from facewrap.jobs.toml_text import find_line, read_toml, toml_key, toml_string, toml_value

TEXT = """version = 1
[inputs]
scan = "a.obj"   # a comment
[wrap]
model = "rbf"
[[wrap.stages]]
iterations = 3
[[wrap.stages]]
iterations = 4
"""


@hsettings(max_examples=200, deadline=None)
@given(st.text())
def test_toml_strings_round_trip(s):
    assert tomllib.loads(f"k = {toml_string(s)}")["k"] == s


@hsettings(max_examples=100, deadline=None)
@given(st.recursive(st.none() | st.booleans() | st.integers(-2**63, 2**63 - 1)
                    | st.floats(allow_nan=False, allow_infinity=False) | st.text(),
                    lambda inner: st.lists(inner, max_size=3)
                    | st.dictionaries(st.text(max_size=5), inner, max_size=3),
                    max_leaves=8).filter(lambda v: v is not None))
def test_values_round_trip(value):
    def clean(v):  # TOML has no null: drop None items the strategy made
        if isinstance(v, list):
            return [clean(x) for x in v if x is not None]
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items() if x is not None}
        return v
    value = clean(value)
    assert tomllib.loads(f"k = {toml_value(value)}")["k"] == value


def test_keys_are_quoted_only_when_needed():
    assert toml_key("node_spacing") == "node_spacing"
    assert tomllib.loads(f"{toml_key('a b.c')} = 1") == {"a b.c": 1}


def test_non_finite_numbers_and_objects_are_refused():
    with pytest.raises(ValueError, match="non-finite"):
        toml_value(math.inf)
    with pytest.raises(TypeError, match="object"):
        toml_value(object())


@pytest.mark.parametrize("table, key, index, line", [
    ("", "version", None, 1), ("inputs", "scan", None, 3), ("wrap", "model", None, 5),
    ("wrap", None, None, 4), ("wrap.stages", None, 1, 8),
    ("wrap.stages", "iterations", 1, 9), ("wrap", "scan", None, None),
])
def test_find_line(table, key, index, line):
    assert find_line(TEXT, table, key, index) == line


def test_read_toml_names_the_line_of_a_syntax_error(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("a = 1\nb = = 2\n")
    with pytest.raises(InputError, match="invalid TOML") as err:
        read_toml(p)
    assert err.value.line == 2
    p.write_bytes(b"a = '\xff'\n")
    with pytest.raises(InputError, match="not UTF-8"):
        read_toml(p)
    data, source = read_toml(_ok(tmp_path))
    assert data == {"wrap": {"model": "rbf"}} and source.line("wrap", "model") == 2
    assert source.error("x", "wrap", "model").line == 2


def _ok(tmp_path):
    p = tmp_path / "ok.toml"
    p.write_text("[wrap]\nmodel = 'rbf'\n")
    return p
