"""PLY reader and writer: round trips, real files, trimesh as an oracle, every error.

Test files are built here by :func:`make_ply`, an encoder written with :mod:`struct`
independently of :func:`facewrap.io.ply.write_ply`, so reader bugs and writer bugs
cannot cancel out.
"""

import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from facewrap.errors import InputError
from facewrap.io.ply import read_ply, write_ply
from facewrap.mesh import Mesh

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
AVATARS = DATA / "onizuka2019" / "avatars"
needs_data = pytest.mark.skipif(not DATA.exists(),
                                reason="../shared/data not found: real-data test skipped")

_STRUCT = {"char": "b", "int8": "b", "uchar": "B", "uint8": "B", "short": "h",
           "int16": "h", "ushort": "H", "uint16": "H", "int": "i", "int32": "i",
           "uint": "I", "uint32": "I", "float": "f", "float32": "f", "double": "d",
           "float64": "d"}


def make_ply(fmt: str, elements, comments=(), header_extra=()) -> bytes:
    """Encode a PLY file.

    ``elements`` is ``[(name, ["float x", "list uchar int vertex_indices", ...],
    rows)]`` with one tuple per row (a sequence for each list property).
    """
    head = ["ply", f"format {fmt} 1.0", *[f"comment {c}" for c in comments],
            *header_extra]
    for name, props, rows in elements:
        head.append(f"element {name} {len(rows)}")
        head += [f"property {p}" for p in props]
    head.append("end_header")
    out = ("\n".join(head) + "\n").encode()
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    for _, props, rows in elements:
        types = [p.split() for p in props]
        for row in rows:
            if order is None:
                toks = []
                for t, v in zip(types, row):
                    toks += [str(len(v)), *map(repr, v)] if t[0] == "list" else [repr(v)]
                out += (" ".join(toks) + "\n").encode()
                continue
            for t, v in zip(types, row):
                if t[0] == "list":
                    out += struct.pack(order + _STRUCT[t[1]], len(v))
                    out += struct.pack(order + _STRUCT[t[2]] * len(v), *v)
                else:
                    out += struct.pack(order + _STRUCT[t[0]], v)
    return out


FORMATS = ["ascii", "binary_little_endian", "binary_big_endian"]
XYZ = ["float x", "float y", "float z"]
TRI = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (1.0, 1.0, 0.5)]


def assert_same_mesh(a: Mesh, b: Mesh):
    assert np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.face_offsets, b.face_offsets)
    assert np.array_equal(a.face_indices, b.face_indices)
    for name in ("uvs", "face_uvs", "normals", "face_normals", "vertex_colors"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert np.array_equal(x, y), name
    assert a.texture == b.texture


def quad_grid(k=4):
    """A k x k grid of quads with awkward float coordinates."""
    rng = np.random.default_rng(1)
    ij = np.stack(np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij"), -1)
    V = np.column_stack([ij.reshape(-1, 2) * 0.1, rng.normal(size=(k + 1) ** 2) / 3])
    vid = np.arange((k + 1) ** 2).reshape(k + 1, k + 1)
    F = np.stack([vid[:-1, :-1], vid[1:, :-1], vid[1:, 1:], vid[:-1, 1:]], -1)
    return V, F.reshape(-1, 4)


def textured_mixed():
    """Two quads, a triangle and a pentagon, with a UV seam and RGBA colours.

    The UV table is in order of first use, which is how the reader rebuilds it,
    so the round trip can be compared exactly.
    """
    V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0],
                  [1, 2, 0.5], [3, 0.5, 1 / 3]])
    faces = [[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 6], [2, 7, 5, 4, 1]]
    uvs = np.array([[0, 0], [.5, 0], [.5, .5], [0, .5], [.6, 0], [1, 0], [1, .5],
                    [.6, .5], [.25, 1], [0.1, 0.7]])
    face_uvs = [[0, 1, 2, 3], [4, 5, 6, 7], [3, 2, 8], [5, 9, 6, 7, 4]]  # seam
    colors = np.arange(32).reshape(8, 4) * 8 / 255.0
    return Mesh(V, faces, uvs=uvs, face_uvs=face_uvs, vertex_colors=colors,
                texture="skin.png")


