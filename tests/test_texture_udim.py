"""facewrap.texture.udim and facewrap.texture.tiles: UDIM tiles, texture sets, baking
one image per tile, what the scanner saw, and a wrap job writing OBJ + MTL + tiles."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from facewrap.geometry import ClosestPointTree
from facewrap.io import read_mesh
from facewrap.io.obj import read_obj, write_obj
from facewrap.mesh import Mesh
from facewrap.sample import make_scan, make_template, write_sample
from facewrap.texture import bake_texture, load_image
from facewrap.texture.bake import scan_visibility
from facewrap.texture.tiles import (bake_tiles, material_images, texture_sets,
                                    tile_image_paths)
from facewrap.texture.udim import tile_origin, triangle_tiles, used_tiles

from conftest import facewrap
from texture_cases import uv_plane

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
ICT = DATA / "ict-facekit" / "FaceXModel" / "generic_neutral_mesh.obj"


def quads_in_tiles(offsets, z=None, materials=None):
    """Unit quads side by side in x (at heights ``z``), quad k's UVs in the unit square
    moved by ``offsets[k]`` (so quad k lies in the tile of that offset)."""
    k = len(offsets)
    z = np.zeros(k) if z is None else np.asarray(z, float)
    V = np.concatenate([[[i, 0, z[i]], [i + 1, 0, z[i]], [i + 1, 1, z[i]], [i, 1, z[i]]]
                        for i in range(k)]).astype(float)
    unit = np.array([[0, 0], [1, 0], [1, 1], [0, 1.]])
    uvs = np.concatenate([unit + np.asarray(o, float) for o in offsets])
    faces = np.arange(4 * k).reshape(k, 4)
    kw = {}
    if materials is not None:
        kw = dict(face_materials=np.asarray(materials), materials=tuple(
            f"m{i}" for i in range(max(materials) + 1)))
    return Mesh(V, faces, uvs=uvs, face_uvs=faces, **kw)


def test_triangle_tiles_follow_the_udim_formula():
    rng = np.random.default_rng(1)
    cells = rng.integers(0, 10, size=(40, 2))
    mesh = quads_in_tiles(cells)
    expect = np.repeat(1001 + cells[:, 0] + 10 * cells[:, 1], 2)   # two triangles a quad
    np.testing.assert_array_equal(triangle_tiles(mesh), expect)
    assert used_tiles(mesh) == tuple(sorted(set(expect.tolist())))
    for t in set(expect.tolist()):
        u0, v0 = tile_origin(t)
        assert 1001 + u0 + 10 * v0 == t
    outside = quads_in_tiles([(-1, 0), (10, 0), (0, -2)])
    assert (triangle_tiles(outside) == -1).all() and used_tiles(outside) == ()
    with pytest.raises(ValueError, match="tile"):
        tile_origin(1000)


def test_file_names_keep_png_for_a_unit_square_and_number_tiles_otherwise():
    assert list(tile_image_paths("a/out.obj", [1001]).values()) == ["a/out.png"]
    assert list(tile_image_paths("out.obj", [1001, 1003]).values()) == [
        "out.1001.png", "out.1003.png"]
    assert list(tile_image_paths("out.obj", [1002]).values()) == ["out.1002.png"]


def test_each_tile_is_baked_from_its_own_triangles_only():
    # two quads of a plane in tiles 1001 and 1002; the scan is the same plane whose
    # image is red on the first quad and blue on the second
    template = quads_in_tiles([(0, 0), (1, 0)])
    scan = uv_plane(4, uv=lambda xy: xy, scale=(2.0, 1.0))
    img = np.zeros((8, 8, 3), np.uint8)
    img[:, :4, 0] = 255
    img[:, 4:, 2] = 255
    baked = bake_tiles(template, scan, img, size=16, padding=0)
    first, second = baked.images
    assert (first.tile, second.tile) == (1001, 1002)
    for res, channel in ((baked.images[first], 0), (baked.images[second], 2)):
        assert res.coverage.all() and res.filled_fraction == 1.0
        inner = res.image[2:-2, 2:-2].reshape(-1, 3)   # away from the bilinear seam
        assert (inner[:, channel] > 200).all() and (inner.sum(axis=1) < 300).all()
    assert baked.filled_fraction == 1.0 and set(baked.seconds) == set(baked.images)


def test_what_the_scanner_did_not_see_is_laid_out_but_not_covered():
    # a front quad on the scan, and a quad right behind it (a tooth behind the lips)
    template = quads_in_tiles([(0, 0), (1, 0)], z=[0.0, -0.3])
    behind = template.vertices.copy()
    behind[4:, 0] -= 1.0                                   # under the front quad
    template = template.with_vertices(behind)
    scan = uv_plane(3)
    vis = scan_visibility(template, ClosestPointTree(scan.vertices, scan.triangles))
    assert (vis[:4] > 0.99).all() and (vis[4:] < 0.01).all()
    baked = bake_tiles(template, scan, np.full((4, 4, 3), 200, np.uint8), size=8,
                       max_distance=1.0)         # near enough: unseen all the same
    cov = {s.tile: r.filled_fraction for s, r in baked.images.items()}
    assert cov == {1001: 1.0, 1002: 0.0}
    assert baked.filled_fraction == pytest.approx(0.5)
    # with nothing in front of it, the same quad is seen
    alone = bake_texture(template, scan, np.full((4, 4, 3), 200, np.uint8), size=8,
                         max_distance=1.0, tile=1002,
                         visibility=np.ones(template.n_vertices))
    assert alone.filled_fraction == 1.0


def test_overlapping_materials_in_one_tile_get_images_of_their_own():
    # m0 and m1 overlap in tile 1001 (like ICT's face and eyes); m2 sits beside m0
    mesh = quads_in_tiles([(0, 0), (0, 0), (1, 0)], materials=[0, 1, 2])
    sets = texture_sets(mesh)
    assert [(s.tile, s.materials, s.label) for s in sets] == [
        (1001, (0,), None), (1001, (1,), "m1"), (1002, (2,), None)]
    paths = tile_image_paths("o.obj", sets)
    assert list(paths.values()) == ["o.1001.png", "o.m1.1001.png", "o.1002.png"]
    face_materials, materials, images = material_images(mesh, paths)
    assert materials == ("m0", "m1", "m2")
    assert images == {"m0": "o.1001.png", "m1": "o.m1.1001.png", "m2": "o.1002.png"}
    # faces without a material get one per tile when baked
    bare = quads_in_tiles([(0, 0), (1, 0)])
    fm, names, shown = material_images(bare, tile_image_paths("o.obj", texture_sets(bare)))
    assert names == ("facewrap_texture_1001", "facewrap_texture_1002")
    assert fm.tolist() == [0, 1] and shown["facewrap_texture_1002"] == "o.1002.png"


def _two_tile_sample(folder: Path) -> Path:
    """The sample, with the template's faces right of x = 0 moved to UV tile 1002."""
    tpl = make_template(24)
    paths = write_sample(folder, tpl, make_scan(tpl, resolution=24, texture_size=32))
    m = read_obj(paths["template"])
    right = m.vertices[m.face_indices].reshape(-1, 3)[:, 0] > 0
    corner_face = np.repeat(np.arange(m.n_faces), m.face_sizes)
    face_right = np.bincount(corner_face, right) > 0.5 * m.face_sizes
    uvs = np.concatenate([m.uvs, m.uvs + [1.0, 0.0]])
    face_uvs = np.where(face_right[corner_face], m.face_uvs + len(m.uvs), m.face_uvs)
    write_obj(paths["template"], Mesh(m.vertices, (m.face_offsets, m.face_indices),
                                      uvs=uvs, face_uvs=(m.face_offsets, face_uvs)))
    return folder


