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