# -- round trips ----------------------------------------------------------------------
@pytest.mark.parametrize("binary", [True, False])
def test_round_trip_triangles(tmp_path, binary):
    rng = np.random.default_rng(0)
    V = rng.normal(size=(60, 3)) * 10.0 ** rng.integers(-8, 8, size=(60, 1))
    F = rng.integers(0, 60, size=(90, 3))
    normals = rng.normal(size=(60, 3))
    mesh = Mesh(V, F, normals=normals, face_normals=F)
    write_ply(tmp_path / "t.ply", mesh, binary=binary)
    back = read_ply(tmp_path / "t.ply")
    assert_same_mesh(mesh, back)
    assert back.is_triangle_mesh


@pytest.mark.parametrize("binary", [True, False])
def test_round_trip_quads_with_vertex_uvs(tmp_path, binary):
    V, F = quad_grid()
    uvs = V[:, :2] / 0.4
    mesh = Mesh(V, F, uvs=uvs)  # one uv per vertex
    write_ply(tmp_path / "q.ply", mesh, binary=binary)
    text = (tmp_path / "q.ply").read_bytes().split(b"end_header")[0]
    assert b"texture_u" in text and b"texcoord" not in text
    back = read_ply(tmp_path / "q.ply")
    assert_same_mesh(mesh, back)
    assert back.face_sizes.tolist() == [4] * 16  # quads stay quads


@pytest.mark.parametrize("binary", [True, False])
def test_round_trip_mixed_polygons_uvs_colours(tmp_path, binary):
    mesh = textured_mixed()
    write_ply(tmp_path / "m.ply", mesh, binary=binary)
    back = read_ply(tmp_path / "m.ply")
    assert_same_mesh(mesh, back)
    assert back.face_sizes.tolist() == [4, 4, 3, 5]


def test_uv_table_is_compacted_but_every_corner_kept(tmp_path):
    mesh = textured_mixed()
    shuffled = np.random.default_rng(2).permutation(len(mesh.uvs))
    inverse = np.argsort(shuffled)
    uvs = np.vstack([mesh.uvs[shuffled], [[9.0, 9.0]]])  # reordered, one unused
    other = Mesh(mesh.vertices, (mesh.face_offsets, mesh.face_indices), uvs=uvs,
                 face_uvs=(mesh.face_offsets, inverse[mesh.face_uvs]))
    write_ply(tmp_path / "u.ply", other)
    back = read_ply(tmp_path / "u.ply")
    assert np.array_equal(back.uvs[back.face_uvs], other.uvs[other.face_uvs])
    assert np.array_equal(back.uvs, mesh.uvs)  # order of first use


def test_writer_drops_normals_that_differ_per_corner_and_keeps_shared_ones(tmp_path):
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.]])
    F = [[0, 1, 2], [2, 1, 3]]
    shared = Mesh(V, F, normals=[[0, 0, 1.], [0, 1, 0]],
                  face_normals=[[0, 0, 1], [1, 0, 0]])
    write_ply(tmp_path / "s.ply", shared)
    back = read_ply(tmp_path / "s.ply")
    assert back.normals[back.face_normals].tolist() == shared.normals[
        shared.face_normals].tolist()
    split = Mesh(V, F, normals=[[0, 0, 1.], [0, 1, 0]], face_normals=[[0, 0, 0], [1, 1, 1]])
    write_ply(tmp_path / "p.ply", split)
    assert read_ply(tmp_path / "p.ply").normals is None


def test_large_polygons_get_a_wider_count_type(tmp_path):
    k = 300
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    V = np.column_stack([np.cos(t), np.sin(t), np.zeros(k)])
    mesh = Mesh(V, [list(range(k))], uvs=V[:, :2], face_uvs=[list(range(k))])
    for binary in (True, False):
        write_ply(tmp_path / "big.ply", mesh, binary=binary)
        assert b"list ushort int vertex_indices" in (tmp_path / "big.ply").read_bytes()
        assert_same_mesh(mesh, read_ply(tmp_path / "big.ply"))


def test_writer_rejects_bad_input_and_is_atomic(tmp_path):
    p = tmp_path / "out.ply"
    p.write_text("old")
    with pytest.raises(TypeError, match="Mesh"):
        write_ply(p, "not a mesh")
    bad = Mesh([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]], [[0, 1, 2]])
    with pytest.raises(ValueError, match="NaN"):
        write_ply(p, bad)
    assert p.read_text() == "old"
    write_ply(tmp_path / "sub" / "new.ply", textured_mixed())  # makes the folder
    assert [q.name for q in tmp_path.rglob("*") if q.name.startswith(".tmp")] == []