def test_a_wrap_of_a_two_tile_template_writes_obj_mtl_and_one_image_per_tile(tmp_path):
    d = _two_tile_sample(tmp_path / "in")
    out = tmp_path / "out"
    assert facewrap("wrap", d / "template.obj", d / "scan.obj", "--template-landmarks",
                    d / "template_landmarks.txt", "--scan-landmarks",
                    d / "scan_landmarks.txt", "--model", "rbf", "-q", "-o", out / "x.obj",
                    "--texture", d / "scan_texture.png", "--texture-size", "32",
                    "--report", out / "r.json") == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "r.json", "x.1001.png", "x.1002.png", "x.mtl", "x.obj"]
    obj = (out / "x.obj").read_text()
    assert re.findall(r"^mtllib (.+)$", obj, re.M) == ["x.mtl"]
    used = set(re.findall(r"^usemtl (.+)$", obj, re.M))
    mtl = (out / "x.mtl").read_text()
    assert set(re.findall(r"^newmtl (.+)$", mtl, re.M)) == used
    maps = re.findall(r"^map_Kd (.+)$", mtl, re.M)
    assert sorted(maps) == ["x.1001.png", "x.1002.png"]
    assert all(load_image(out / m).shape == (32, 32, 3) for m in maps)
    report = json.loads((out / "r.json").read_text())
    tex = report["texture"]
    assert [i["tile"] for i in tex["images"]] == [1001, 1002]
    assert all(0 < i["coverage"] <= 1 for i in tex["images"])
    laid = sum(i["laid_out_texels"] for i in tex["images"])
    assert tex["coverage"] == pytest.approx(
        sum(i["coverage"] * i["laid_out_texels"] for i in tex["images"]) / laid)
    t = report["timings"]
    assert t["total"] == pytest.approx(t["read"] + t["fit"] + t["bake"] + t["write"])
    assert t["bake"] >= sum(i["seconds"] for i in tex["images"]) > 0
    assert read_mesh(out / "x.obj").n_vertices == read_mesh(d / "template.obj").n_vertices


