import json
import subprocess
import sys

import numpy as np
import pytest

from facewrap.cli import main
from facewrap.io.obj import read_obj, write_obj


def test_help_lists_subcommands(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for cmd in ("wrap", "info", "convert", "sample", "demo", "animate"):
        assert cmd in out


def test_info_and_convert(mixed_mesh, tmp_path, capsys):
    src = tmp_path / "m.obj"
    write_obj(src, mixed_mesh)
    assert main(["info", str(src), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["vertices"] == 7 and info["polygon_sizes"] == {"3": 1, "4": 2}
    assert info["boundary_loops"] == 1 and info["components"] == 1
    ply = tmp_path / "m.ply"
    assert main(["convert", str(src), str(ply)]) == 0
    back = tmp_path / "back.obj"
    assert main(["convert", str(ply), str(back)]) == 0
    assert np.array_equal(read_obj(back).face_indices, mixed_mesh.face_indices)


@pytest.mark.slow
def test_bad_input_is_one_line_and_exit_2(tmp_path):
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
    r = subprocess.run([sys.executable, "-m", "facewrap.cli", "info", str(bad)],
                       capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.strip() == f"facewrap: error: {bad}:4: vertex index 7 out of " \
                               "range (the file has 3)"
    r = subprocess.run([sys.executable, "-m", "facewrap.cli", "info",
                        str(tmp_path / "none.obj")], capture_output=True, text=True)
    assert r.returncode == 2 and "no such file" in r.stderr
    r = subprocess.run([sys.executable, "-m", "facewrap.cli", "info",
                        str(tmp_path / "x.fbx")], capture_output=True, text=True)
    assert r.returncode == 2 and "unknown mesh format" in r.stderr


def test_animate_sequence(mixed_mesh, tmp_path):
    a, b = tmp_path / "a.obj", tmp_path / "b.obj"
    write_obj(a, mixed_mesh)
    write_obj(b, mixed_mesh.with_vertices(mixed_mesh.vertices + [0, 0, 2]))
    assert main(["animate", str(a), str(b), "--frames", "5", "-o",
                 str(tmp_path / "seq")]) == 0
    frames = sorted((tmp_path / "seq").glob("*.obj"))
    assert len(frames) == 5
    mid = read_obj(frames[2])
    assert np.allclose(mid.vertices, mixed_mesh.vertices + [0, 0, 1])
    assert np.array_equal(mid.face_uvs, mixed_mesh.face_uvs)
    other = tmp_path / "c.obj"
    write_obj(other, mixed_mesh.submesh([0])[0])
    assert main(["animate", str(a), str(other), "-o", str(tmp_path / "s2")]) == 2


def test_a_value_the_settings_refuse_is_one_line_and_exit_2(tmp_path, capsys):
    argv = ["wrap", "t.obj", "s.obj", "-o", str(tmp_path / "o.obj"),
            "--template-landmarks", "t.txt", "--scan-landmarks", "s.txt",
            "--node-spacing", "-1"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    # the option as typed, not the settings field behind it
    assert err.startswith("facewrap: error: --node-spacing: must be") and "\n" not in err
    assert not (tmp_path / "o.obj").exists()


def test_every_command_has_help(capsys):
    for cmd in ("info", "convert", "sample", "wrap", "animate", "track", "transfer",
                "evaluate", "report", "run", "batch", "demo"):
        with pytest.raises(SystemExit) as exc:
            main([cmd, "--help"])
        assert exc.value.code == 0 and f"facewrap {cmd}" in capsys.readouterr().out
