"""``facewrap wrap --gltf`` (job key ``gltf``): the fitted mesh as glTF, as a user runs it.

Oracles: the GLB's positions are the OBJ's in metres, its triangles the OBJ's, each
embedded image the very PNG baked beside the OBJ, and each primitive holds exactly
the triangles of its texture set; inputs are never changed, errors are one line.
"""

import hashlib
import io
import json
import re
import struct
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from facewrap.io import read_mesh
from facewrap.io.gltf import read_gltf_morphs
from facewrap.io.obj import read_obj, write_obj
from facewrap.mesh import Mesh
from facewrap.sample import make_scan, make_template, write_sample
from facewrap.texture import load_image

from conftest import facewrap


@pytest.fixture(scope="module")
def sample(tmp_path_factory) -> Path:
    tpl = make_template(24)
    folder = tmp_path_factory.mktemp("sample")
    write_sample(folder, tpl, make_scan(tpl, resolution=24, texture_size=32))
    return folder


def _digest(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _wrap(d: Path, *more) -> int:
    return facewrap("wrap", d / "template.obj", d / "scan.obj", "--template-landmarks",
                    d / "template_landmarks.txt", "--scan-landmarks",
                    d / "scan_landmarks.txt", "--model", "rbf", "-q", *more)


class Glb:
    """A GLB's JSON and binary chunk, with the accessors and images read by hand."""

    def __init__(self, path: Path):
        data = path.read_bytes()
        assert data[:4] == b"glTF" and struct.unpack("<I", data[8:12])[0] == len(data)
        (n,) = struct.unpack("<I", data[12:16])
        self.doc = json.loads(data[20:20 + n])
        self.bin = data[20 + n + 8:]

    def view(self, k: int) -> bytes:
        v = self.doc["bufferViews"][k]
        return self.bin[v.get("byteOffset", 0):v.get("byteOffset", 0) + v["byteLength"]]

    def accessor(self, k: int) -> np.ndarray:
        a = self.doc["accessors"][k]
        dtype = {5126: "<f4", 5125: "<u4"}[a["componentType"]]
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[a["type"]]
        return np.frombuffer(self.view(a["bufferView"]), dtype).reshape(a["count"], width)

    def image_of(self, prim: dict) -> np.ndarray:
        material = self.doc["materials"][prim["material"]]
        tex = material["pbrMetallicRoughness"]["baseColorTexture"]["index"]
        image = self.doc["images"][self.doc["textures"][tex]["source"]]
        return np.asarray(Image.open(io.BytesIO(self.view(image["bufferView"]))).convert("RGB"))

    def triangles_of(self, prim: dict) -> np.ndarray:
        """The primitive's triangles in original vertex ids, sorted rows."""
        vid = self.accessor(prim["attributes"]["_FACEWRAP_VERTEX"])[:, 0].astype(int)
        tris = vid[self.accessor(prim["indices"]).reshape(-1, 3)]
        return _rows(tris)


def _rows(tris: np.ndarray) -> np.ndarray:
    return np.unique(np.sort(tris, axis=1), axis=0)


def test_a_textured_wrap_writes_a_glb_in_metres_with_its_baked_image(sample, tmp_path):
    before = _digest(sample)
    out = tmp_path / "out"
    assert _wrap(sample, "-o", out / "x.obj", "--texture", sample / "scan_texture.png",
                 "--texture-size", "32", "--report", out / "r.json",
                 "--gltf", out / "x.glb") == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "r.json", "x.glb", "x.mtl", "x.obj", "x.png"]
    report = json.loads((out / "r.json").read_text())
    assert report["units"] == "mm" and report["job"]["gltf"] == str(out / "x.glb")
    assert report["gltf"] == {"path": str(out / "x.glb"), "scale": 0.001, "units": "m"}
    obj = read_mesh(out / "x.obj")
    back = read_gltf_morphs(out / "x.glb")
    np.testing.assert_allclose(back.vertices, obj.vertices * 0.001, rtol=1e-6, atol=1e-8)
    np.testing.assert_array_equal(_rows(back.triangles), _rows(obj.triangles))
    glb = Glb(out / "x.glb")
    (prim,) = glb.doc["meshes"][0]["primitives"]
    normals = glb.accessor(prim["attributes"]["NORMAL"])
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
    material = glb.doc["materials"][prim["material"]]["pbrMetallicRoughness"]
    assert material["metallicFactor"] == 0
    np.testing.assert_array_equal(glb.image_of(prim), load_image(out / "x.png"))
    assert _digest(sample) == before


