"""Start-up (issue 20): a command imports what it uses and nothing else.

Checked on the modules a fresh ``python -m facewrap.cli ...`` process holds when it
ends (``sys.modules``), never on time; and the help a command prints is the same
whether only it or every command was loaded.
"""

from __future__ import annotations

import importlib
import json
import subprocess
import sys

import pytest

from facewrap.cli import COMMANDS, build_parser

#: what no help and no wrap needs: the pictures, batches, transfer, avatar, job files,
#: and the heavy third-party packages behind them
NEVER_FOR_A_WRAP = ("facewrap.report", "facewrap.batch", "facewrap.transfer",
                    "facewrap.avatar", "facewrap.jobs.transfer_job", "facewrap.jobs.jobfile",
                    "facewrap.wrapping.track", "facewrap.animation", "dask",
                    "distributed", "trimesh", "rich", "pygltflib", "PIL")

_PROBE = """
import contextlib, io, json, sys
from facewrap.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    try:
        code = main(sys.argv[1:])
    except SystemExit as stop:
        code = stop.code
print(json.dumps({"code": code, "modules": sorted(sys.modules)}))
"""


def _modules_after(*argv) -> set[str]:
    """The modules of a fresh process that ran ``facewrap ARGV`` (its status must be 0)."""
    run = subprocess.run([sys.executable, "-c", _PROBE, *map(str, argv)],
                         capture_output=True, text=True, check=True)
    out = json.loads(run.stdout.strip().splitlines()[-1])
    assert out["code"] in (0, None), run.stderr
    return set(out["modules"])


def _fresh(code: str) -> str:
    """What ``python -c CODE`` prints, in a fresh process."""
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True).stdout.strip()


def _loaded(modules: set[str], names) -> list[str]:
    """Those of ``names`` (packages included with their submodules) in ``modules``."""
    return sorted(n for n in names if any(m == n or m.startswith(n + ".") for m in modules))


@pytest.mark.parametrize("argv", [["--help"], ["info", "--help"], ["convert", "--help"],
                                  ["evaluate", "--help"], ["report", "--help"],
                                  ["sample", "--help"], ["batch", "--help"]])
def test_light_helps_load_no_numerics(argv):
    modules = _modules_after(*argv)
    assert _loaded(modules, NEVER_FOR_A_WRAP + ("scipy", "igl", "facewrap.wrapping",
                                                "facewrap.geometry")) == []


def test_wrap_help_loads_no_report_batch_transfer_or_heavy_readers():
    modules = _modules_after("wrap", "--help")
    assert _loaded(modules, NEVER_FOR_A_WRAP) == []
    assert "facewrap.wrapping.settings" in modules       # its choices come from there


def test_a_whole_wrap_of_the_sample_loads_only_what_a_wrap_uses(tmp_path):
    _modules_after("sample", tmp_path / "in")
    d = tmp_path / "in"
    modules = _modules_after("wrap", d / "template.obj", d / "scan.obj",
                             "-o", tmp_path / "out.obj", "--template-landmarks",
                             d / "template_landmarks.txt", "--scan-landmarks",
                             d / "scan_landmarks.txt", "--blendshapes", d / "blendshapes",
                             "-q")
    assert (tmp_path / "out.obj").is_file()
    assert _loaded(modules, NEVER_FOR_A_WRAP) == []


@pytest.mark.parametrize("name", list(COMMANDS))
def test_a_command_prints_the_same_help_alone_or_with_every_command(name, capsys):
    def help_of(parser) -> str:
        with pytest.raises(SystemExit) as stop:
            parser.parse_args([name, "--help"])
        assert stop.value.code == 0
        return capsys.readouterr().out

    alone = help_of(build_parser(name, every=False))
    assert alone == help_of(build_parser()) and "usage: facewrap " + name in alone


@pytest.mark.parametrize("package", ["facewrap.geometry", "facewrap.wrapping",
                                     "facewrap.jobs"])
def test_lazy_packages_give_every_public_name(package):
    assert _fresh(f"import {package} as p, sys; "
                  "missing = [n for n in p.__all__ if n not in dir(p)]; "
                  "values = [getattr(p, n) for n in p.__all__]; "
                  "print(missing, all(not isinstance(v, type(sys)) for v in values))"
                  ) == "[] True"


def test_a_public_name_that_is_also_a_submodule_stays_the_public_object():
    # wrapping.track is the function even after its module, wrapping/track.py, loads
    assert _fresh("import facewrap.wrapping.track, facewrap.wrapping as w, facewrap; "
                  "from facewrap.wrapping import track; "
                  "print(callable(track), track is w.track is facewrap.track, "
                  "type(track).__name__)") == "True True function"


def test_an_unknown_name_of_a_lazy_package_is_an_attribute_error():
    geometry = importlib.import_module("facewrap.geometry")
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        geometry.no_such_name  # noqa: B018
    with pytest.raises(ImportError):
        exec("from facewrap.geometry import no_such_name", {})
