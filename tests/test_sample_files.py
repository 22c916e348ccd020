"""facewrap.sample.files: the sample written as plain files reads back."""

import numpy as np
import pytest

from facewrap.sample import EXPRESSIONS, make_scan, make_template, write_sample


@pytest.fixture(scope="module")
def tpl():
    return make_template()


def test_write_sample_round_trips(tmp_path):
    from PIL import Image

    from facewrap.io.landmarks import read_landmarks
    from facewrap.io.obj import read_obj

    tpl = make_template(32)
    sc = make_scan(tpl, resolution=40, texture_size=64)
    paths = write_sample(tmp_path / "out", tpl, sc)
    expected = {"template", "template_landmarks", "scan", "scan_mtl", "scan_texture",
                "scan_landmarks", "ground_truth"} | {f"blendshapes/{k}" for k in EXPRESSIONS}
    assert set(paths) == expected and all(p.is_file() for p in paths.values())
    t = read_obj(paths["template"])
    assert np.array_equal(t.vertices, tpl.mesh.vertices)
    assert np.array_equal(t.face_offsets, tpl.mesh.face_offsets)
    assert t.groups == tpl.mesh.groups
    b = read_obj(paths["blendshapes/jaw_open"])
    assert np.array_equal(b.vertices, tpl.blendshapes["jaw_open"])
    s = read_obj(paths["scan"])
    assert s.mtllib == ("scan.mtl",) and s.materials == ("skin",)
    assert np.array_equal(s.vertices, sc.mesh.vertices)
    assert np.array_equal(s.uvs[s.face_uvs], sc.mesh.uvs[sc.mesh.face_indices])
    assert "map_Kd scan_texture.png" in paths["scan_mtl"].read_text()
    assert np.array_equal(np.asarray(Image.open(paths["scan_texture"])), sc.texture)
    lines = paths["template_landmarks"].read_text().split()
    assert [int(x) for x in lines] == tpl.landmarks.vertex.tolist()
    pts = read_landmarks(paths["scan_landmarks"])
    np.testing.assert_array_equal(pts.points, sc.landmarks.points)
    np.testing.assert_array_equal(np.load(paths["ground_truth"]), sc.ground_truth)
