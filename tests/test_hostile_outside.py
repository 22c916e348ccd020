"""Hostile cases found by a corpus from outside the repository (issue 16).

Built on the machinery of ``tests/test_hostile.py`` (its :class:`Case`, sample
copies, argument builders and the three-rule check of ``test_hostile_input``:
inputs unchanged, an error is one line naming the culprit with nothing written,
an ``ok`` case fits like the untouched job).  Kept apart from its corpus so the
two lists grow independently; ``docs/reliability.md`` is generated from that one.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import test_hostile as hostile
from facewrap.cli import main
from facewrap.io.files import memory_budget
from facewrap.texture.tiles import bake_memory
from facewrap.io.images import png_bytes
from test_hostile import Case, Run, close_to_base, sample_copy, transfer_argv, wrap_argv

base = hostile.base   # the module-scoped sample fixture

OUTSIDE: list[Case] = []


def case(kind, what, expect, match="", check=None):
    def register(build):
        OUTSIDE.append(Case(build.__name__, kind, what, expect, match, build, check))
        return build
    return register


def deep(n: int = 100_000) -> str:
    return "[" * n + "]" * n


def run_json(ctx):
    """A copy of the untouched run's JSON report."""
    return ctx.write("run.json", json.dumps(ctx.base.report))


def noise_png() -> bytes:
    """A 64 x 64 PNG of noise (so that cutting it loses pixels)."""
    rng = np.random.default_rng(0)
    return png_bytes(rng.integers(0, 256, (64, 64, 3), dtype=np.uint8))


# -- readers -----------------------------------------------------------------------------
@case("OBJ", "face index -10^22 in a face of v/vt corners", "error",
      "face index out of range")
def outside_obj_index_overflow_mixed(ctx):
    text = ctx.scan_text() + "vt 0 0\nf 1/1 2/1 -10000000000000000000000/1\n"
    p = ctx.write("scan.obj", text)
    return ctx.run(p, scan=p)


@case("landmarks", "landmark JSON nested 100000 arrays deep", "error", "nested too deeply")
def outside_landmarks_json_deep(ctx):
    p = ctx.write("scan_landmarks.json", deep())
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "scan landmark text with a UTF-8 byte-order mark", "ok",
      check=close_to_base(atol=1e-6))
def outside_landmarks_bom(ctx):
    text = "".join(f"{x!r}, {y!r}, {z!r}\r\n" for x, y, z in ctx.base.points.tolist())
    p = ctx.write("scan_landmarks.txt", b"\xef\xbb\xbf" + text.encode())
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "facewrap landmark JSON of points without names (pairs by order)", "ok",
      check=close_to_base(atol=1e-6))
def outside_landmarks_json_unnamed(ctx):
    items = [{"point": list(map(float, q))} for q in ctx.base.points]
    p = ctx.write("scan_landmarks.json",
                  json.dumps({"format": "facewrap.landmarks", "landmarks": items}))
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "scan landmarks that are a folder", "error", "is a folder")
def outside_landmarks_folder(ctx):
    p = ctx.dir / "landmarks.txt"
    p.mkdir()
    return ctx.run(p, scan_landmarks=p)


@case("markers", "one source vertex paired with two targets", "error",
      r"markers 0 and 2 pair source vertex 5 with two target vertices \(6 and 9\)")
def outside_markers_two_targets(ctx):
    p = ctx.write("markers.txt", "5 6\n7 8\n5 9\n")
    return Run(p, call=lambda: hostile.read_markers(p))


@case("markers", "one target vertex paired with two sources (YAML)", "error",
      r"target vertex 8 with two source vertices \(7 and 1\)")
def outside_markers_two_sources(ctx):
    p = ctx.write("markers.yaml", 'markers: ["5:6", "7:8", "5:6", "1:8"]\n')
    return Run(p, call=lambda: hostile.read_markers(p))


@case("transfer", "transfer with contradictory markers", "error", "one partner only")
def outside_transfer_markers_conflict(ctx):
    p = sample_copy(ctx)
    argv = transfer_argv(ctx, p, p["blendshapes/blink"].parent, "-o", ctx.dir / "shapes")
    markers = ctx.dir / "markers.txt"
    first = markers.read_text().split()[0]
    markers.write_text(markers.read_text() + f"{first} {int(first) + 1}\n")
    return Run(markers, argv)


