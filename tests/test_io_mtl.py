"""facewrap.io.mtl: material libraries read, rebased and written beside an OBJ; and no
OBJ a command writes (wrap, transfer, track, convert) names a library not beside it."""

import hashlib
import os
import re
from pathlib import Path

import numpy as np
import pytest

from facewrap.errors import InputError
from facewrap.io.images import save_png
from facewrap.io.mtl import (DEFAULT_MATERIAL, TEXTURE_MATERIAL, library_beside,
                             output_library, read_mtl, with_library, write_mtl)
from facewrap.io.obj import read_obj, write_obj
from facewrap.io.ply import write_ply
from facewrap.mesh import Mesh
from facewrap.sample import make_scan, make_template, write_sample

from conftest import facewrap


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


def _tri(**kw) -> Mesh:
    return Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]], uvs=[[0, 0], [1, 0], [0, 1]],
                face_uvs=[[0, 1, 2]], **kw)


def test_library_beside_keeps_materials_shows_a_plys_texture_or_names_none(tmp_path):
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "lib.mtl").write_text("newmtl skin\nKd 0.5 0.5 0.5\nmap_Kd skin.png\n")
    src, out = tmp_path / "in" / "a.obj", tmp_path / "out" / "b.obj"
    mesh, lib = library_beside(_tri(face_materials=[0], materials=["skin"],
                                    mtllib=["lib.mtl"]), src, out)
    assert mesh.mtllib == ("b.mtl",) and mesh.materials == ("skin",)
    assert lib == {"skin": ["Kd 0.5 0.5 0.5", "map_Kd ../in/skin.png"]}
    mesh, lib = library_beside(_tri(texture="tex/t.png"), tmp_path / "in" / "a.ply", out,
                               "shared.mtl")
    assert mesh.mtllib == ("shared.mtl",) and mesh.materials == (TEXTURE_MATERIAL,)
    assert mesh.face_materials.tolist() == [0]
    assert lib[TEXTURE_MATERIAL][-2:] == ["Kd 1 1 1", "map_Kd ../in/tex/t.png"]
    # a library named but no materials, or a texture without UVs: no library
    for bare in (_tri(mtllib=["lib.mtl"]),
                 Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]], texture="t.png")):
        mesh, lib = library_beside(bare, src, out)
        assert mesh.mtllib == () and lib is None


def _digest(folder: Path) -> dict:
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _check_libraries(obj: Path) -> list[str]:
    """Every ``mtllib`` of ``obj`` is a file beside it defining its ``usemtl``
    materials, whose ``map_Kd`` images exist; returns the library names."""
    text = obj.read_text()
    names = re.findall(r"^mtllib (.+)$", text, re.M)
    defined = set()
    for name in names:
        lib = obj.parent / name
        assert lib.is_file(), f"{obj} names {name}, not beside it"
        materials = read_mtl(lib)
        defined |= set(materials)
        for lines in materials.values():
            for image in (s.split()[-1] for s in lines if s.startswith("map_Kd")):
                assert (lib.parent / image).is_file(), f"{lib}: {image} is missing"
    if names:
        assert set(re.findall(r"^usemtl (.+)$", text, re.M)) <= defined
    return names


@pytest.fixture
def textured(tmp_path) -> dict:
    """The sample, its template given a material ``skin`` showing the scan's image
    through ``lib.mtl`` (an OBJ read with a library)."""
    tpl = make_template(24)
    paths = write_sample(tmp_path / "in", tpl, make_scan(tpl, resolution=24,
                                                         texture_size=16))
    m = read_obj(paths["template"])
    (tmp_path / "in" / "lib.mtl").write_text("newmtl skin\nKd 1 1 1\nmap_Kd "
                                             "scan_texture.png\n")
    write_obj(paths["template"], Mesh(
        m.vertices, (m.face_offsets, m.face_indices), uvs=m.uvs,
        face_uvs=(m.face_offsets, m.face_uvs), face_materials=np.zeros(m.n_faces, int),
        materials=["skin"], mtllib=["lib.mtl"]))
    ids = paths["template_landmarks"].read_text().split()[:12]
    (tmp_path / "in" / "markers.txt").write_text("".join(f"{i} {i}\n" for i in ids))
    return paths


