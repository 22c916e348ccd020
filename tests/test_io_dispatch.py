"""Reading meshes by extension (facewrap.io.dispatch): STL, OFF and glTF through trimesh."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")

from facewrap.errors import InputError  # noqa: E402
from facewrap.io.dispatch import (MESH_READ_EXTENSIONS, read_mesh,  # noqa: E402
                                  read_mesh_texture, write_mesh)
from facewrap.mesh import Mesh  # noqa: E402
from conftest import facewrap  # noqa: E402


@pytest.fixture(scope="module")
def sample(tmp_path_factory):
    from facewrap.sample import make_scan, make_template, write_sample
    tpl = make_template(24)
    scan = make_scan(tpl, resolution=40, texture_size=16)
    return scan, write_sample(tmp_path_factory.mktemp("sample"), tpl, scan)


def _tm(V, F, **kw):
    return trimesh.Trimesh(np.asarray(V), np.asarray(F), process=False, **kw)


def _same_surface(mesh, V, T, tol):
    """Every triangle of ``mesh`` is one of (V, T), corner positions within ``tol``."""
    assert len(mesh.triangles) == len(T)
    assert np.abs(mesh.vertices[mesh.triangles] - np.asarray(V)[np.asarray(T)]).max() < tol


@pytest.mark.parametrize("file_type", ["stl", "stl_ascii"])
def test_stl_corners_are_merged_into_the_scan_surface(sample, tmp_path, file_type):
    scan, _ = sample
    V, T = np.asarray(scan.mesh.vertices), np.asarray(scan.mesh.triangles)
    p = tmp_path / "scan.stl"
    _tm(V, T).export(p, file_type=file_type)
    mesh = read_mesh(p)
    _same_surface(mesh, V, T, 1e-4 * scan.mesh.scale())  # binary STL is float32
    used = np.unique(T)
    # one vertex per distinct corner position, not three per triangle
    assert mesh.n_vertices == len(np.unique(V[used].astype(np.float32), axis=0))


def test_off_keeps_vertex_order_and_faces(mixed_mesh, tmp_path):
    p = tmp_path / "m.off"
    _tm(mixed_mesh.vertices, mixed_mesh.triangles).export(p)
    mesh = read_mesh(p)
    assert np.abs(mesh.vertices - mixed_mesh.vertices).max() < 1e-9
    assert np.array_equal(mesh.triangles, mixed_mesh.triangles)


def _textured(V, F, uv, image):
    from PIL import Image
    visual = trimesh.visual.TextureVisuals(uv=uv, image=Image.fromarray(image))
    return _tm(V, F, visual=visual)


def test_glb_pieces_in_world_space_with_uvs_and_image(tmp_path):
    rng = np.random.default_rng(0)
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.2]])
    F = np.array([[0, 1, 2], [1, 3, 2]])
    uv = np.array([[0, 0], [1, 0], [0, 1], [1, 1.0]])
    image = rng.integers(0, 256, (8, 12, 3), dtype=np.uint8)
    scene = trimesh.Scene()
    moved = trimesh.transformations.compose_matrix(angles=[0, 0, np.pi / 2],
                                                   translate=[5, 0, 1])
    scene.add_geometry(_textured(V, F, uv, image), node_name="first", transform=moved)
    scene.add_geometry(_textured(V + 2, F, uv, image), node_name="second")
    p = tmp_path / "scan.glb"
    scene.export(p)
    mesh = read_mesh(p)
    assert mesh.n_vertices == 8 and len(mesh.triangles) == 4
    world = V @ moved[:3, :3].T + moved[:3, 3]
    assert np.abs(mesh.vertices[:4] - world).max() < 1e-5   # glTF stores float32
    assert np.abs(mesh.vertices[4:] - (V + 2)).max() < 1e-5
    assert np.array_equal(mesh.triangles, np.vstack([F, F + 4]))
    assert np.abs(mesh.uvs - np.vstack([uv, uv])).max() < 1e-6
    assert np.array_equal(read_mesh_texture(p), image)
    gltf = tmp_path / "scan.gltf"
    scene.export(gltf)
    assert np.abs(read_mesh(gltf).vertices - mesh.vertices).max() < 1e-6


def test_glb_without_uvs_everywhere_keeps_none_and_no_image(tmp_path):
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    F = np.array([[0, 1, 2]])
    scene = trimesh.Scene([_textured(V, F, V[:, :2], np.zeros((4, 4, 3), np.uint8)),
                           _tm(V + 1, F)])
    p = tmp_path / "mixed.glb"
    scene.export(p)
    assert read_mesh(p).uvs is None and read_mesh_texture(p) is None
    assert read_mesh_texture(tmp_path / "x.obj") is None


def test_two_images_cannot_be_baked_from(tmp_path):
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    F = np.array([[0, 1, 2]])
    scene = trimesh.Scene([_textured(V, F, V[:, :2], np.zeros((4, 4, 3), np.uint8)),
                           _textured(V + 1, F, V[:, :2], np.full((4, 4, 3), 9, np.uint8))])
    p = tmp_path / "two.glb"
    scene.export(p)
    with pytest.raises(InputError, match="2 different base-colour images"):
        read_mesh_texture(p)


def glb_bytes(doc: dict, binary: bytes = b"") -> bytes:
    """A GLB file of a glTF JSON document and an optional binary chunk."""
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    chunks = struct.pack("<II", len(js), 0x4E4F534A) + js
    if binary:
        binary += b"\0" * (-len(binary) % 4)
        chunks += struct.pack("<II", len(binary), 0x004E4942) + binary
    return b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks


OFF = "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n"


@pytest.mark.parametrize("name, data, match", [
    ("cut.stl", b"\0" * 80 + struct.pack("<I", 10) + b"\0" * 200, "header says 10 triangles"),
    ("short.stl", b"solid\0", "shorter than a binary STL header"),
    ("none.stl", b"\0" * 80 + struct.pack("<I", 0), "no triangles"),
    ("counts.off", OFF.replace("4 2 0", "4 3 0"), "only 6 rows follow"),
    ("huge.off", OFF.replace("4 2 0", "40000000 2 0"), "at least 240000016 bytes"),
    ("notoff.off", "PLY\n4 2 0\n", "not an OFF file"),
    ("nocounts.off", "OFF\nx y\n", "vertex and face counts"),
    ("index.off", OFF.replace("3 1 3 2", "3 1 9 2"), "outside the range|must lie in"),
    ("nan.off", OFF.replace("1 1 0", "nan 1 0"), "NaN or infinite"),
    ("empty.glb", glb_bytes({"asset": {"version": "2.0"}, "scenes": [{"nodes": []}],
                             "scene": 0}), "holds no triangle mesh"),
    ("magic.glb", b"GLTF" + b"\0" * 40, "no 'glTF' magic"),
    ("v1.glb", b"glTF" + struct.pack("<IIII", 1, 20, 0, 0x4E4F534A), "version 1"),
    ("cut.glb", glb_bytes({"asset": {"version": "2.0"}})[:-3], "truncated GLB"),
    ("text.gltf", "not json", "not glTF JSON"),
    ("noasset.gltf", "{}", "no 'asset'"),
    ("empty.off", "", "empty file"),
])
def test_bad_files_are_one_error_naming_the_file(tmp_path, name, data, match):
    p = tmp_path / name
    p.write_bytes(data if isinstance(data, bytes) else data.encode())
    with pytest.raises(InputError, match=match) as info:
        read_mesh(p)
    assert str(p) in str(info.value) and "\n" not in str(info.value)


def test_glb_accessor_beyond_its_buffer_is_refused(tmp_path):
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"mesh": 0}], "meshes": [{"primitives": [{"attributes": {
               "POSITION": 0}, "indices": 1}]}],
           "buffers": [{"byteLength": 48}],
           "bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36,
                                                             "byteLength": 12}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 10 ** 9,
                          "type": "VEC3"},
                         {"bufferView": 1, "componentType": 5125, "count": 3,
                          "type": "SCALAR"}]}
    p = tmp_path / "liar.glb"
    p.write_bytes(glb_bytes(doc, b"\0" * 48))
    with pytest.raises(InputError) as info:
        read_mesh(p)
    assert str(p) in str(info.value)


def test_a_sparse_off_is_refused_without_reading_it(tmp_path):
    p = tmp_path / "sparse.off"
    with open(p, "wb") as fh:
        fh.write(b"OFF\n100000000 100000000 0\n")
        fh.truncate(2 << 30)
    with pytest.raises(InputError, match="binary data"):
        read_mesh(p)


def test_unknown_extension_lists_what_is_read(tmp_path):
    with pytest.raises(InputError) as info:
        read_mesh(tmp_path / "scan.fbx")
    for ext in MESH_READ_EXTENSIONS:
        assert ext in str(info.value)
    with pytest.raises(InputError, match="use .obj, .ply"):
        write_mesh(tmp_path / "out.stl", Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]],
                                              [[0, 1, 2]]))


@pytest.mark.parametrize("ext", [".stl", ".off", ".glb"])
def test_wrap_reads_a_scan_in_each_format(sample, tmp_path, ext, capsys):
    from facewrap.io import read_mesh as read
    scan, paths = sample
    p = tmp_path / f"scan{ext}"
    _tm(scan.mesh.vertices, scan.mesh.triangles).export(p)
    out = tmp_path / "fitted.obj"
    argv = [paths["template"], p, "--template-landmarks", paths["template_landmarks"],
            "--scan-landmarks", paths["scan_landmarks"], "--model", "rbf"]
    assert facewrap("wrap", *argv, "-o", out) == 0
    assert "warning" not in capsys.readouterr().err
    ref = tmp_path / "ref.obj"
    assert facewrap("wrap", *argv[:1], paths["scan"], *argv[2:], "-o", ref) == 0
    # the same scan surface, read through another format: the same fit
    assert np.abs(read(out).vertices - read(ref).vertices).max() < 1e-3 * scan.mesh.scale()


def test_read_mesh_says_what_a_path_that_is_no_file_is(tmp_path):
    import os
    from facewrap.errors import InputError
    from facewrap.io import read_mesh
    (tmp_path / "dir.obj").mkdir()
    os.mkfifo(tmp_path / "pipe.obj")
    for name, what in (("dir.obj", "is a folder"), ("pipe.obj", "is a fifo"),
                       ("gone.obj", "no such file"), ("", "is a folder")):
        with pytest.raises(InputError, match=what):
            read_mesh(tmp_path / name)
