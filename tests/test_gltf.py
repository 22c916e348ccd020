"""glTF/GLB with named morph targets: round trips."""

import json

import numpy as np
import pytest

from facewrap.errors import InputError
from facewrap.io.gltf import read_gltf_morphs, write_gltf_morphs
from facewrap.mesh import Mesh


def _shapes(mesh, names):
    rng = np.random.default_rng(0)
    return {k: mesh.vertices + rng.normal(scale=0.1, size=mesh.vertices.shape)
            for k in names}


def test_round_trip_with_uv_seams_and_quads(mixed_mesh, tmp_path):
    shapes = _shapes(mixed_mesh, ["jawOpen", "eyeBlink_L", "mouthSmile_R"])
    path = tmp_path / "a.glb"
    write_gltf_morphs(path, mixed_mesh, shapes)
    back = read_gltf_morphs(path)
    np.testing.assert_allclose(back.vertices, mixed_mesh.vertices, atol=1e-6)
    np.testing.assert_array_equal(back.triangles, mixed_mesh.triangles)
    assert list(back.shapes) == ["jawOpen", "eyeBlink_L", "mouthSmile_R"]
    for k, v in shapes.items():
        np.testing.assert_allclose(back.shapes[k], v, atol=1e-5)


def test_glb_is_valid_binary_gltf(mixed_mesh, tmp_path):
    import pygltflib
    path = tmp_path / "b.glb"
    write_gltf_morphs(path, mixed_mesh, _shapes(mixed_mesh, ["a"]), scale=0.01)
    assert path.read_bytes()[:4] == b"glTF"
    doc = pygltflib.GLTF2().load(str(path))
    prim = doc.meshes[0].primitives[0]
    assert doc.meshes[0].extras["targetNames"] == ["a"]
    assert prim.attributes.TEXCOORD_0 is not None and len(prim.targets) == 1
    # seams split vertices: 7 positions become one per distinct (vertex, uv) pair
    assert doc.accessors[prim.attributes.POSITION].count == 9
    np.testing.assert_allclose(read_gltf_morphs(path).vertices,
                               mixed_mesh.vertices * 0.01, atol=1e-7)


def test_mesh_without_uvs_and_without_shapes(tmp_path):
    mesh = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1.]], [[0, 1, 2], [1, 3, 2]])
    write_gltf_morphs(tmp_path / "c.glb", mesh, {})
    back = read_gltf_morphs(tmp_path / "c.glb")
    np.testing.assert_allclose(back.vertices, mesh.vertices)
    assert back.shapes == {}


def test_errors(mixed_mesh, tmp_path):
    with pytest.raises(ValueError, match="bad"):
        write_gltf_morphs(tmp_path / "d.glb", mixed_mesh, {"bad": np.zeros((3, 3))})
    assert not (tmp_path / "d.glb").exists()
    junk = tmp_path / "junk.glb"
    junk.write_bytes(b"nonsense")
    with pytest.raises(InputError, match="junk.glb"):
        read_gltf_morphs(junk)
    with pytest.raises(InputError, match="no such file"):
        read_gltf_morphs(tmp_path / "none.glb")


# -- both forms by extension -------------------------------------------------------
def _buffer_of(doc, path):
    """The bytes of the one buffer, GLB chunk or data URI, read independently."""
    import base64
    uri = doc.buffers[0].uri
    if uri is None:
        return doc.binary_blob()
    assert uri.startswith("data:application/octet-stream;base64,")
    return base64.b64decode(uri.split(",", 1)[1])


