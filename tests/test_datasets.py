import numpy as np
import pytest

from facewrap.datasets import ICT_PARTS, ICTFaceKit, load_shape_folder, load_sumner_pair
from facewrap.errors import InputError
from facewrap.io.obj import write_obj
from facewrap.mesh import Mesh

from conftest import needs_data, DATA


def test_shape_folder_checks_topology(tmp_path, mixed_mesh):
    write_obj(tmp_path / "neutral.obj", mixed_mesh)
    write_obj(tmp_path / "up.obj", mixed_mesh.with_vertices(mixed_mesh.vertices + [0, 0, 1]))
    write_obj(tmp_path / "same.obj", mixed_mesh)
    shapes = load_shape_folder(tmp_path, reference=mixed_mesh)
    assert list(shapes) == ["up"]  # neutral by name, 'same' by content, skipped
    write_obj(tmp_path / "bad.obj", Mesh(np.eye(3), [[0, 1, 2]]))
    with pytest.raises(InputError, match="bad.obj: has 3 vertices, expected 7"):
        load_shape_folder(tmp_path, reference=mixed_mesh)
    with pytest.raises(InputError, match="not a folder"):
        load_shape_folder(tmp_path / "nope")


def test_ict_loader_rejects_other_folders(tmp_path):
    with pytest.raises(InputError, match="generic_neutral_mesh.obj: missing"):
        ICTFaceKit(tmp_path)


@needs_data
def test_ict_facekit_layout(ict_folder):
    kit = ICTFaceKit(ict_folder)
    assert kit.neutral.n_vertices == 26719
    assert "jawOpen" in kit.expression_names and kit.identity_names == ["identity000"]
    assert len(kit.landmarks) == 68 and kit.landmarks.vertex[0] == 1225
    jaw = kit.shape("jawOpen")
    assert jaw.shape == (26719, 3) and not jaw.flags.writeable
    # jawOpen moves the chin (landmark 8) down by centimetres, not the forehead
    d = kit.deltas(["jawOpen"])[0]
    assert d[kit.landmarks.vertex[8], 1] < -1.0
    face = kit.part_mesh("face")
    assert face.n_vertices == 9409 and face.n_faces == ICT_PARTS["face"][3] + 1
    assert np.array_equal(face.vertices, kit.neutral.vertices[:9409])


@needs_data
def test_sumner_and_onizuka_layouts():
    pair = load_sumner_pair(DATA / "sumner2004/cat-lion/markers-cat-lion.yml")
    assert len(pair.source.poses) == 9 and len(pair.target.poses) == 9
    assert pair.source.poses[0].shape == pair.source.reference.vertices.shape
    assert len(pair.markers[0]) > 0
    assert pair.markers[0].max() < pair.source.reference.n_vertices
    assert pair.markers[1].max() < pair.target.reference.n_vertices
    from facewrap.io import read_mesh
    neutral = read_mesh(DATA / "onizuka2019/blendshapes/Neutralm.obj")
    shapes = load_shape_folder(DATA / "onizuka2019/blendshapes", reference=neutral)
    assert len(shapes) == 48 and "00m" in shapes


def test_ict_expansion_is_atomic_and_not_redone(data_dir, tmp_path):
    """Processes sharing the cache never see a half-written shape: files appear
    by rename, nothing temporary is left, and a finished folder is not rewritten."""
    import os

    from facewrap.datasets import expand_ict_facekit
    out = tmp_path / "FaceXModel"
    expand_ict_facekit(data_dir / "ict-facekit", out, ["jawOpen"])
    first = (out / "jawOpen.obj").stat().st_mtime_ns
    assert (out / "generic_neutral_mesh.obj").is_file()
    expand_ict_facekit(data_dir / "ict-facekit", out, ["jawOpen", "eyeBlink_L"])
    assert (out / "jawOpen.obj").stat().st_mtime_ns == first          # kept
    from facewrap.datasets import ICTFaceKit
    kit = ICTFaceKit(out)
    assert kit.shape("eyeBlink_L").shape == kit.neutral.vertices.shape
    assert sorted(os.listdir(tmp_path)) == ["FaceXModel"]              # no temp left
    assert not (out / ".expanded-all").exists()                        # partial