def test_point_cloud_and_empty_face_element(tmp_path):
    p = tmp_path / "pc.ply"
    p.write_bytes(make_ply("ascii", [("vertex", XYZ, TRI)]))
    m = read_ply(p)
    assert m.n_vertices == 4 and m.n_faces == 0
    p.write_bytes(make_ply("binary_little_endian", [
        ("vertex", XYZ, TRI), ("face", ["list uchar int vertex_indices"], [])]))
    assert read_ply(p).n_faces == 0


# -- reading what other writers make -------------------------------------------------
@pytest.mark.parametrize("fmt", FORMATS)
def test_any_element_order_unknown_elements_and_properties_skipped(tmp_path, fmt):
    V = [(0.5, 0.0, 0.0), (1.0, 0.25, 0.0), (0.0, 1.0, -2.0), (1.0, 1.0, 0.5)]
    elements = [
        ("material", ["uchar ambient_red", "list ushort double weights", "float power"],
         [(1, (0.5, 0.25), 2.0), (2, (), 3.0)]),
        ("face", ["uchar flags", "list int8 uint vertex_index", "list uint16 short junk",
                  "int texnumber"],
         [(7, (0, 1, 2), (5, -6, 7, 8), 0), (9, (2, 1, 3, 0), (), 1),
          (1, (3, 2, 1), (1,), 2)]),
        ("edge", ["int vertex1", "int vertex2"], [(0, 1), (1, 2)]),
        ("vertex", ["double confidence", "float x", "list uchar float extra",
                    "float y", "ushort red", "float z", "ushort green", "ushort blue",
                    "float nx", "float ny", "float nz", "float s", "float t"],
         [(0.9, *v[:1], tuple(range(i)), v[1], 65535 * (i % 2), v[2], 0, 65535,
           0.0, 0.0, 1.0, i / 4, 1 - i / 4) for i, v in enumerate(V)]),
    ]
    p = tmp_path / "odd.ply"
    p.write_bytes(make_ply(fmt, elements, comments=["made by hand", "TextureFile a b.png",
                                                    "TextureFile second.png"],
                           header_extra=["obj_info scanner 3"]))
    m = read_ply(p)
    assert m.vertices.tolist() == [list(v) for v in V]
    assert [f.tolist() for f in m.polygons()] == [[0, 1, 2], [2, 1, 3, 0], [3, 2, 1]]
    assert m.vertex_colors.tolist() == [[0, 0, 1], [1, 0, 1], [0, 0, 1], [1, 0, 1]]
    assert m.normals.tolist() == [[0, 0, 1]] * 4
    assert np.array_equal(m.face_normals, m.face_indices)
    assert m.uvs.tolist() == [[i / 4, 1 - i / 4] for i in range(4)]
    assert m.texture == "a b.png"


@pytest.mark.parametrize("fmt", FORMATS)
def test_per_corner_texcoord_like_meshlab(tmp_path, fmt):
    faces = [((0, 1, 2), (0.0, 0.0, 1.0, 0.0, 0.0, 1.0), 0),
             ((2, 1, 3), (0.5, 0.5, 1.0, 0.0, 1.0, 1.0), 1),  # corner 2: seam
             ((0, 2, 3, 1), (0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0), 0)]
    p = tmp_path / "tc.ply"
    p.write_bytes(make_ply(fmt, [
        ("vertex", XYZ + ["uchar red", "uchar green", "uchar blue", "uchar alpha"],
         [(*v, 255, 0, 51, 255) for v in TRI]),
        ("face", ["list uchar int vertex_indices", "list uchar float texcoord",
                  "int texnumber", "uchar red", "uchar green", "uchar blue"],
         [(*f, 1, 2, 3) for f in faces])], comments=["TextureFile tex.png"]))
    m = read_ply(p)
    assert m.face_sizes.tolist() == [3, 3, 4]
    corner_uv = np.concatenate([np.reshape(f[1], (-1, 2)) for f in faces])
    assert np.array_equal(m.uvs[m.face_uvs], corner_uv)
    assert len(m.uvs) == len(np.unique(corner_uv, axis=0)) == 5
    assert m.vertex_colors.tolist() == [[1, 0, 0.2, 1]] * 4
    assert m.texture == "tex.png"


def test_empty_texcoord_lists_mean_no_uvs(tmp_path):
    p = tmp_path / "e.ply"
    p.write_bytes(make_ply("binary_little_endian", [
        ("vertex", XYZ, TRI),
        ("face", ["list uchar int vertex_indices", "list uchar float texcoord"],
         [((0, 1, 2), ()), ((1, 3, 2), ())])]))
    assert read_ply(p).uvs is None