@pytest.mark.parametrize("frame", ["scan", "template"])
def test_the_gltf_lies_in_the_frame_the_job_asks_for_and_can_be_json(sample, tmp_path,
                                                                     frame):
    out = tmp_path / "out"
    assert _wrap(sample, "-o", out / "x.ply", "--output-frame", frame, "--units", "cm",
                 "--gltf", out / "x.gltf", "--report", out / "r.json") == 0
    text = (out / "x.gltf").read_text()
    doc = json.loads(text)
    assert doc["buffers"][0]["uri"].startswith("data:")      # one self-contained file
    assert "images" not in doc and len(doc["materials"]) == 1
    assert json.loads((out / "r.json").read_text())["gltf"]["scale"] == 0.01
    np.testing.assert_allclose(read_gltf_morphs(out / "x.gltf").vertices,
                               read_mesh(out / "x.ply").vertices * 0.01, rtol=1e-6,
                               atol=1e-7)


def test_unknown_units_leave_positions_as_they_are(tmp_path):
    # the sample shrunk a thousand times: no unit fits its size
    tpl = make_template(24)
    d = tmp_path / "in"
    paths = write_sample(d, tpl, make_scan(tpl, resolution=24, texture_size=8))
    for key in ("template", "scan"):
        m = read_obj(paths[key])
        write_obj(paths[key], m.with_vertices(m.vertices * 1e-4))
    lm = np.loadtxt(paths["scan_landmarks"]) * 1e-4
    np.savetxt(paths["scan_landmarks"], lm)
    out = tmp_path / "out"
    assert _wrap(d, "-o", out / "x.obj", "--gltf", out / "x.glb", "--report",
                 out / "r.json") == 0
    report = json.loads((out / "r.json").read_text())
    assert report["units"] == "units"
    assert report["gltf"] == {"path": str(out / "x.glb"), "scale": 1.0, "units": "units"}
    np.testing.assert_allclose(read_gltf_morphs(out / "x.glb").vertices,
                               read_mesh(out / "x.obj").vertices, rtol=1e-6)


def _overlapping_sample(folder: Path) -> Path:
    """The sample whose template has three materials: ``skin`` (tile 1001), ``eye``
    (faces at the top, their UVs squeezed onto the skin's in tile 1001) and ``back``
    (faces right of x = 0, moved to tile 1002)."""
    tpl = make_template(24)
    paths = write_sample(folder, tpl, make_scan(tpl, resolution=24, texture_size=32))
    m = read_obj(paths["template"])
    corner_face = np.repeat(np.arange(m.n_faces), m.face_sizes)
    centre = np.stack([np.bincount(corner_face, m.vertices[m.face_indices][:, k])
                       / m.face_sizes for k in range(3)], axis=1)
    material = np.zeros(m.n_faces, dtype=np.int64)
    material[centre[:, 1] > np.quantile(centre[:, 1], 0.8)] = 1
    material[(material == 0) & (centre[:, 0] > 0)] = 2
    corner_material = material[corner_face]
    uvs = np.concatenate([m.uvs, m.uvs * 0.5 + 0.25, m.uvs + [1.0, 0.0]])
    face_uvs = m.face_uvs + len(m.uvs) * corner_material
    write_obj(paths["template"], Mesh(
        m.vertices, (m.face_offsets, m.face_indices), uvs=uvs,
        face_uvs=(m.face_offsets, face_uvs), face_materials=material,
        materials=("skin", "eye", "back")))
    return folder


