import json
import os
import re

import numpy as np
import pytest

from facewrap.errors import InputError
from facewrap.io.landmarks import (read_landmarks, read_landmarks_json, read_ljson,
                                   read_markers, read_points, read_vertex_indices,
                                   write_landmarks_json, write_markers, write_points,
                                   write_vertex_indices)
from facewrap.landmarks import IBUG68_NAMES, Landmarks, pair_landmarks
from facewrap.mesh import Mesh

from conftest import needs_data, DATA


def test_positions_of_every_kind():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.]])
    T = np.array([[0, 1, 2], [1, 3, 2]])
    lm = Landmarks([3, -1, -1], [-1, 1, -1], [[0, 0, 0], [0.5, 0.5, 0], [0, 0, 0]],
                   [[np.nan] * 3, [np.nan] * 3, [7, 8, 9]], names=["a", "b", "c"])
    P = lm.positions(Mesh(V, T))
    assert P.tolist() == [[1, 1, 0], [1, 0.5, 0], [7, 8, 9]]
    assert lm.kinds.tolist() == ["vertex", "surface", "point"]
    with pytest.raises(ValueError, match="triangles"):
        lm.positions(V)


def test_landmark_kind_must_be_unique():
    with pytest.raises(ValueError, match="exactly one"):
        Landmarks([1], [2], [[1, 0, 0]], [[np.nan] * 3])
    with pytest.raises(ValueError, match="unique"):
        Landmarks.from_vertices([1, 2], names=["x", "x"])


def test_out_of_range_landmark_is_named():
    lm = Landmarks.from_vertices([0, 10], names=["chin", "nose"])
    with pytest.raises(ValueError, match="nose: vertex 10 out of range"):
        lm.positions(np.zeros((5, 3)))


def test_pairing_by_name_and_by_order():
    a = Landmarks.from_vertices([5, 6, 7])
    b = Landmarks.from_points(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="counts differ: 3 vs 2"):
        pair_landmarks(a, b)
    ia, ib = pair_landmarks(a, Landmarks.from_points(np.ones((3, 3))))
    assert ia.tolist() == ib.tolist() == [0, 1, 2]
    named = Landmarks.from_vertices([1, 2], names=["x", "y"])
    with pytest.raises(ValueError, match="no name in common"):
        pair_landmarks(named, Landmarks.from_vertices([1], names=["z"]))


def test_ibug_names():
    assert len(IBUG68_NAMES) == 68 and len(set(IBUG68_NAMES)) == 68
    assert IBUG68_NAMES[17] == "brow_r_0" and IBUG68_NAMES[36] == "eye_r_0"
    assert IBUG68_NAMES[48] == "mouth_outer_0" and IBUG68_NAMES[67] == "mouth_inner_7"


def test_round_trips(tmp_path):
    lm = Landmarks([3, -1, -1], [-1, 1, -1], [[0, 0, 0], [0.2, 0.3, 0.5], [0, 0, 0]],
                   [[np.nan] * 3, [np.nan] * 3, [7.1, 8e-9, -9]], names=["a", "b", "c"])
    write_landmarks_json(tmp_path / "l.json", lm)
    back = read_landmarks(tmp_path / "l.json")
    for k in ("vertex", "triangle", "barycentric"):
        assert np.array_equal(getattr(back, k), getattr(lm, k))
    assert np.array_equal(back.points[2], lm.points[2]) and back.names == lm.names

    pts = Landmarks.from_points(np.random.default_rng(1).normal(size=(5, 3)))
    write_points(tmp_path / "p.txt", pts)
    assert np.array_equal(read_landmarks(tmp_path / "p.txt").points, pts.points)

    vid = Landmarks.from_vertices([4, 0, 12])
    write_vertex_indices(tmp_path / "v.txt", vid)
    assert read_landmarks(tmp_path / "v.txt").vertex.tolist() == [4, 0, 12]

    write_markers(tmp_path / "m.cons", [1, 2], [30, 40])
    s, t = read_markers(tmp_path / "m.cons")
    assert s.tolist() == [1, 2] and t.tolist() == [30, 40]


def test_formats_with_names_commas_and_comments(tmp_path):
    p = tmp_path / "pts.csv"
    p.write_text("# header\n1,2,3\n4, 5, 6\n")
    assert read_landmarks(p).points.tolist() == [[1, 2, 3], [4, 5, 6]]
    p.write_text("1 2 3 tip\n4 5 6 chin\n")
    assert read_points(p).names == ("tip", "chin")
    p.write_text("750, 3386\n524, 3737\n")
    assert read_markers(p)[1].tolist() == [3386, 3737]
    p = tmp_path / "m.yml"
    p.write_text('markers:\n  - "1:2"  # a comment\n  - "3:4"\n')
    assert read_markers(p)[0].tolist() == [1, 3]
    p = tmp_path / "m.json"
    p.write_text(json.dumps({"format": "facewrap.markers", "version": 1,
                             "pairs": [[1, 2], [3, 4]]}))
    assert read_markers(p)[1].tolist() == [2, 4]


