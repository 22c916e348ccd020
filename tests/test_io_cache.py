"""The on-disk cache: content keys, entries read back whole, bad entries ignored."""

import os

import numpy as np
import pytest

from facewrap.io import cache


@pytest.fixture
def folder(tmp_path, monkeypatch):
    monkeypatch.setenv("FACEWRAP_CACHE_DIR", str(tmp_path / "c"))
    monkeypatch.delenv("FACEWRAP_CACHE", raising=False)
    return tmp_path / "c"


def test_round_trip_and_names(folder):
    key = cache.content_key(np.arange(4.0), "x")
    arrays = {"v": np.random.default_rng(0).normal(size=(5, 3)), "m": np.ones(5, bool)}
    cache.save_arrays("demo", key, arrays)
    got = cache.load_arrays("demo", key, ["v", "m"])
    assert np.array_equal(got["v"], arrays["v"]) and got["m"].dtype == bool
    assert cache.load_arrays("demo", key, ["v", "missing"]) is None
    assert cache.load_arrays("other", key, ["v"]) is None


def test_keys_follow_content():
    a = np.arange(6.0)
    assert cache.content_key(a) != cache.content_key(a + 1e-12)
    assert cache.content_key(a) != cache.content_key(a.reshape(2, 3))
    assert cache.content_key(a) != cache.content_key(a.astype(np.float32))
    assert cache.content_key(b"ab", b"c") != cache.content_key(b"a", b"bc")


def test_version_mismatch_is_a_miss(folder):
    key = cache.content_key(b"v")
    cache.save_arrays("demo", key, {"x": np.zeros(2)}, version=1)
    assert cache.load_arrays("demo", key, ["x"], version=2) is None
    assert cache.load_arrays("demo", key, ["x"], version=1) is not None


