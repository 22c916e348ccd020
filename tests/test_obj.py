import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from facewrap.errors import InputError
from facewrap.io.obj import read_obj, read_obj_vertices, write_obj, write_obj_series
from facewrap.mesh import Mesh

from conftest import needs_data, DATA


def assert_same_mesh(a: Mesh, b: Mesh):
    assert np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.face_offsets, b.face_offsets)
    assert np.array_equal(a.face_indices, b.face_indices)
    for name in ("uvs", "face_uvs", "normals", "face_normals", "face_materials",
                 "face_groups"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert np.array_equal(x, y), name
    assert a.materials == b.materials and a.groups == b.groups and a.mtllib == b.mtllib


def test_round_trip_mixed_polygons_with_seams(mixed_mesh, tmp_path):
    p = tmp_path / "m.obj"
    write_obj(p, mixed_mesh)
    back = read_obj(p)
    assert_same_mesh(mixed_mesh, back)
    assert back.face_sizes.tolist() == [4, 4, 3]  # quads stay quads


def test_round_trip_is_bit_exact_for_awkward_floats(tmp_path):
    rng = np.random.default_rng(0)
    V = rng.normal(size=(50, 3)) * 10.0 ** rng.integers(-8, 8, size=(50, 1))
    F = rng.integers(0, 50, size=(30, 3))
    p = tmp_path / "f.obj"
    write_obj(p, Mesh(V, F))
    assert np.array_equal(read_obj(p).vertices, V)


def test_negative_indices_and_formats(tmp_path):
    p = tmp_path / "n.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                 "vn 0 0 1\nf -3/-3/-1 -2/-2/-1 -1/-1/-1\n"
                 "v 1 1 0\nf 2//1 4//1 3//1\n")
    with pytest.raises(InputError, match="some face corners have texture"):
        read_obj(p)
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 1 1 0\nf 2 -1 3\n")
    m = read_obj(p)
    assert m.polygons()[0].tolist() == [0, 1, 2] and m.polygons()[1].tolist() == [1, 3, 2]


def test_vertex_colours_and_groups(tmp_path):
    p = tmp_path / "c.obj"
    p.write_text("o thing\nv 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\n"
                 "usemtl red\nf 1 2 3\ng other\nusemtl blue\nf 3 2 1\n")
    m = read_obj(p)
    assert m.vertex_colors[1].tolist() == [0, 1, 0]
    assert m.groups == ("thing", "other") and m.face_groups.tolist() == [0, 1]
    assert m.materials == ("red", "blue") and m.face_materials.tolist() == [0, 1]
    write_obj(tmp_path / "c2.obj", m)
    assert_same_mesh(m, read_obj(tmp_path / "c2.obj"))


def test_a_series_writes_what_write_obj_writes_of_each_vertex_set(tmp_path):
    """Byte for byte, with UVs, normals (dropped with the old positions), colours,
    groups, materials and a library, into a folder the series makes."""
    p = tmp_path / "c.obj"
    p.write_text("mtllib lib.mtl\no thing\nv 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\n"
                 "v 1 1 0 1 1 1\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n"
                 "usemtl red\nf 1/1/1 2/2/1 3/3/1\ng other\nusemtl blue\nf 3/3/1 2/2/1 4/1/1\n")
    mesh = read_obj(p)
    rng = np.random.default_rng(1)
    sets = [mesh.vertices + rng.normal(size=mesh.vertices.shape) for _ in range(5)]
    paths = [tmp_path / "new" / f"s{k}.obj" for k in range(5)]
    write_obj_series(paths, mesh, sets)
    for k, V in enumerate(sets):
        write_obj(tmp_path / "one.obj", mesh.with_vertices(V))
        assert paths[k].read_bytes() == (tmp_path / "one.obj").read_bytes()
        assert np.array_equal(read_obj(paths[k]).vertices, V)
    assert read_obj(paths[0]).normals is None