# -- options -----------------------------------------------------------------------------
@case("options", "--pca-components beyond the number of blendshapes", "error",
      r"--pca-components\) is 99 but the folder holds 5 shape")
def outside_pca_too_many(ctx):
    p = sample_copy(ctx)
    shapes = p["blendshapes/blink"].parent
    return Run(shapes, wrap_argv(p, "-o", ctx.out, "--blendshapes", shapes,
                                 "--pca-components", "99"))


@case("options", "a value the settings refuse names the option", "error",
      r"^facewrap: error: --node-spacing: must be")
def outside_option_named(ctx):
    p = sample_copy(ctx)
    return Run("--node-spacing", wrap_argv(p, "-o", ctx.out, "--node-spacing", "0"))


@case("options", "--texture-size whose bake needs more memory than allowed", "error",
      r"--texture-size\) 16384: baking needs about 16\.3 GiB")
def outside_texture_size_memory(ctx):
    if bake_memory(16384) <= memory_budget():
        pytest.skip("this machine could bake 16384 x 16384")
    p = sample_copy(ctx)
    return Run("--texture-size", wrap_argv(p, "-o", ctx.out, "--texture", p["scan_texture"],
                                           "--texture-size", "16384"))


@case("animate", "--frames 10^9", "error", r"--frames: must be an int in \[2, 100000\]")
def outside_frames_huge(ctx):
    p = sample_copy(ctx)
    return Run("--frames", ["animate", p["template"], p["template"], "--frames",
                            "1000000000", "-o", ctx.dir / "seq"])


# -- report ------------------------------------------------------------------------------
@case("report", "run JSON nested 100000 deep", "error", "nested too deeply")
def outside_report_json_deep(ctx):
    p = ctx.write("run.json", deep())
    return Run(p, ["report", p, "-o", ctx.dir / "page"])


@case("report", "--image a truncated PNG", "error", "cannot read image")
def outside_report_image_truncated(ctx):
    img = ctx.write("img.png", noise_png()[:6000])
    return Run(img, ["report", run_json(ctx), "-o", ctx.dir / "page", "--image", img])


# -- outputs that are neither a file nor a folder ----------------------------------------
@case("outputs", "wrap -o a fifo", "error", "is a fifo, not a file")
def outside_output_fifo(ctx):
    p = sample_copy(ctx)
    fifo = ctx.dir / "fit.obj"
    os.mkfifo(fifo)
    return Run(fifo, wrap_argv(p, "-o", fifo))


@case("outputs", "sample into a fifo", "error", "is a fifo, not a folder")
def outside_sample_into_fifo(ctx):
    fifo = ctx.dir / "out"
    os.mkfifo(fifo)
    return Run(fifo, ["sample", fifo])


@case("outputs", "convert onto a character device", "error", "is a character device")
def outside_convert_onto_device(ctx):
    p = sample_copy(ctx)
    return Run("/dev/null", ["convert", p["scan"], "/dev/null"])


@case("outputs", "sample into an empty folder name", "error", "name is empty")
def outside_sample_empty_name(ctx):
    return Run("OUT", ["sample", ""])


def test_outside_corpus_names_are_new():
    names = [c.name for c in OUTSIDE]
    assert len(set(names)) == len(names) >= 15
    assert not set(names) & {c.name for c in hostile.CASES}


@pytest.mark.parametrize("c", [pytest.param(c, id=c.name) for c in OUTSIDE])
def test_outside_hostile_input(c, base, tmp_path, capsys):
    hostile.test_hostile_input(c, base, tmp_path, capsys)


def test_no_staged_folder_is_left_when_a_run_fails(base, tmp_path, capsys):
    """A device where the sample's folder goes is refused before any work, and
    nothing (no ``.facewrap-staged-*``) is left beside it."""
    fifo = tmp_path / "out"
    os.mkfifo(fifo)
    assert hostile.facewrap("sample", fifo) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


@pytest.mark.parametrize("argv, option", [
    (["batch", "--workers", "0", "m.csv"], "--workers"),
    (["batch", "--workers", "-3", "m.csv"], "--workers"),
    (["animate", "a.obj", "b.obj", "--frames", "many", "-o", "x"], "--frames"),
    (["wrap", "a.obj"], "required")])
def test_option_errors_of_the_parser_are_one_line(argv, option, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and len(err) == 1, err
    assert err[0].startswith("facewrap: error: ") and option in err[0]