@pytest.mark.parametrize("name, text, reader, phrase, line", [
    ("e.txt", "", read_vertex_indices, "empty file", None),
    ("v.txt", "1 2\n3 x\n", read_vertex_indices, "not an integer", 2),
    ("v.txt", "1 2\n-3\n", read_vertex_indices, "negative", 2),
    ("p.txt", "1 2 3\n4 5\n", read_points, "expected 'x y z'", 2),
    ("p.txt", "1 2 3\n4 5 nan\n", read_points, "NaN", 2),
    ("p.txt", "1 2 3\n4 5 q\n", read_points, "not a number", 2),
    ("p.txt", "1 2 3 a\n4 5 6\n", read_points, "some points have names", None),
    ("m.cons", "3\n1 2\n3 4\n", read_markers, "count line says 3", None),
    ("m.cons", "2\n1 2\n3\n", read_markers, "expected 'source_vertex", 3),
    ("m.cons", "1 -2\n", read_markers, "negative vertex id", 1),
    ("m.yml", "markers: [\n", read_markers, "invalid YAML", None),
    ("m.yml", "other: 1\n", read_markers, "no 'markers'", None),
    ("m.yml", "markers:\n  - 'a:b'\n", read_markers, "not 'source:target'", None),
    ("l.json", "{", read_landmarks_json, "invalid JSON", 1),
    ("l.json", '{"format": "x"}', read_landmarks_json, "not a facewrap landmark", None),
    ("l.json", '{"format": "facewrap.landmarks", "landmarks": [{"vertex": -1}]}',
     read_landmarks_json, "non-negative", None),
    ("l.json", '{"format": "facewrap.landmarks", "landmarks": [{"vertex": 1, '
     '"point": [1, 2, 3]}]}', read_landmarks_json, "exactly one", None),
    ("l.json", '{"format": "facewrap.landmarks", "landmarks": [{"point": [1, 2]}]}',
     read_landmarks_json, "3 finite numbers", None),
    ("l.ljson", '{"version": 3, "groups": {}}', read_ljson, "no 'groups'", None),
    ("l.ljson", '{"version": 3, "groups": {"LJSON": {"landmarks": {"points": '
     '[[1, 2, 3], null]}}}}', read_ljson, "landmark 1 is missing", None),
])
def test_malformed_landmark_files(tmp_path, name, text, reader, phrase, line):
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(InputError) as exc:
        reader(p)
    assert str(exc.value).startswith(str(p)) and phrase in str(exc.value)
    if line is not None:
        assert exc.value.line == line


def test_vertex_index_range_checked(tmp_path):
    p = tmp_path / "v.txt"
    p.write_text("0 1\n2 9\n")
    with pytest.raises(InputError, match="9 out of range"):
        read_vertex_indices(p, n_vertices=5)


@needs_data
def test_real_landmark_files():
    raw = read_ljson(DATA / "scans/james/james.ljson", ibug68=False)
    assert len(raw) == 68 and raw.names[0] == "chin_0"
    assert raw.names[17] == "leye_0" and raw.names[48] == "mouth_0"
    james = read_ljson(DATA / "scans/james/james.ljson")
    assert james.names == IBUG68_NAMES
    # iBUG order: brows 17-26 come before the nose, eyes 36-47 after it
    assert np.array_equal(james.points[17], raw.points[29])  # leyebrow_0
    assert np.array_equal(james.points[36], raw.points[17])  # leye_0
    assert np.array_equal(james.points[42], raw.points[23])  # reye_0
    # both brows above both eyes; the first brow on the first eye's side
    assert james.points[17:27, 1].min() > james.points[36:48, 1].max() - 5
    assert np.sign(james.points[19, 0] - james.points[30, 0]) == \
        np.sign(james.points[37, 0] - james.points[30, 0])
    horse = read_landmarks(DATA / "onizuka2019/landmarks/landmarks_Horse.txt")
    assert len(horse) == 51 and horse.vertex[0] == 1115
    src, tgt = read_markers(DATA / "sumner2004/horse-camel/horse_camel.cons")
    assert len(src) == 107 and (src[0], tgt[0]) == (750, 3386)
    src, tgt = read_markers(DATA / "sumner2004/cat-lion/markers-cat-lion.yml")
    assert (src[0], tgt[0]) == (2653, 1316)
    five = read_landmarks(DATA / "scans/meshmonk/DemoFaceLandmarks.csv")
    assert len(five) == 5


