"""The ``facewrap`` entry point (``facewrap.cli``): one module per command, loaded
only when that command runs."""

from __future__ import annotations

import json
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


def _command_environment(**chosen) -> dict:
    """The environment a ``facewrap info --help`` process ends with, started with
    the memory settings ``chosen`` and none of the others."""
    names = ("NUMPY_MADVISE_HUGEPAGE", "MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_")
    env = {k: v for k, v in os.environ.items() if k not in names} | chosen
    code = ("import json, os, sys; sys.argv = ['facewrap', 'info', '--help']\n"
            "from facewrap.cli import main\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "print(json.dumps(dict(os.environ)))")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True).stdout
    return json.loads(out.splitlines()[-1])


def test_the_command_line_sets_memory_defaults_unless_told():
    # measured: huge pages and glibc's unmapping of freed blocks cost a
    # 951k-triangle wrap 7 % and 10 % of its wall time on the CI machine
    env = _command_environment()
    assert env["NUMPY_MADVISE_HUGEPAGE"] == "0"
    glibc = sys.platform == "linux" and os.confstr("CS_GNU_LIBC_VERSION")
    if glibc:
        assert int(env["MALLOC_MMAP_THRESHOLD_"]) in (256 << 20, 32 << 20)
        assert int(env["MALLOC_TRIM_THRESHOLD_"]) == 1 << 30
    else:
        assert "MALLOC_MMAP_THRESHOLD_" not in env


def test_a_users_memory_settings_are_kept():
    env = _command_environment(NUMPY_MADVISE_HUGEPAGE="1", MALLOC_TRIM_THRESHOLD_="4096")
    assert env["NUMPY_MADVISE_HUGEPAGE"] == "1"
    assert env["MALLOC_TRIM_THRESHOLD_"] == "4096"
    assert "MALLOC_MMAP_THRESHOLD_" not in env     # the user tunes malloc: none of ours