def test_transfer_shapes_share_a_library_written_beside_them(textured, tmp_path):
    p, before = textured, _digest(tmp_path / "in")
    out = tmp_path / "shapes"
    assert facewrap("transfer", p["template"], p["template"], "--markers",
                    tmp_path / "in" / "markers.txt", "--source-shapes",
                    tmp_path / "in" / "blendshapes", "-o", out, "-q") == 0
    objs = sorted(out.glob("*.obj"))
    assert len(objs) == 5 and all(_check_libraries(o) == ["materials.mtl"] for o in objs)
    assert read_mtl(out / "materials.mtl")["skin"] == ["Kd 1 1 1",
                                                      "map_Kd ../in/scan_texture.png"]
    assert read_obj(objs[0]).materials == ("skin",)
    # a target without materials: the shapes name no library, none is written
    plain = tmp_path / "plain.obj"
    m = read_obj(p["template"])
    write_obj(plain, Mesh(m.vertices, (m.face_offsets, m.face_indices), mtllib=["lib.mtl"]))
    assert facewrap("transfer", p["template"], plain, "--markers",
                    tmp_path / "in" / "markers.txt", "--source-shapes",
                    tmp_path / "in" / "blendshapes", "-o", tmp_path / "s2", "-q") == 0
    assert not (tmp_path / "s2" / "materials.mtl").exists()
    assert all(_check_libraries(o) == [] for o in (tmp_path / "s2").glob("*.obj"))
    assert _digest(tmp_path / "in") == before


def test_transfer_refuses_a_library_over_an_input_before_any_work(textured, tmp_path,
                                                                  capsys):
    p = textured
    # -o the input folder, whose materials.mtl the template reads: refused
    (tmp_path / "in" / "lib.mtl").rename(tmp_path / "in" / "materials.mtl")
    text = p["template"].read_text().replace("mtllib lib.mtl", "mtllib materials.mtl")
    p["template"].write_text(text)
    before = _digest(tmp_path / "in")
    assert facewrap("transfer", p["template"], p["template"], "--markers",
                    tmp_path / "in" / "markers.txt", "--source-shapes",
                    p["blendshapes/blink"], "-o", tmp_path / "in", "-q") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "materials.mtl" in err[0] and "input" in err[0], err
    assert _digest(tmp_path / "in") == before


def test_convert_writes_the_library_beside_its_obj_or_names_none(textured, tmp_path,
                                                                 capsys):
    p, before = textured, _digest(tmp_path / "in")
    out = tmp_path / "out"
    assert facewrap("convert", p["template"], out / "t.obj") == 0
    assert _check_libraries(out / "t.obj") == ["t.mtl"]
    assert read_mtl(out / "t.mtl")["skin"][-1] == "map_Kd ../in/scan_texture.png"
    # a PLY with a TextureFile: a material showing it
    m = read_obj(p["template"])
    write_ply(tmp_path / "in" / "t.ply", Mesh(m.vertices, (m.face_offsets, m.face_indices),
                                              uvs=m.uvs, face_uvs=(m.face_offsets,
                                                                   m.face_uvs),
                                              texture="scan_texture.png"))
    before = _digest(tmp_path / "in")
    assert facewrap("convert", tmp_path / "in" / "t.ply", out / "p.obj") == 0
    assert _check_libraries(out / "p.obj") == ["p.mtl"]
    assert read_obj(out / "p.obj").materials == (TEXTURE_MATERIAL,)
    # no materials: no library (and none named)
    assert facewrap("convert", p["blendshapes/blink"], out / "b.obj") == 0
    assert _check_libraries(out / "b.obj") == [] and not (out / "b.mtl").exists()
    # OUT.mtl on an input library: refused, nothing written
    capsys.readouterr()
    assert facewrap("convert", p["template"], tmp_path / "in" / "lib.obj") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "lib.mtl" in err[0] and "input" in err[0], err
    assert facewrap("convert", p["template"], out / "t.stl") == 2
    assert str(out / "t.stl") in capsys.readouterr().err
    assert _digest(tmp_path / "in") == before


def test_wrap_and_track_objs_name_only_libraries_beside_them(textured, tmp_path):
    p, before = textured, _digest(tmp_path / "in")
    common = ["--template-landmarks", p["template_landmarks"], "--scan-landmarks",
              p["scan_landmarks"], "--model", "rbf", "-q"]
    assert facewrap("wrap", p["template"], p["scan"], *common, "-o",
                    tmp_path / "w" / "x.obj") == 0
    assert _check_libraries(tmp_path / "w" / "x.obj") == ["x.mtl"]
    seq = tmp_path / "seq"
    seq.mkdir()
    (seq / "f0.obj").write_bytes(p["scan"].read_bytes())
    assert facewrap("track", p["template"], seq, *common, "-o", tmp_path / "t") == 0
    frames = sorted((tmp_path / "t").glob("*.obj"))
    assert frames and all(_check_libraries(f) == [] for f in frames)
    assert read_obj(frames[0]).materials == ("skin",)      # kept, with no library
    assert _digest(tmp_path / "in") == before