def test_an_output_tile_image_on_an_input_is_refused_before_any_work(tmp_path, capsys):
    d = _two_tile_sample(tmp_path / "in")
    # x.1002.png would overwrite the scan's texture: refused, nothing written
    (d / "x.1002.png").write_bytes((d / "scan_texture.png").read_bytes())
    before = (d / "x.1002.png").read_bytes()
    assert facewrap("wrap", d / "template.obj", d / "scan.obj", "--template-landmarks",
                    d / "template_landmarks.txt", "--scan-landmarks",
                    d / "scan_landmarks.txt", "--model", "rbf", "-q", "-o", d / "x.obj",
                    "--texture", d / "x.1002.png") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "x.1002.png" in err[0]
    assert (d / "x.1002.png").read_bytes() == before and not (d / "x.obj").exists()


@pytest.mark.slow
@pytest.mark.skipif(not ICT.exists(), reason="needs ../shared/data (ICT-FaceKit)")
def test_ict_head_bakes_its_face_from_a_face_scan_and_leaves_the_teeth_unseen():
    head = read_obj(ICT)
    sets = texture_sets(head)
    assert sorted({s.tile for s in sets}) == list(range(1001, 1008))
    main = {s.tile: s for s in sets if s.label is None}
    assert [head.materials[m] for m in main[1001].materials] == ["M_Face"]
    # the scan: ICT's own face part with its UVs, textured with a flat colour
    face, _ = head.submesh(np.flatnonzero(np.asarray(head.face_materials) == 0))
    baked = bake_tiles(head, face, np.full((8, 8, 3), 180, np.uint8), size=64,
                       sets=[main[1001], main[1004]])
    cov = {s.tile: r.filled_fraction for s, r in baked.images.items()}
    assert cov[1001] > 0.95 and cov[1004] < 0.02       # face seen, teeth not


def test_material_images_of_a_mesh_without_uvs_keep_its_materials():
    m = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]], face_materials=[0],
             materials=["a"])
    fm, names, shown = material_images(m, {})
    assert fm.tolist() == [0] and names == ("a",) and shown == {}
    assert material_images(Mesh(m.vertices, [[0, 1, 2]]), {}) == (None, (), {})



