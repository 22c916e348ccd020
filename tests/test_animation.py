"""In-between frames and OBJ sequences (SPEC §1.5)."""

import numpy as np
import pytest

from facewrap.animation import (FRAME_MATERIAL, check_sequence_budget, interpolate_textures,
                                interpolate_vertices, obj_sequence_files,
                                write_obj_sequence)
from facewrap.io.obj import read_obj
from facewrap.mesh import Mesh
from facewrap.texture import load_image


def test_interpolate_vertices_ends_exact_midpoint_mean_and_linear():
    rng = np.random.default_rng(0)
    S0 = rng.normal(size=(50, 3)) * 1e3
    SN = rng.normal(size=(50, 3)) * 0.1
    assert not np.array_equal(S0 + (SN - S0), SN)     # rounding would show at the end
    S = interpolate_vertices(S0, SN, 3)
    assert S.shape == (3, 50, 3)
    np.testing.assert_array_equal(S[0], S0)
    np.testing.assert_array_equal(S[-1], SN)
    np.testing.assert_allclose(S[1], (S0 + SN) / 2, rtol=1e-14, atol=1e-12)
    S = interpolate_vertices(S0, SN, 11)
    np.testing.assert_allclose(np.diff(S, axis=0), np.broadcast_to(
        (SN - S0) / 10, (10, 50, 3)), rtol=1e-9, atol=1e-9)
    S0_before = S0.copy()
    interpolate_vertices(S0, SN, 4)
    np.testing.assert_array_equal(S0, S0_before)


@pytest.mark.parametrize("frames", [1, 0, True, 2.0])
def test_interpolate_vertices_needs_two_frames(frames):
    with pytest.raises(ValueError, match="frames"):
        interpolate_vertices(np.zeros((2, 3)), np.ones((2, 3)), frames)


def test_interpolate_vertices_checks_shapes():
    with pytest.raises(ValueError, match="same shape"):
        interpolate_vertices(np.zeros((2, 3)), np.ones((3, 3)), 2)
    with pytest.raises(ValueError, match="start"):
        interpolate_vertices(np.zeros((2, 2)), np.ones((2, 2)), 2)


def test_interpolate_textures_ends_exact():
    a = np.random.default_rng(1).integers(0, 256, (4, 5, 3)).astype(np.uint8)
    b = np.random.default_rng(2).integers(0, 256, (4, 5, 3)).astype(np.uint8)
    T = interpolate_textures(a, b, 5)
    assert T.shape == (5, 4, 5, 3) and T.dtype == np.uint8
    np.testing.assert_array_equal(T[0], a)
    np.testing.assert_array_equal(T[-1], b)
    assert np.abs(T[2].astype(float) - (a / 2 + b / 2)).max() <= 0.5


def same_topology(read, mesh):
    np.testing.assert_array_equal(read.face_offsets, mesh.face_offsets)
    np.testing.assert_array_equal(read.face_indices, mesh.face_indices)
    np.testing.assert_array_equal(read.uvs, mesh.uvs)
    np.testing.assert_array_equal(read.face_uvs, mesh.face_uvs)
    assert read.groups == mesh.groups
    np.testing.assert_array_equal(read.face_groups, mesh.face_groups)


def test_write_obj_sequence_keeps_topology_and_writes_each_frame(mixed_mesh, tmp_path):
    end = mixed_mesh.vertices + [0.1, -0.2, 0.3]
    frames = interpolate_vertices(mixed_mesh.vertices, end, 4)
    paths = write_obj_sequence(tmp_path / "seq", mixed_mesh, frames)
    assert [p.name for p in paths] == [f"frame_{k:04d}.obj" for k in range(4)]
    assert sorted(p.name for p in (tmp_path / "seq").iterdir()) == [p.name for p in paths]
    for k, p in enumerate(paths):
        read = read_obj(p)
        same_topology(read, mixed_mesh)
        np.testing.assert_array_equal(read.vertices, frames[k])
        assert read.materials == mixed_mesh.materials
        np.testing.assert_array_equal(read.face_materials, mixed_mesh.face_materials)
        assert read.mtllib == mixed_mesh.mtllib
    np.testing.assert_array_equal(read_obj(paths[0]).vertices, mixed_mesh.vertices)
    np.testing.assert_array_equal(read_obj(paths[-1]).vertices, end)