@pytest.mark.parametrize("fmt", FORMATS)
def test_mixed_sizes_with_several_lists_use_the_row_walk(tmp_path, fmt):
    rng = np.random.default_rng(3)
    sizes = rng.integers(3, 7, size=200)
    faces = [tuple(int(i) for i in rng.integers(0, 4, size=k)) for k in sizes]
    rows = [(f, tuple(float(j) for j in range(k % 3)),
             tuple(0.5 * j for j in range(2 * len(f))), 3) for k, f in enumerate(faces)]
    p = tmp_path / "w.ply"
    p.write_bytes(make_ply(fmt, [
        ("vertex", XYZ, TRI),
        ("face", ["list ushort uint vertex_indices", "list uint double junk",
                  "list uchar double texcoord", "short after"], rows)]))
    m = read_ply(p)
    assert [tuple(f.tolist()) for f in m.polygons()] == faces
    assert np.array_equal(m.uvs[m.face_uvs].ravel(),
                          np.concatenate([r[2] for r in rows]))


def test_big_endian_matches_little_endian(tmp_path):
    rng = np.random.default_rng(4)
    V = [tuple(v) for v in rng.normal(size=(30, 3)).tolist()]
    F = [tuple(f) for f in rng.integers(0, 30, size=(40, 3)).tolist()]
    meshes = []
    for fmt in ("binary_little_endian", "binary_big_endian", "ascii"):
        p = tmp_path / f"{fmt}.ply"
        p.write_bytes(make_ply(fmt, [("vertex", ["double x", "double y", "double z"], V),
                                     ("face", ["list uchar int vertex_indices"],
                                      [(f,) for f in F])]))
        meshes.append(read_ply(p))
    for m in meshes:
        assert m.vertices.tolist() == [list(v) for v in V]
        assert m.faces_array().tolist() == [list(f) for f in F]


def test_crlf_blank_lines_and_trailing_spaces_in_ascii(tmp_path):
    text = ("ply\r\nformat ascii 1.0\r\nelement vertex 3\r\nproperty float x\r\n"
            "property float y\r\nproperty float z\r\nelement face 1\r\n"
            "property list uchar int vertex_indices\r\nend_header\r\n"
            "0 0 0 \r\n\r\n1 0 0\r\n  0 1e0 0\r\n3 0 1 2\r\n\r\n")
    p = tmp_path / "crlf.ply"
    p.write_bytes(text.encode())
    m = read_ply(p)
    assert m.vertices.tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    assert m.faces_array().tolist() == [[0, 1, 2]]


def test_per_corner_uvs_are_the_distinct_pairs_in_order_of_first_use(tmp_path):
    rng = np.random.default_rng(5)
    for denominator in (4.0, 3.0):        # float32-exact pairs, and pairs that are not
        pairs = rng.integers(0, 4, size=(3 * 170, 2)) / denominator
        faces = [([0, 1, 2], list(pairs[3 * k:3 * k + 3].ravel())) for k in range(170)]
        path = tmp_path / f"uv{int(denominator)}.ply"
        path.write_bytes(make_ply("binary_little_endian", [
            ("vertex", ["double x", "double y", "double z"], TRI[:3]),
            ("face", ["list uchar int vertex_indices", "list uchar double texcoord"],
             faces)]))
        m = read_ply(path)
        idx = m.face_uvs
        assert np.array_equal(m.uvs[idx], pairs)
        assert len(m.uvs) == len(np.unique(pairs, axis=0))
        first_use = [int(np.argmax(idx == k)) for k in range(len(m.uvs))]
        assert first_use == sorted(first_use)


# -- real data --------------------------------------------------------------------------
def _text_rows(path: Path):
    lines = path.read_text().splitlines()
    start = lines.index("end_header") + 1
    return lines, start


@needs_data
@pytest.mark.parametrize("name, n_vertices, n_faces", [
    ("Horse", 2435, 4817), ("Mario", 898, 1682), ("Oldman", 15941, 31620)])
