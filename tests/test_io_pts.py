"""iBUG .pts landmark files (facewrap.io.landmarks.read_pts)."""

from __future__ import annotations

import numpy as np
import pytest

from facewrap.errors import InputError
from facewrap.io.landmarks import read_landmarks, read_pts


def pts_text(rows, n=None, header="version: 1\n"):
    body = "".join(" ".join(repr(float(x)) for x in r) + "\n" for r in rows)
    return f"{header}n_points: {len(rows) if n is None else n}\n{{\n{body}}}\n"


def test_3d_rows_are_points_in_file_order(tmp_path):
    P = np.random.default_rng(1).normal(size=(68, 3)) * 50
    p = tmp_path / "scan.pts"
    p.write_text(pts_text(P))
    for lm in (read_pts(p), read_landmarks(p), read_landmarks(p, kind="points")):
        assert len(lm) == 68 and lm.names is None
        assert np.array_equal(lm.points, P)  # repr round-trips exactly


def test_windows_line_ends_and_comments_are_read(tmp_path):
    p = tmp_path / "a.pts"
    p.write_bytes(pts_text([[1, 2, 3], [4, 5, 6], [7, 8, 9]]).replace(
        "\n", "  # note\r\n", 1).replace("\n", "\r\n").encode())
    assert read_pts(p).points.tolist() == [[1, 2, 3], [4, 5, 6], [7, 8, 9]]


@pytest.mark.parametrize("text, match", [
    (pts_text([[1, 2], [3, 4], [5, 6]]), "2-D landmarks; facewrap needs 3-D points"),
    (pts_text([[1, 2, 3], [3, 4, 5]], n=3), "n_points says 3 but 2 rows follow"),
    (pts_text([[1, 2, 3], [3, 4]]), "expected 'x y z'"),
    (pts_text([[1, 2, 3]]).replace("}\n", ""), "no '}' closing"),
    (pts_text([[1, 2, 3]]).replace("{\n", ""), "not an iBUG .pts header line"),
    (pts_text([[1, 2, 3]]).replace("n_points: 1\n", ""), "no 'n_points:' line"),
    (pts_text([[1, 2, 3]], n="-2"), "n_points must be a positive integer"),
    (pts_text([[1, 2, 3]], n="x"), "n_points must be a positive integer"),
    (pts_text([[1, 2, 3]]).replace("3.0", "abc"), "not a number"),
    (pts_text([[1, 2, 3]]).replace("3.0", "nan"), "NaN or infinite coordinate"),
    ("version: 1\n", "no '{' opening"),
    ("", "empty file"),
])
def test_bad_files_are_one_line_naming_the_file(tmp_path, text, match):
    p = tmp_path / "bad.pts"
    p.write_text(text)
    with pytest.raises(InputError, match=match) as info:
        read_landmarks(p)
    assert str(p) in str(info.value) and "\n" not in str(info.value)


def test_wrap_refuses_2d_pts_with_one_line(tmp_path, capsys):
    from conftest import facewrap
    from facewrap.sample import make_scan, make_template, write_sample
    tpl = make_template(24)
    paths = write_sample(tmp_path / "s", tpl, make_scan(tpl, resolution=30, texture_size=8))
    lm = tmp_path / "scan.pts"
    lm.write_text(pts_text(np.loadtxt(paths["scan_landmarks"], usecols=(0, 1))))
    capsys.readouterr()
    rc = facewrap("wrap", paths["template"], paths["scan"], "-o", tmp_path / "o.obj",
                  "--template-landmarks", paths["template_landmarks"],
                  "--scan-landmarks", lm)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and err == [f"facewrap: error: {lm}: 2-D landmarks; facewrap needs "
                               "3-D points"]
    assert not (tmp_path / "o.obj").exists()