def test_a_series_refuses_mismatched_inputs_before_writing(tmp_path, mixed_mesh):
    with pytest.raises(ValueError, match="2 paths but 1 vertex sets"):
        write_obj_series([tmp_path / "a.obj", tmp_path / "b.obj"], mixed_mesh,
                         [mixed_mesh.vertices])
    with pytest.raises(ValueError, match="vertices must have shape"):
        write_obj_series([tmp_path / "a.obj", tmp_path / "b.obj"], mixed_mesh,
                         [mixed_mesh.vertices, mixed_mesh.vertices[:-1]])
    assert list(tmp_path.iterdir()) == []


def test_writer_is_atomic_and_leaves_no_temp(tmp_path, mixed_mesh):
    p = tmp_path / "out.obj"
    p.write_text("old")

    class Boom(Mesh):   # fails after the vertices are formatted, before the faces
        @property
        def face_indices(self):
            raise RuntimeError("disk on fire")
    broken = Boom.__new__(Boom)
    broken.__dict__.update(mixed_mesh.__dict__)
    with pytest.raises(RuntimeError):
        write_obj(p, broken)
    assert p.read_text() == "old"
    assert [x.name for x in tmp_path.iterdir()] == ["out.obj"]


@pytest.mark.parametrize("text, phrase, line", [
    ("", "empty file", None),
    ("   \n\n", "empty file", None),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces", None),
    ("f 1 2 3\n", "no vertices", None),
    ("v 0 0 0\nv 1 0 x\nv 0 1 0\nf 1 2 3\n", "not a number", 2),
    ("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n", "NaN", 2),
    ("v 0 0 0\nv 1 0 inf\nv 0 1 0\nf 1 2 3\n", "NaN", 2),
    ("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", "needs 3 numbers", 2),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "out of range", 4),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 0 1 2\n", "index 0", 5),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -9\n", "out of range", 4),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "at least 3", 4),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 a\n", "not an integer", 4),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2/2 3/3\n", "no 'vt' lines", 4),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n", "out of range", 5),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n", "", 4),
])
def test_malformed_obj_names_file_and_line(tmp_path, text, phrase, line):
    p = tmp_path / "bad.obj"
    p.write_text(text)
    with pytest.raises(InputError) as exc:
        read_obj(p)
    msg = str(exc.value)
    assert msg.startswith(str(p)) and phrase in msg
    if line is not None:
        assert exc.value.line == line


def test_binary_garbage_and_missing_file(tmp_path):
    p = tmp_path / "garbage.obj"
    p.write_bytes(bytes(range(256)) * 10)
    with pytest.raises(InputError, match="binary"):
        read_obj(p)
    with pytest.raises(InputError, match="cannot read"):
        read_obj(tmp_path / "missing.obj")
    with pytest.raises(InputError, match="is a folder, not a file"):
        read_obj(tmp_path)


def test_read_vertices_only_checks_count(tmp_path, mixed_mesh):
    p = tmp_path / "m.obj"
    write_obj(p, mixed_mesh)
    assert np.array_equal(read_obj_vertices(p), mixed_mesh.vertices)
    with pytest.raises(InputError, match="same topology"):
        read_obj_vertices(p, n_vertices=3)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.sampled_from([
    "v 0 0 0", "v 1 2 3", "v 1e400 0 0", "v a b c", "v 1 2", "vt 0.5 0.5", "vn 0 0 1",
    "f 1 2 3", "f 1/1 2/1 3/1", "f 1//1 2//1 3//1", "f -1 -2 -3", "f 1 2", "f 4 5 6 7",
    "f 0 1 2", "usemtl x", "g", "o", "# c", "", "s off", "l 1 2", "f 1/ 2/ 3/", "v",
    "f //1 2 3", "vt", "mtllib", "\x00", "f 1/2/3/4 2 3"]), max_size=12))