def _check_structure(path):
    """What the Khronos validator checks of accessors, views and buffers."""
    import pygltflib
    doc = pygltflib.GLTF2().load(str(path))
    blob = _buffer_of(doc, path)
    assert doc.asset.version == "2.0" and len(doc.buffers) == 1
    assert doc.buffers[0].byteLength <= len(blob) < doc.buffers[0].byteLength + 4
    for view in doc.bufferViews:
        assert view.byteOffset % 4 == 0
        assert view.byteOffset + view.byteLength <= doc.buffers[0].byteLength
    size = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}
    for acc in doc.accessors:
        view = doc.bufferViews[acc.bufferView]
        assert (acc.byteOffset or 0) + acc.count * size[acc.type] * 4 <= view.byteLength
    prim = doc.meshes[0].primitives[0]
    count = doc.accessors[prim.attributes.POSITION].count
    attributes = [prim.attributes.POSITION, prim.attributes.TEXCOORD_0,
                  prim.attributes._FACEWRAP_VERTEX]
    positions = [prim.attributes.POSITION] + [t["POSITION"] for t in prim.targets or []]
    for index in [i for i in attributes + positions if i is not None]:
        assert doc.accessors[index].count == count
    for index in positions:  # POSITION accessors must carry exact min and max
        acc, view = doc.accessors[index], doc.bufferViews[doc.accessors[index].bufferView]
        values = np.frombuffer(blob, "<f4", acc.count * 3, view.byteOffset).reshape(-1, 3)
        np.testing.assert_allclose(acc.min, values.min(axis=0), rtol=0, atol=1e-12)
        np.testing.assert_allclose(acc.max, values.max(axis=0), rtol=0, atol=1e-12)
    idx = doc.accessors[prim.indices]
    view = doc.bufferViews[idx.bufferView]
    tri = np.frombuffer(blob, "<u4", idx.count, view.byteOffset)
    assert idx.count % 3 == 0 and tri.max() < count
    names = doc.meshes[0].extras["targetNames"]
    assert len(names) == len(prim.targets or []) == len(doc.meshes[0].weights or [])
    return doc


@pytest.mark.parametrize("name", ["shapes.glb", "shapes.gltf", "SHAPES.GLTF"])
def test_both_forms_round_trip_and_are_valid(mixed_mesh, tmp_path, name):
    shapes = _shapes(mixed_mesh, ["jawOpen", "eyeBlink_L"])
    path = tmp_path / name
    write_gltf_morphs(path, mixed_mesh, shapes, scale=0.01)
    if name.endswith(".glb"):
        assert path.read_bytes()[:4] == b"glTF"
    else:  # one self-contained JSON file, nothing beside it
        assert json.loads(path.read_text())["asset"]["version"] == "2.0"
        assert [p.name for p in tmp_path.iterdir()] == [name]
    _check_structure(path)
    back = read_gltf_morphs(path)
    np.testing.assert_allclose(back.vertices, mixed_mesh.vertices * 0.01, atol=1e-7)
    np.testing.assert_array_equal(back.triangles, mixed_mesh.triangles)
    assert list(back.shapes) == ["jawOpen", "eyeBlink_L"]
    for k, v in shapes.items():
        np.testing.assert_allclose(back.shapes[k], v * 0.01, atol=1e-7)


def test_gltf_with_a_bin_file_beside_it_is_read(mixed_mesh, tmp_path):
    import base64
    write_gltf_morphs(tmp_path / "a.gltf", mixed_mesh, _shapes(mixed_mesh, ["x"]))
    doc = json.loads((tmp_path / "a.gltf").read_text())
    blob = base64.b64decode(doc["buffers"][0]["uri"].split(",", 1)[1])
    (tmp_path / "my data.bin").write_bytes(blob)
    doc["buffers"][0]["uri"] = "my%20data.bin"
    (tmp_path / "b.gltf").write_text(json.dumps(doc))
    a, b = read_gltf_morphs(tmp_path / "a.gltf"), read_gltf_morphs(tmp_path / "b.gltf")
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.shapes["x"], b.shapes["x"])
    (tmp_path / "my data.bin").write_bytes(blob[:-8])
    with pytest.raises(InputError, match="b.gltf: buffer 0 needs"):
        read_gltf_morphs(tmp_path / "b.gltf")
    (tmp_path / "my data.bin").unlink()
    with pytest.raises(InputError, match="cannot read"):
        read_gltf_morphs(tmp_path / "b.gltf")