@pytest.mark.parametrize("damage", ["truncate", "garbage", "empty"])
def test_damaged_entry_is_ignored_then_rewritten(folder, damage):
    key = cache.content_key(b"d")
    cache.save_arrays("demo", key, {"x": np.arange(1000.0)})
    (path,) = list(folder.iterdir())
    data = path.read_bytes()
    path.write_bytes({"truncate": data[: len(data) // 2], "garbage": os.urandom(300),
                      "empty": b""}[damage])
    assert cache.load_arrays("demo", key, ["x"]) is None
    cache.save_arrays("demo", key, {"x": np.arange(1000.0)})
    assert np.array_equal(cache.load_arrays("demo", key, ["x"])["x"], np.arange(1000.0))


def test_off_switch_reads_and_writes_nothing(folder, monkeypatch):
    monkeypatch.setenv("FACEWRAP_CACHE", "0")
    cache.save_arrays("demo", "k", {"x": np.zeros(1)})
    assert not folder.exists()
    assert cache.load_arrays("demo", "k", ["x"]) is None


def test_unwritable_cache_is_not_an_error(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("FACEWRAP_CACHE_DIR", str(blocker / "sub"))
    cache.save_arrays("demo", "k", {"x": np.zeros(1)})  # no exception
    assert cache.load_arrays("demo", "k", ["x"]) is None


def test_pickled_objects_are_never_loaded(folder):
    folder.mkdir(parents=True)
    key = cache.content_key(b"p")
    with open(folder / f"demo-{key}.npz", "wb") as f:
        np.savez(f, x=np.array([{"a": 1}], dtype=object),
                 __facewrap_cache__=np.array([1, 1]))
    assert cache.load_arrays("demo", key, ["x"]) is None


# -- shape folders read once per content (datasets.load_shape_folder) ------------------

def _shape_folder(tmp_path, mesh, n_shapes=3):
    from facewrap.io.obj import write_obj
    folder = tmp_path / "shapes"
    folder.mkdir()
    rng = np.random.default_rng(1)
    for k in range(n_shapes):
        write_obj(folder / f"s{k}.obj", mesh.with_vertices(
            mesh.vertices + rng.normal(size=mesh.vertices.shape)))
    return folder


def _entries(folder, kind="obj-vertices"):
    return sorted(folder.glob(f"{kind}-*.npz")) if folder.exists() else []


def test_shape_folder_is_cached_outside_the_inputs(folder, tmp_path, mixed_mesh):
    from facewrap.datasets import load_shape_folder
    shapes_dir = _shape_folder(tmp_path, mixed_mesh)
    inputs_before = sorted(p.name for p in shapes_dir.iterdir())
    first = load_shape_folder(shapes_dir, mixed_mesh)
    assert len(_entries(folder)) == 3
    stamps = [p.stat().st_mtime_ns for p in _entries(folder)]
    again = load_shape_folder(shapes_dir, mixed_mesh)
    assert list(again) == list(first)
    for name in first:
        assert again[name].dtype == np.float64
        assert np.array_equal(again[name], first[name])
    # answered from the entries, not rewritten; nothing written beside the inputs
    assert [p.stat().st_mtime_ns for p in _entries(folder)] == stamps
    assert sorted(p.name for p in shapes_dir.iterdir()) == inputs_before


def test_edited_shape_with_same_size_and_time_is_read_again(folder, tmp_path, mixed_mesh):
    from facewrap.datasets import load_shape_folder
    shapes_dir = _shape_folder(tmp_path, mixed_mesh, 1)
    path = shapes_dir / "s0.obj"
    load_shape_folder(shapes_dir, mixed_mesh)
    text, st = path.read_bytes(), path.stat()
    # swap two digits: same size, and the old modification time put back
    i = text.index(b"v ") + 2
    while not (text[i:i + 1].isdigit() and text[i + 1:i + 2].isdigit()
               and text[i] != text[i + 1]):
        i += 1
    edited = text[:i] + text[i + 1:i + 2] + text[i:i + 1] + text[i + 2:]
    path.write_bytes(edited)
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    from facewrap.io.obj import read_obj_vertices
    assert np.array_equal(load_shape_folder(shapes_dir, mixed_mesh)["s0"],
                          read_obj_vertices(path))
    assert not np.array_equal(read_obj_vertices(path),
                              read_obj_vertices(path, data=text))


def _foreign(path, shape, kind):
    """Replace a cache entry of arrays of ``shape`` by a well-formed one that is not
    what a parse gives."""
    meta = np.array([1, 1], dtype=np.int64)
    fewer = shape[:-2] + (shape[-2] - 1, 3)
    arrays = {"wrong count": np.zeros(fewer), "float32": np.zeros(shape, np.float32),
              "nan": np.full(shape, np.nan), "other version": np.zeros(shape),
              "flat": np.zeros(int(np.prod(shape))), "no vertices": None}
    payload = {"__facewrap_cache__": np.array([1, 7]) if kind == "other version" else meta}
    if arrays[kind] is not None:
        payload["vertices"] = arrays[kind]
    with open(path, "wb") as f:
        np.savez(f, **payload)


@pytest.mark.parametrize("kind", ["garbage", "truncated", "wrong count", "float32", "nan",
                                  "other version", "flat", "no vertices"])
def test_bad_shape_entries_are_ignored_and_rewritten(folder, tmp_path, mixed_mesh, kind):
    from facewrap.datasets import load_shape_folder
    shapes_dir = _shape_folder(tmp_path, mixed_mesh, 1)
    truth = load_shape_folder(shapes_dir, mixed_mesh)["s0"]
    n = mixed_mesh.n_vertices
    for entry, shape in ((_entries(folder)[0], (n, 3)),
                         (_entries(folder, "shape-folder")[0], (1, n, 3))):
        good = entry.read_bytes()
        if kind == "garbage":
            entry.write_bytes(os.urandom(len(good)))
        elif kind == "truncated":
            entry.write_bytes(good[: len(good) // 2])
        else:
            _foreign(entry, shape, kind)
    assert np.array_equal(load_shape_folder(shapes_dir, mixed_mesh)["s0"], truth)
    # both rewritten with the parse: the next read is a hit on good entries
    with np.load(_entries(folder)[0]) as data:
        assert np.array_equal(data["vertices"], truth)
    with np.load(_entries(folder, "shape-folder")[0]) as data:
        assert np.array_equal(data["vertices"], truth[None])


def test_a_folder_seen_before_is_one_entry_and_an_edit_reparses_one_file(
        folder, tmp_path, mixed_mesh):
    from facewrap.datasets import load_shape_folder
    from facewrap.io.obj import read_obj_vertices, write_obj
    shapes_dir = _shape_folder(tmp_path, mixed_mesh, 3)
    first = load_shape_folder(shapes_dir, mixed_mesh)
    assert len(_entries(folder, "shape-folder")) == 1
    for entry in _entries(folder):          # the folder's entry alone answers
        entry.unlink()
    again = load_shape_folder(shapes_dir, mixed_mesh)
    assert all(np.array_equal(again[k], first[k]) for k in first)
    assert _entries(folder) == []
    load_shape_folder(shapes_dir, mixed_mesh, exclude=("s2",))   # another file set
    stamps = {p.name: p.stat().st_mtime_ns for p in _entries(folder)}
    assert len(stamps) == 2
    moved = mixed_mesh.vertices + 1.0
    write_obj(shapes_dir / "s1.obj", mixed_mesh.with_vertices(moved))
    edited = load_shape_folder(shapes_dir, mixed_mesh)
    assert np.array_equal(edited["s1"], read_obj_vertices(shapes_dir / "s1.obj"))
    assert np.array_equal(edited["s0"], first["s0"])
    # s0's entry was used as it was; s1's new content got an entry of its own
    after = {p.name: p.stat().st_mtime_ns for p in _entries(folder)}
    assert {k: v for k, v in after.items() if k in stamps} == stamps
    assert len(after) == 4


def test_shape_cache_off_and_errors_unchanged(folder, tmp_path, mixed_mesh, monkeypatch):
    from facewrap.datasets import load_shape_folder
    from facewrap.errors import InputError
    from facewrap.mesh import Mesh
    shapes_dir = _shape_folder(tmp_path, mixed_mesh, 2)
    monkeypatch.setenv("FACEWRAP_CACHE", "0")
    load_shape_folder(shapes_dir, mixed_mesh)
    assert not folder.exists()
    monkeypatch.delenv("FACEWRAP_CACHE")
    load_shape_folder(shapes_dir, mixed_mesh)   # cached for 7 vertices ...
    other = Mesh(np.eye(3), [[0, 1, 2]])
    with pytest.raises(InputError, match=r"s0\.obj: has 7 vertices, expected 3"):
        load_shape_folder(shapes_dir, other)    # ... which says nothing about 3


def _settled(monkeypatch):
    """Folders hashed from now on count as hashed long after their files were written
    (as a template's shapes are on a user's second run)."""
    import facewrap.datasets as ds
    monkeypatch.setattr(ds.time, "time", lambda: 4e9)   # (2096: long after)


def _count_reads(monkeypatch):
    import facewrap.datasets as ds
    reads = []
    real = ds.read_file_bytes
    monkeypatch.setattr(ds, "read_file_bytes", lambda p, **kw: reads.append(p) or real(p, **kw))
    return reads


def test_a_settled_folder_is_not_read_again(folder, tmp_path, mixed_mesh, monkeypatch):
    from facewrap.datasets import load_shape_folder
    from facewrap.io.obj import read_obj_vertices, write_obj
    shapes_dir = _shape_folder(tmp_path, mixed_mesh, 3)
    _settled(monkeypatch)
    first = load_shape_folder(shapes_dir, mixed_mesh)
    assert len(_entries(folder, "folder-stat")) == 1
    reads = _count_reads(monkeypatch)
    again = load_shape_folder(shapes_dir, mixed_mesh)
    assert reads == [] and all(np.array_equal(again[k], first[k]) for k in first)
    # a file replaced (another inode, size and times): its folder is read and hashed
    moved = mixed_mesh.vertices + 1.0
    write_obj(shapes_dir / "s1.obj", mixed_mesh.with_vertices(moved))
    edited = load_shape_folder(shapes_dir, mixed_mesh)
    assert len(reads) == 3
    assert np.array_equal(edited["s1"], read_obj_vertices(shapes_dir / "s1.obj"))


def test_a_folder_written_just_now_is_always_read(folder, tmp_path, mixed_mesh,
                                                  monkeypatch):
    # files changed within STAT_SETTLED of the hashing could be changed again with
    # the same times: their stat records are not trusted, the bytes are hashed
    from facewrap.datasets import load_shape_folder
    shapes_dir = _shape_folder(tmp_path, mixed_mesh, 2)
    load_shape_folder(shapes_dir, mixed_mesh)
    reads = _count_reads(monkeypatch)
    load_shape_folder(shapes_dir, mixed_mesh)
    assert len(reads) == 2
