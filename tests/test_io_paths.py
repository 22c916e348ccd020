"""facewrap.io.paths: the one output guard, the pre-flight and staged outputs."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from facewrap.errors import InputError
from facewrap.io.paths import (StagedOutputs, check_output_paths, check_outputs_apart,
                               check_writable, find_overlap, new_folders_removed_on_failure,
                               shown_path, side_files, special_kind, staged_outputs)


@pytest.fixture
def tree(tmp_path) -> Path:
    """in/a.obj (with an MTL and its texture), in/shapes/s.obj, out/."""
    (tmp_path / "in" / "shapes").mkdir(parents=True)
    (tmp_path / "in" / "a.obj").write_text("# head\nmtllib a.mtl\nv 0 0 0\n")
    (tmp_path / "in" / "a.mtl").write_text("newmtl m\nmap_Kd -s 1 1 1 tex/a.png\n")
    (tmp_path / "in" / "shapes" / "s.obj").write_text("v 0 0 0\n")
    (tmp_path / "out").mkdir()
    return tmp_path


def test_an_output_on_an_input_is_found_however_it_is_spelt(tree):
    a = tree / "in" / "a.obj"
    os.symlink(a, tree / "link.obj")
    os.symlink(tree / "in", tree / "in_link")
    for spelling in (a, tree / "out" / ".." / "in" / "a.obj", tree / "link.obj",
                     tree / "in_link" / "a.obj"):
        hit = find_overlap([spelling], [a])
        assert hit is not None and hit[1] == f"is also an input {str(a)!r}"
    assert find_overlap([tree / "out" / "a.obj"], [a]) is None


def test_outputs_inside_an_input_folder_are_refused(tree):
    shapes = tree / "in" / "shapes"
    for out in (shapes, shapes / "s.obj", shapes / "new" / "x.obj"):
        with pytest.raises(InputError, match="inputs are never overwritten") as exc:
            check_outputs_apart([out], [shapes])
        assert str(shapes) in str(exc.value) and str(out) in str(exc.value)
    # a folder beside the input folder, or its parent folder, is not inside it
    check_outputs_apart([tree / "in" / "shapes2", tree / "in"], [shapes])


def test_an_input_obj_brings_its_material_files_and_textures(tree):
    a = tree / "in" / "a.obj"
    assert side_files(a) == [str(tree / "in" / "a.mtl"), str(tree / "in" / "tex" / "a.png")]
    with pytest.raises(InputError, match=r"a\.png.*\(read with .*a\.obj'\)"):
        check_outputs_apart([tree / "in" / "tex" / "a.png"], [a])
    assert side_files(tree / "in" / "shapes" / "s.obj") == []
    assert side_files(tree / "missing.obj") == []


def test_two_outputs_that_are_one_file_are_refused(tree):
    with pytest.raises(InputError, match="same file"):
        check_outputs_apart([tree / "out" / "x.obj", tree / "out" / "." / "x.obj"], [])


def test_pre_flight_names_what_is_in_the_way(tree):
    a = tree / "in" / "a.obj"
    with pytest.raises(InputError, match="is a file, not a folder") as exc:
        check_writable(files=[a / "deeper" / "x.obj"])
    assert str(a) in str(exc.value)
    with pytest.raises(InputError, match="output folder .* is a file"):
        check_writable(folders=[a])
    with pytest.raises(InputError, match="is a folder, not a file"):
        check_writable(files=[tree / "out"])
    check_writable(files=[tree / "new" / "deep" / "x.obj"], folders=[tree / "new2"])
    assert not (tree / "new").exists() and not (tree / "new2").exists()


def test_a_read_only_folder_is_refused(tree):
    ro = tree / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        if os.access(ro, os.W_OK):
            pytest.skip("running as root: a read-only mode does not stop writes")
        with pytest.raises(InputError, match="is not writable"):
            check_output_paths(files=[ro / "sub" / "x.obj"])
    finally:
        ro.chmod(0o755)


def test_staged_outputs_appear_together(tree):
    out = tree / "out"
    with staged_outputs() as stage:
        stage.file(out / "a.txt").write_text("a")
        folder = stage.folder(out / "frames")
        (folder / "f0.obj").write_text("f0")
        (folder / "sub").mkdir()
        (folder / "sub" / "g.obj").write_text("g")
        # nothing is in place before the block ends
        assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == []
    assert (out / "a.txt").read_text() == "a"
    assert (out / "frames" / "f0.obj").read_text() == "f0"
    assert (out / "frames" / "sub" / "g.obj").read_text() == "g"
    assert sorted(p.name for p in out.iterdir()) == ["a.txt", "frames"]
    # a second run merges into the existing folders and replaces the files
    with staged_outputs() as stage:
        (stage.folder(out / "frames") / "sub").mkdir()
        stage.file(out / "a.txt").write_text("b")
    assert (out / "a.txt").read_text() == "b" and (out / "frames" / "f0.obj").is_file()


def test_a_failed_run_leaves_nothing_and_keeps_earlier_outputs(tree):
    out = tree / "out"
    (out / "old.txt").write_text("earlier run")
    with pytest.raises(OSError, match="disk full"):
        with staged_outputs() as stage:
            stage.file(out / "old.txt").write_text("half")
            (stage.folder(tree / "new" / "deep" / "frames") / "f0.obj").write_text("x")
            raise OSError("disk full")
    assert (out / "old.txt").read_text() == "earlier run"
    assert sorted(p.name for p in out.iterdir()) == ["old.txt"]
    assert not (tree / "new").exists()    # the folders made for the run are gone


def test_discard_keeps_folders_that_were_there(tree):
    stage = StagedOutputs()
    stage.file(tree / "out" / "x.obj").write_text("x")
    stage.discard()
    assert (tree / "out").is_dir() and list((tree / "out").iterdir()) == []


def test_outputs_that_are_devices_or_fifos_are_refused(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for path, folder, said in ((fifo, False, "is a fifo, not a file"),
                               (fifo, True, "is a fifo, not a folder"),
                               ("/dev/null", False, "is a character device")):
        with pytest.raises(InputError, match=said):
            check_writable(**({"folders": [path]} if folder else {"files": [path]}))
    loop = tmp_path / "loop"
    os.symlink(loop, loop)
    assert special_kind(loop) == "a symlink loop"
    assert special_kind(tmp_path) is None and special_kind(tmp_path / "none") is None
    with pytest.raises(InputError, match="name is empty"):
        check_writable(folders=[""])


def test_a_commit_that_fails_leaves_no_staged_files(tmp_path):
    """A folder output whose destination turned into a file meanwhile: the move
    fails, and neither the staged folder nor its files are left behind."""
    final = tmp_path / "out"
    with pytest.raises(OSError):
        with staged_outputs() as stage:
            (stage.folder(final) / "a.txt").write_text("a")
            final.write_text("in the way")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_shown_path_takes_staged_names_off():
    staged = os.path.join("o", ".facewrap-staged-0123abcd-seq", ".tmp-89abcdef-f.obj")
    assert shown_path(staged) == os.path.join("o", "seq", "f.obj")
    assert shown_path("a/.hidden-f.obj") == "a/.hidden-f.obj"


def test_new_folders_are_removed_on_failure_only(tmp_path):
    kept = tmp_path / "ok" / "deep"
    with new_folders_removed_on_failure(kept):
        kept.mkdir(parents=True)
    assert kept.is_dir()
    with pytest.raises(RuntimeError):
        with new_folders_removed_on_failure(tmp_path / "x" / "y"):
            (tmp_path / "x" / "y").mkdir(parents=True)
            (tmp_path / "x" / "other.txt").write_text("not ours to remove")
            raise RuntimeError
    assert sorted(p.name for p in (tmp_path / "x").iterdir()) == ["other.txt"]