def test_each_texture_set_is_a_primitive_showing_its_own_baked_image(tmp_path):
    d = _overlapping_sample(tmp_path / "in")
    before = _digest(d)
    out = tmp_path / "out"
    assert _wrap(d, "-o", out / "x.obj", "--texture", d / "scan_texture.png",
                 "--texture-size", "32", "--gltf", out / "x.glb",
                 "--report", out / "r.json") == 0
    images = json.loads((out / "r.json").read_text())["texture"]["images"]
    assert sorted(Path(i["image"]).name for i in images) == [
        "x.1001.png", "x.1002.png", "x.eye.1001.png"]
    template = read_obj(d / "template.obj")
    face_of = template.triangle_faces
    material = np.asarray(template.face_materials)[face_of]
    glb = Glb(out / "x.glb")
    prims = glb.doc["meshes"][0]["primitives"]
    assert len(prims) == 3 and len(glb.doc["images"]) == 3
    for info in images:
        ids = [template.materials.index(name) for name in info["materials"]]
        want = _rows(template.triangles[np.isin(material, ids)])
        shown = [p for p in prims if len(glb.triangles_of(p)) == len(want)
                 and np.array_equal(glb.triangles_of(p), want)]
        assert len(shown) == 1, info
        np.testing.assert_array_equal(glb.image_of(shown[0]), load_image(info["image"]))
    assert _digest(d) == before


def test_a_job_file_takes_the_gltf_key(sample, tmp_path):
    job = tmp_path / "job.toml"
    job.write_text(f'[inputs]\ntemplate = "{sample / "template.obj"}"\n'
                   f'scan = "{sample / "scan.obj"}"\n'
                   f'template_landmarks = "{sample / "template_landmarks.txt"}"\n'
                   f'scan_landmarks = "{sample / "scan_landmarks.txt"}"\n'
                   '[outputs]\noutput = "out/x.obj"\ngltf = "out/x.glb"\n'
                   '[wrap]\nmodel = "rbf"\n')
    assert facewrap("run", "-q", job) == 0
    assert (tmp_path / "out" / "x.glb").read_bytes()[:4] == b"glTF"


def _one_error(capsys, *names) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("facewrap: error: "), err
    assert all(str(n) in err[0] for n in names), err
    return err[0]


def test_bad_gltf_outputs_are_one_line_before_any_work(sample, tmp_path, capsys):
    before = _digest(sample)
    out = tmp_path / "out"
    assert _wrap(sample, "-o", out / "x.obj", "--gltf", out / "x.fbx") == 2
    assert re.search(r"\.glb \(binary\) or \.gltf", _one_error(capsys, out / "x.fbx"))
    folder = tmp_path / "x.glb"
    folder.mkdir()
    assert _wrap(sample, "-o", out / "x.obj", "--gltf", folder) == 2
    assert "is a folder" in _one_error(capsys, folder)
    assert _wrap(sample, "-o", out / "x.obj", "--gltf", out / "x.glb", "--report",
                 out / "x.glb") == 2
    assert "same file" in _one_error(capsys, out / "x.glb")
    # an input that is a glTF: the scan as a GLB
    from facewrap.io.gltf import write_gltf_morphs
    scan = tmp_path / "scan.glb"
    write_gltf_morphs(scan, read_mesh(sample / "scan.obj"), {})
    kept = scan.read_bytes()
    assert facewrap("wrap", sample / "template.obj", scan, "--template-landmarks",
                    sample / "template_landmarks.txt", "--scan-landmarks",
                    sample / "scan_landmarks.txt", "-o", out / "x.obj", "--gltf",
                    scan) == 2
    assert "also an input" in _one_error(capsys, scan)
    assert scan.read_bytes() == kept and not out.exists()
    assert _digest(sample) == before
