"""Atomic outputs: complete or absent, with the permissions ``open`` would give."""

import contextlib
import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from facewrap.io import write_mesh
from facewrap.io.atomic import atomic_write
from facewrap.io.gltf import write_gltf_morphs
from facewrap.mesh import Mesh

SRC = Path(__file__).resolve().parents[1] / "src"
posix_only = pytest.mark.skipif(os.name != "posix", reason="permission bits are POSIX")


@contextlib.contextmanager
def umask(value: int):
    old = os.umask(value)
    try:
        yield
    finally:
        os.umask(old)


def mode_of(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def litter(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if p.name.startswith(".tmp")]


@posix_only
@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002, 0o027])
def test_new_file_gets_0666_less_the_umask(tmp_path, mask):
    target = tmp_path / "out.txt"
    with umask(mask):
        with atomic_write(target) as fh:
            fh.write("done")
        with open(tmp_path / "plain.txt", "w") as fh:  # what open() would make
            fh.write("done")
    assert mode_of(target) == 0o666 & ~mask == mode_of(tmp_path / "plain.txt")
    assert target.read_text() == "done" and litter(tmp_path) == []


@posix_only
@pytest.mark.parametrize("kept", [0o640, 0o600, 0o664])
def test_replaced_file_keeps_its_permission_bits(tmp_path, kept):
    target = tmp_path / "out.bin"
    target.write_bytes(b"old")
    os.chmod(target, kept)
    with umask(0o022):
        with atomic_write(target, "wb") as fh:
            fh.write(b"new")
    assert target.read_bytes() == b"new"
    assert mode_of(target) == kept


@posix_only
def test_set_id_bits_of_a_replaced_file_are_dropped(tmp_path):
    target = tmp_path / "tool"
    target.write_bytes(b"old")
    os.chmod(target, 0o4755)
    with atomic_write(target, "wb") as fh:
        fh.write(b"new")
    assert mode_of(target) == 0o755


def test_a_failed_write_leaves_the_old_file_and_no_litter(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    before = os.stat(target)
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_write(target) as fh:
            fh.write("half")
            raise RuntimeError("boom")
    assert target.read_text() == "old" and litter(tmp_path) == []
    assert stat.S_IMODE(before.st_mode) == mode_of(target)
    with pytest.raises(RuntimeError):
        with atomic_write(tmp_path / "new.txt") as fh:
            raise RuntimeError("boom")
    assert not (tmp_path / "new.txt").exists() and litter(tmp_path) == []


def test_bad_open_arguments_leave_no_litter(tmp_path):
    with pytest.raises(LookupError):
        with atomic_write(tmp_path / "x.txt", encoding="no-such-codec"):
            pass
    assert list(tmp_path.iterdir()) == []


@posix_only
@pytest.mark.parametrize("name", ["m.obj", "m.ply", "m.glb", "m.gltf"])
def test_every_mesh_writer_follows_the_umask(tmp_path, name):
    mesh = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]])
    with umask(0o027):
        if name.endswith((".glb", ".gltf")):
            write_gltf_morphs(tmp_path / name, mesh, {"a": mesh.vertices + 1})
        else:
            write_mesh(tmp_path / name, mesh)
    assert mode_of(tmp_path / name) == 0o640


@posix_only
def test_cli_output_follows_the_umask_of_the_shell(tmp_path):
    src = tmp_path / "in.obj"
    src.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    os.chmod(src, 0o444)
    before = src.read_bytes()
    env = dict(os.environ, PYTHONPATH=str(SRC))
    for mask, expected in ((0o022, 0o644), (0o077, 0o600)):
        out = tmp_path / f"out{mask:o}.ply"
        r = subprocess.run([sys.executable, "-m", "facewrap.cli", "convert", str(src),
                            str(out)], capture_output=True, text=True, env=env,
                           preexec_fn=lambda m=mask: os.umask(m))
        assert r.returncode == 0, r.stderr
        assert mode_of(out) == expected
    assert src.read_bytes() == before and mode_of(src) == 0o444


def test_a_write_beyond_the_file_size_limit_names_the_output(tmp_path):
    """EFBIG (``ulimit -f``; ENOSPC alike) carries no file name: the error names the
    output as the user asked for it, and nothing is left."""
    import errno
    import resource
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    staged = tmp_path / ".facewrap-staged-0123abcd-out"
    staged.mkdir()
    target = staged / "big.bin"
    resource.setrlimit(resource.RLIMIT_FSIZE, (4096, hard))
    try:
        with pytest.raises(OSError) as exc:
            with atomic_write(target, "wb") as fh:
                fh.write(b"x" * 100_000)
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
    assert exc.value.errno == errno.EFBIG
    assert exc.value.filename == str(tmp_path / "out" / "big.bin")
    assert litter(staged) == [] and not target.exists()