def test_fuzz_reader_returns_mesh_or_input_error(tmp_path_factory, lines):
    p = tmp_path_factory.mktemp("fz") / "f.obj"
    p.write_text("\n".join(lines))
    try:
        m = read_obj(p)
    except InputError:
        return
    assert m.n_vertices > 0 and m.n_faces > 0
    assert np.isfinite(m.vertices).all()


@needs_data
def test_round_trip_ict_neutral(tmp_path):
    src = DATA / "ict-facekit" / "FaceXModel" / "generic_neutral_mesh.obj"
    m = read_obj(src)
    assert (m.n_vertices, m.n_faces, len(m.uvs)) == (26719, 26384, 28911)
    assert int((m.face_sizes == 4).sum()) == 25836
    assert len(m.materials) == 12
    # first and last vertex as written in the file
    lines = [l for l in src.read_text().splitlines() if l.startswith("v ")]
    assert m.vertices[0].tolist() == [float(x) for x in lines[0].split()[1:]]
    assert m.vertices[-1].tolist() == [float(x) for x in lines[-1].split()[1:]]
    write_obj(tmp_path / "ict.obj", m)
    assert_same_mesh(m, read_obj(tmp_path / "ict.obj"))


@needs_data
@pytest.mark.parametrize("rel, counts", [
    ("scans/james/james.obj", (6393, 12228, 6680)),
    ("onizuka2019/blendshapes/Neutralm.obj", (4325, 8518, 4495)),
    ("scans/meshmonk/Template.obj", (7160, None, 7160)),
    ("sumner2004/horse-camel/horse_ref.obj", (8431, None, None)),
])
def test_round_trip_other_real_meshes(tmp_path, rel, counts):
    import trimesh
    m = read_obj(DATA / rel)
    nv, nf, nuv = counts
    assert m.n_vertices == nv
    if nf is not None:
        assert m.n_faces == nf
    if nuv is not None:
        assert len(m.uvs) == nuv
    # agrees with trimesh on the raw vertex list and faces (no processing)
    tm = trimesh.load(DATA / rel, process=False, maintain_order=True)
    if len(tm.vertices) == m.n_vertices:
        assert np.allclose(tm.vertices, m.vertices)
    write_obj(tmp_path / "x.obj", m)
    assert_same_mesh(m, read_obj(tmp_path / "x.obj"))


_WITHOUT_ACCELERATORS = """
import sys
sys.modules["fastnumbers"] = None   # import fails: numpy's parser and repr are used
sys.modules["orjson"] = None
import numpy as np
from facewrap.io.obj import read_obj, write_obj
mesh = read_obj(sys.argv[1])
write_obj(sys.argv[2], mesh)
np.save(sys.argv[3], read_obj(sys.argv[2]).vertices)
"""


def test_same_values_with_and_without_the_float_accelerators(tmp_path, mixed_mesh):
    """fastnumbers/orjson (when installed) and numpy/repr give bit-identical meshes,
    across each other's files too."""
    import os
    import subprocess
    import sys
    from pathlib import Path
    rng = np.random.default_rng(5)
    V = rng.normal(size=(mixed_mesh.n_vertices, 3)) * 10.0 ** rng.integers(
        -300, 300, size=(mixed_mesh.n_vertices, 1))
    V[0] = [5e-324, -0.0, 1.7976931348623157e308]
    mesh = mixed_mesh.with_vertices(V)
    fast = tmp_path / "fast.obj"
    write_obj(fast, mesh)
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1] / "src"))
    subprocess.run([sys.executable, "-c", _WITHOUT_ACCELERATORS, str(fast),
                    str(tmp_path / "plain.obj"), str(tmp_path / "v.npy")],
                   env=env, check=True)
    plain = read_obj(tmp_path / "plain.obj")
    assert_same_mesh(plain, mesh)
    assert np.array_equal(np.load(tmp_path / "v.npy").view(np.int64), V.view(np.int64))
    assert np.array_equal(read_obj(fast).vertices.view(np.int64), V.view(np.int64))