def test_real_avatars_match_text_and_trimesh(name, n_vertices, n_faces):
    trimesh = pytest.importorskip("trimesh")
    path = AVATARS / f"{name}.ply"
    m = read_ply(path)
    assert (m.n_vertices, m.n_faces) == (n_vertices, n_faces)
    lines, start = _text_rows(path)
    assert m.vertices[0].tolist() == [float(t) for t in lines[start].split()[:3]]
    last = lines[start + n_vertices - 1].split()
    assert m.vertices[-1].tolist() == [float(t) for t in last[:3]]
    face_last = lines[start + n_vertices + n_faces - 1].split()
    assert m.polygons()[-1].tolist() == [int(t) for t in face_last[1:4]]
    t = trimesh.load(path, process=False, fix_texture=False)
    assert np.array_equal(t.faces, m.faces_array())
    # trimesh parses the declared float32; we keep the text's value in float64
    np.testing.assert_allclose(m.vertices, t.vertices, rtol=1e-6, atol=1e-5)


@needs_data
def test_real_mario_texcoords_colours_and_texture():
    path = AVATARS / "Mario.ply"
    m = read_ply(path)
    assert m.texture == "Mario_body.png"
    assert m.vertex_colors.shape == (898, 4)
    assert m.vertex_colors[0].tolist() == [192 / 255] * 3 + [1.0]
    lines, start = _text_rows(path)
    corner_uv = np.array([[float(t) for t in lines[start + 898 + f].split()[5:11]]
                          for f in range(m.n_faces)]).reshape(-1, 2)
    assert np.array_equal(m.uvs[m.face_uvs], corner_uv)
    assert len(m.uvs) == len(np.unique(corner_uv, axis=0)) < len(corner_uv)


@needs_data
def test_real_file_survives_binary_and_ascii_round_trips(tmp_path):
    m = read_ply(AVATARS / "Mario.ply")
    for binary in (True, False):
        write_ply(tmp_path / "mario.ply", m, binary=binary)
        assert_same_mesh(m, read_ply(tmp_path / "mario.ply"))


# -- trimesh as an oracle ------------------------------------------------------------
def test_trimesh_binary_export_reads_identically(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    rng = np.random.default_rng(6)
    V = rng.normal(size=(100, 3)).astype(np.float32).astype(np.float64)
    F = rng.integers(0, 100, size=(150, 3))
    p = tmp_path / "tm.ply"
    p.write_bytes(trimesh.Trimesh(V, F, process=False).export(file_type="ply"))
    m = read_ply(p)
    assert np.array_equal(m.vertices, V) and np.array_equal(m.faces_array(), F)
    t = trimesh.load(p, process=False)
    assert np.array_equal(m.vertices, t.vertices)
    assert np.array_equal(m.faces_array(), t.faces)


def test_our_binary_output_loads_in_trimesh(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    rng = np.random.default_rng(7)
    V = rng.normal(size=(100, 3))
    F = rng.integers(0, 100, size=(150, 3))
    colors = rng.integers(0, 256, size=(100, 3)) / 255
    write_ply(tmp_path / "ours.ply", Mesh(V, F, vertex_colors=colors))
    t = trimesh.load(tmp_path / "ours.ply", process=False)
    assert np.array_equal(t.vertices, V) and np.array_equal(t.faces, F)
    assert np.array_equal(t.visual.vertex_colors[:, :3], np.rint(colors * 255))
    # trimesh's binary reader needs one list length per element: use triangles
    mixed = textured_mixed()
    tris = Mesh(mixed.vertices, mixed.triangles, uvs=mixed.uvs, face_uvs=mixed.triangle_uvs)
    write_ply(tmp_path / "tex.ply", tris)
    t = trimesh.load(tmp_path / "tex.ply", process=False)  # splits vertices at seams
    assert np.array_equal(t.visual.uv[t.faces], tris.uvs[tris.triangle_uvs])
    assert np.array_equal(t.vertices[t.faces], tris.vertices[tris.triangles])


# -- errors ---------------------------------------------------------------------------
def check_error(path: Path, phrase: str, line: int | None = None):
    with pytest.raises(InputError) as info:
        read_ply(path)
    message = str(info.value)
    assert path.name in message and phrase in message, message
    if line is not None:
        assert info.value.line == line and f":{line}:" in message, message
    return info.value


ASCII_HEAD = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
              "property float y\nproperty float z\nelement face 1\n"
              "property list uchar int vertex_indices\nend_header\n")  # 9 lines


def test_error_missing_and_empty_file(tmp_path):
    check_error(tmp_path / "nope.ply", "cannot read file")
    (tmp_path / "empty.ply").write_bytes(b"")
    check_error(tmp_path / "empty.ply", "empty file")
    (tmp_path / "blank.ply").write_bytes(b"\n  \n")
    check_error(tmp_path / "blank.ply", "empty file")


@pytest.mark.parametrize("text, phrase, line", [
    ("PLY\nformat ascii 1.0\nend_header\n", "not a PLY file", 1),
    ("solid cube\nfacet normal 0 0 1\n", "not a PLY file", 1),
    ("ply\nelement vertex 0\nproperty float x\nend_header\n", "no 'format' line", None),
    ("ply\nformat utf8 1.0\nend_header\n", "unknown format 'utf8'", 2),
    ("ply\nformat ascii\nend_header\n", "format line", 2),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n0\n", "end_header",
     None),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n0\n",
     "unknown property type 'float128'", 4),
    ("ply\nformat ascii 1.0\nelement face 1\nproperty list float int vertex_indices\n"
     "end_header\n", "list count type must be an integer", 4),
    ("ply\nformat ascii 1.0\nelement vertex -1\nend_header\n", "element line", 3),
    ("ply\nformat ascii 1.0\nproperty float x\nend_header\n", "before any element", 3),
    ("ply\nformat ascii 1.0\nelemnt vertex 1\nend_header\n", "unknown header line", 3),
    ("ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\n"
     "end_header\n", "no 'vertex' element", None),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
     "end_header\n0 0\n", "vertex element has no property 'z'", 3),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
     "property list uchar float z\nend_header\n0 0 1 0\n", "must not be a list", 6),
    (ASCII_HEAD.replace("vertex_indices", "corners") + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
     "no list property 'vertex_indices'", 7),
])
def test_header_errors(tmp_path, text, phrase, line):
    p = tmp_path / "bad_header.ply"
    p.write_bytes(text.encode())
    check_error(p, phrase, line)


