"""The transfer command end to end (facewrap.cli.transfer on the library)."""

import argparse
import json
import numpy as np
import pytest

from facewrap.errors import InputError
from facewrap.io import read_mesh, write_obj
from transfer_cases import pair


def _run_cli(argv):
    from facewrap.cli.transfer import register
    p = argparse.ArgumentParser()
    register(p.add_subparsers(), "summary")
    args = p.parse_args(["transfer", *argv])
    return args.func(args)


def test_cli_transfer_writes_objs_glb_report(pair, tmp_path):
    face, scan, markers, shapes, _ = pair
    write_obj(tmp_path / "src.obj", face)
    write_obj(tmp_path / "tgt.obj", scan)
    (tmp_path / "shapes").mkdir()
    for k in ("jaw_open", "smile"):
        write_obj(tmp_path / "shapes" / f"{k}.obj", face.with_vertices(shapes[k]))
    (tmp_path / "m.txt").write_text(f"{len(markers[0])}\n" + "".join(
        f"{a} {b}\n" for a, b in zip(*markers)))
    argv = [str(tmp_path / "src.obj"), str(tmp_path / "tgt.obj"), "--source-shapes",
            str(tmp_path / "shapes"), "--markers", str(tmp_path / "m.txt"), "-o",
            str(tmp_path / "out"), "--gltf", str(tmp_path / "o.glb"), "--correspondence",
            str(tmp_path / "c.npz"), "--report", str(tmp_path / "r.json"), "-q"]
    assert _run_cli(argv) == 0
    out = read_mesh(tmp_path / "out" / "jaw_open.obj")
    assert out.n_vertices == scan.n_vertices
    np.testing.assert_array_equal(out.face_indices, scan.face_indices)
    assert (tmp_path / "c.npz").is_file() and (tmp_path / "o.glb").is_file()
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["shapes"] == 2
    first = out.vertices
    assert _run_cli(argv) == 0            # second run reuses the correspondence
    np.testing.assert_allclose(read_mesh(tmp_path / "out" / "jaw_open.obj").vertices,
                               first, atol=1e-5)
    assert isinstance(report["flip_repairs"], dict)
    assert report["ambiguity"] is None                 # only when asked for
    assert _run_cli(argv + ["--ambiguity"]) == 0
    amb = json.loads((tmp_path / "r.json").read_text())["ambiguity"]
    assert amb["marker_hints"] and all(0 <= v < scan.n_vertices
                                       for v in amb["marker_hints"])
    # --no-fix-flips: the plain solve (equal here: nothing flips on the sample)
    assert _run_cli(argv + ["--no-fix-flips"]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["flip_repairs"] == {}
    np.testing.assert_allclose(read_mesh(tmp_path / "out" / "jaw_open.obj").vertices,
                               first, atol=1e-5)


def test_cli_bad_inputs_name_the_file(pair, tmp_path):
    face, scan, markers, shapes, _ = pair
    write_obj(tmp_path / "src.obj", face)
    write_obj(tmp_path / "tgt.obj", scan)
    write_obj(tmp_path / "wrong.obj", scan)            # a shape of the wrong topology
    (tmp_path / "m.txt").write_text("0 0\n1 999999\n")
    base = [str(tmp_path / "src.obj"), str(tmp_path / "tgt.obj"), "-o",
            str(tmp_path / "out"), "-q"]
    with pytest.raises(InputError, match="m.txt.*999999"):
        _run_cli(base + ["--source-shapes", str(tmp_path / "src.obj"), "--markers",
                         str(tmp_path / "m.txt")])
    (tmp_path / "m.txt").write_text("0 0\n1 1\n2 2\n")
    with pytest.raises(InputError, match="wrong.obj"):
        _run_cli(base + ["--source-shapes", str(tmp_path / "wrong.obj"), "--markers",
                         str(tmp_path / "m.txt")])


@pytest.mark.parametrize("name,ok", [("o.gltf", True), ("o.obj", False)])
def test_cli_transfer_gltf_form_by_extension_and_refused_before_the_fit(pair, tmp_path,
                                                                         name, ok):
    face, scan, markers, shapes, _ = pair
    write_obj(tmp_path / "src.obj", face)
    write_obj(tmp_path / "tgt.obj", scan)
    (tmp_path / "shapes").mkdir()
    write_obj(tmp_path / "shapes" / "smile.obj", face.with_vertices(shapes["smile"]))
    (tmp_path / "m.txt").write_text(f"{len(markers[0])}\n" + "".join(
        f"{a} {b}\n" for a, b in zip(*markers)))
    argv = [str(tmp_path / "src.obj"), str(tmp_path / "tgt.obj"), "--source-shapes",
            str(tmp_path / "shapes"), "--markers", str(tmp_path / "m.txt"), "-o",
            str(tmp_path / "out"), "--gltf", str(tmp_path / name), "-q"]
    if ok:
        assert _run_cli(argv) == 0
        assert json.loads((tmp_path / name).read_text())["asset"]["version"] == "2.0"
    else:
        with pytest.raises(InputError, match=r"\.glb \(binary\) or \.gltf"):
            _run_cli(argv)
        assert not (tmp_path / "out").exists() and not (tmp_path / name).exists()