def test_file_textures_reads_an_objs_maps_per_tile_and_a_plys_single_texture(tmp_path):
    from facewrap.io.images import save_png
    from facewrap.io.ply import write_ply
    from facewrap.texture.tiles import file_textures
    mesh = quads_in_tiles([(0, 0), (1, 0)], materials=[0, 1])
    save_png(tmp_path / "a.png", np.full((2, 2, 3), 10, np.uint8))
    save_png(tmp_path / "b.png", np.full((2, 2, 3), 20, np.uint8))
    (tmp_path / "m.mtl").write_text("newmtl m0\nmap_Kd a.png\nnewmtl m1\nmap_Kd b.png\n")
    faces = mesh.faces_array()
    obj = Mesh(mesh.vertices, faces, uvs=mesh.uvs, face_uvs=faces,
               face_materials=mesh.face_materials, materials=mesh.materials,
               mtllib=["m.mtl"])
    write_obj(tmp_path / "t.obj", obj)
    found = file_textures(tmp_path / "t.obj", read_obj(tmp_path / "t.obj"))
    assert {t: int(im[0, 0, 0]) for t, im in found.items()} == {1001: 10, 1002: 20}
    (tmp_path / "m.mtl").write_text("newmtl m0\nmap_Kd gone.png\n")   # missing: left out
    assert file_textures(tmp_path / "t.obj", read_obj(tmp_path / "t.obj")) == {}
    ply = tmp_path / "t.ply"
    one = uv_plane(2)
    quads = one.faces_array()
    write_ply(ply, Mesh(one.vertices, quads, uvs=one.uvs, face_uvs=quads, texture="a.png"))
    assert list(file_textures(ply, read_mesh(ply))) == [1001]
    text = ply.read_bytes().replace(b"comment TextureFile a.png\n",
                                    b"comment TextureFile a.png\ncomment TextureFile b.png\n")
    ply.write_bytes(text)            # which face shows which image is not read: none
    assert file_textures(ply, read_mesh(ply)) == {}


def test_a_transfer_onto_a_textured_target_embeds_its_texture_in_the_glb(tmp_path):
    import struct
    from facewrap.io.images import save_png
    tpl = make_template(24)
    paths = write_sample(tmp_path, tpl, make_scan(tpl, resolution=24, texture_size=16))
    m = read_obj(paths["template"])
    save_png(tmp_path / "skin.png", np.full((8, 8, 3), 77, np.uint8))
    (tmp_path / "t.mtl").write_text("newmtl skin\nKd 1 1 1\nmap_Kd skin.png\n")
    write_obj(tmp_path / "target.obj", Mesh(
        m.vertices, (m.face_offsets, m.face_indices), uvs=m.uvs,
        face_uvs=(m.face_offsets, m.face_uvs), face_materials=np.zeros(m.n_faces, int),
        materials=["skin"], mtllib=["t.mtl"]))
    ids = paths["template_landmarks"].read_text().split()[:12]
    (tmp_path / "markers.txt").write_text("".join(f"{i} {i}\n" for i in ids))
    assert facewrap("transfer", paths["template"], tmp_path / "target.obj", "--markers",
                    tmp_path / "markers.txt", "--source-shapes", tmp_path / "blendshapes",
                    "-o", tmp_path / "shapes", "--gltf", tmp_path / "s.glb", "-q") == 0
    data = (tmp_path / "s.glb").read_bytes()
    (length,) = struct.unpack("<I", data[12:16])
    doc = json.loads(data[20:20 + length])
    assert len(doc["images"]) == 1
    prim = doc["meshes"][0]["primitives"][0]
    assert "NORMAL" in prim["attributes"] and all("NORMAL" in t for t in prim["targets"])
    material = doc["materials"][prim["material"]]
    assert material["pbrMetallicRoughness"]["baseColorTexture"]["index"] == 0


def test_a_triangle_straddling_two_tiles_is_baked_in_its_centroids_tile_clipped():
    from facewrap.texture import rasterize_uv
    # centroid u = 0.8 (tile 1001); its corner at u = 1.4 reaches into tile 1002
    tri = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0.]], [[0, 1, 2]],
               uvs=[[0.5, 0.1], [1.4, 0.1], [0.5, 0.9]], face_uvs=[[0, 1, 2]])
    assert triangle_tiles(tri).tolist() == [1001] and used_tiles(tri) == (1001,)
    inside = rasterize_uv(tri, 20, 1001)
    u = (inside.pixels[:, 1] + 0.5) / 20
    assert len(inside) and u.min() > 0.5 and u.max() < 1.0     # clipped at the tile edge
    assert len(rasterize_uv(tri, 20, 1002)) == 0                # not folded into 1002