@pytest.mark.parametrize("body, phrase, line", [
    ("0 0 0\n1 0 0\n", "truncated", 11),
    ("0 0 0\n1 0 0\n0 1 0\n", "truncated", 12),
    ("0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n", "'zero' is not a number", 11),
    ("0 0 0\n1 0 0\n0 1 0\n3 0 1 x2\n", "'x2' is not a number", 13),
    ("0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n", "NaN or infinite", 11),
    ("0 0 0\n1 0 0\n0 1 -inf\n3 0 1 2\n", "NaN or infinite", 12),
    ("0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "out of range", 13),
    ("0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n", "out of range", 13),
    ("0 0 0\n1 0 0\n0 1 0\n3 0 1.5 2\n", "out of range", 13),
    ("0 0 0\n1 0 0\n0 1 0\n2 0 1\n", "at least 3 are needed", 13),
    ("0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n", "does not match", 13),
    ("0 0 0\n1 0 0 7\n0 1 0\n3 0 1 2\n", "does not match", 11),
    ("0 0 0\n1 0\n0 1 0\n3 0 1 2\n", "does not match", 11),
    ("0 0 0\n1 0 0\n0 1 0\n-3 0 1 2\n", "does not match", 13),
])
def test_ascii_data_errors_name_the_line(tmp_path, body, phrase, line):
    p = tmp_path / "bad_data.ply"
    p.write_bytes((ASCII_HEAD + body).encode())
    check_error(p, phrase, line)


def test_ascii_colour_and_texcoord_errors(tmp_path):
    p = tmp_path / "colour.ply"
    p.write_bytes(make_ply("ascii", [
        ("vertex", XYZ + ["uchar red", "uchar green", "uchar blue"],
         [(*v, 0, 300, 0) for v in TRI])]))
    check_error(p, "is not an integer in [0, 255]", 11)
    p.write_bytes(make_ply("ascii", [
        ("vertex", XYZ, TRI),
        ("face", ["list uchar int vertex_indices", "list uchar float texcoord"],
         [((0, 1, 2), (0.0,) * 6), ((1, 3, 2), (0.0,) * 4)])]))
    check_error(p, "expected 2 per corner", 16)


@pytest.mark.parametrize("fmt", ["binary_little_endian", "binary_big_endian"])
def test_binary_data_errors_name_row_and_byte(tmp_path, fmt):
    def write(vertices, faces, face_props=("list uchar int vertex_indices",)):
        p = tmp_path / "bad.ply"
        p.write_bytes(make_ply(fmt, [("vertex", XYZ, vertices),
                                     ("face", list(face_props), faces)]))
        return p

    good = write(TRI, [((0, 1, 2),), ((1, 3, 2),)])
    data = good.read_bytes()
    for cut in (1, 5, 13, 14 + 26):
        good.write_bytes(data[:-cut])
        err = check_error(good, "truncated")
        assert "byte" in str(err) and err.line is None
    check_error(write([*TRI[:3], (1.0, float("nan"), 0.0)], [((0, 1, 2),)]),
                "vertex 3: vertex coordinate is NaN or infinite (row starts at byte")
    check_error(write(TRI, [((0, 1, 2),), ((1, 4, 2),)]), "face 1: face index 4")
    check_error(write(TRI, [((0, 1, 2),), ((1, -1, 2),)]), "out of range")
    check_error(write(TRI, [((0, 1, 2),), ((1, 2),)]), "face 1: face has 2 corners")
    check_error(write(TRI, [((0, 1, 2),), ((1, 2, 3, 1),), ((0, 1),)]),
                "face 2: face has 2 corners")
    check_error(write(TRI, [((0, 1, 2),), ((1, 2, 4),)],
                      ["list char int vertex_indices"]), "out of range")
    p = write(TRI, [((0, 1, 2),), ((1, 2, 3),)], ["list char int vertex_indices"])
    raw = bytearray(p.read_bytes())
    raw[-13] = 0xFF  # second face: list length -1
    p.write_bytes(bytes(raw))
    check_error(p, "negative list length -1")


def test_binary_huge_counts_are_truncation_not_memory_errors(tmp_path):
    p = tmp_path / "huge.ply"
    p.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 99999999999999\n"
                  b"property float x\nproperty float y\nproperty float z\nend_header\n"
                  + bytes(24))
    check_error(p, "truncated")
    p.write_bytes(make_ply("binary_little_endian", [
        ("vertex", XYZ, TRI), ("face", ["list uint int vertex_indices"],
                               [((0, 1, 2),)])])[:-16] + struct.pack("<I", 2**31))
    check_error(p, "truncated")


