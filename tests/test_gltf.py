"""glTF/GLB with named morph targets: round trips."""

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