def test_write_obj_sequence_with_textures(mixed_mesh, tmp_path):
    frames = interpolate_vertices(mixed_mesh.vertices, mixed_mesh.vertices * 2, 3)
    a = np.zeros((8, 8, 3), np.uint8)
    b = np.full((8, 8, 3), 200, np.uint8)
    textures = interpolate_textures(a, b, 3)
    paths = write_obj_sequence(tmp_path, mixed_mesh, frames, pattern="smile_{}.obj",
                               textures=textures)
    assert [p.name for p in paths] == ["smile_0.obj", "smile_1.obj", "smile_2.obj"]
    for k, p in enumerate(paths):
        read = read_obj(p)
        same_topology(read, mixed_mesh)
        np.testing.assert_array_equal(read.vertices, frames[k])
        assert read.mtllib == (f"smile_{k}.mtl",)
        assert read.materials == mixed_mesh.materials
        mtl = (tmp_path / f"smile_{k}.mtl").read_text()
        for name in mixed_mesh.materials:
            assert f"newmtl {name}\n" in mtl
        assert mtl.count(f"map_Kd smile_{k}.png\n") == len(mixed_mesh.materials)
        np.testing.assert_array_equal(load_image(tmp_path / f"smile_{k}.png"),
                                      textures[k])


def test_textured_frames_of_a_mesh_without_materials(tmp_path):
    mesh = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]],
                uvs=[[0, 0], [1, 0], [0, 1.]], face_uvs=[[0, 1, 2]])
    img = np.full((2, 2, 3), 5, np.uint8)
    [path] = write_obj_sequence(tmp_path, mesh, mesh.vertices[None], textures=[img])
    read = read_obj(path)
    assert read.materials == (FRAME_MATERIAL,)
    assert read.face_materials.tolist() == [0]
    assert "map_Kd frame_0000.png" in (tmp_path / "frame_0000.mtl").read_text()


def test_write_obj_sequence_checks_its_arguments(mixed_mesh, tmp_path):
    frames = np.stack([mixed_mesh.vertices] * 2)
    for pattern in ["frame.obj", "frame_{}.png", "frame_{name}.obj"]:
        with pytest.raises(ValueError, match="pattern"):
            write_obj_sequence(tmp_path, mixed_mesh, frames, pattern=pattern)
    with pytest.raises(ValueError, match="vertex_frames"):
        write_obj_sequence(tmp_path, mixed_mesh, frames[:, :3])
    with pytest.raises(ValueError, match="one image per frame"):
        write_obj_sequence(tmp_path, mixed_mesh, frames,
                           textures=[np.zeros((2, 2, 3), np.uint8)])
    bare = Mesh(mixed_mesh.vertices, [[0, 1, 2]])
    with pytest.raises(ValueError, match="texture coordinates"):
        write_obj_sequence(tmp_path, bare, np.stack([bare.vertices] * 2),
                           textures=[np.zeros((2, 2, 3), np.uint8)] * 2)
    assert list(tmp_path.iterdir()) == []


def test_frame_counts_are_bounded_before_any_work(tmp_path):
    with pytest.raises(ValueError, match=r"in \[2, 100000\]"):
        obj_sequence_files(tmp_path, 10 ** 9)
    with pytest.raises(ValueError, match=r"need about 0\.4 GiB of memory"):
        check_sequence_budget(tmp_path, 10, 10 ** 6, 100, memory_limit=2 ** 28)
    # an image per frame counts too: 1000 frames of 4096 x 4096 RGB is 47 GiB
    with pytest.raises(ValueError, match="need about 46.9 GiB of memory"):
        check_sequence_budget(tmp_path, 1000, 10, 100, image_shape=(4096, 4096, 3),
                              memory_limit=2 ** 30)
    check_sequence_budget(tmp_path / "new" / "folder", 100, 1000, 10_000)


def test_animate_refuses_a_frame_count_in_one_line(mixed_mesh, tmp_path, capsys):
    from facewrap.cli import main
    from facewrap.io.obj import write_obj
    a = tmp_path / "a.obj"
    write_obj(a, mixed_mesh)
    assert main(["animate", str(a), str(a), "--frames", "1000000000", "-o",
                 str(tmp_path / "seq")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("facewrap: error: --frames: must be an int in [2, 100000]")
    assert "\n" not in err and sorted(p.name for p in tmp_path.iterdir()) == ["a.obj"]
