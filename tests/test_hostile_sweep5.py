"""Hostile inputs of a fifth sweep: files that are valid but implausible.

Classes:

- an ASCII STL missing only its last ``endsolid`` line was "holds no triangles"
  (trimesh's reader looks for ``endsolid`` before anything else), and a vertex row
  with a word among its numbers was read as the numbers before it, silently; STL
  is now read by facewrap itself (``io/stl.py``), a missing last ``endsolid`` read
  as the end of the solid, every other row checked against the format's pattern
  and a bad one named by its line;
- a GLB whose accessor or bufferView points beyond the bytes it reads from failed
  with "cannot read GLB: AssertionError" (or a numpy reshape error); each
  bufferView is now checked inside its buffer and each accessor inside its
  bufferView (a byteStride shorter than an element, which trimesh read as
  overlapping garbage, too), naming the one that overruns;

Inputs are tiny meshes written here and the built-in sample at its smallest.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from conftest import facewrap
from facewrap.io.dispatch import read_mesh
# the fixture: the built-in sample at its smallest (template 24, scan 40), as files
from test_hostile_more import sample  # noqa: F401
from test_hostile_sweep import error_line, warning_lines, wrap_argv


# -- STL: a missing last endsolid, rows out of the pattern -----------------------------------
def ascii_stl(n: int = 3) -> list[str]:
    """The rows of an ASCII STL of ``n`` triangles of a fan, ``endsolid`` last."""
    rows = ["solid scan"]
    for k in range(n):
        a, b = 2 * np.pi * k / n, 2 * np.pi * (k + 1) / n
        rows += ["  facet normal 0 0 1", "    outer loop", "      vertex 0 0 0",
                 f"      vertex {10 * np.cos(a):.9g} {10 * np.sin(a):.9g} 0",
                 f"      vertex {10 * np.cos(b):.9g} {10 * np.sin(b):.9g} 0",
                 "    endloop", "  endfacet"]
    return rows + ["endsolid scan"]


def test_an_ascii_stl_without_its_last_endsolid_reads(tmp_path):
    whole, cut = tmp_path / "whole.stl", tmp_path / "cut.stl"
    whole.write_text("\n".join(ascii_stl()) + "\n")
    cut.write_text("\n".join(ascii_stl()[:-1]) + "\n")
    a, b = read_mesh(whole), read_mesh(cut)
    assert len(a.triangles) == 3
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.triangles, b.triangles)


@pytest.mark.parametrize("edit, needle", [
    (lambda r: r[:-4], "the facet of line 16 runs to the end of the file (cut short?)"),
    (lambda r: r[:-4] + ["endsolid"], "the facet of line 16 ends early"),
    (lambda r: r[:3] + ["      vertex 1 abc 2"] + r[4:], "cut.stl:4: vertex row is not "
                                                          "three numbers"),
    (lambda r: r[:3] + ["      vertex 1 2"] + r[4:], "cut.stl:4: vertex row is not three"),
    (lambda r: r[:6] + r[7:], "cut.stl:7: expected 'endloop', found 'endfacet'"),
    (lambda r: [r[0], r[-1]], "holds no triangles"),
])
def test_an_ascii_stl_out_of_its_pattern_names_the_line(tmp_path, capsys, edit, needle):
    p = tmp_path / "cut.stl"
    p.write_text("\n".join(edit(ascii_stl())) + "\n")
    error_line(capsys, facewrap("info", p), str(p), needle)


# -- GLB: accessors and bufferViews beyond their bytes ----------------------------------------
def glb(doc: dict, binary: bytes) -> bytes:
    """A GLB of the glTF JSON ``doc`` and one binary chunk."""
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = (struct.pack("<II", len(js), 0x4E4F534A) + js
              + struct.pack("<II", len(binary), 0x004E4942) + binary)
    return b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks


def quad_doc() -> tuple[dict, bytes]:
    V = np.array([[0, 0, 0], [100, 0, 0], [0, 100, 0], [100, 100, 10]], np.float32)
    I = np.array([0, 1, 2, 1, 3, 2], np.uint32)
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
           "buffers": [{"byteLength": 72}],
           "bufferViews": [{"buffer": 0, "byteLength": 48},
                           {"buffer": 0, "byteOffset": 48, "byteLength": 24}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4,
                          "type": "VEC3", "min": [0, 0, 0], "max": [100, 100, 10]},
                         {"bufferView": 1, "componentType": 5125, "count": 6,
                          "type": "SCALAR"}]}
    return doc, V.tobytes() + I.tobytes()


@pytest.mark.parametrize("change, needle", [
    (lambda d: d["accessors"][0].update(byteOffset=4096),
     "accessor 0 overruns bufferView 0: its 4 elements need bytes 4096 to 4144, the view "
     "holds 48 bytes"),
    (lambda d: d["accessors"][1].update(count=600),
     "accessor 1 overruns bufferView 1"),
    (lambda d: d["bufferViews"][1].update(byteOffset=4096),
     "bufferView 1 overruns buffer 0: it spans bytes 4096 to 4120, the buffer holds 72"),
    (lambda d: d["bufferViews"][0].update(byteLength=4096), "bufferView 0 overruns"),
    # the JSON says the buffer is bigger, the file's binary chunk is not
    (lambda d: (d["buffers"][0].update(byteLength=8192),
                d["bufferViews"][1].update(byteOffset=4096)), "the buffer holds 72"),
    (lambda d: d["bufferViews"][0].update(buffer=3), "names buffer 3, which the file"),
    (lambda d: d["accessors"][1].update(bufferView=7), "names bufferView 7"),
    (lambda d: d["bufferViews"][0].update(byteStride=4), "byteStride 4, less than the "
                                                         "12 bytes"),
    (lambda d: d["accessors"][1].update(count=-1), "count is -1, not a whole number"),
])
def test_a_glb_overrunning_its_buffer_names_the_culprit(tmp_path, capsys, change,
                                                        needle):
    doc, binary = quad_doc()
    p = tmp_path / "scan.glb"
    p.write_bytes(glb(doc, binary))
    assert facewrap("info", p) == 0            # the file as it is reads
    capsys.readouterr()
    change(doc)
    p.write_bytes(glb(doc, binary))
    line = error_line(capsys, facewrap("info", p), str(p), needle)
    assert "AssertionError" not in line and "reshape" not in line