# -- bounded resources ----------------------------------------------------------------
BOGUS = {
    "ascii.ply": b"ply\nformat ascii 1.0\nelement vertex 100000000\nproperty float x\n"
                 b"property float y\nproperty float z\nend_header\n",
    "binary.ply": b"ply\nformat binary_little_endian 1.0\nelement vertex 100000000\n"
                  b"property double x\nproperty double y\nproperty double z\n"
                  b"end_header\n",
    "mesh.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "tail.ply": make_ply("binary_little_endian", [  # a good PLY, then 2 GB of zeros
        ("vertex", XYZ, [(0, 0, 0), (1, 0, 0), (0, 1, 0)]),
        ("face", ["list uchar int vertex_indices"], [((0, 1, 2),)])]),
}
# A fresh interpreter reads the file under an address-space limit: a reader that
# allocated for the header's claim, or read the file whole, fails with MemoryError.
_READ_BOUNDED = """
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, (int(sys.argv[2]), int(sys.argv[2])))
from facewrap.errors import InputError
from facewrap.io import read_mesh
try:
    print(len(read_mesh(sys.argv[1]).vertices), "vertices")
except InputError as exc:
    print(exc)
# VmHWM, not ru_maxrss: the latter keeps the parent's size from before the exec
peak_kb = next(int(line.split()[1]) for line in open("/proc/self/status")
               if line.startswith("VmHWM:"))
print(peak_kb // 1024)
"""


@pytest.mark.skipif(sys.platform != "linux", reason="sparse files and RLIMIT_AS")
@pytest.mark.parametrize("name, message", [
    ("ascii.ply", "NUL bytes in an ASCII PLY (a binary or sparse file with an ASCII "
                  "header?)"),
    ("binary.ply", "element 'vertex' needs at least 2400000000 bytes from byte 126, "
                   "the file has 2147483522"),
    ("mesh.obj", "binary data, not a text file"),
    ("tail.ply", None),
])
def test_a_bogus_2gb_sparse_file_is_refused_without_reading_it(tmp_path, name, message):
    path = tmp_path / name
    with open(path, "wb") as fh:
        fh.write(BOGUS[name])
        fh.truncate(2 << 30)
    if os.stat(path).st_blocks * 512 > 1 << 20:
        pytest.skip("this file system does not keep files sparse")
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1] / "src"),
               OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    # a binary PLY is mapped, which takes address space (not memory) for the file
    limit = (4 << 30) if name == "tail.ply" else (2 << 30)
    r = subprocess.run([sys.executable, "-c", _READ_BOUNDED, str(path), str(limit)],
                       capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
    error, peak_mb = r.stdout.splitlines()
    if message is None:  # the header's data is read, the rest is never touched
        assert error == "3 vertices"
    else:
        prefix = "file is truncated: " if "binary" in name else ""
        assert error == f"{path}: {prefix}{message}"
    assert int(peak_mb) < 200


def test_ascii_counts_beyond_a_large_file_are_refused_from_the_header(tmp_path):
    rows = b"0 0 0\n" * 200_000  # 1.2 MB: past the first read
    path = tmp_path / "big.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 10000000\nproperty float x\n"
                     b"property float y\nproperty float z\nend_header\n" + rows)
    check_error(path, "need 30000000 values (at least 59999999 bytes) from byte 107, "
                      "the file has 1200000")
    path.write_bytes(path.read_bytes().replace(b"10000000", b"200000  "))
    assert len(read_ply(path).vertices) == 200_000
    path.write_bytes(b"ply\nformat ascii 1.0\n" + b"comment padding\n" * 70_000)
    check_error(path, "no 'end_header' line in the first 1 MiB")