@pytest.mark.parametrize("name", ["shapes.obj", "shapes", "shapes.glb.tmp"])
def test_other_extensions_are_refused_before_anything_is_written(mixed_mesh, tmp_path,
                                                                 name):
    with pytest.raises(InputError, match=r"must end in \.glb \(binary\) or \.gltf"):
        write_gltf_morphs(tmp_path / name, mixed_mesh, {})
    assert list(tmp_path.iterdir()) == []


def test_unused_vertices_survive_a_uv_mesh(mixed_mesh, tmp_path):
    V = np.vstack([mixed_mesh.vertices, [[5.0, 5.0, 5.0]]])
    faces = [[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 6]]  # vertex 7 is in no face
    face_uvs = [[0, 1, 3, 2], [4, 5, 7, 6], [2, 3, 8]]
    mesh = Mesh(V, faces, uvs=mixed_mesh.uvs, face_uvs=face_uvs)
    shapes = {"up": V + [0, 0, 1]}
    for name in ("u.glb", "u.gltf"):
        write_gltf_morphs(tmp_path / name, mesh, shapes)
        back = read_gltf_morphs(tmp_path / name)
        np.testing.assert_allclose(back.vertices, V, atol=1e-6)
        np.testing.assert_allclose(back.shapes["up"], V + [0, 0, 1], atol=1e-6)


def _edited(tmp_path, mixed_mesh, edit):
    write_gltf_morphs(tmp_path / "ok.gltf", mixed_mesh, _shapes(mixed_mesh, ["x"]))
    doc = json.loads((tmp_path / "ok.gltf").read_text())
    edit(doc)
    (tmp_path / "bad.gltf").write_text(json.dumps(doc))
    return tmp_path / "bad.gltf"


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["accessors"][0].update(count=10 ** 9), "accessor 0 .* runs past"),
    (lambda d: d["buffers"][0].update(byteLength=10 ** 9), "byteLength says"),
    (lambda d: d["buffers"][0].update(uri="data:application/octet-stream;base64,@@"),
     "not valid base64"),
    (lambda d: d["meshes"][0]["primitives"][0].update(mode=1), "not triangles"),
    (lambda d: d["meshes"][0]["primitives"][0].update(indices=99), "accessor 99"),
    (lambda d: d["accessors"][0].update(bufferView=99), "buffer view 99 or count"),
    (lambda d: d["accessors"][0].update(bufferView=-1), "buffer view -1 or count"),
    (lambda d: d["accessors"][0].update(count=-3), "count -3 out of range"),
    (lambda d: d["bufferViews"][0].update(buffer=-1), "buffer -1 does not exist"),
    (lambda d: d["meshes"][0]["primitives"][0]["targets"][0].update(POSITION=2),
     "another vertex count"),
    (lambda d: d.update(bufferViews=[{"buffer": 0}]), "malformed glTF"),
])
def test_broken_files_are_one_input_error(mixed_mesh, tmp_path, edit, message):
    with pytest.raises(InputError, match=message):
        read_gltf_morphs(_edited(tmp_path, mixed_mesh, edit))


def test_indices_out_of_range_are_refused(tmp_path):
    import pygltflib
    mesh = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]])
    write_gltf_morphs(tmp_path / "t.glb", mesh, {})
    doc = pygltflib.GLTF2().load(str(tmp_path / "t.glb"))
    blob = bytearray(doc.binary_blob())
    view = doc.bufferViews[doc.accessors[doc.meshes[0].primitives[0].indices].bufferView]
    blob[view.byteOffset:view.byteOffset + 4] = np.uint32(7).tobytes()
    doc.set_binary_blob(bytes(blob))
    doc.save(str(tmp_path / "t.glb"))
    with pytest.raises(InputError, match="index the 3 vertices"):
        read_gltf_morphs(tmp_path / "t.glb")


