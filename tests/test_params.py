"""Settings are checked at the door: every constraint of every settings class refuses
what it must, and the defaults pass (generated from the classes' own tables)."""

from __future__ import annotations

import dataclasses
import importlib
import pkgutil

import pytest

import facewrap
from facewrap.params import Interval, Options, choices_of, invalid_examples


def _settings_classes():
    found = {}
    for info in pkgutil.walk_packages(facewrap.__path__, "facewrap."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for obj in vars(module).values():
            if isinstance(obj, type) and dataclasses.is_dataclass(obj) \
                    and isinstance(getattr(obj, "constraints", None), dict) \
                    and obj.__module__ == module.__name__:
                found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return found


SETTINGS = _settings_classes()
CASES = [(name, field, value) for name, cls in sorted(SETTINGS.items())
         for field, value in invalid_examples(cls)]


def test_the_settings_classes_are_found():
    names = {n.rsplit(".", 1)[1] for n in SETTINGS}
    assert {"WrapSettings", "Stage"} <= names


@pytest.mark.parametrize("name", sorted(SETTINGS))
def test_defaults_pass_and_every_field_is_constrained(name):
    cls = SETTINGS[name]
    cls()                                   # the defaults are valid
    unconstrained = [f.name for f in dataclasses.fields(cls) if f.name not in cls.constraints]
    assert not unconstrained, f"{name}: no constraint for {unconstrained}"


@pytest.mark.parametrize("name,field,value", CASES, ids=[f"{n.rsplit('.', 1)[1]}.{f}={v!r}"
                                                         for n, f, v in CASES])
def test_every_constraint_refuses_a_wrong_value(name, field, value):
    cls = SETTINGS[name]
    with pytest.raises(ValueError) as err:
        cls(**{field: value})
    text = str(err.value)
    assert f"{cls.__name__}.{field}" in text and repr(value) in text


def test_the_message_names_field_allowed_values_and_what_was_given():
    from facewrap.wrapping import WrapSettings
    with pytest.raises(ValueError, match=r"WrapSettings.model must be one of 'auto', .*"
                                         r"got 'grpah'"):
        WrapSettings(model="grpah")
    with pytest.raises(ValueError, match=r"WrapSettings.blend_order must be one of 1, 2; "
                                         r"got 7"):
        WrapSettings(blend_order=7)
    with pytest.raises(ValueError, match="node_spacing"):
        WrapSettings(node_spacing=-1.0)
    with pytest.raises(ValueError, match="robust"):
        WrapSettings(robust="hubr")


def test_choices_come_from_the_table():
    from facewrap.wrapping import WrapSettings
    assert choices_of(WrapSettings, "robust") == ("welsch", "huber", "geman_mcclure", "none")
    assert choices_of(WrapSettings, "node_spacing") is None


@pytest.mark.parametrize("rule,good,bad", [
    (Interval(float, 0, 1, closed="neither"), [0.5, 1e-9], [0.0, 1.0, float("inf"), True]),
    (Interval(float, 0, 1, closed="both"), [0.0, 1.0, 1], [-1e-9, float("nan")]),
    (Interval(int, 1, None), [1, 10**9], [0, 1.0, False]),
    (Options("a", "b"), ["a"], ["c", None, 1]),
    (Options(1, 2), [1, 2], [True, 1.0, 3]),
])
def test_constraints_alone(rule, good, bad):
    assert all(rule.holds(v) for v in good)
    assert not any(rule.holds(v) for v in bad)