# -- fuzzing ---------------------------------------------------------------------------
SEEDS = [
    ASCII_HEAD.encode() + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    make_ply("binary_little_endian", [
        ("vertex", XYZ + ["uchar red", "uchar green", "uchar blue"],
         [(*v, 1, 2, 3) for v in TRI]),
        ("face", ["list uchar int vertex_indices", "list uchar float texcoord"],
         [((0, 1, 2), (0.0,) * 6), ((1, 3, 2, 0), (0.5,) * 8)])]),
    make_ply("binary_big_endian", [
        ("junk", ["list int double w", "short k"], [((1.0,), 3)]),
        ("vertex", ["double x", "double y", "double z", "float nx", "float ny",
                    "float nz", "float u", "float v"],
         [(*v, 0.0, 0.0, 1.0, 0.5, 0.5) for v in TRI]),
        ("face", ["list ushort uint vertex_index"], [((0, 1, 2),), ((3, 2, 1, 0),)])]),
]


def _read_or_input_error(path):
    try:
        assert isinstance(read_ply(path), Mesh)
    except InputError:
        pass


@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.sampled_from(SEEDS), body=st.binary(max_size=200),
       keep=st.integers(0, 200))
def test_fuzz_random_bytes_after_a_valid_header(tmp_path, seed, body, keep):
    head, _, data = seed.partition(b"end_header\n")
    p = tmp_path / "fuzz.ply"
    p.write_bytes(head + b"end_header\n" + data[:keep] + body)
    _read_or_input_error(p)


@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.sampled_from(SEEDS), data=st.data())
def test_fuzz_header_and_data_mutations(tmp_path, seed, data):
    head, _, body = seed.partition(b"end_header\n")
    lines = head.split(b"\n")[:-1]
    for _ in range(data.draw(st.integers(1, 3))):
        k = data.draw(st.integers(0, len(lines) - 1))
        op = data.draw(st.sampled_from(["delete", "duplicate", "replace", "token",
                                        "number"]))
        if op == "delete":
            del lines[k]
        elif op == "duplicate":
            lines.insert(k, lines[k])
        elif op == "replace":
            lines[k] = data.draw(st.binary(max_size=30))
        elif op == "token":
            toks = lines[k].split() or [b""]
            j = data.draw(st.integers(0, len(toks) - 1))
            toks[j] = data.draw(st.sampled_from(
                [b"list", b"uchar", b"int", b"float", b"double", b"vertex", b"face",
                 b"x", b"vertex_indices", b"texcoord", b"ascii", b"binary_big_endian",
                 b"binary_little_endian", b"-1", b"0", b"4294967296", b"nan"]))
            lines[k] = b" ".join(toks)
        else:
            toks = lines[k].split() or [b""]
            toks[-1] = str(data.draw(st.integers(-2, 2**40))).encode()
            lines[k] = b" ".join(toks)
        if not lines:
            break
    body = bytearray(body)
    for _ in range(data.draw(st.integers(0, 4))):
        if body:
            body[data.draw(st.integers(0, len(body) - 1))] = data.draw(st.integers(0, 255))
    p = tmp_path / "fuzz.ply"
    p.write_bytes(b"\n".join(lines) + b"\nend_header\n" + bytes(body))
    _read_or_input_error(p)


@settings(max_examples=200, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=st.text(alphabet="0123456789 .-+e\nnaif\t", max_size=120))
def test_fuzz_ascii_number_soup(tmp_path, text):
    p = tmp_path / "soup.ply"
    p.write_bytes(ASCII_HEAD.encode() + text.encode())
    _read_or_input_error(p)