def test_container_checks_come_before_reading(mixed_mesh, tmp_path):
    path = tmp_path / "a.glb"
    write_gltf_morphs(path, mixed_mesh, _shapes(mixed_mesh, ["x"]))
    size = path.stat().st_size
    with open(path, "r+b") as fh:  # a good GLB, then zeros (a sparse tail)
        fh.truncate(size + (1 << 20))
    with pytest.raises(InputError, match=f"GLB header says the file has {size} bytes, "
                                         f"it has {size + (1 << 20)}"):
        read_gltf_morphs(path)
    path.write_bytes(b"glTF\x02\x00")
    with pytest.raises(InputError, match="GLB header is cut short"):
        read_gltf_morphs(path)
    text = tmp_path / "b.gltf"
    text.write_bytes(b'{"asset": {"version": "2.0"}}' + bytes(1 << 17))
    with pytest.raises(InputError, match="binary data, not a glTF"):
        read_gltf_morphs(text)


def _glb_json(path):
    import struct
    data = path.read_bytes()
    (length,) = struct.unpack("<I", data[12:16])
    return json.loads(data[20:20 + length])


def test_smooth_normals_are_unit_shared_across_seams_and_morph_with_the_shapes(
        mixed_mesh, tmp_path):
    import pygltflib
    from facewrap.geometry.normals import vertex_normals
    shapes = _shapes(mixed_mesh, ["a", "b"])
    path = tmp_path / "n.glb"
    write_gltf_morphs(path, mixed_mesh, shapes)
    doc = pygltflib.GLTF2().load(str(path))
    blob = doc.binary_blob()

    def accessor(i):
        acc = doc.accessors[i]
        view = doc.bufferViews[acc.bufferView]
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[acc.type]
        return np.frombuffer(blob, np.float32, acc.count * width,
                             view.byteOffset or 0).reshape(acc.count, -1)

    prim = doc.meshes[0].primitives[0]
    vid = accessor(prim.attributes._FACEWRAP_VERTEX)[:, 0].astype(int)
    N = accessor(prim.attributes.NORMAL).astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1, atol=1e-6)
    assert len(vid) > mixed_mesh.n_vertices                 # split at the UV seams...
    oracle = vertex_normals(mixed_mesh.vertices, mixed_mesh.triangles)
    used = np.linalg.norm(oracle[vid], axis=1) > 0.5
    np.testing.assert_allclose(N[used], oracle[vid][used], atol=1e-6)  # ...one normal
    for k, name in enumerate(shapes):
        moved = N + accessor(prim.targets[k]["NORMAL"])
        want = vertex_normals(shapes[name], mixed_mesh.triangles)[vid]
        ok = used & (np.linalg.norm(want, axis=1) > 0.5)
        np.testing.assert_allclose(moved[ok], want[ok], atol=1e-5)


def test_textures_one_primitive_and_material_per_tile_round_trip_exactly(tmp_path):
    # two quads in UV tiles 1001 and 1002, a texture for each
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0.]])
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [1, 0], [2, 0], [2, 1], [1, 1.]])
    mesh = Mesh(V, [[0, 1, 2, 3], [1, 4, 5, 2]], uvs=uvs, face_uvs=[[0, 1, 2, 3],
                                                                    [4, 5, 6, 7]])
    images = {1001: np.full((4, 4, 3), 10, np.uint8), 1002: np.full((4, 4, 3), 99, np.uint8)}
    shapes = {"up": V + [0, 0, 0.5]}
    path = tmp_path / "t.glb"
    write_gltf_morphs(path, mesh, shapes, textures=images)
    doc = _glb_json(path)
    prims = doc["meshes"][0]["primitives"]
    assert len(prims) == 2 and len(doc["images"]) == 2 and len(doc["textures"]) == 2
    mats = [doc["materials"][p["material"]] for p in prims]
    assert [m["name"] for m in mats] == ["facewrap_1001", "facewrap_1002"]
    assert all(m["pbrMetallicRoughness"]["metallicFactor"] == 0 for m in mats)
    assert {m["pbrMetallicRoughness"]["baseColorTexture"]["index"] for m in mats} == {0, 1}
    assert all(i["mimeType"] == "image/png" for i in doc["images"])
    back = read_gltf_morphs(path)
    np.testing.assert_array_equal(back.vertices, V.astype(np.float32))
    np.testing.assert_array_equal(back.shapes["up"] - back.vertices,
                                  (shapes["up"] - V).astype(np.float32))
    assert sorted(map(tuple, back.triangles)) == sorted(map(tuple, mesh.triangles))
    # an image alone is tile 1001's; the other tile gets the plain material
    write_gltf_morphs(path, mesh, {}, textures=images[1001])
    doc = _glb_json(path)
    names = [doc["materials"][p["material"]]["name"]
             for p in doc["meshes"][0]["primitives"]]
    assert names == ["facewrap_1001", "facewrap"] and len(doc["images"]) == 1


