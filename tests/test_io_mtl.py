"""facewrap.io.mtl: material libraries read, rebased and written beside an OBJ."""

import os

import numpy as np
import pytest

from facewrap.errors import InputError
from facewrap.io.mtl import (DEFAULT_MATERIAL, output_library, read_mtl, with_library,
                             write_mtl)
from facewrap.mesh import Mesh


def test_read_keeps_statements_and_names_the_line_of_an_error(tmp_path):
    p = tmp_path / "a.mtl"
    p.write_text("# c\nnewmtl a\nKd 1  1 1 # grey\n\nnewmtl b\n map_Kd -s 1 1 1 t.png\n")
    assert read_mtl(p) == {"a": ["Kd 1 1 1"], "b": ["map_Kd -s 1 1 1 t.png"]}
    p.write_text("Kd 1 1 1\nnewmtl a\n")
    with pytest.raises(InputError, match=r"a.mtl.*1.*before any 'newmtl'"):
        read_mtl(p)
    with pytest.raises(InputError, match="missing.mtl"):
        read_mtl(tmp_path / "missing.mtl")


def test_output_library_keeps_materials_rebases_maps_and_links_baked_images(tmp_path):
    src = tmp_path / "in"
    (src / "tex").mkdir(parents=True)
    (src / "lib.mtl").write_text("newmtl skin\nKd 0.6 0.6 0.6\nNs 18\nmap_Kd tex/skin.png\n"
                                 "newmtl eye\nKd 0.2 0.2 0.2\nbump tex/eye_n.png\n")
    out = tmp_path / "a" / "b" / "o.obj"
    lib = output_library(["skin", "eye", "lost"], src / "t.obj", ["lib.mtl"], out,
                         {"skin": out.parent / "o.1001.png"})
    assert lib["skin"] == ["Ns 18", "Kd 1 1 1", "map_Kd o.1001.png"]
    assert lib["eye"] == ["Kd 0.2 0.2 0.2", "bump ../../in/tex/eye_n.png"]
    # the rebased path names the very file it named before
    rel = lib["eye"][1].split()[-1]
    assert os.path.normpath(out.parent / rel) == os.path.normpath(src / "tex" / "eye_n.png")
    assert lib["lost"] == list(DEFAULT_MATERIAL)      # not in any library: defaults
    # an unreadable library adds nothing; nothing fails
    assert output_library(["skin"], src / "t.obj", ["gone.mtl"], out, {})["skin"] == \
        list(DEFAULT_MATERIAL)
    write_mtl(out.with_suffix(".mtl"), lib)
    assert read_mtl(out.with_suffix(".mtl")) == lib


def test_with_library_names_one_library_and_keeps_the_rest():
    m = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]], uvs=[[0, 0], [1, 0], [0, 1]],
             face_uvs=[[0, 1, 2]], face_materials=[0], materials=["a"],
             mtllib=["elsewhere.mtl"])
    w = with_library(m, "o.mtl")
    assert w.mtllib == ("o.mtl",) and w.materials == ("a",)
    np.testing.assert_array_equal(w.face_uvs, m.face_uvs)
    assert with_library(m, None).mtllib == ()
    v = with_library(m, "o.mtl", face_materials=[1], materials=["a", "b"])
    assert v.face_materials.tolist() == [1] and v.materials == ("a", "b")
