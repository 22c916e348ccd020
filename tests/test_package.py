"""The package's public API (``facewrap/__init__.py``): every name resolves, lazily."""

from __future__ import annotations

import subprocess
import sys

import facewrap


def test_every_public_name_resolves_and_is_listed():
    for name in facewrap.__all__:
        assert getattr(facewrap, name) is not None, name
    assert set(facewrap.__all__) <= set(dir(facewrap))


def test_public_names_are_the_packages_own_objects():
    from facewrap.avatar import AvatarTransfer
    from facewrap.wrapping import wrap
    assert facewrap.wrap is wrap and facewrap.AvatarTransfer is AvatarTransfer


def test_importing_the_package_loads_no_engine():
    code = ("import sys, facewrap; "
            "print(sorted(m for m in sys.modules if m.startswith('facewrap.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert "facewrap.wrapping" not in out and "facewrap.transfer" not in out, out


def test_an_unknown_name_is_an_attribute_error():
    try:
        facewrap.no_such_thing
    except AttributeError as exc:
        assert "no_such_thing" in str(exc)
    else:
        raise AssertionError("expected AttributeError")