def test_a_mesh_without_uvs_gets_a_plain_material_and_no_texture(tmp_path):
    mesh = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]])
    path = tmp_path / "p.glb"
    write_gltf_morphs(path, mesh, {}, textures=np.zeros((2, 2, 3), np.uint8))
    doc = _glb_json(path)
    assert "images" not in doc and len(doc["materials"]) == 1
    assert doc["meshes"][0]["primitives"][0]["material"] == 0


def test_textures_by_tile_and_materials_split_overlapping_materials(tmp_path):
    # quads 0 and 1 overlap in tile 1001 with materials 0 and 1; quad 2 in tile 1002
    V = np.array([[x, y, 0] for x in range(4) for y in (0, 1)], float)
    unit = np.array([[0, 0], [1, 0], [1, 1], [0, 1.]])
    uvs = np.concatenate([unit, unit, unit + [1, 0]])
    faces = [[0, 2, 3, 1], [2, 4, 5, 3], [4, 6, 7, 5]]
    mesh = Mesh(V, faces, uvs=uvs, face_uvs=np.arange(12).reshape(3, 4),
                face_materials=[0, 1, 0], materials=["skin", "eye"])
    images = {(1001, (0,)): np.full((2, 2, 3), 10, np.uint8),
              (1001, (1,)): np.full((2, 2, 3), 20, np.uint8),
              (1002, (0, 1)): np.full((2, 2, 3), 30, np.uint8)}
    path = tmp_path / "m.glb"
    write_gltf_morphs(path, mesh, {}, textures=images)
    doc = _glb_json(path)
    prims = doc["meshes"][0]["primitives"]
    names = [doc["materials"][p["material"]]["name"] for p in prims]
    assert names == ["skin_1001", "eye_1001", "skin+eye_1002"]   # the mesh's names
    assert [doc["accessors"][p["indices"]]["count"] for p in prims] == [6, 6, 6]
    back = read_gltf_morphs(path)
    # primitive k holds quad k's two triangles (in original vertex ids)
    for k, tris in enumerate(back.triangles.reshape(3, 2, 3)):
        assert sorted(set(tris.ravel().tolist())) == sorted(faces[k])
    # only the images a triangle shows are embedded; a tile with none is plain
    write_gltf_morphs(path, mesh, {}, textures={(1001, (1,)): images[(1001, (1,))]})
    doc = _glb_json(path)
    assert [doc["materials"][p["material"]]["name"]
            for p in doc["meshes"][0]["primitives"]] == ["eye_1001", "facewrap"]
    assert len(doc["images"]) == 1
    with pytest.raises(ValueError, match="not both"):
        write_gltf_morphs(path, mesh, {}, textures={1001: images[(1001, (0,))],
                                                   (1001, (1,)): images[(1001, (1,))]})
    with pytest.raises(ValueError, match="neither a tile"):
        write_gltf_morphs(path, mesh, {}, textures={"face": images[(1001, (0,))]})