def test_pair_landmarks_refuses_names_on_one_side_only():
    named = Landmarks.from_vertices([0, 1, 2], names=["a", "b", "c"])
    unnamed = Landmarks.from_points(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="the template landmarks have names and the "
                                         "scan landmarks have none"):
        pair_landmarks(named, unnamed, ("template", "scan"))
    with pytest.raises(ValueError, match="the scan landmarks have names"):
        pair_landmarks(unnamed, named, ("template", "scan"))
    ia, ib = pair_landmarks(Landmarks.from_vertices([0, 1, 2]), unnamed)
    assert ia.tolist() == ib.tolist() == [0, 1, 2]
    # iBUG-68 names in their order (a menpo .ljson) beside 68 plain ids: by order
    ibug = Landmarks.from_points(np.zeros((68, 3)), names=IBUG68_NAMES)
    ia, ib = pair_landmarks(Landmarks.from_vertices(np.arange(68)), ibug)
    assert ia.tolist() == ib.tolist() == list(range(68))
    shuffled = Landmarks.from_points(np.zeros((68, 3)), names=IBUG68_NAMES[::-1])
    with pytest.raises(ValueError, match="have names"):
        pair_landmarks(Landmarks.from_vertices(np.arange(68)), shuffled)


def test_markers_giving_a_vertex_two_partners_are_refused(tmp_path):
    p = tmp_path / "m.txt"
    p.write_text("5 6\n7 8\n5 6\n")   # a pair given twice agrees with itself
    src, tgt = read_markers(p)
    assert src.tolist() == [5, 7, 5] and tgt.tolist() == [6, 8, 6]
    for text, said in (("5 6\n7 8\n5 9\n", "markers 0 and 2 pair source vertex 5 with "
                                           r"two target vertices \(6 and 9\)"),
                       ("5 6\n7 8\n1 8\n", "markers 1 and 2 pair target vertex 8 with "
                                           r"two source vertices \(7 and 1\)")):
        p.write_text(text)
        with pytest.raises(InputError, match=f"^{re.escape(str(p))}: {said}"):
            read_markers(p)
    j = tmp_path / "m.json"
    j.write_text(json.dumps({"format": "facewrap.markers", "pairs": [[1, 2], [1, 3]]}))
    with pytest.raises(InputError, match="one partner only"):
        read_markers(j)


def test_landmark_text_with_a_byte_order_mark(tmp_path):
    p = tmp_path / "l.txt"
    p.write_bytes(b"\xef\xbb\xbf1, 2, 3\r\n4 5 6\r\n7 8 9.5\r\n")
    assert read_landmarks(p, kind="points").points[0].tolist() == [1.0, 2.0, 3.0]


def test_landmark_json_without_names_is_unnamed_and_stays_so(tmp_path):
    p = tmp_path / "l.json"
    p.write_text(json.dumps({"format": "facewrap.landmarks",
                             "landmarks": [{"vertex": 3}, {"point": [1, 2, 3]}]}))
    lm = read_landmarks_json(p)
    assert lm.names is None and lm.vertex.tolist() == [3, -1]
    write_landmarks_json(tmp_path / "w.json", lm)
    assert read_landmarks_json(tmp_path / "w.json").names is None
    p.write_text(json.dumps({"format": "facewrap.landmarks",
                             "landmarks": [{"vertex": 3, "name": "nose"}, {"vertex": 4}]}))
    assert read_landmarks_json(p).names == ("nose", "1")   # one named: all are


@pytest.mark.parametrize("make, said", [
    (lambda p: p.mkdir(), "is a folder, not a file"),
    (lambda p: os.mkfifo(p), "is a fifo, not a regular file"),
    (lambda p: os.symlink(p, p), "is a symlink loop, not a regular file")])
def test_an_input_that_is_not_a_file_says_what_it_is(tmp_path, make, said):
    p = tmp_path / "l.txt"
    make(p)
    with pytest.raises(InputError, match=f"^{re.escape(str(p))}: {said}$"):
        read_landmarks(p)


def test_deeply_nested_json_is_one_error(tmp_path):
    p = tmp_path / "l.json"
    p.write_text("[" * 200_000 + "]" * 200_000)
    with pytest.raises(InputError, match="nested too deeply"):
        read_landmarks(p)


@pytest.mark.parametrize("items, said", [
    ([{"point": [True, False, 1]}], "landmark 0: 'point' must be 3 finite numbers"),
    ([{"point": [1, 2]}], "'point' must be 3 finite numbers"),
    ([{"triangle": 0, "barycentric": [1, 0, None]}], "'barycentric' must be 3 finite")])
def test_landmark_json_numbers_are_numbers(tmp_path, items, said):
    p = tmp_path / "l.json"
    p.write_text(json.dumps({"format": "facewrap.landmarks", "landmarks": items}))
    with pytest.raises(InputError, match=said):
        read_landmarks_json(p)


def test_a_later_landmark_format_version_is_refused(tmp_path):
    p = tmp_path / "l.json"
    p.write_text(json.dumps({"format": "facewrap.landmarks", "version": 99,
                             "landmarks": [{"vertex": 1}]}))
    with pytest.raises(InputError, match="format version 99 is not supported"):
        read_landmarks_json(p)
