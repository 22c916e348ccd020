"""The ``facewrap`` entry point (``facewrap.cli``): one module per command, loaded
only when that command runs."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from facewrap.cli import COMMANDS, build_parser, chosen_command, main


def test_the_command_is_the_first_word_that_is_not_an_option():
    assert chosen_command(["-v", "--silent", "wrap", "t.obj"]) == "wrap"
    assert chosen_command(["--version"]) is None


def test_help_lists_every_command_with_its_summary(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--help"])
    assert stop.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    for name in COMMANDS:
        assert name in text
    assert "fit a template onto a scan" in text


def test_every_command_registers_its_options():
    parser = build_parser()                    # every command loaded
    for name in COMMANDS:
        with pytest.raises(SystemExit) as stop:
            parser.parse_args([name, "--help"])
        assert stop.value.code == 0


@pytest.mark.parametrize("command,absent", [
    ("info", "facewrap.wrapping"), ("convert", "facewrap.jobs"), (None, "facewrap.io")])
def test_a_command_loads_only_what_it_uses(command, absent):
    code = ("import sys; from facewrap.cli import build_parser; "
            f"build_parser({command!r}, every=False); print({absent!r} in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "False"


@pytest.mark.parametrize("chosen,expected", [(None, "0"), ("1", "1")])
def test_the_command_line_asks_numpy_for_small_pages_unless_told(chosen, expected):
    # measured: huge pages cost a 951k-triangle wrap 7 % of its wall time in the
    # kernel on the CI machine; a user's own setting is kept
    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    if chosen is not None:
        env["NUMPY_MADVISE_HUGEPAGE"] = chosen
    code = ("import os, sys; sys.argv = ['facewrap', 'info', '--help']\n"
            "from facewrap.cli import main\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "print(os.environ['NUMPY_MADVISE_HUGEPAGE'])")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True).stdout
    assert out.split()[-1] == expected
